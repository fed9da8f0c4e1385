"""What both game loops enforce (:func:`~.matches.play` and :class:`~.training_games.SelfPlayGames`): every game
ends, at its declared length or at :data:`UNDECLARED_MAX_STEPS`, and no number that is not finite reaches a policy,
a learner or the league."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..envs import EnvSpec

__all__ = ["UNDECLARED_MAX_STEPS", "GameLength", "first_nonfinite"]

UNDECLARED_MAX_STEPS = 100_000
"""The most steps a game is played for when it declares no maximum length (a PettingZoo game without
``metadata["marl_max_steps"]`` or ``max_cycles``, pong with ``max_steps=0``): 5.5 times the longest game a built-in
game declares (pong's 18,000), so a game that can end is never cut by it, while one that never ends still does."""

_warned: set[str] = set()  # games whose cut by UNDECLARED_MAX_STEPS was already reported (once a process)


def first_nonfinite(per_seat: Any, n: int) -> tuple[int, int, str] | None:
    """``(seat, slot, "NaN" | "inf" | "-inf")`` of the first number in ``per_seat`` (per seat, ``(n, ...)`` arrays: a
    step's observations or rewards) that is not finite, None when all are. One ``np.isfinite(...).all()`` per seat
    array (one for all of them when they are one array): the search for the culprit runs only when one fails."""
    arrays = [per_seat] if isinstance(per_seat, np.ndarray) else [np.asarray(a) for a in per_seat]
    if all(a.dtype.kind not in "fc" or np.isfinite(a).all() for a in arrays):
        return None
    for s in range(len(per_seat)):
        a = np.asarray(per_seat[s]).reshape(n, -1)
        bad = ~np.isfinite(a).all(axis=1) if a.dtype.kind in "fc" else np.zeros(n, dtype=bool)
        if bad.any():
            slot = int(np.flatnonzero(bad)[0])
            value = a[slot][~np.isfinite(a[slot])][0]
            return s, slot, "NaN" if np.isnan(value) else "inf" if value > 0 else "-inf"
    return None


@dataclass(frozen=True)
class GameLength:
    """How long one game of a game (for given options) may last: the most steps it declares, else
    :data:`UNDECLARED_MAX_STEPS`. Both game loops end a game that reaches it as truncated, so every game ends,
    whether or not the game itself keeps its declared length."""

    name: str
    limit: int
    declared: bool

    @classmethod
    def of(cls, spec: EnvSpec, cfg: Any) -> GameLength:
        declared = spec.max_steps(cfg)
        return cls(spec.name, int(declared), True) if declared else cls(spec.name, UNDECLARED_MAX_STEPS, False)

    def over(self, steps: np.ndarray, done: np.ndarray) -> np.ndarray:
        """The games not yet ``done`` that have played their length (to end now, as truncated); the first time a
        game is cut by the loops' own cap, one line on stderr says so."""
        over = (np.asarray(steps) >= self.limit) & ~done
        if not self.declared and self.name not in _warned and over.any():
            _warned.add(self.name)
            sys.stderr.write(f"marl: warning: {self.name} declares no maximum game length (metadata marl_max_steps) "
                             f"and a game reached {self.limit:,} steps: such games are cut there, as truncated\n")
            sys.stderr.flush()
        return over
