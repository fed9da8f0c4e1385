"""AlphaStar's league roles (``--league alphastar``): whom each learner plays, when it snapshots, when it restarts.

A run with ``--league alphastar`` trains one learner per role: ``main`` main agents, ``main_exploiters`` main
exploiters and ``league_exploiters`` league exploiters (AlphaStar's 1, 1, 2 by default), each with its own network,
optimiser, buffer and seed, each playing its own share of the run's games in one seat against opponents its role's
rule draws. Everything here works on plain data (player ids, learner indices, a :class:`~.win_rates.WinRates` book),
so it is testable without a database, like :mod:`.matchmaking`.

The rules are those of AlphaStar's published pseudocode (Vinyals et al. 2019, the ``multiagent.py`` of its
supplementary material; DI-star re-implements the same). *Past players* are every snapshot of the run, of any role
(AlphaStar's ``Historical``); a learner's win rate ``p`` against an opponent is its :class:`~.win_rates.WinRates`
figure (decayed by ``[opponents] decay``, 0.99 a game of the pair as AlphaStar's ``Payoff``, with marl's prior of
``[opponents] prior`` games at 50% where AlphaStar's unseen pair is 0.5 and its seen one has no prior). PFSP draws a
candidate with probability proportional to ``f(p)``: ``squared`` (1 - p)^2, ``variance`` p(1 - p), ``linear_capped``
min(0.5, 1 - p); weights that sum to ~0 are taken uniform (as there).

* **Main agent** (``MainPlayer.get_match``). A coin ``u``: ``u < pfsp`` (0.5): PFSP ``squared`` over every past
  player. Otherwise a main agent ``m`` is drawn uniformly (the learner itself among them); ``u < pfsp +
  verification`` (0.65): *verification*: if the learner's lowest win rate against the main exploiters' snapshots is
  below ``verify_exploiters`` (0.3), PFSP ``squared`` over all of those snapshots; else, over ``m``'s own snapshots
  with their monotonic suffix removed (the newest run of snapshots whose win rates only fall, i.e. ever harder,
  is left out: what remains is forgetting), PFSP ``squared`` if the lowest win rate there is below
  ``verify_forgetting`` (0.7); else, as the rest: *self-play*: ``m`` as it is now when the learner beats it more
  than ``selfplay_rate`` (0.3) of the time, else PFSP ``variance`` over ``m``'s snapshots. So 50% PFSP, 15%
  verification (falling through to self-play), 35% self-play.
* **Main exploiter** (``MainExploiter.get_match``): a main agent ``m`` drawn uniformly; ``m`` as it is now when
  the exploiter's win rate against it is above ``exploiter_rate`` (0.1), else PFSP ``variance`` over ``m``'s
  snapshots.
* **League exploiter** (``LeagueExploiter.get_match``): PFSP ``linear_capped`` over every past player.

Where a rule's candidates are none (before the run's first snapshots), it plays a main agent as it is now.

**Snapshots** (``ready_to_checkpoint``): a learner takes one when it has played at least ``min_steps`` game steps
since its last (AlphaStar: 2e9 agent steps) and either beats every opponent of its targets more than
``snapshot_rate`` (0.7) of the time or has played ``max_steps`` (AlphaStar: 4e9). Targets: a main agent's and a
league exploiter's, every past player; a main exploiter's, the main agents as they are now. A learner's steps are
the game steps of its own games (its share of the run's). **Restarts** (``checkpoint``): a main exploiter restarts
from its first state at every snapshot, a league exploiter with probability ``league_exploiter_reset`` (0.25). (The
pseudocode resets a main exploiter's weights *before* copying them into its snapshot, which would file the first
weights every time; the evident intent, followed here, is the snapshot first, then the restart.)

AlphaStar's 2e9/4e9 steps are a run of weeks; here ``min_steps`` 250k and ``max_steps`` 500k keep AlphaStar's ratio
(the limit twice the minimum) at the cadence of an ordinary marl run: its default 6M steps shared by the default
four learners are 1.5M steps each, so each takes 3 to 6 snapshots, as an ordinary run takes one every 1M steps
(``--snapshot-steps``) of its 6M.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import MarlError
from .win_rates import WinRates

ROLES = ("main", "main_exploiter", "league_exploiter")
"""A league learner's role, as its snapshots' rows carry it in ``meta["league_role"]``."""

LEAGUE_MODES = ("alphastar",)
"""What ``--league`` takes."""

LIVE = -2
"""Opponent ids from ``LIVE`` down are learners as they are now: ``LIVE - j`` is learner ``j`` (never a player id of
the league, nor :data:`~.win_rates.LATEST_LEARNER`)."""

WEIGHTINGS = {
    "squared": lambda x: (1.0 - x) ** 2,
    "variance": lambda x: x * (1.0 - x),
    "linear_capped": lambda x: np.minimum(0.5, 1.0 - x),
}
"""AlphaStar's PFSP weightings by the pseudocode's names."""


def live(j: int) -> int:
    """The opponent id of learner ``j`` as it is now."""
    return LIVE - int(j)


def live_learner(pid: int) -> int | None:
    """The learner an opponent id stands for as it is now (None: a player of the league)."""
    return LIVE - int(pid) if pid <= LIVE else None


def pfsp(win_rates: npt.ArrayLike, weighting: str) -> npt.NDArray[np.float64]:
    """AlphaStar's PFSP probabilities over candidates with these win rates (uniform where the weights sum to ~0)."""
    p = np.asarray(win_rates, dtype=np.float64)
    w = WEIGHTINGS[weighting](p)
    total = float(w.sum())
    if total < 1e-10:
        return np.full(p.size, 1.0 / p.size)
    return w / total


