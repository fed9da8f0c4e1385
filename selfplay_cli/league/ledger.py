"""The game ledger: matches, the append-only games with their seats, the online Elo, and the rating table derived
from them for every kind of game.

:class:`Ledger` is a part of :class:`~selfplay_cli.league.store.League`. The ledger keeps real games: any number of
seats, each seat's player, float score and points (:class:`~selfplay_cli.results.GameResult` is what goes in). A
match row says how its games were played (``params``), and, for a game whose results are not decided like Pong's
(two seats, one against the other), its :class:`~selfplay_cli.results.Rules` (``params["rules"]``: kind, sides, tie
tolerance), so the ratings never depend on code that may be gone when they are recomputed.

What ratings are fitted from is derived (:meth:`Ledger.games`), one row per pairwise result:

* two-sides: one row per game between the two sides' players (seat-swapped games of one seed pair up);
* cooperative: one row per comparison: two different players' episodes on the same seed within one match, the
  higher team return winning (a difference within the tie tolerance: a draw); the i-th episode of one player on a
  seed is compared with the i-th of the other;
* free-for-all: one row per two different players of a game, from the final order of their scores.

Ratings are per variant (:mod:`selfplay_cli.league.variants`): every reader takes the games of one variant of a
game, the default one unless it asks for another, derived from the options each match row records
(``params["env_options"]``).

The online Elo on each player row is a cache updated from the same pairwise results, in the transaction that
stores their games (several results of one game move the ratings together, from the ratings before it);
:meth:`Ledger.recompute_online_elo` rebuilds it from the ledger. A player has one online Elo, so only the games of
the default variant move it: it is the live view beside the default ladder.
"""

from __future__ import annotations

import contextlib
import math
from collections import defaultdict
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import and_, func, or_, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, aliased, raiseload

from selfplay_cli.league.bounded_json import say_unusable, unreadable
from selfplay_cli.league.db import Database, LeagueError, Part
from selfplay_cli.league.games import declaration
from selfplay_cli.league.models import Game, GameSeat, Match, Player, utcnow
from selfplay_cli.league.roster import DEFAULT_ELO, check_env_name
from selfplay_cli.league.seeds import Seeds
from selfplay_cli.league.variants import variant_key
from selfplay_cli.results import COOPERATIVE, FREE_FOR_ALL, TWO_SIDES, GameResult, Rules, compare, pairwise
from selfplay_cli.stats.elo import elo_update

__all__ = ["KIND_CODES", "MATCH_KINDS", "GameRow", "GameTable", "Ledger", "rules_for_env"]

MATCH_KINDS = ("match", "tournament", "gate", "training", "eval")
KIND_CODES = {TWO_SIDES: 0, COOPERATIVE: 1, FREE_FOR_ALL: 2}
"""The ``kind`` column of a :class:`GameTable`: what made each row."""


def rules_for_env(env: str, env_options: dict[str, Any] | None = None) -> Rules:
    """The :class:`~selfplay_cli.results.Rules` a registered game declares (with these options: a lander game of M
    landers has M seats); the default for a game this process does not know."""
    spec = declaration(env)
    if spec is None:
        return Rules()
    with contextlib.suppress(TypeError, ValueError):  # options this version of the game does not take: as declared
        spec = spec.for_options(**(env_options or {}))
    return Rules.of(spec)


UNREADABLE_VARIANT = "(unreadable)"
"""The variant of the games of a match whose parameters cannot be read (too large, nested too deep, not JSON): no
variant a ladder is asked for (a real key is ``""`` or JSON), so its games stay out of every ladder."""


def _rules_of(params: dict[str, Any] | None) -> Rules:
    return Rules.from_json((params or {}).get("rules"))


def _variant_of(env: str, params: dict[str, Any] | None) -> str:
    """The variant a match's games belong to, from the options its row records (none: the default;
    :data:`UNREADABLE_VARIANT` when they cannot be read)."""
    if unreadable(params) is not None:
        return UNREADABLE_VARIANT
    options = (params or {}).get("env_options")
    return variant_key(env, options if isinstance(options, dict) else None)


def _said(match_id: int, params: Any) -> Any:
    """``params`` of a match, said once on stderr when they cannot be read (its games then count in no ladder)."""
    bad = unreadable(params)
    if bad is not None:
        say_unusable(f"match {match_id}", "params", bad, "its games count in no ladder")
    return params


@dataclass(frozen=True)
class GameRow:
    """One stored game with everything needed to replay it: :meth:`League.game`.

    ``players`` are player ids per seat; ``match_params`` are the parameters of the match that played it (for
    rated and training matches, ``env_options``: the game options it was played under); ``actions`` the encoded
    action record, None for games stored without one (by an older marl).
    """

    id: int
    match_id: int
    match_kind: str
    match_params: dict[str, Any]
    env: str
    seed: int
    length: int
    truncated: bool
    players: tuple[int, ...]
    scores: tuple[float, ...]
    outcome: tuple[float, ...]
    actions: bytes | None
    created_at: datetime


