"""What a finished game is, from the runner to the ledger, and what it means by the game's kind.

One record type, :class:`GameResult`, carries a game everywhere: both game loops (:func:`selfplay_cli.play.play`
for whole games, :class:`~selfplay_cli.play.training_games.SelfPlayGames` for training's) make it, by
:func:`game_results`, with the players' ids per seat; rated play swaps policy ids for league player ids
(:meth:`GameResult.with_players`) and the ledger stores it (:meth:`selfplay_cli.league.store.League.record_games`).

:class:`Rules` are the part of a game's declaration that decides results and who may sit where: its kind, its sides,
its tie tolerance and, where its seats differ, each seat's role (a policy plays only seats of its own role; see
:meth:`~selfplay_cli.envs.contract.EnvSpec.seat_roles`).

* ``two-sides``: zero-sum between two sides (``sides``: the seats of each; by default seat 0 against seat 1). The
  side with the higher total score wins; a difference of at most ``tie_tolerance`` is a draw. Every seat of a side
  gets the side's points (1, 0.5, 0). A game played for ``stakes`` (poker: a hand is won by some chips, up to the
  stakes) scores by what was won instead: ``1/2 + (the side's total - the other's) / (4 stakes)``, so a hand won
  by all the stakes is 1, one won by a quarter of them 0.625, and the points of a match are the chips won, not the
  hands (a player that wins many small pots and loses the big ones is behind).
* ``cooperative``: every seat plays for one team. One game has no winner (every seat gets 0.5 points); two policies
  are compared by flying the same seed each, the higher team return (the sum of the seats' scores) winning
  (:func:`compare`), a difference of at most ``tie_tolerance`` being a draw.
* ``free-for-all``: every seat for itself. Pairwise results come from the final order of the scores (equal within
  ``tie_tolerance``: a draw); a seat's points are its mean pairwise result against every other seat.

Between league players a game gives *pairwise results* (:func:`pairwise`): two-sides, one for every two different
players on opposite sides (one for a game between two policies, whatever the number of seats); free-for-all, one for
every two different players (a player on several seats scores the mean over its seats' pairings); cooperative games
give theirs only in pairs of episodes (:func:`compare`). Ratings are fitted from these.

numpy only; this module imports nothing else of marl.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = ["COOPERATIVE", "FREE_FOR_ALL", "KINDS", "TWO_SIDES", "GameResult", "Rules", "compare", "format_score",
           "game_results", "pairwise", "points_between", "truncated_rule"]

TWO_SIDES = "two-sides"
COOPERATIVE = "cooperative"
FREE_FOR_ALL = "free-for-all"
KINDS = (TWO_SIDES, COOPERATIVE, FREE_FOR_ALL)


@dataclass(frozen=True)
class GameResult:
    """One finished game: who sat where, its seed, every seat's score and points, its length, its actions.

    Attributes:
        env: the game's registered name.
        players: one entry per seat: the policy's id (from a game loop) or the league player's id (to the ledger;
            see :meth:`with_players`).
        seed: the game's seed.
        scores: each seat's score (float: points in Pong, summed rewards in a PettingZoo game).
        outcome: each seat's points by the game's :class:`Rules`: 1 win, 0.5 draw, 0 loss (two-sides); its mean
            pairwise result (free-for-all); 0.5 (cooperative: a single game has no winner).
        length: steps played.
        truncated: the game was cut short (its time limit, or :func:`~selfplay_cli.play.play`'s ``stop_when``) and
            decided by the score at that moment.
        actions: the encoded actions of every step (:mod:`selfplay_cli.play.replay`), when they were recorded.
        index: the game's position in :func:`~selfplay_cli.play.play`'s schedule (training's games: its slot).
    """

    env: str
    players: tuple[Any, ...]
    seed: int
    scores: tuple[float, ...]
    outcome: tuple[float, ...]
    length: int
    truncated: bool
    actions: bytes | None = None
    index: int = 0

    def points_of(self, player: Any) -> float:
        """``player``'s points: the mean outcome of the seats it holds (0.0 if it holds none)."""
        mine = [o for p, o in zip(self.players, self.outcome, strict=True) if p == player]
        return sum(mine) / len(mine) if mine else 0.0

    def score_of(self, player: Any) -> float:
        """The total score of the seats ``player`` holds (its side's points, its team return, its seats' scores)."""
        return float(sum(s for p, s in zip(self.players, self.scores, strict=True) if p == player))

    def with_players(self, ids: Mapping[Any, Any]) -> GameResult:
        """The same game with every seat's player replaced by ``ids[player]`` (policy ids to league player ids)."""
        return replace(self, players=tuple(ids[p] for p in self.players))


def game_results(env: str, rules: Rules, scores: np.ndarray, players: Sequence[tuple[Any, ...]],
                 seeds: Sequence[int], lengths: Sequence[int], truncated: Sequence[bool], indices: Sequence[int],
                 actions: Sequence[bytes | None] | None = None) -> list[GameResult]:
    """The results of games that ended together, from their final ``scores`` (``(n_seats, m)``, one column per game)
    and, per game, its players by seat, seed, length, whether it was cut short, its index and its encoded actions:
    each seat's points by ``rules``, every number a plain Python one. The one place a game loop makes results."""
    scores = np.asarray(scores, dtype=np.float64)
    outcome = rules.outcome(scores)
    return [GameResult(env=env, players=tuple(players[k]), seed=int(seeds[k]),
                       scores=tuple(float(x) for x in scores[:, k]), outcome=tuple(float(x) for x in outcome[:, k]),
                       length=int(lengths[k]), truncated=bool(truncated[k]), index=int(indices[k]),
                       actions=None if actions is None else actions[k])
            for k in range(scores.shape[1])]


def format_score(x: float) -> str:
    """A score for people: ``21`` for a whole number, else up to 4 decimals (``-3.25``)."""
    x = float(x)
    return str(int(x)) if x.is_integer() else f"{x:.4f}".rstrip("0")


@dataclass(frozen=True)
class Rules:
    """How a game's scores become results: its ``kind``, ``sides`` (two-sides) and ``tie_tolerance``; ``roles``,
    each seat's role where the seats are not all of one (None: any policy may sit anywhere)."""

    n_seats: int = 2
    kind: str = TWO_SIDES
    sides: tuple[tuple[int, ...], ...] | None = None
    tie_tolerance: float = 0.0
    roles: tuple[str, ...] | None = None
    stakes: float | None = None  # two-sides only: the most a side can win (points follow the margin, see above)

    def __post_init__(self) -> None:
        if self.stakes is not None:
            if self.kind != TWO_SIDES:
                raise ValueError(f"a {self.kind} game is not played for stakes (two-sides games only)")
            if not (np.isfinite(self.stakes) and self.stakes > 0):
                raise ValueError(f"the stakes must be a finite number > 0, not {self.stakes}")
            object.__setattr__(self, "stakes", float(self.stakes))
        if self.kind not in KINDS:
            raise ValueError(f"unknown game kind {self.kind!r} (expected one of {', '.join(KINDS)})")
        if not self.n_seats >= 1:
            raise ValueError(f"a game needs at least one seat, not {self.n_seats}")
        if not (self.tie_tolerance >= 0 and np.isfinite(self.tie_tolerance)):
            raise ValueError(f"the tie tolerance must be a finite number >= 0, not {self.tie_tolerance}")
        if self.kind == TWO_SIDES:
            sides = self.sides
            if sides is None:
                if self.n_seats != 2:
                    raise ValueError(f"a two-sides game of {self.n_seats} seats must say which seats form each side")
                sides = ((0,), (1,))
            sides = tuple(tuple(int(s) for s in side) for side in sides)
            seats = sorted(s for side in sides for s in side)
            if len(sides) != 2 or not all(sides) or seats != list(range(self.n_seats)):
                raise ValueError(f"the sides {sides} must split the {self.n_seats} seats into two non-empty sides")
            object.__setattr__(self, "sides", sides)
        elif self.sides is not None:
            raise ValueError(f"a {self.kind} game has no sides")
        if self.roles is not None:
            roles = tuple(str(r) for r in self.roles)
            if len(roles) != self.n_seats:
                raise ValueError(f"{len(roles)} roles for a game of {self.n_seats} seats")
            object.__setattr__(self, "roles", roles if len(set(roles)) > 1 else None)

    @classmethod
    def of(cls, spec: Any) -> Rules:
        """The rules a game's declaration (an :class:`~selfplay_cli.envs.contract.EnvSpec`) states; a declaration
        without ``kind`` is a two-sides game."""
        roles = spec.seat_roles() if callable(getattr(spec, "seat_roles", None)) else None
        return cls(n_seats=len(spec.agents), kind=getattr(spec, "kind", TWO_SIDES) or TWO_SIDES,
                   sides=getattr(spec, "sides", None), tie_tolerance=float(getattr(spec, "tie_tolerance", 0.0) or 0.0),
                   roles=roles, stakes=getattr(spec, "stakes", None))

    @property
    def is_default(self) -> bool:
        """Two seats, one against the other, exact ties: Pong's rules, and those of any ledger entry that states
        none."""
        return self == Rules()

    @property
    def sides_differ(self) -> bool:
        """A two-sides game whose sides hold different roles (a hunter against a runner): each policy plays only its
        own side, so it is rated against the other side's players only, per side."""
        if self.kind != TWO_SIDES or self.roles is None:
            return False
        assert self.sides is not None
        first, second = (sorted(self.roles[s] for s in side) for side in self.sides)
        return first != second

    def side_roles(self) -> tuple[str, ...]:
        """A name for each side of a two-sides game: its seats' roles (``hunter``; ``attacker+keeper``)."""
        assert self.sides is not None
        roles = self.roles or ("",) * self.n_seats
        return tuple("+".join(dict.fromkeys(roles[s] for s in side)) for side in self.sides)

    def to_json(self) -> dict[str, Any]:
        out = {"n_seats": self.n_seats, "kind": self.kind,
               "sides": None if self.sides is None else [list(s) for s in self.sides],
               "tie_tolerance": self.tie_tolerance}
        if self.roles is not None:
            out["roles"] = list(self.roles)
        if self.stakes is not None:
            out["stakes"] = self.stakes
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any] | None) -> Rules:
        """Rules stored with :meth:`to_json`; none stored: the default (:attr:`is_default`)."""
        if not data:
            return cls()
        sides, roles, stakes = data.get("sides"), data.get("roles"), data.get("stakes")
        return cls(n_seats=int(data.get("n_seats", 2)), kind=str(data.get("kind", TWO_SIDES)),
                   sides=None if sides is None else tuple(tuple(s) for s in sides),
                   tie_tolerance=float(data.get("tie_tolerance", 0.0)),
                   roles=None if roles is None else tuple(roles), stakes=None if stakes is None else float(stakes))

    def _cmp(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Points of ``x`` against ``y``: 1 above, 0 below, 0.5 within the tie tolerance."""
        d = np.asarray(x, dtype=np.float64) - np.asarray(y, dtype=np.float64)
        return np.where(np.abs(d) <= self.tie_tolerance, 0.5, np.where(d > 0, 1.0, 0.0))

    def outcome(self, scores: np.ndarray) -> np.ndarray:
        """Points per seat of finished games from their scores, ``(n_seats, m) -> (n_seats, m)`` float64."""
        s = np.asarray(scores, dtype=np.float64)
        if s.shape[0] != self.n_seats:
            raise ValueError(f"scores of {s.shape[0]} seats for a game of {self.n_seats}")
        if self.kind == TWO_SIDES:
            assert self.sides is not None
            mine, theirs = s[list(self.sides[0])].sum(axis=0), s[list(self.sides[1])].sum(axis=0)
            first = self._cmp(mine, theirs)
            if self.stakes is not None:  # by what was won
                won = np.clip(0.5 + (mine - theirs) / (4.0 * self.stakes), 0.0, 1.0)
                first = np.where(first == 0.5, 0.5, won)
            out = np.empty_like(s)
            out[list(self.sides[0])] = first
            out[list(self.sides[1])] = 1.0 - first
            return out
        if self.kind == COOPERATIVE or self.n_seats == 1:
            return np.full_like(s, 0.5)
        pair = self._cmp(s[:, None], s[None, :])  # (seat, other seat, game)
        return (pair.sum(axis=1) - 0.5) / (self.n_seats - 1)  # less the seat against itself


def pairwise(rules: Rules, players: Sequence[Any], scores: Sequence[float],
             outcome: Sequence[float]) -> list[tuple[Any, Any, float]]:
    """The pairwise results ``(a, b, a's points)`` between different players that one game gives (see the module
    docstring), ``a`` the player of the lower first seat (two-sides: ``a`` on the first side); none for cooperative
    games and for a game whose seats do not fit ``rules``.

    Two-sides results are the stored ``outcome`` of the sides (the result the game was filed with); free-for-all
    ones come from the ``scores``."""
    n = len(players)
    if n != rules.n_seats or rules.kind == COOPERATIVE:
        return []
    if rules.kind == TWO_SIDES:
        assert rules.sides is not None
        first, second = rules.sides
        points = float(outcome[first[0]])
        out: list[tuple[Any, Any, float]] = []
        seen: set[tuple[Any, Any]] = set()
        for a in dict.fromkeys(players[s] for s in first):
            for b in dict.fromkeys(players[s] for s in second):
                if a != b and (a, b) not in seen:
                    seen.add((a, b))
                    out.append((a, b, points))
        return out
    seats: dict[Any, list[int]] = {}
    for k, p in enumerate(players):
        seats.setdefault(p, []).append(k)
    who = list(seats)
    s = np.asarray(scores, dtype=np.float64)
    out = []
    for i, a in enumerate(who):
        for b in who[i + 1:]:
            pts = rules._cmp(s[seats[a]][:, None], s[seats[b]][None, :])
            out.append((a, b, float(pts.mean())))
    return out


def truncated_rule(kind: str, tie_tolerance: float = 0.0) -> str:
    """What a truncated game counts as, in words, by the game's kind. A game cut short is scored like any other
    (:func:`game_results`, :meth:`Rules.outcome`, :func:`compare`), from the scores it had at the cut: two-sides,
    the side ahead wins; free-for-all, the scores' order; cooperative, the team return summed up to the cut is
    compared. Scores within ``tie_tolerance`` are level: a draw."""
    level = "level is a draw" if not tie_tolerance else f"within {format_score(tie_tolerance)} is a draw"
    if kind == COOPERATIVE:
        return (f"a truncated episode's team return is what it scored up to the cut, compared like any other: the "
                f"higher wins, {level}")
    if kind == FREE_FOR_ALL:
        return f"each truncated game is ordered by the scores at the cut: the higher beats the lower, {level}"
    return f"each truncated game is decided by the score at the cut: the side ahead wins it, {level}"


def compare(return_a: float, return_b: float, tie_tolerance: float = 0.0) -> float:
    """A's points in a cooperative comparison: its team return against B's on the same seed (1, 0.5 or 0)."""
    d = float(return_a) - float(return_b)
    return 0.5 if abs(d) <= tie_tolerance else 1.0 if d > 0 else 0.0


def crew(player: Any) -> frozenset:
    """The players an id stands for: itself, or a team's members (a tuple of ids)."""
    return frozenset(player) if isinstance(player, tuple) else frozenset((player,))


def points_between(rules: Rules, games: Sequence[GameResult], a: Any, b: Any) -> list[float]:
    """A's points in every result between players ``a`` and ``b`` that ``games`` give (one round of rated play, see
    :mod:`selfplay_cli.play.schedule`): two-sides and free-for-all, one per game (:func:`pairwise`); cooperative,
    one per comparison of A's episode with B's (the i-th of each, in order)."""
    if rules.kind == COOPERATIVE:  # a or b may be a team flying together: a tuple of its members' ids
        mine = [sum(g.scores) for g in games if frozenset(g.players) == crew(a)]
        theirs = [sum(g.scores) for g in games if frozenset(g.players) == crew(b)]
        return [compare(x, y, rules.tie_tolerance) for x, y in zip(mine, theirs, strict=False)]
    out = []
    for g in games:
        for x, y, pts in pairwise(rules, g.players, g.scores, g.outcome):
            if (x, y) == (a, b):
                out.append(pts)
            elif (x, y) == (b, a):
                out.append(1.0 - pts)
    return out
