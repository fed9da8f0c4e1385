"""The game ledger: matches, the append-only games with their seats, and the online Elo kept from them.

:class:`Ledger` is a part of :class:`~selfplay_cli.league.store.League`. The ledger keeps real games: any number of
seats, each seat's player, float score and points (:class:`~selfplay_cli.results.GameResult` is what goes in). A
match row says how its games were played (``params``), and, for a game whose results are not decided like Pong's
(two seats, one against the other), its :class:`~selfplay_cli.results.Rules` (``params["rules"]``: kind, sides, tie
tolerance), so the ratings never depend on code that may be gone when they are recomputed.

What ratings are fitted from (:meth:`Ledger.games`, a :class:`~selfplay_cli.league.game_table.GameTable`) is derived
from the stored games, one row per pairwise result, per variant, as :mod:`selfplay_cli.league.derivation` says.

The online Elo on each player row is a cache updated from the same pairwise results, in the transaction that
stores their games (several results of one game move the ratings together, from the ratings before it);
:meth:`Ledger.recompute_online_elo` rebuilds it from the ledger. A player has one online Elo, so only the games of
the default variant move it: it is the live view beside the default ladder.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, raiseload

from selfplay_cli.league.db import Database, Part
from selfplay_cli.league.derivation import (
    UNREADABLE_VARIANT,
    Episodes,
    StoredGame,
    derived_rows,
    games_query,
    match_rules,
    pairwise_results,
    rules_for_env,
    rules_of,
    said,
    same_weights_in,
    stored_games,
    two_seat_query,
    variant_of,
)
from selfplay_cli.league.failures import LeagueError
from selfplay_cli.league.game_table import GameRow, GameTable
from selfplay_cli.league.models import Game, GameSeat, Match, Player, utcnow
from selfplay_cli.league.roster import DEFAULT_ELO, check_env_name
from selfplay_cli.league.seeds import Seeds
from selfplay_cli.results import COOPERATIVE, GameResult, Rules
from selfplay_cli.stats.elo import elo_update

__all__ = ["MATCH_KINDS", "Ledger"]

MATCH_KINDS = ("match", "tournament", "gate", "training", "eval")


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
        give (see :mod:`selfplay_cli.league.derivation`) with :func:`~selfplay_cli.stats.elo.elo_update`
        (K = :attr:`elo_k`), game by game in order; every player's ``games`` counter counts each game it sat in once.
        Either the whole batch is stored or nothing is.

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
        rules = rules_of(match.params)
        episodes = Episodes()
        if rules.kind == COOPERATIVE:  # the earlier episodes of these seeds in this match, to pair the new ones with
            seeds = sorted({int(g.seed) for g in games})
            earlier = (select(Game.id).where(Game.match_id == match.id, Game.seed.in_(seeds), Game.id < min(ids))
                       .order_by(Game.id))
            for old in stored_games(s, earlier):
                episodes.add(old, rules)
        online = variant_of(match.env, match.params) == ""  # the online Elo follows the default variant's games
        for gid, g in zip(ids, games, strict=True):
            stored = StoredGame(gid, match.id, int(g.seed), int(g.length), bool(g.truncated),
                                [int(p) for p in g.players], [float(x) for x in g.scores],
                                [float(x) for x in g.outcome])
            _count_game(players, stored.players)
            if online:
                _apply_elo(players, pairwise_results(stored, rules, episodes), self.db.elo_k)
        return ids

    def games(self, env: str | None = None, players: Iterable[int] | None = None,
              any_seat: bool = False, rated: bool = True, variant: str | None = "",
              pooled: bool | Mapping[int, int] = True) -> GameTable:
        """The pairwise results of the ledger (of ``env``), one row each, in game-id order (see
        :mod:`selfplay_cli.league.derivation` and :class:`~selfplay_cli.league.game_table.GameTable`).

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
            same = same_weights_in(s, env) if pooled is True else dict(pooled or {})
            names = None  # the players' every name (one set of weights may have several): the query's filter
            if players is not None:
                pop = {same.get(int(p), int(p)) for p in players}
                names = sorted(pop | {k for k, v in same.items() if v in pop})
            matches = match_rules(s, env, rated, variant)
            special = {mid: r for mid, r in matches.items() if not r.is_default}
            query = two_seat_query(env, rated, names, any_seat)
            rows = [(*r[:8], 0, 0.5 * (r[8] - r[9])) for r in s.execute(query).all()
                    if r[1] in matches and r[1] not in special]
            if special:
                rows += derived_rows(s, env, rated, special)
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
        return self._read(lambda s: same_weights_in(s, env))

    def mean_returns(self, env: str | None = None, rated: bool = True,
                     variant: str | None = "") -> dict[int, tuple[int, float]]:
        """Every player's cooperative episodes (of ``variant``, as in :meth:`games`) and their mean team return (the
        sum of the seats' scores), by player id: ``{player: (episodes, mean return)}``. Empty where there are no
        cooperative games."""

        def work(s: Session) -> dict[int, tuple[int, float]]:
            coop = {mid for mid, r in match_rules(s, env, rated, variant).items() if r.kind == COOPERATIVE}
            totals: dict[int, list[float]] = defaultdict(lambda: [0, 0.0])
            if coop:
                for g in stored_games(s, games_query(env, rated)):
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
                variant = variant_of(env, said(mid, params))
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
            rules = match_rules(s, env, rated=False)
            online = match_rules(s, env, rated=False, variant="")
            episodes = Episodes()
            for g in stored_games(s, games_query(env, rated=False)):
                _count_game(players, g.players)
                if g.match_id in online:
                    _apply_elo(players, pairwise_results(g, rules.get(g.match_id, Rules()), episodes), self.db.elo_k)

        self._unit(work)


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
