"""Schedules of rated play: which policy sits where on which seed, by the game's kind.

A schedule is made of *rounds*: the games of one seed that together are fair to every policy.

* two-sides: a seat-swapped pair. Each policy fills every seat of its side, once on the first side and once on the
  second, so the seat (and the serve) luck cancels within the pair.
* cooperative: one episode per policy, each flying every seat of the team on the same seed. A round of two policies
  is one comparison of their team returns.
* free-for-all: the rotations of the seating. The policies fill the seats in turn (policy ``i % k`` on seat ``i``),
  and every rotation of that seating is played, so each policy sits on every seat equally often.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..results import COOPERATIVE, TWO_SIDES, Rules
from .runner import Game

__all__ = ["round_of", "round_size", "rounds"]


def round_size(rules: Rules, n_policies: int) -> int:
    """Games in one round of ``n_policies`` policies."""
    if rules.kind == TWO_SIDES:
        return 2
    if rules.kind == COOPERATIVE:
        return n_policies
    return rules.n_seats


def round_of(rules: Rules, players: Sequence[int | tuple[int, ...]], seed: int) -> list[Game]:
    """The games of one round on ``seed``: ``players`` are the policies' indices (two for two-sides games); in a
    cooperative game a player may be a crew, a tuple of one policy index per seat, flying together."""
    if not players:
        raise ValueError("a round needs players")
    n = rules.n_seats
    if rules.kind == TWO_SIDES:
        if len(players) != 2:
            raise ValueError(f"a two-sides round is between two policies, not {len(players)}")
        assert rules.sides is not None
        games = []
        for first, second in (players, players[::-1]):
            seats = [0] * n
            for s in rules.sides[0]:
                seats[s] = first
            for s in rules.sides[1]:
                seats[s] = second
            games.append(Game(seed, tuple(seats)))
        return games
    if rules.kind == COOPERATIVE:  # a player may be a crew: a tuple of policy indices, one per seat
        return [Game(seed, tuple(p) if isinstance(p, tuple) else (p,) * n) for p in players]
    base = [players[i % len(players)] for i in range(n)]
    return [Game(seed, tuple(base[(i + r) % n] for i in range(n))) for r in range(n)]


def rounds(rules: Rules, players: Sequence[int], n_rounds: int, first_seed: int = 0) -> list[Game]:
    """``n_rounds`` rounds, round ``r`` on seed ``first_seed + r`` (:func:`round_of`)."""
    return [g for r in range(n_rounds) for g in round_of(rules, players, first_seed + r)]
