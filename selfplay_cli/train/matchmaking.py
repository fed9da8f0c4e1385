"""Opponent matchmaking for self-play training: self / latest / uniform / PFSP / Nash over a snapshot pool, plus bots.

The training loop asks a :class:`Matchmaker` for the opponents of a batch of new games of one learner, and
reports finished games back to a :class:`~.win_rates.WinRates` book (:mod:`.win_rates`), which PFSP reads.
Everything here works on plain data (integer player ids and results), so it is testable without a database.

Opponent distribution
---------------------
For a learner, :meth:`Matchmaker.probabilities` builds the distribution in three layers:

1. **Bots** first: scripted bot ``b`` is the opponent with probability ``bots[b]`` (config, summing to
   ``B <= 1``). The remaining mass is ``R = 1 - B``.
2. **Self** (ML-Agents ``play_against_latest_model_ratio``): the opponent is :data:`LATEST_LEARNER`
   (the learner itself / its current partner; the loop decides which) with probability
   ``R * latest_ratio``. In mode ``self``, or while the pool is empty (no snapshot yet), it gets all of ``R``.
3. **Pool**: the remaining ``R * (1 - latest_ratio)`` goes to the last ``window`` snapshots of the pool
   (ML-Agents ``window``; the pool is given oldest first):

   * ``latest``: all of it to the newest snapshot;
   * ``uniform``: split equally (ML-Agents self-play is exactly ``uniform`` + ``latest_ratio``);
   * ``pfsp``: AlphaStar prioritized fictitious self-play, candidate ``B`` weighted by ``f(P[learner beats B])``
     with ``f_hard(x) = (1 - x)**2`` (focus on the opponents the learner loses to) or
     ``f_var(x) = x * (1 - x)`` (focus on opponents of the learner's level), weights normalised.

   * ``nash``: PSRO's meta-strategy, the Nash mixture of the run's snapshots (:meth:`Matchmaker.set_mixture`, solved
     from the ledger by :func:`~selfplay_cli.ratings.meta_nash.run_nash`), restricted to the candidates and
     renormalised; uniform over them while no mixture is known (or none of its support is a candidate). The
     ``window`` does not cut it: PSRO mixes over the whole population, so every snapshot of the pool is a candidate.

   PFSP has **no epsilon floor** (as in AlphaStar): with the default ``prior > 0`` every win rate lies
   strictly inside (0, 1), so every candidate already has a positive weight. Only with ``prior = 0`` can a
   weight be exactly 0 (a candidate never beaten / always beaten); such a candidate is then never drawn,
   and if *every* weight is 0 the pool share is split uniformly instead.

Ids with probability 0 are left out of the returned dict; the ids that remain sum to 1.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.errors import MarlError
from selfplay_cli.train.win_rates import LATEST_LEARNER, WinRates

__all__ = [
    "MODES",
    "PFSP_WEIGHTINGS",
    "Matchmaker",
    "MatchmakerConfig",
    "f_hard",
    "f_var",
    "parse_bots",
]

MODES = ("self", "latest", "uniform", "pfsp", "nash")
"""Opponent selection modes of :class:`MatchmakerConfig`."""

NASH_PAYOFFS = ("points", "score")
"""Units of the ``nash`` mode's meta-game: :data:`selfplay_cli.ratings.pairs.PAYOFFS` (named again here: this module
imports nothing of the league)."""

_SUM_TOL = 1e-9
_STATE_VERSION = 1


def f_hard(x: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """AlphaStar ``f_hard(x) = (1 - x)**2``: weight opponents the learner loses to."""
    x = np.asarray(x, dtype=np.float64)
    return (1.0 - x) ** 2


def f_var(x: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """AlphaStar ``f_var(x) = x * (1 - x)``: weight opponents of about the learner's level."""
    x = np.asarray(x, dtype=np.float64)
    return x * (1.0 - x)