@dataclass(frozen=True)
class GameTable:
    """The pairwise results of the ledger as numpy arrays, in game-id order, for rating fits (see the module
    docstring): one row per result between two different players (a player against itself carries no rating
    information).

    ``score_a`` is ``player_a``'s points (1 / 0.5 / 0; the mean over its seats' pairings for a free-for-all player on
    several seats); ``player_a`` is the first side's player (two-sides), the player of the earlier episode
    (cooperative) or of the lower seat (free-for-all). ``game_id``, ``length`` and ``truncated`` are the game's (a
    cooperative comparison: its later episode's id and length, truncated if either episode was); ``kind`` is the
    :data:`KIND_CODES` code of the game's kind. ``margin_a`` is half of ``player_a``'s score minus ``player_b``'s (the
    game's own units: chips, goals; a player on several seats: the mean of its seats' scores; cooperative: the two
    team returns): in a zero-sum game of two seats, exactly ``player_a``'s return. NaN where not known (a table built
    from rows without it).
    """

    game_id: npt.NDArray[np.int64]
    match_id: npt.NDArray[np.int64]
    player_a: npt.NDArray[np.int64]
    player_b: npt.NDArray[np.int64]
    score_a: npt.NDArray[np.float64]
    seed: npt.NDArray[np.int64]
    length: npt.NDArray[np.int64]
    truncated: npt.NDArray[np.bool_]
    kind: npt.NDArray[np.int8] = field(default=None)  # type: ignore[assignment]
    margin_a: npt.NDArray[np.float64] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.kind is None:
            object.__setattr__(self, "kind", np.zeros(self.game_id.size, dtype=np.int8))
        if self.margin_a is None:
            object.__setattr__(self, "margin_a", np.full(self.game_id.size, np.nan))
    def __len__(self) -> int:
        return int(self.game_id.size)

    def player_ids(self) -> npt.NDArray[np.int64]:
        """Sorted distinct player ids that appear in the table."""
        return np.unique(np.concatenate([self.player_a, self.player_b])).astype(np.int64)

    def indexed(
        self, ids: Sequence[int] | npt.ArrayLike | None = None
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Map player ids to indices ``0..n-1`` for :func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`.

        Args:
            ids: the population (default :meth:`player_ids`); every player in the table must be in it.

        Returns:
            ``(ids, a, b)``: the id of each index and the per-game index arrays of seat 0 and seat 1.
        """
        pop = self.player_ids() if ids is None else np.asarray(ids, dtype=np.int64).ravel()
        order = np.argsort(pop, kind="stable")
        sorted_ids = pop[order]

        def lookup(x: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
            pos = np.searchsorted(sorted_ids, x)
            pos = np.clip(pos, 0, max(sorted_ids.size - 1, 0))
            if x.size and (sorted_ids.size == 0 or np.any(sorted_ids[pos] != x)):
                raise ValueError("GameTable.indexed: a player of the table is missing from ids")
            return order[pos].astype(np.int64)

        return pop, lookup(self.player_a), lookup(self.player_b)


    def select(self, mask: npt.NDArray[np.bool_]) -> GameTable:
        """The sub-table of the rows where ``mask`` is True."""
        return GameTable(*(getattr(self, f)[mask] for f in _GAME_TABLE_FIELDS))

    def by_side(self) -> tuple[GameTable, dict[int, tuple[int, int]]]:
        """The table with each player as the side it played (``player_a`` the first side's, ``player_b`` the
        second's; two-sides rows), for a game whose sides differ, where a player's rating means something only
        against the other side's. A player seen on both sides (a scripted player) becomes two players, keyed
        ``-(2 * id + side) - 1``; one seen on one side keeps its id. Returns the table and, for every key in it,
        ``(player id, side)`` (side 0 or 1)."""
        both = np.intersect1d(self.player_a, self.player_b)
        a = np.where(np.isin(self.player_a, both), -(2 * self.player_a) - 1, self.player_a)
        b = np.where(np.isin(self.player_b, both), -(2 * self.player_b + 1) - 1, self.player_b)
        sides: dict[int, tuple[int, int]] = {}
        for keys, side in ((a, 0), (b, 1)):
            for key in np.unique(keys).tolist():
                sides[int(key)] = ((-int(key) - 1) // 2, side) if key < 0 else (int(key), side)
        return replace(self, player_a=a.astype(np.int64), player_b=b.astype(np.int64)), sides

    def games_played(self) -> int:
        """How many ledger games the rows stand for: two per cooperative comparison (its two episodes), one per
        other row."""
        return int(self.game_id.size + np.count_nonzero(self.kind == KIND_CODES[COOPERATIVE]))

    @classmethod
    def empty(cls) -> GameTable:
        """A table without games."""
        i = np.zeros(0, dtype=np.int64)
        return cls(i, i.copy(), i.copy(), i.copy(), np.zeros(0), i.copy(), i.copy(), np.zeros(0, dtype=bool))

    @classmethod
    def of_rows(cls, rows: Sequence[tuple]) -> GameTable:
        """A table of ``(game_id, match_id, player_a, player_b, score_a, seed, length, truncated, kind[, margin_a])``
        rows (all with the margin or none)."""
        if not rows:
            return cls.empty()
        cols = list(zip(*rows, strict=True))
        margin = np.asarray(cols[9], dtype=np.float64) if len(cols) > 9 else None
        return cls(game_id=np.asarray(cols[0], dtype=np.int64), match_id=np.asarray(cols[1], dtype=np.int64),
                   player_a=np.asarray(cols[2], dtype=np.int64), player_b=np.asarray(cols[3], dtype=np.int64),
                   score_a=np.asarray(cols[4], dtype=np.float64), seed=np.asarray(cols[5], dtype=np.int64),
                   length=np.asarray(cols[6], dtype=np.int64), truncated=np.asarray(cols[7], dtype=bool),
                   kind=np.asarray(cols[8], dtype=np.int8), margin_a=margin)


_GAME_TABLE_FIELDS = ("game_id", "match_id", "player_a", "player_b", "score_a", "seed", "length", "truncated", "kind",
                      "margin_a")


@dataclass
class _Stored:
    """One game of the ledger as the derivation reads it."""

    id: int
    match_id: int
    seed: int
    length: int
    truncated: bool
    players: list[int]
    scores: list[float]
    points: list[float]


class _Episodes:
    """Cooperative episodes seen so far, by (match, seed) and crew (the players that flew it: one policy on every
    seat, or a team of them), to pair each new one with the others."""

    def __init__(self) -> None:
        self.seen: dict[tuple[int, int], dict[frozenset[int], list[_Stored]]] = defaultdict(dict)

    def add(self, g: _Stored, rules: Rules) -> list[tuple[_Stored, int, int, float]]:
        """Add an episode; returns the comparisons it completes: ``(earlier episode, a, b, a's points)`` for every
        player ``a`` of the earlier episode's crew and ``b`` of this one's (a team's comparison counts for each of
        its members; a player in both crews is not compared with itself)."""
        if not g.players:
            return []
        me = frozenset(g.players)
        by_crew = self.seen[(g.match_id, g.seed)]
        mine = by_crew.setdefault(me, [])
        i = len(mine)
        out = []
        for other, theirs in by_crew.items():
            if other != me and len(theirs) > i:
                first = theirs[i]
                pts = compare(sum(first.scores), sum(g.scores), rules.tie_tolerance)
                out += [(first, a, b, pts) for a in sorted(other) for b in sorted(me) if a != b]
        mine.append(g)
        return out


def _results(g: _Stored, rules: Rules, episodes: _Episodes) -> list[tuple[int, int, float, _Stored | None]]:
    """The pairwise results ``(a, b, a's points, earlier episode or None)`` one stored game adds to the ledger."""
    if rules.kind == COOPERATIVE:
        return [(a, b, pts, first) for first, a, b, pts in episodes.add(g, rules)]
    return [(a, b, pts, None) for a, b, pts in pairwise(rules, g.players, g.scores, g.points)]


def _apply_elo(players: dict[int, Player], results: Sequence[tuple[int, int, float, Any]], k: float) -> None:
    """Move the online Elo by one game's pairwise results, all from the ratings before the game (one result: exactly
    :func:`~selfplay_cli.stats.elo.elo_update`)."""
    if len(results) == 1:
        a, b = players.get(results[0][0]), players.get(results[0][1])
        if a is not None and b is not None:
            a.elo, b.elo = elo_update(float(a.elo), float(b.elo), results[0][2], k)
        return
    delta: dict[int, float] = defaultdict(float)
    for ia, ib, pts, _ in results:
        a, b = players.get(ia), players.get(ib)
        if a is not None and b is not None:
            na, nb = elo_update(float(a.elo), float(b.elo), pts, k)
            delta[ia] += na - float(a.elo)
            delta[ib] += nb - float(b.elo)
    for pid, d in delta.items():
        players[pid].elo = float(players[pid].elo) + d


def _count_game(players: dict[int, Player], seats: Iterable[int]) -> None:
    for pid in dict.fromkeys(seats):
        p = players.get(pid)
        if p is not None:
            p.games = int(p.games or 0) + 1


class Ledger(Part):
    """Matches and the game ledger, the online Elo, and the derived rating table (``league.ledger``)."""

    def __init__(self, db: Database, seeds: Seeds) -> None:
        super().__init__(db)
        self.seeds = seeds

    def create_match(self, env: str, kind: str, params: dict[str, Any] | None = None) -> int:
        """Open a match record (kind: match, tournament, gate, training, eval) and return its id.

        A game whose results are not Pong's two seats, one against the other, gets its rules stored with the match
        (``params["rules"]``, from the game's declaration unless ``params`` states them)."""
        params = _match_params(env, kind, params)

        def work(s: Session) -> int:
            m = Match(env=env, kind=kind, params=params)
            s.add(m)
            s.flush()
            return m.id

        return self._unit(work)

    def record_games(self, match_id: int, games: Sequence[GameResult]) -> list[int]:
        """Append a batch of games to the ledger in ONE transaction and update the online Elo.

        ``players`` of each game are league player ids. The online Elo moves by the pairwise results the games
        give (see the module docstring) with :func:`~selfplay_cli.stats.elo.elo_update` (K = :attr:`elo_k`), game
        by game in order; every player's ``games`` counter counts each game it sat in once. Either the whole batch
        is stored or nothing is.

        Returns:
            The new game ids, in the order of ``games``.

        Raises:
            LeagueError: unknown match or player, env mismatch, malformed record.
        """
        games = list(games)
        if not games:
            return []
        pids = _check_games(games)

        def work(s: Session) -> list[int]:
            match = s.get(Match, int(match_id))
            if match is None:
                raise LeagueError(f"no match with id {match_id}")
            return self._insert_games(s, match, games, pids)

        return self._unit(work)

    def create_match_with_games(self, env: str, kind: str, params: dict[str, Any] | None,
                                games: Sequence[GameResult], key: str | None = None) -> tuple[int, list[int]]:
        """Open a match record and store its first games in ONE transaction (a match row never exists without
        games, whatever instant the process is killed at). Returns the match id and the game ids.

        ``key``: the unit of work these games are (:attr:`Match.work_key`). If a match holds that key already, the
        work was done before (by a process killed since, or by another one at the same time): nothing is stored, and
        that match's id comes back with no game ids."""
        params = _match_params(env, kind, params)
        games = list(games)
        pids = _check_games(games)

        def work(s: Session) -> tuple[int, list[int]]:
            return self.store_match(s, env, kind, params, games, pids, key)

        try:  # a keyed unit may be done again after its COMMIT was cut off: stored then, it stores nothing now
            return self._unit(work, idempotent=key is not None)
        except IntegrityError:  # another process stored the same unit between our look and our insert
            if key is None:
                raise
            return self._unit(work, idempotent=True)

    def store_match(self, s: Session, env: str, kind: str, params: dict[str, Any], games: list[GameResult],
                     pids: set[int], key: str | None, look: bool = True) -> tuple[int, list[int]]:
        """:meth:`create_match_with_games` inside the caller's transaction (``params`` and ``games`` checked).
        ``look=False``: the caller knows no match holds ``key`` yet (its unique index still says so if one does)."""
        if key is not None and look:
            done = s.execute(select(Match.id).where(Match.work_key == key)).scalar()
            if done is not None:
                return int(done), []
        m = Match(env=env, kind=kind, params=params, work_key=key)
        s.add(m)
        s.flush()
        return m.id, self._insert_games(s, m, games, pids) if games else []

    def keyed_matches(self, prefix: str) -> dict[str, tuple[int, dict[str, Any]]]:
        """The matches whose :attr:`~selfplay_cli.league.models.Match.work_key` starts with ``prefix``: key ->
        (match id, parameters)."""
        like = prefix.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_") + "%"

        def work(s: Session) -> dict[str, tuple[int, dict[str, Any]]]:
            q = select(Match.work_key, Match.id, Match.params).where(Match.work_key.like(like, escape="\\"))
            return {str(k): (int(i), dict(p or {})) for k, i, p in s.execute(q)}

        return self._read(work)

    def update_match(self, match_id: int, **params: Any) -> None:
        """Merge ``params`` into a match's parameters (e.g. ``status="interrupted"``). LeagueError if unknown."""

        def work(s: Session) -> None:
            m = s.get(Match, int(match_id))
            if m is None:
                raise LeagueError(f"no match with id {match_id}")
            m.params = {**dict(m.params or {}), **params}

        self._unit(work)

    def _insert_games(self, s: Session, match: Match, games: list[GameResult], pids: set[int]) -> list[int]:
        """Store checked ``games`` of ``match`` inside the session's transaction; the online Elo goes with them."""
        # Locked in one order (PostgreSQL): two writers sharing players queue behind each other, never deadlock.
        q = select(Player).where(Player.id.in_(pids)).order_by(Player.id).options(raiseload("*")).with_for_update()
        rows = s.execute(q).scalars().all()
        players = {p.id: p for p in rows}
        for i, g in enumerate(games):
            if g.env != match.env:
                raise LeagueError(f"game {i}: env {g.env!r} differs from match {match.id}'s env {match.env!r}")
            for pid in g.players:
                p = players.get(int(pid))
                if p is None:
                    raise LeagueError(f"game {i}: no player with id {pid}")
                if p.env != g.env:
                    raise LeagueError(f"game {i}: player {p.id} ({p.name}) belongs to env {p.env!r}")
        now = utcnow()
        game_rows = [
            {"match_id": match.id, "env": g.env, "n_seats": len(g.players), "seed": int(g.seed),
             "length": int(g.length), "truncated": bool(g.truncated), "created_at": now, "actions": g.actions}
            for g in games
        ]
        ids = list(s.scalars(Game.__table__.insert().returning(Game.__table__.c.id, sort_by_parameter_order=True),
                             game_rows))
        seat_rows = [
            {"game_id": gid, "seat": k, "player_id": int(pid), "score": float(g.scores[k]),
             "points": float(g.outcome[k])}
            for gid, g in zip(ids, games, strict=True)
            for k, pid in enumerate(g.players)
        ]
        s.execute(GameSeat.__table__.insert(), seat_rows)
        rules = _rules_of(match.params)
        episodes = _Episodes()
        if rules.kind == COOPERATIVE:  # the earlier episodes of these seeds in this match, to pair the new ones with
            seeds = sorted({int(g.seed) for g in games})
            earlier = (select(Game.id).where(Game.match_id == match.id, Game.seed.in_(seeds), Game.id < min(ids))
                       .order_by(Game.id))
            for old in _stored(s, earlier):
                episodes.add(old, rules)
        online = _variant_of(match.env, match.params) == ""  # the online Elo follows the default variant's games
        for gid, g in zip(ids, games, strict=True):
            stored = _Stored(gid, match.id, int(g.seed), int(g.length), bool(g.truncated), [int(p) for p in g.players],
                             [float(x) for x in g.scores], [float(x) for x in g.outcome])
            _count_game(players, stored.players)
            if online:
                _apply_elo(players, _results(stored, rules, episodes), self.db.elo_k)
        return ids

    def games(self, env: str | None = None, players: Iterable[int] | None = None,
              any_seat: bool = False, rated: bool = True, variant: str | None = "",
              pooled: bool | Mapping[int, int] = True) -> GameTable:
        """The pairwise results of the ledger (of ``env``), one row each, in game-id order (see the module
        docstring and :class:`GameTable`).

        ``variant``: the key (:func:`~selfplay_cli.league.variants.variant_key`) of the variant whose games to take,
        the default variant (``""``) unless given; None takes the games of every variant (which games exist, never a
        rating).

        ``players`` restricts the table to results between those players (both in the set), or, with
        ``any_seat=True``, to results in which at least one of them played.

        ``pooled`` (the default): snapshots of the same weights are one player (:meth:`same_weights`), their games
        filed under the first of them (``players`` may name any of them); False keeps every name's games apart; a
        caller that has looked :meth:`same_weights` up already passes it.

        ``rated`` (the default) leaves out the games of training matches: there a learner that kept learning after
        its latest snapshot played under that snapshot's name, so they measure no fixed player. Every rating is
        fitted from the others (matches, tournaments, gates and the evaluation games after each snapshot);
        ``rated=False`` includes the training games too.
        """

        def work(s: Session) -> tuple[list[tuple], dict[int, int]]:
            same = _same_weights(s, env) if pooled is True else dict(pooled or {})
            names = None  # the players' every name (one set of weights may have several): the query's filter
            if players is not None:
                pop = {same.get(int(p), int(p)) for p in players}
                names = sorted(pop | {k for k, v in same.items() if v in pop})
            matches = _match_rules(s, env, rated, variant)
            special = {mid: r for mid, r in matches.items() if not r.is_default}
            query = _two_seat_query(env, rated, names, any_seat)
            rows = [(*r[:8], 0, 0.5 * (r[8] - r[9])) for r in s.execute(query).all()
                    if r[1] in matches and r[1] not in special]
            if special:
                rows += _derived_rows(s, env, rated, special)
                rows.sort(key=lambda r: r[0])
            return rows, same

        rows, same = self._read(work)
        table = GameTable.of_rows(rows)
        if same:  # one set of weights is one player: its games under every name are its own
            for column in (table.player_a, table.player_b):  # (fresh arrays of this call)
                column[:] = [same.get(int(p), int(p)) for p in column.tolist()]
            table = table.select(table.player_a != table.player_b)  # a player against its copy says nothing
        if players is not None:
            pop = np.fromiter((same.get(int(p), int(p)) for p in players), dtype=np.int64)
            in_a, in_b = np.isin(table.player_a, pop), np.isin(table.player_b, pop)
            table = table.select(in_a | in_b if any_seat else in_a & in_b)
        return table

    def same_weights(self, env: str | None = None) -> dict[int, int]:
        """Snapshots whose weights another snapshot of the game holds too: id -> the id of the player they all are
        (the first live one, by id). One set of weights is one player: every rating pools its games under each of its
        names (:meth:`games`), an import of known weights is refused, and two names of it never play each other."""
        return self._read(lambda s: _same_weights(s, env))

    def mean_returns(self, env: str | None = None, rated: bool = True,
                     variant: str | None = "") -> dict[int, tuple[int, float]]:
        """Every player's cooperative episodes (of ``variant``, as in :meth:`games`) and their mean team return (the
        sum of the seats' scores), by player id: ``{player: (episodes, mean return)}``. Empty where there are no
        cooperative games."""

        def work(s: Session) -> dict[int, tuple[int, float]]:
            coop = {mid for mid, r in _match_rules(s, env, rated, variant).items() if r.kind == COOPERATIVE}
            totals: dict[int, list[float]] = defaultdict(lambda: [0, 0.0])
            if coop:
                for g in _stored(s, _games_query(env, rated)):
                    if g.match_id in coop:
                        for pid in dict.fromkeys(g.players):
                            totals[pid][0] += 1
                            totals[pid][1] += sum(g.scores)
            return {pid: (int(n), total / n) for pid, (n, total) in totals.items()}

        return self._read(work)

    def variants(self, env: str) -> dict[str, int]:
        """The rated games of ``env`` (training games left out) by variant key, in key order; the default variant
        is ``""`` (see :mod:`selfplay_cli.league.variants`)."""

        def work(s: Session) -> dict[str, int]:
            q = (select(Game.match_id, func.count(Game.id)).where(Game.env == env).group_by(Game.match_id))
            counts = dict(s.execute(q).all())
            out: dict[str, int] = defaultdict(int)
            for mid, params in s.execute(select(Match.id, Match.params).where(Match.env == env,
                                                                             Match.kind != "training")):
                variant = _variant_of(env, _said(mid, params))
                if counts.get(mid) and variant != UNREADABLE_VARIANT:  # (in no variant: said)
                    out[variant] += int(counts[mid])
            return dict(sorted(out.items()))

        return self._read(work)

    def match_info(self, match_id: int) -> tuple[str, dict[str, Any]]:
        """The kind and parameters of a match. Raises LeagueError if unknown."""

        def work(s: Session) -> tuple[str, dict[str, Any]]:
            m = s.get(Match, int(match_id))
            if m is None:
                raise LeagueError(f"no match with id {match_id}")
            return m.kind, dict(m.params or {})

        return self._read(work)

    def match_params(self, env: str | None = None, kind: str | None = None) -> dict[int, dict[str, Any]]:
        """Every match's parameters (of ``env``, of ``kind``) by match id, in id order."""

        def work(s: Session) -> dict[int, dict[str, Any]]:
            q = select(Match.id, Match.params).order_by(Match.id)
            if env is not None:
                q = q.where(Match.env == env)
            if kind is not None:
                q = q.where(Match.kind == kind)
            return {int(mid): dict(params or {}) for mid, params in s.execute(q)}

        return self._read(work)

    def game(self, game_id: int) -> GameRow:
        """The stored game ``game_id`` with its seats, its match and its actions. Raises LeagueError if unknown."""

        def work(s: Session) -> GameRow:
            g = s.get(Game, int(game_id))
            if g is None:
                raise LeagueError(f"no game with id {game_id} in the ledger")
            match = s.get(Match, g.match_id)
            seats = s.execute(select(GameSeat).where(GameSeat.game_id == g.id).order_by(GameSeat.seat)).scalars().all()
            return GameRow(
                id=g.id, match_id=g.match_id, match_kind=match.kind if match else "", env=g.env,
                match_params=dict(match.params or {}) if match else {}, seed=int(g.seed), length=int(g.length),
                truncated=bool(g.truncated), players=tuple(int(x.player_id) for x in seats),
                scores=tuple(float(x.score) for x in seats), outcome=tuple(float(x.points) for x in seats),
                actions=g.actions, created_at=g.created_at,
            )

        return self._read(work)

    def count_games(self, env: str | None = None) -> int:
        """Number of games in the ledger (any number of seats)."""

        def work(s: Session) -> int:
            q = select(func.count(Game.id))
            if env is not None:
                q = q.where(Game.env == env)
            return int(s.execute(q).scalar_one())

        return self._read(work)

    def fresh_seed(self, a: int, b: int) -> int:
        """The first seed above every stored game between players ``a`` and ``b``, in any variant, and above every
        seed taken for their games still to come (queued, or in play: :mod:`selfplay_cli.league.seeds`); 0 when they
        never met: where a new match of the two starts by default, so that it never plays, and stores, games it
        already has or will have (two deterministic players on the same seeds play the same games: stored twice,
        they would count twice)."""
        return max(self.played_seed_end(a, b), self.seeds.seeds_end(a, b))

    def played_seed_end(self, a: int, b: int) -> int:
        """The first seed above every stored game between players ``a`` and ``b``, in any variant (0: none)."""
        t = self.games(players=[int(a), int(b)], rated=False, variant=None)
        return int(t.seed.max()) + 1 if len(t) else 0

    def pair_counts(self, a: int, b: int, variant: str = "") -> tuple[int, int, int]:
        """Wins, draws and losses of player ``a`` against player ``b`` over all their pairwise results in
        ``variant`` (the default unless given), training games included."""
        if int(a) == int(b):
            raise LeagueError(f"player {a} cannot be paired with itself")
        same = self.same_weights()  # (a name of another's weights: its games are filed under the first name)
        t = self.games(players=[int(a), int(b)], rated=False, variant=variant, pooled=same)
        pts = np.where(t.player_a == same.get(int(a), int(a)), t.score_a, 1.0 - t.score_a)
        return int(np.sum(pts > 0.5)), int(np.sum(pts == 0.5)), int(np.sum(pts < 0.5))

    def recompute_online_elo(self, env: str | None = None) -> None:
        """Rebuild every player's online Elo and game count by replaying the ledger in game-id order.

        All players (of ``env``) restart from 1000 and 0 games; the result equals the incrementally
        stored values, because games are numbered in commit order under SQLite's single writer. As there, every game
        counts in the players' game counts and only the default variant's move their online Elo.
        """

        def work(s: Session) -> None:
            pq = select(Player)
            if env is not None:
                pq = pq.where(Player.env == env)
            pq = pq.order_by(Player.id).options(raiseload("*")).with_for_update()
            players = {p.id: p for p in s.execute(pq).scalars()}
            for p in players.values():
                p.elo, p.games = DEFAULT_ELO, 0
            rules = _match_rules(s, env, rated=False)
            online = _match_rules(s, env, rated=False, variant="")
            episodes = _Episodes()
            for g in _stored(s, _games_query(env, rated=False)):
                _count_game(players, g.players)
                if g.match_id in online:
                    _apply_elo(players, _results(g, rules.get(g.match_id, Rules()), episodes), self.db.elo_k)

        self._unit(work)


def _same_weights(s: Session, env: str | None) -> dict[int, int]:
    """:meth:`Ledger.same_weights` in a session: snapshots grouped by (game, weights' checksum), each mapped to its
    group's first live member (its first member when all are removed); only groups of two or more."""
    q = select(Player.id, Player.env, Player.meta, Player.removed).where(Player.kind == "snapshot").order_by(Player.id)
    if env is not None:
        q = q.where(Player.env == env)
    groups: dict[tuple[str, str], list[tuple[int, bool]]] = defaultdict(list)
    for pid, penv, meta, removed in s.execute(q):
        sha = (meta or {}).get("weights_sha256")
        if sha:
            groups[(penv, sha)].append((int(pid), bool(removed)))
    out: dict[int, int] = {}
    for members in groups.values():
        if len(members) > 1:
            lead = next((pid for pid, removed in members if not removed), members[0][0])
            out.update({pid: lead for pid, _ in members if pid != lead})
    return out


def _match_params(env: str, kind: str, params: dict[str, Any] | None) -> dict[str, Any]:
    """A new match's parameters, checked, with the game's rules where they are not the default."""
    check_env_name(env)
    if kind not in MATCH_KINDS:
        raise LeagueError(f"unknown match kind {kind!r} (expected one of {', '.join(MATCH_KINDS)})")
    params = dict(params or {})
    if "rules" not in params:
        options = params.get("env_options")
        rules = rules_for_env(env, options if isinstance(options, dict) else None)
        if not rules.is_default:
            params["rules"] = rules.to_json()
    else:
        try:
            Rules.from_json(params["rules"])
        except (TypeError, ValueError) as e:
            raise LeagueError(f"a match's rules are malformed: {e}") from None
    return params


def _match_rules(s: Session, env: str | None, rated: bool, variant: str | None = None) -> dict[int, Rules]:
    """The rules of every match (of ``env``; without training matches when ``rated``; of ``variant`` unless None)
    by match id."""
    q = select(Match.id, Match.env, Match.params)
    if env is not None:
        q = q.where(Match.env == env)
    if rated:
        q = q.where(Match.kind != "training")
    return {int(mid): _rules_of(params) for mid, menv, params in s.execute(q)
            if variant is None or _variant_of(menv, _said(mid, params)) == variant}


PLAYER_FILTER_MAX = 5_000
"""Players a ledger query names in its ``WHERE`` at most (more: the whole ledger is read, then filtered)."""


def _two_seat_query(env: str | None, rated: bool, players: Sequence[int] | None = None,
                    any_seat: bool = False) -> Any:
    """Games of two seats held by two different players, as ``(game, match, seat 0's player, seat 1's player, seat 0's
    points, seed, length, truncated, seat 0's score, seat 1's score)``: the whole derivation for games with the
    default rules, in one query. ``players``: only games between two of them (``any_seat``: with one of them), found
    by the seats' player index, so a pair's games are read without the league's million training games."""
    s0, s1 = aliased(GameSeat), aliased(GameSeat)
    q = (
        select(Game.id, Game.match_id, s0.player_id, s1.player_id, s0.points, Game.seed, Game.length, Game.truncated,
               s0.score, s1.score)
        .join(s0, and_(s0.game_id == Game.id, s0.seat == 0))
        .join(s1, and_(s1.game_id == Game.id, s1.seat == 1))
        .where(Game.n_seats == 2, s0.player_id != s1.player_id)
        .order_by(Game.id)
    )
    if env is not None:
        q = q.where(Game.env == env)
    if rated:
        q = q.join(Match, Match.id == Game.match_id).where(Match.kind != "training")
    if players is not None and len(players) <= PLAYER_FILTER_MAX:
        ids = [int(p) for p in players]
        both = (s0.player_id.in_(ids), s1.player_id.in_(ids))
        q = q.where(or_(*both) if any_seat else and_(*both))
    return q


def _games_query(env: str | None, rated: bool) -> Any:
    """The ids of the games (of ``env``; without training games when ``rated``), in id order."""
    q = select(Game.id).order_by(Game.id)
    if env is not None:
        q = q.where(Game.env == env)
    if rated:
        q = q.join(Match, Match.id == Game.match_id).where(Match.kind != "training")
    return q


def _stored(s: Session, ids: Any) -> Iterator[_Stored]:
    """The games whose ids the select ``ids`` gives, with their seats, in id order."""
    sub = ids.subquery()
    q = (select(Game.id, Game.match_id, Game.seed, Game.length, Game.truncated, GameSeat.player_id, GameSeat.score,
                GameSeat.points)
         .join(GameSeat, GameSeat.game_id == Game.id)
         .where(Game.id.in_(select(sub.c.id)))
         .order_by(Game.id, GameSeat.seat))
    current: _Stored | None = None
    for gid, mid, seed, length, truncated, pid, score, points in s.execute(q):
        if current is None or current.id != gid:
            if current is not None:
                yield current
            current = _Stored(int(gid), int(mid), int(seed), int(length), bool(truncated), [], [], [])
        current.players.append(int(pid))
        current.scores.append(float(score))
        current.points.append(float(points))
    if current is not None:
        yield current


def _derived_rows(s: Session, env: str | None, rated: bool, special: dict[int, Rules]) -> list[tuple]:
    """The :class:`GameTable` rows of the games of ``special`` matches (rules other than the default)."""
    rows: list[tuple] = []
    episodes = _Episodes()
    for g in _stored(s, _games_query(env, rated)):
        rules = special.get(g.match_id)
        if rules is None:
            continue
        code = KIND_CODES[rules.kind]
        for a, b, pts, first in _results(g, rules, episodes):
            truncated = g.truncated or (first is not None and first.truncated)
            if first is not None:  # a cooperative comparison: the two team returns
                margin = 0.5 * (sum(first.scores) - sum(g.scores))
            else:  # each player's mean score over its seats
                margin = 0.5 * (_mean_score(g, a) - _mean_score(g, b))
            rows.append((g.id, g.match_id, a, b, pts, g.seed, g.length, truncated, code, margin))
    return rows


def _mean_score(g: _Stored, player: int) -> float:
    """The mean score of ``player``'s seats in game ``g``."""
    mine = [x for p, x in zip(g.players, g.scores, strict=True) if p == player]
    return sum(mine) / len(mine)


def _check_games(games: list[GameResult]) -> set[int]:
    """The ids of the players of ``games``, each game checked for shape and result (LeagueError if malformed)."""
    pids: set[int] = set()
    for i, g in enumerate(games):
        n = len(g.players)
        if n < 1 or len(g.scores) != n or len(g.outcome) != n:
            raise LeagueError(f"game {i}: players, scores and outcome must have one entry per seat")
        if any(not (0.0 <= float(o) <= 1.0) or math.isnan(float(o)) for o in g.outcome):
            raise LeagueError(f"game {i}: outcome points must lie in [0, 1], got {g.outcome}")
        if any(not math.isfinite(float(x)) for x in g.scores):
            raise LeagueError(f"game {i}: scores must be finite numbers, got {g.scores}")
        if n == 2 and abs(float(g.outcome[0]) + float(g.outcome[1]) - 1.0) > 1e-9:
            raise LeagueError(f"game {i}: two-player outcome must sum to 1, got {g.outcome}")
        if not all(isinstance(p, int | np.integer) for p in g.players):
            raise LeagueError(f"game {i}: players must be league player ids, got {g.players}")
        pids.update(int(p) for p in g.players)
    return pids