def remove_monotonic_suffix(win_rates: npt.ArrayLike, ids: Sequence[int]) -> tuple[np.ndarray, list[int]]:
    """The pseudocode's forgetting check: snapshots oldest first, cut after the last one whose win rate is above its
    predecessor's (the newest run of ever-lower win rates goes); nothing when the win rates never rise."""
    p = np.asarray(win_rates, dtype=np.float64)
    for i in range(len(p) - 1, 0, -1):
        if p[i - 1] < p[i]:
            return p[: i + 1], list(ids[: i + 1])
    return np.array([]), []


def _unit(name: str, value: float) -> float:
    if not 0.0 <= float(value) <= 1.0:
        raise MarlError(f"[league] {name} must lie between 0 and 1, not {value:g}")
    return float(value)


@dataclass(frozen=True)
class LeagueConfig:
    """``[league]``: AlphaStar's roles and their rules' numbers (see the module docstring for what each does)."""

    main: int = 1  # main agents
    main_exploiters: int = 1
    league_exploiters: int = 2
    pfsp: float = 0.5  # main agents: share of games by PFSP over every past player
    verification: float = 0.15  # main agents: share of verification games (the rest, 0.35: self-play)
    selfplay_rate: float = 0.3  # main agents' self-play: a main agent as it is now when beaten more than this
    verify_exploiters: float = 0.3  # verification: main exploiters' snapshots when one is beaten less than this
    verify_forgetting: float = 0.7  # verification: own past snapshots when one is beaten less than this
    exploiter_rate: float = 0.1  # main exploiters: a main agent as it is now when beaten more than this
    snapshot_rate: float = 0.7  # a snapshot when every target is beaten more than this, after min_steps
    min_steps: int = 250_000  # a learner's own game steps between its snapshots, at least (AlphaStar: 2e9)
    max_steps: int = 500_000  # ... and at most (AlphaStar: 4e9)
    league_exploiter_reset: float = 0.25  # probability a league exploiter restarts at its snapshot

    def __post_init__(self) -> None:
        if self.main < 1:
            raise MarlError(f"[league] main must be at least 1 (every rule plays the main agents), not {self.main}")
        if self.main_exploiters < 0 or self.league_exploiters < 0:
            raise MarlError("[league] main_exploiters and league_exploiters must not be negative")
        for name in ("pfsp", "verification", "selfplay_rate", "verify_exploiters", "verify_forgetting",
                     "exploiter_rate", "snapshot_rate", "league_exploiter_reset"):
            _unit(name, getattr(self, name))
        if self.pfsp + self.verification > 1.0 + 1e-9:
            raise MarlError(f"[league] pfsp + verification must be at most 1 (the rest is self-play), not "
                            f"{self.pfsp + self.verification:g}")
        if not 1 <= self.min_steps <= self.max_steps:
            raise MarlError(f"[league] needs 1 <= min_steps <= max_steps, not {self.min_steps} and {self.max_steps}")

    def roles(self) -> list[str]:
        """Each learner's role, in learner order: the main agents, the main exploiters, the league exploiters."""
        return (["main"] * self.main + ["main_exploiter"] * self.main_exploiters
                + ["league_exploiter"] * self.league_exploiters)

    def names(self) -> list[str]:
        """Each learner's name (its snapshots end in it): ``main``, ``mainx``, ``leaguex1``, ``leaguex2``; numbered
        where a role has several learners."""
        out = []
        for short, count in (("main", self.main), ("mainx", self.main_exploiters),
                             ("leaguex", self.league_exploiters)):
            out += [short if count == 1 else f"{short}{k + 1}" for k in range(count)]
        return out