PFSP_WEIGHTINGS: dict[str, Callable[[npt.ArrayLike], npt.NDArray[np.float64]]] = {"hard": f_hard, "var": f_var}
"""PFSP weighting functions by ``--pfsp`` name."""


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _check_bots(bots: Mapping[str, float]) -> dict[str, float]:
    """Validate a bot mix and return it as a plain ``{name: float}`` dict."""
    if not isinstance(bots, Mapping):
        raise MarlError(f"bots must map bot names to probabilities, got {type(bots).__name__}")
    out: dict[str, float] = {}
    for name, p in bots.items():
        if not isinstance(name, str) or not name.strip() or name != name.strip():
            raise MarlError(f"invalid bot name {name!r}")
        if not _is_number(p) or not math.isfinite(float(p)):
            raise MarlError(f"bot {name!r}: probability must be a number, got {p!r}")
        if float(p) < 0.0:
            raise MarlError(f"bot {name!r}: probability must be >= 0, got {float(p):g}")
        out[name] = float(p)
    total = sum(out.values())
    if total > 1.0 + _SUM_TOL:
        raise MarlError(f"bot probabilities sum to {total:g}, more than 1")
    return out


def parse_bots(text: str) -> dict[str, float]:
    """Parse a ``--bots`` value such as ``"cpu=0.1,random=0.05"`` into ``{"cpu": 0.1, "random": 0.05}``.

    Whitespace around names and numbers is ignored; an empty (or blank) string means no bots.

    Raises:
        MarlError: an item without ``=``, an empty name, a value that is not a number, a repeated name,
            a negative probability, or probabilities summing to more than 1.
    """
    out: dict[str, float] = {}
    if text is None or not text.strip():
        return out
    for raw in text.split(","):
        item = raw.strip()
        if not item:
            raise MarlError(f"invalid --bots {text!r}: empty item (expected name=prob,name=prob)")
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name:
            raise MarlError(f"invalid --bots item {item!r}: expected name=probability")
        try:
            p = float(value)
        except ValueError:
            raise MarlError(f"invalid --bots item {item!r}: {value!r} is not a number") from None
        if name in out:
            raise MarlError(f"invalid --bots {text!r}: bot {name!r} given twice")
        out[name] = p
    return _check_bots(out)


@dataclass(frozen=True)
class MatchmakerConfig:
    """How a learner's opponents are chosen (see the module docstring for the exact distribution).

    Attributes:
        mode: ``self`` | ``latest`` | ``uniform`` | ``pfsp`` | ``nash``.
        window: how many of the newest pool snapshots are candidates (ML-Agents ``window``, >= 1; ``nash``: all).
        latest_ratio: probability (after bots) of playing :data:`LATEST_LEARNER` (ML-Agents
            ``play_against_latest_model_ratio``), in [0, 1].
        bots: bot name -> probability of facing that bot, taken before anything else; sum <= 1.
        pfsp: PFSP weighting, ``hard`` (``(1-x)**2``) or ``var`` (``x*(1-x)``).
        decay: per-game decay of the win-rate book, in (0, 1].
        prior: weight (in games) of the 50 % prior of the win-rate book, >= 0.
        nash_payoff: ``nash``: the meta-game's units, ``points`` (win 1, draw 0.5) or ``score`` (the game's own
            scores: a poker game's chips, PSRO's expected return); see :mod:`selfplay_cli.ratings.meta_nash`.
    """

    mode: str = "pfsp"
    window: int = 10
    latest_ratio: float = 0.5
    bots: dict[str, float] = field(default_factory=dict)
    pfsp: str = "hard"
    decay: float = 0.99
    prior: float = 1.0
    nash_payoff: str = "points"

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise MarlError(f"unknown matchmaking mode {self.mode!r} (expected one of {', '.join(MODES)})")
        if self.nash_payoff not in NASH_PAYOFFS:
            raise MarlError(f"unknown Nash payoff {self.nash_payoff!r} (expected one of {', '.join(NASH_PAYOFFS)})")
        if self.pfsp not in PFSP_WEIGHTINGS:
            raise MarlError(f"unknown PFSP weighting {self.pfsp!r} (expected one of {', '.join(PFSP_WEIGHTINGS)})")
        if not isinstance(self.window, (int, np.integer)) or isinstance(self.window, bool) or self.window < 1:
            raise MarlError(f"window must be a whole number >= 1, got {self.window!r}")
        if not _is_number(self.latest_ratio) or not (0.0 <= float(self.latest_ratio) <= 1.0):
            raise MarlError(f"latest ratio must lie in [0, 1], got {self.latest_ratio!r}")
        if not _is_number(self.decay) or not (0.0 < float(self.decay) <= 1.0):
            raise MarlError(f"win-rate decay must lie in (0, 1], got {self.decay!r}")
        if not _is_number(self.prior) or not math.isfinite(float(self.prior)) or float(self.prior) < 0.0:
            raise MarlError(f"win-rate prior must be a number >= 0, got {self.prior!r}")
        object.__setattr__(self, "window", int(self.window))
        object.__setattr__(self, "latest_ratio", float(self.latest_ratio))
        object.__setattr__(self, "decay", float(self.decay))
        object.__setattr__(self, "prior", float(self.prior))
        object.__setattr__(self, "bots", _check_bots(self.bots))



