"""Which learner holds which seat of training's games (:func:`plan_seats`), and every (seat, game) slot's holder for a
batch of games (:func:`plan_layout`): a learner's index, or :data:`OPPONENT` for a slot the matchmaker fills. By the
game's kind, ``--agents`` and ``--sharing``:

* **two sides** (pong, tic-tac-toe, a 2v2 game): with two learners each holds one side (all its seats); with one
  learner it holds one side, alternating game by game, against opponents from the league on the other;
* **cooperative**: every seat is a learner's, seat s going to learner ``s % agents`` (``--agents 1``: one network
  flies every seat; ``--agents N`` for N seats: one network per seat);
* **free-for-all**: with one learner per seat every seat is a learner's; with fewer, learners take the first seats,
  rotating with the game, and opponents the rest;
* ``--sharing fups`` makes every learner one network (parameter sharing); ``--seats`` states the mapping outright
  (a learner number or ``-`` for an opponent, per seat);
* with every seat a learner's, ``league_games`` > 0 gives that share of the games to one learner (on its own
  seats, the learners taking turns game by game) against opponents from the league.
* a league of roles (``--league alphastar``, :func:`league_layout`): each learner has games of its own, one seat in
  each as a lone learner would take them, opponents on the others.

The seats a learner holds must share one space and one role (:func:`learner_spaces`, :func:`learner_roles`): one
network reads one observation shape and plays one action space. The games themselves are
:class:`~.training_games.SelfPlayGames`'.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..envs import EnvSpec, SeatSpace, describe_space
from ..errors import MarlError
from ..results import COOPERATIVE, TWO_SIDES

OPPONENT = -1


SHARING = ("nops", "fups", "sa")  # one network per learner; one shared by all; one agent over the team's seats


@dataclass(frozen=True)
class SeatPlan:
    """Who holds each seat: ``home[s]`` the learner of seat s when every seat is a learner's (-1: an opponent's
    even then), ``rotate`` whether learners move round the seats game by game (fewer learners than seats),
    ``sides``: with one learner in a two-sides game, the seats it takes (one side, alternating game by game)."""

    home: tuple[int, ...]
    rotate: bool = False
    sides: tuple[tuple[int, ...], ...] | None = None

    @property
    def every_seat_learns(self) -> bool:
        """Whether learners hold every seat of every game (what ``league_games`` divides)."""
        return not (self.rotate or self.sides is not None or OPPONENT in self.home)


def parse_seats(text: str, n_seats: int) -> tuple[int, ...]:
    """``--seats`` as a learner index per seat: ``"1,2"`` / ``"1,1,-"``: learners numbered from 1, ``-`` an
    opponent's seat."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != n_seats:
        raise MarlError(f"--seats must name one learner (1, 2, ...) or '-' (an opponent) for each of the game's "
                        f"{n_seats} seats, not {text!r}")
    out = []
    for p in parts:
        if p in ("-", "x", "opponent"):
            out.append(OPPONENT)
        elif p.isdigit() and int(p) >= 1:
            out.append(int(p) - 1)
        else:
            raise MarlError(f"--seats: {p!r} is neither a learner number (1, 2, ...) nor '-' (an opponent's seat)")
    used = sorted({s for s in out if s >= 0})
    if not used:
        raise MarlError(f"--seats {text!r} gives no seat to a learner")
    if used != list(range(len(used))):
        raise MarlError(f"--seats {text!r}: learners must be numbered 1 to {len(used)} without gaps")
    return tuple(out)


def plan_seats(spec: EnvSpec, agents: int, sharing: str = "nops", seats: Sequence[int] | None = None) -> SeatPlan:
    """Which learner holds which seat (see the module docstring); a :class:`MarlError` for a mapping the game
    cannot take."""
    if sharing not in SHARING:
        raise MarlError(f"--sharing must be one of {', '.join(SHARING)}, not '{sharing}'")
    n = spec.n_seats
    if sharing == "sa":  # one agent over the whole team: every seat of every game is its
        if spec.kind != COOPERATIVE or spec.turns != "simultaneous":
            raise MarlError(f"--sharing sa makes one agent of a cooperative team acting together; {spec.name} is "
                            f"{spec.kind}, {spec.turns}: use --sharing fups or nops")
        if seats is not None:
            raise MarlError("--sharing sa holds every seat: --seats does not apply")
        return SeatPlan(tuple(0 for _ in range(n)))
    if seats is not None:
        home = tuple(int(s) for s in seats)
        if len(home) != n:
            raise MarlError(f"--seats names {len(home)} seats; {spec.name} has {n} ({', '.join(spec.agents)})")
        if sharing == "fups":
            home = tuple(0 if s >= 0 else OPPONENT for s in home)
        return SeatPlan(home)
    if not 1 <= agents <= n:
        raise MarlError(f"{spec.name} has {n} seat{'s' * (n != 1)}: --agents must be between 1 and {n}, not {agents}")
    sides = spec.side_seats() if spec.kind == TWO_SIDES else None
    if spec.kind == TWO_SIDES and n > 2 and agents not in (1, 2, n):
        raise MarlError(f"{spec.name} is two sides of {n} seats: --agents 1 (one side against the league), 2 (one "
                        f"learner per side) or {n} (one per seat); or say which learner holds each seat with --seats")
    if spec.kind == TWO_SIDES and sides is not None and agents <= 2:
        if agents == 1:  # one side a game, against the league
            return SeatPlan(tuple(0 for _ in range(n)), sides=sides)
        home = tuple(next(i for i, side in enumerate(sides) if s in side) for s in range(n))
        return SeatPlan(_shared(home, sharing))
    if spec.kind == COOPERATIVE:
        return SeatPlan(_shared(tuple(s % agents for s in range(n)), sharing))
    if agents == n:
        return SeatPlan(_shared(tuple(range(n)), sharing))
    return SeatPlan(_shared(tuple(s % agents for s in range(n)), sharing), rotate=True)


