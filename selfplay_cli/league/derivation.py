"""How the table ratings are fitted from is derived from the stored games, inside a unit of work of the ledger
(:class:`~selfplay_cli.league.ledger.Ledger`; each function here takes its session), one row per pairwise result:

* two-sides: one row per game between the two sides' players (seat-swapped games of one seed pair up);
* cooperative: one row per comparison: two different players' episodes on the same seed within one match, the
  higher team return winning (a difference within the tie tolerance: a draw); the i-th episode of one player on a
  seed is compared with the i-th of the other;
* free-for-all: one row per two different players of a game, from the final order of their scores.

Each match's rules are read from its row (``params["rules"]``; the default where it states none), and the rules a game
declares from the game's declaration (:func:`rules_for_env`). Games of two seats under the default rules are read in
one query (:func:`two_seat_query`); the others are replayed game by game (:func:`derived_rows`). One set of weights is
one player (:func:`same_weights_in`).

Ratings are per variant (:mod:`selfplay_cli.league.variants`): every reader takes the games of one variant of a
game, the default one unless it asks for another, derived from the options each match row records
(``params["env_options"]``; :func:`variant_of`).
"""

from __future__ import annotations

import contextlib
from collections import defaultdict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import and_, or_, select
from sqlalchemy.orm import Session, aliased

from selfplay_cli.league.bounded_json import say_unusable, unreadable
from selfplay_cli.league.game_table import KIND_CODES
from selfplay_cli.league.games import declaration
from selfplay_cli.league.models import Game, GameSeat, Match, Player
from selfplay_cli.league.variants import variant_key
from selfplay_cli.results import COOPERATIVE, Rules, compare, pairwise

__all__ = ["PLAYER_FILTER_MAX", "UNREADABLE_VARIANT", "Episodes", "StoredGame", "derived_rows", "games_query",
           "match_rules", "pairwise_results", "rules_for_env", "rules_of", "said", "same_weights_in", "stored_games",
           "two_seat_query", "variant_of"]


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


def rules_of(params: dict[str, Any] | None) -> Rules:
    return Rules.from_json((params or {}).get("rules"))


def variant_of(env: str, params: dict[str, Any] | None) -> str:
    """The variant a match's games belong to, from the options its row records (none: the default;
    :data:`UNREADABLE_VARIANT` when they cannot be read)."""
    if unreadable(params) is not None:
        return UNREADABLE_VARIANT
    options = (params or {}).get("env_options")
    return variant_key(env, options if isinstance(options, dict) else None)


def said(match_id: int, params: Any) -> Any:
    """``params`` of a match, said once on stderr when they cannot be read (its games then count in no ladder)."""
    bad = unreadable(params)
    if bad is not None:
        say_unusable(f"match {match_id}", "params", bad, "its games count in no ladder")
    return params


@dataclass
class StoredGame:
    """One game of the ledger as the derivation reads it."""

    id: int
    match_id: int
    seed: int
    length: int
    truncated: bool
    players: list[int]
    scores: list[float]
    points: list[float]


class Episodes:
    """Cooperative episodes seen so far, by (match, seed) and crew (the players that flew it: one policy on every
    seat, or a team of them), to pair each new one with the others."""

    def __init__(self) -> None:
        self.seen: dict[tuple[int, int], dict[frozenset[int], list[StoredGame]]] = defaultdict(dict)

    def add(self, g: StoredGame, rules: Rules) -> list[tuple[StoredGame, int, int, float]]:
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


def pairwise_results(g: StoredGame, rules: Rules,
                     episodes: Episodes) -> list[tuple[int, int, float, StoredGame | None]]:
    """The pairwise results ``(a, b, a's points, earlier episode or None)`` one stored game adds to the ledger."""
    if rules.kind == COOPERATIVE:
        return [(a, b, pts, first) for first, a, b, pts in episodes.add(g, rules)]
    return [(a, b, pts, None) for a, b, pts in pairwise(rules, g.players, g.scores, g.points)]


def same_weights_in(s: Session, env: str | None) -> dict[int, int]:
    """:meth:`~selfplay_cli.league.ledger.Ledger.same_weights` in a session: snapshots grouped by (game, weights'
    checksum), each mapped to its group's first live member (its first member when all are removed); only groups of
    two or more."""
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


def match_rules(s: Session, env: str | None, rated: bool, variant: str | None = None) -> dict[int, Rules]:
    """The rules of every match (of ``env``; without training matches when ``rated``; of ``variant`` unless None)
    by match id."""
    q = select(Match.id, Match.env, Match.params)
    if env is not None:
        q = q.where(Match.env == env)
    if rated:
        q = q.where(Match.kind != "training")
    return {int(mid): rules_of(params) for mid, menv, params in s.execute(q)
            if variant is None or variant_of(menv, said(mid, params)) == variant}


PLAYER_FILTER_MAX = 5_000
"""Players a ledger query names in its ``WHERE`` at most (more: the whole ledger is read, then filtered)."""


def two_seat_query(env: str | None, rated: bool, players: Sequence[int] | None = None,
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


def games_query(env: str | None, rated: bool) -> Any:
    """The ids of the games (of ``env``; without training games when ``rated``), in id order."""
    q = select(Game.id).order_by(Game.id)
    if env is not None:
        q = q.where(Game.env == env)
    if rated:
        q = q.join(Match, Match.id == Game.match_id).where(Match.kind != "training")
    return q


def stored_games(s: Session, ids: Any) -> Iterator[StoredGame]:
    """The games whose ids the select ``ids`` gives, with their seats, in id order."""
    sub = ids.subquery()
    q = (select(Game.id, Game.match_id, Game.seed, Game.length, Game.truncated, GameSeat.player_id, GameSeat.score,
                GameSeat.points)
         .join(GameSeat, GameSeat.game_id == Game.id)
         .where(Game.id.in_(select(sub.c.id)))
         .order_by(Game.id, GameSeat.seat))
    current: StoredGame | None = None
    for gid, mid, seed, length, truncated, pid, score, points in s.execute(q):
        if current is None or current.id != gid:
            if current is not None:
                yield current
            current = StoredGame(int(gid), int(mid), int(seed), int(length), bool(truncated), [], [], [])
        current.players.append(int(pid))
        current.scores.append(float(score))
        current.points.append(float(points))
    if current is not None:
        yield current


def derived_rows(s: Session, env: str | None, rated: bool, special: dict[int, Rules]) -> list[tuple]:
    """The :class:`~selfplay_cli.league.game_table.GameTable` rows of the games of ``special`` matches (rules other
    than the default)."""
    rows: list[tuple] = []
    episodes = Episodes()
    for g in stored_games(s, games_query(env, rated)):
        rules = special.get(g.match_id)
        if rules is None:
            continue
        code = KIND_CODES[rules.kind]
        for a, b, pts, first in pairwise_results(g, rules, episodes):
            truncated = g.truncated or (first is not None and first.truncated)
            if first is not None:  # a cooperative comparison: the two team returns
                margin = 0.5 * (sum(first.scores) - sum(g.scores))
            else:  # each player's mean score over its seats
                margin = 0.5 * (_mean_score(g, a) - _mean_score(g, b))
            rows.append((g.id, g.match_id, a, b, pts, g.seed, g.length, truncated, code, margin))
    return rows


def _mean_score(g: StoredGame, player: int) -> float:
    """The mean score of ``player``'s seats in game ``g``."""
    mine = [x for p, x in zip(g.players, g.scores, strict=True) if p == player]
    return sum(mine) / len(mine)