# --------------------------------------------------------------------------------------------------
# Matchmaker
# --------------------------------------------------------------------------------------------------


class Matchmaker:
    """Draws opponents for learners from bots, :data:`LATEST_LEARNER` and the snapshot pool.

    Args:
        config: the selection rules.
        rng: the generator every draw uses (its state is part of :meth:`state_dict`).
        bot_ids: bot name -> player id, for at least every bot of ``config.bots``.

    Raises:
        MarlError: a bot of the config has no id (unknown bot for this env).
    """

    def __init__(self, config: MatchmakerConfig, rng: np.random.Generator, bot_ids: Mapping[str, int]) -> None:
        self.config = config
        self.rng = rng
        self.bot_ids = {str(k): int(v) for k, v in bot_ids.items()}
        missing = [b for b in config.bots if b not in self.bot_ids]
        if missing:
            known = ", ".join(sorted(self.bot_ids)) or "none"
            raise MarlError(f"unknown bot {missing[0]!r} (known bots: {known})")
        for name, pid in self.bot_ids.items():
            if pid == LATEST_LEARNER:
                raise ValueError(f"bot {name!r} has the reserved id {LATEST_LEARNER}")
        self._weight_fn = PFSP_WEIGHTINGS[config.pfsp]
        self._pool: tuple[int, ...] = ()
        self._mixture: dict[int, float] = {}  # mode nash: snapshot id -> Nash weight (empty: none solved yet)

    # ------------------------------------------------------------------ pool

    def set_pool(self, snapshot_ids: Sequence[int]) -> None:
        """Set the snapshot pool, oldest first; the candidates are the last ``window`` of them.

        Raises ValueError for a repeated id or the reserved id :data:`LATEST_LEARNER`.
        """
        self._pool = self._check_pool(snapshot_ids)

    @staticmethod
    def _check_pool(snapshot_ids: Iterable[int]) -> tuple[int, ...]:
        pool = tuple(int(x) for x in snapshot_ids)
        if len(set(pool)) != len(pool):
            raise ValueError("set_pool: snapshot ids must be distinct")
        if LATEST_LEARNER in pool:
            raise ValueError(f"set_pool: {LATEST_LEARNER} is reserved for LATEST_LEARNER")
        return pool

    @property
    def pool(self) -> tuple[int, ...]:
        """The whole pool, oldest first."""
        return self._pool

    @property
    def candidates(self) -> tuple[int, ...]:
        """The last ``window`` snapshots of the pool, oldest first (mode ``nash``: the whole pool)."""
        return self._pool if self.config.mode == "nash" else self._pool[-self.config.window:]

    def candidates_among(self, among: Collection[int] | None) -> tuple[int, ...]:
        """The :attr:`candidates` that are in ``among`` (all of them when None): the snapshots that can play a seat
        (a game whose seats hold different roles)."""
        if among is None:
            return self.candidates
        mine = tuple(p for p in self._pool if p in among)
        return mine if self.config.mode == "nash" else mine[-self.config.window:]

    def set_mixture(self, weights: Mapping[int, float] | None) -> None:
        """Mode ``nash``: the Nash mixture to draw the pool's share from (snapshot id -> weight; weights of ids
        outside the pool are ignored), or None while there is none (uniform over the candidates).

        Raises ValueError for a negative or non-finite weight."""
        mixture = {int(p): float(w) for p, w in (weights or {}).items()}
        if any(not (math.isfinite(w) and w >= 0.0) for w in mixture.values()):
            raise ValueError("set_mixture: weights must be finite and >= 0")
        self._mixture = mixture

    @property
    def mixture(self) -> dict[int, float]:
        """The Nash mixture of :meth:`set_mixture` (empty: none)."""
        return dict(self._mixture)

    # ------------------------------------------------------------------ distribution

    def pool_weights(self, learner: int, rates: WinRates, among: Collection[int] | None = None) -> dict[int, float]:
        """The mode's distribution over :attr:`candidates` alone (sums to 1; empty for an empty pool / ``self``);
        ``among``: only the candidates of :meth:`candidates_among`."""
        cand = self.candidates_among(among)
        mode = self.config.mode
        if not cand or mode == "self":
            return {}
        if mode == "latest":
            return {cand[-1]: 1.0}
        if mode == "uniform":
            return {c: 1.0 / len(cand) for c in cand}
        if mode == "nash":
            mine = {c: self._mixture.get(c, 0.0) for c in cand}
            total = sum(mine.values())
            if not total > 0.0:  # no mixture yet, or none of its support can play here: uniform
                return {c: 1.0 / len(cand) for c in cand}
            return {c: w / total for c, w in mine.items() if w > 0.0}
        w = self._weight_fn(rates.p_win_many(learner, cand))
        total = float(w.sum())
        if not total > 0.0:  # only possible with prior = 0: every candidate always won / lost
            return {c: 1.0 / len(cand) for c in cand}
        return {c: float(x) / total for c, x in zip(cand, w, strict=True)}

    def probabilities(self, learner: int, rates: WinRates, among: Collection[int] | None = None) -> dict[int, float]:
        """Opponent id (bots, :data:`LATEST_LEARNER`, snapshots) -> probability, summing to 1; ``among`` limits the
        snapshots (:meth:`candidates_among`).

        Ids with probability 0 are omitted. Order: bots (config order), LATEST_LEARNER, candidates.
        """
        cfg = self.config
        out: dict[int, float] = {}

        def add(pid: int, p: float) -> None:
            if p > 0.0:
                out[pid] = out.get(pid, 0.0) + p

        for name, p in cfg.bots.items():
            add(self.bot_ids[name], p)
        rest = max(0.0, 1.0 - sum(cfg.bots.values()))
        pool = self.pool_weights(learner, rates, among)
        if not pool:
            add(LATEST_LEARNER, rest)
            return out
        add(LATEST_LEARNER, rest * cfg.latest_ratio)
        share = rest * (1.0 - cfg.latest_ratio)
        for pid, p in pool.items():
            add(pid, share * p)
        return out

    def sample(self, learner: int, n: int, rates: WinRates, among: Collection[int] | None = None
               ) -> npt.NDArray[np.int64]:
        """``n`` opponent ids drawn i.i.d. from :meth:`probabilities` (int64 array)."""
        n = int(n)
        if n < 0:
            raise ValueError(f"sample: n must be >= 0, got {n}")
        probs = self.probabilities(learner, rates, among)
        ids = np.fromiter(probs.keys(), dtype=np.int64, count=len(probs))
        cdf = np.cumsum(np.fromiter(probs.values(), dtype=np.float64, count=len(probs)))
        cdf /= cdf[-1]
        cdf[-1] = 1.0
        u = self.rng.random(n)
        return ids[np.searchsorted(cdf, u, side="right")]

    # ------------------------------------------------------------------ resume

    def state_dict(self) -> dict[str, Any]:
        """JSON-serialisable state: the generator state and the pool (the config is not included)."""
        return {"version": _STATE_VERSION, "rng": self.rng.bit_generator.state, "pool": list(self._pool)}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`; later draws repeat those after the save. MarlError if malformed."""
        try:
            if int(state.get("version", 0)) != _STATE_VERSION:
                raise ValueError(f"unsupported version {state.get('version')!r}")
            rng_state = dict(state["rng"])
            want = type(self.rng.bit_generator).__name__
            if rng_state.get("bit_generator") != want:
                raise ValueError(f"generator {rng_state.get('bit_generator')!r} is not {want!r}")
            pool = self._check_pool(state["pool"])
            self.rng.bit_generator.state = rng_state
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise MarlError(f"malformed matchmaker state: {exc}") from None
        self._pool = pool