def _shared(home: tuple[int, ...], sharing: str) -> tuple[int, ...]:
    return tuple(0 if s >= 0 else s for s in home) if sharing in ("fups", "sa") else home


def plan_layout(plan: SeatPlan, n_games: int, agents: int, league_games: float = 0.0) -> np.ndarray:
    """The learner index of every (seat, game) slot, -1 for opponent slots, for ``n_games`` games."""
    if not 0.0 <= league_games <= 1.0:
        raise ValueError(f"league_games must lie in [0, 1], not {league_games}")
    home = np.asarray(plan.home, dtype=np.int64)
    n = home.size
    games = np.arange(n_games)
    layout = np.full((n, n_games), OPPONENT, dtype=np.int64)
    if plan.sides is not None:  # one learner, one side a game, alternating
        for g in range(n_games):
            layout[list(plan.sides[g % 2]), g] = 0
        return layout
    if plan.rotate:  # fewer learners than seats: learner k on seat (g + k) % n of game g
        for k in range(min(agents, n)):
            layout[(games + k) % n, games] = home[k]
        return layout
    layout[:] = home[:, None]
    k = round(league_games * n_games)  # the first k games: one learner against the league, on its own seats
    if k:
        learners = sorted({int(h) for h in home if h >= 0})
        seat_of = np.array([[s for s in range(n) if home[s] == i] for i in learners], dtype=object)
        layout[:, :k] = OPPONENT
        for g in range(k):
            if len(learners) == 1 and home.size > 1 and all(h == learners[0] for h in home):
                layout[g % n, g] = learners[0]  # one network on every seat: it takes one seat a game
            else:
                i = g % len(learners)
                layout[list(seat_of[i]), g] = learners[i]
    return layout


def league_layout(plan: SeatPlan, n_games: int, n_learners: int) -> np.ndarray:
    """A league's layout (``--league``): game g is learner ``g % n_learners``'s, on the seats a lone learner takes
    in its ``g // n_learners``-th game (``plan``: :func:`plan_seats` with one learner: one side, alternating game by
    game; free-for-all: one seat, rotating), opponents on the rest."""
    games = np.arange(n_games)
    lone = plan_layout(plan, -(-n_games // n_learners), 1)
    return np.where(lone[:, games // n_learners] == 0, games % n_learners, OPPONENT)


def learner_spaces(spec: EnvSpec, seat_spaces: Sequence[SeatSpace], layout: np.ndarray,
                   roles: Sequence[str] | None = None) -> list[SeatSpace]:
    """Each learner's :class:`SeatSpace`: the seats a learner holds must share one (a network reads one observation
    shape and plays one action space) and, where the game gives its seats ``roles``, one role; a
    :class:`MarlError` naming the seats otherwise."""
    out = []
    for i in range(int(layout.max()) + 1):
        held = sorted({int(s) for s in np.nonzero(layout == i)[0]})
        first = seat_spaces[held[0]]
        for s in held[1:]:
            other = seat_spaces[s]
            if (other.observation.shape != first.observation.shape or other.action != first.action
                    or other.mask != first.mask):
                raise MarlError(f"{spec.name}: seats {spec.agents[held[0]]} and {spec.agents[s]} have different "
                                f"spaces ({_describe_seat(spec.agents[held[0]], first)}; "
                                f"{_describe_seat(spec.agents[s], other)}), so one network cannot play both; give "
                                "them separate learners (--sharing nops, or --seats)")
            if roles is not None and roles[s] != roles[held[0]]:
                raise MarlError(f"{spec.name}: seats {spec.agents[held[0]]} and {spec.agents[s]} are of different "
                                f"roles ({roles[held[0]]}, {roles[s]}), so one network cannot play both; give them "
                                "separate learners (--sharing nops, or --seats)")
        out.append(first)
    return out


def _describe_seat(agent: str, seat: SeatSpace) -> str:
    """``agent: observation (3,), actions Discrete(3), masked``: what decides whether one network plays a seat."""
    return (f"{agent}: observation {tuple(seat.observation.shape)}, actions {describe_space(seat.action)}"
            f"{', masked' if seat.mask else ''}")


def learner_roles(layout: np.ndarray, roles: Sequence[str] | None) -> list[str | None]:
    """The role each learner learns (of the seats it holds: :func:`learner_spaces` sees they share one), None for
    every learner of a game whose seats are all of one role."""
    n = int(layout.max()) + 1
    if roles is None:
        return [None] * n
    return [roles[int(np.nonzero(layout == i)[0][0])] for i in range(n)]
