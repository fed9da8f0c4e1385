"""Schedules of rated play: which policy sits where on which seed, by the game's kind.

A schedule is made of *rounds*: the games of one seed that together are fair to every policy.

* two-sides: a seat-swapped pair. Each policy fills every seat of its side, once on the first side and once on the
  second, so the seat (and the serve) luck cancels within the pair.
* cooperative: one episode per policy, each flying every seat of the team on the same seed. A round of two policies
  is one comparison of their team returns.
* free-for-all: the rotations of the seating. The policies fill the seats in turn (policy ``i % k`` on seat ``i``),
  and every rotation of that seating is played, so each policy sits on every seat equally often.

Where a game's seats hold different roles (:attr:`~selfplay_cli.results.Rules.roles`), a policy plays only seats of
the roles it learned (``roles``: per policy index, the roles it may play; None, or no entry, for a policy that plays
any seat, such as a scripted player), and a round keeps only the seatings that respect that:

* two-sides, sides that differ: each policy on its own side alone, so a round is one game (rounds pair up by seed
  only, no seat swap); two policies of the same side cannot meet (:class:`CannotMeet`);
* cooperative: a policy flies the team alone only if it plays every seat's role (a crew puts each member on its
  own seat);
* free-for-all: the rotations whose seating fits; where none does, each seat goes in turn to the policies that may
  play it.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

from ..results import COOPERATIVE, TWO_SIDES, Rules
from .matches import Game

__all__ = ["CannotMeet", "PlayerRoles", "can_meet", "round_of", "round_size", "rounds"]

PlayerRoles = Mapping[int, Collection[str] | None]
"""Per policy index, the roles it may play (None: any seat)."""


class CannotMeet(ValueError):
    """No seating of the game lets these policies play each other: each may play only seats of its role."""


def _may_sit(rules: Rules, policy: int, seat: int, roles: PlayerRoles | None) -> bool:
    """Whether the policy may play the seat: any policy where the seats are of one role; else one of that role."""
    if rules.roles is None or not roles:
        return True
    may = roles.get(policy)
    return may is None or rules.roles[seat] in may


def _fits(rules: Rules, seats: Sequence[int], roles: PlayerRoles | None) -> bool:
    """Whether every policy of a seating (a policy index per seat) may play the seat it is given."""
    return all(_may_sit(rules, p, seat, roles) for seat, p in enumerate(seats))


def can_meet(rules: Rules, a: Collection[str] | None, b: Collection[str] | None) -> bool:
    """Whether a policy of roles ``a`` and one of roles ``b`` (None: any seat) can play each other in this game."""
    try:
        round_of(rules, (0, 1), 0, {0: a, 1: b})
    except CannotMeet:
        return False
    return True


def round_size(rules: Rules, n_policies: int) -> int:
    """Games in one round of ``n_policies`` policies that may sit anywhere (:func:`round_of` says how many a round
    of policies bound to their roles has)."""
    if rules.kind == TWO_SIDES:
        return 2
    if rules.kind == COOPERATIVE:
        return n_policies
    return rules.n_seats


def round_of(rules: Rules, players: Sequence[int | tuple[int, ...]], seed: int,
             roles: PlayerRoles | None = None) -> list[Game]:
    """The games of one round on ``seed``: ``players`` are the policies' indices (two for two-sides games); in a
    cooperative game a player may be a crew, a tuple of one policy index per seat, flying together. ``roles``: the
    roles each policy may play (see the module docstring); :class:`CannotMeet` when no seating fits them."""
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
    elif rules.kind == COOPERATIVE:  # a player may be a crew: a tuple of policy indices, one per seat
        games = [Game(seed, tuple(p) if isinstance(p, tuple) else (p,) * n) for p in players]
        if not all(_fits(rules, g.seats, roles) for g in games):
            raise CannotMeet("a player would fly seats of a role it did not learn")
        return games
    else:
        base = [players[i % len(players)] for i in range(n)]
        games = [Game(seed, tuple(base[(i + r) % n] for i in range(n))) for r in range(n)]
    fitting = [g for g in games if _fits(rules, g.seats, roles)]
    if not fitting and rules.kind != TWO_SIDES:
        fitting = _seat_by_role(rules, players, seed, roles)  # type: ignore[arg-type]
    if not fitting:
        raise CannotMeet("no seating gives each player only seats of its own role")
    return fitting


def _seat_by_role(rules: Rules, players: Sequence[int], seed: int, roles: PlayerRoles | None) -> list[Game]:
    """A free-for-all round where no rotation fits: rotation r gives seat i the ``(i + r)``-th of the policies
    that may play it; the distinct seatings in which every policy plays."""
    may = [[p for p in players if _may_sit(rules, p, seat, roles)] for seat in range(rules.n_seats)]
    if any(not m for m in may):
        return []
    out: dict[tuple[int, ...], Game] = {}
    for r in range(rules.n_seats):
        seats = tuple(m[(i + r) % len(m)] for i, m in enumerate(may))
        if set(seats) == set(players):
            out.setdefault(seats, Game(seed, seats))
    return list(out.values())


def rounds(rules: Rules, players: Sequence[int], n_rounds: int, first_seed: int = 0,
           roles: PlayerRoles | None = None) -> list[Game]:
    """``n_rounds`` rounds, round ``r`` on seed ``first_seed + r`` (:func:`round_of`)."""
    return [g for r in range(n_rounds) for g in round_of(rules, players, first_seed + r, roles)]