@dataclass(frozen=True)
class Past:
    """A past player: a snapshot of the run (its league id) and the learner that took it."""

    id: int
    learner: int


Draw = tuple[list[int], np.ndarray]
"""A distribution a rule draws from: opponent ids and their probabilities."""


class LeagueRoles:
    """The roles of one league run: each learner's opponents, its snapshot moments and its restarts.

    ``shares``: each learner's share of the run's games (its steps are that share of the run's); ``rng``: the
    generator of every draw (its state is part of :meth:`state_dict`)."""

    def __init__(self, config: LeagueConfig, shares: Sequence[float], rng: np.random.Generator) -> None:
        self.config, self.rng = config, rng
        self.roles = config.roles()
        if len(shares) != len(self.roles):
            raise ValueError(f"{len(shares)} shares for {len(self.roles)} learners")
        self.shares = [float(s) for s in shares]
        self.mains = [i for i, r in enumerate(self.roles) if r == "main"]
        self.pool: list[Past] = []
        self.since = [0] * len(self.roles)  # the run's step at each learner's last snapshot

    def set_pool(self, past: Sequence[Past]) -> None:
        """The run's snapshots, oldest first."""
        self.pool = list(past)

    # -- opponents ---------------------------------------------------------------------------------------------
    def _of(self, learners: Sequence[int] | None = None) -> list[int]:
        """The past players (ids, oldest first) taken by ``learners`` (None: every one)."""
        return [p.id for p in self.pool if learners is None or p.learner in learners]

    def _pfsp(self, i: int, ids: list[int], rates: WinRates, weighting: str) -> Draw | None:
        return (ids, pfsp(rates.p_win_many(i, ids), weighting)) if ids else None

    def _selfplay(self, i: int, m: int, rates: WinRates) -> Draw:
        """A main agent's self-play against main agent ``m`` (``_selfplay_branch``)."""
        if rates.p_win(i, live(m)) > self.config.selfplay_rate:
            return [live(m)], np.ones(1)
        return self._pfsp(i, self._of([m]), rates, "variance") or ([live(m)], np.ones(1))

    def _verification(self, i: int, m: int, rates: WinRates) -> Draw | None:
        """A main agent's verification games (``_verification_branch``); None: nothing to verify."""
        exploiters = [j for j, r in enumerate(self.roles) if r == "main_exploiter"]
        ids = self._of(exploiters)
        p = rates.p_win_many(i, ids)
        if len(ids) and p.min() < self.config.verify_exploiters:
            return ids, pfsp(p, "squared")
        own = self._of([m])
        p, kept = remove_monotonic_suffix(rates.p_win_many(i, own), own)
        if len(kept) and p.min() < self.config.verify_forgetting:
            return kept, pfsp(p, "squared")
        return None

    def _take(self, out: np.ndarray, where: np.ndarray, draw: Draw) -> None:
        n = int(where.sum())
        if n:
            ids, p = draw
            out[where] = np.asarray(ids, dtype=np.int64)[self.rng.choice(len(ids), size=n, p=p)]

    def sample(self, i: int, n: int, rates: WinRates) -> npt.NDArray[np.int64]:
        """``n`` opponent ids for games of learner ``i``, each drawn by its role's rule (:data:`LIVE` ids: a
        learner as it is now)."""
        out = np.empty(int(n), dtype=np.int64)
        if n == 0:
            return out
        role, cfg = self.roles[i], self.config
        if role == "league_exploiter":
            everyone = self._pfsp(i, self._of(), rates, "linear_capped")
            if everyone is not None:
                self._take(out, np.ones(n, dtype=bool), everyone)
                return out
        mains = np.asarray(self.mains)[self.rng.integers(len(self.mains), size=n)]
        coin = self.rng.random(n) if role == "main" else np.ones(n)
        done = np.zeros(n, dtype=bool)
        if role == "main":
            everyone = self._pfsp(i, self._of(), rates, "squared")
            if everyone is not None:
                done = coin < cfg.pfsp
                self._take(out, done, everyone)
        for m in self.mains:
            mine = ~done & (mains == m)
            if role == "main_exploiter":
                if rates.p_win(i, live(m)) > cfg.exploiter_rate:
                    self._take(out, mine, ([live(m)], np.ones(1)))
                else:
                    self._take(out, mine, self._pfsp(i, self._of([m]), rates, "variance") or ([live(m)], np.ones(1)))
                continue
            if role == "main":
                verify = mine & (coin < cfg.pfsp + cfg.verification)
                check = self._verification(i, m, rates) if verify.any() else None
                if check is not None:
                    self._take(out, verify, check)
                    mine &= ~verify
            self._take(out, mine, self._selfplay(i, m, rates))
        return out

    # -- snapshots and restarts ----------------------------------------------------------------------------------
    def targets(self, i: int) -> list[int]:
        """The opponents learner ``i`` must beat to take a snapshot early: a main exploiter's, the main agents as
        they are now; the others', every past player."""
        if self.roles[i] == "main_exploiter":
            return [live(m) for m in self.mains]
        return self._of()

    def steps_since(self, i: int, steps: int) -> int:
        """Learner ``i``'s own game steps since its last snapshot, the run at ``steps``."""
        return int((steps - self.since[i]) * self.shares[i])

    def due(self, steps: int, rates: WinRates) -> list[int]:
        """The learners whose snapshot is due, the run at ``steps``."""
        cfg, out = self.config, []
        for i in range(len(self.roles)):
            passed = self.steps_since(i, steps)
            if passed < cfg.min_steps:
                continue
            targets = self.targets(i)
            beaten = bool(targets) and rates.p_win_many(i, targets).min() > cfg.snapshot_rate
            if beaten or passed >= cfg.max_steps:
                out.append(i)
        return out

    def taken(self, learners: Sequence[int], steps: int) -> list[int]:
        """Note the snapshots of ``learners`` taken at the run's ``steps``; returns those that restart from their
        first state now (every main exploiter; a league exploiter with probability ``league_exploiter_reset``)."""
        restart = []
        for i in learners:
            self.since[i] = int(steps)
            role = self.roles[i]
            if role == "main_exploiter" or (role == "league_exploiter"
                                             and self.rng.random() < self.config.league_exploiter_reset):
                restart.append(i)
        return restart

    def state_dict(self) -> dict[str, Any]:
        """JSON-serialisable: the generator's state and each learner's last snapshot step (the pool is the
        league's)."""
        return {"rng": self.rng.bit_generator.state, "since": list(self.since)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        try:
            since = [int(s) for s in state["since"]]
            if len(since) != len(self.roles):
                raise ValueError(f"{len(since)} learners saved, {len(self.roles)} configured")
            self.rng.bit_generator.state = dict(state["rng"])
        except (KeyError, TypeError, ValueError) as e:
            raise MarlError(f"malformed league roles state: {e}") from None
        self.since = since
