"""One agent for a whole cooperative team (``--sharing sa``): a network over every seat's observation, side by
side, choosing one joint action that stands for every seat's action.

With N seats of ``base`` actions each, the joint action is ``b = sum_n a_n * base**n``, so
``a_n = (b // base**n) % base``. The joint space grows as ``base**N``: :data:`MAX_JOINT_ACTIONS` bounds it.

A :class:`JointPolicy` plays every seat of each game it is given: the runner hands a policy its rows seat by seat
(all of seat 0's games, then seat 1's...), and a cooperative comparison seats one policy on every seat of a game, so
the rows regroup into whole games.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from ..errors import MarlError
from .base import Policy

MAX_JOINT_ACTIONS = 4096
"""The most joint actions SA takes (4 actions: 6 seats); beyond, one network a seat (nops) or shared (fups)."""


def encode(actions: np.ndarray, base: int) -> np.ndarray:
    """``(N, G)`` per-seat actions -> ``(G,)`` joint actions, ``sum_n a_n * base**n``."""
    a = np.asarray(actions, dtype=np.int64)
    return (a * (base ** np.arange(a.shape[0], dtype=np.int64))[:, None]).sum(axis=0)


def decode(joint: np.ndarray, n: int, base: int) -> np.ndarray:
    """``(G,)`` joint actions -> ``(N, G)`` per-seat actions (the inverse of :func:`encode`)."""
    b = np.asarray(joint, dtype=np.int64)
    return (b[None, :] // (base ** np.arange(n, dtype=np.int64))[:, None]) % base


def joint_spaces(observation: spaces.Box, action: spaces.Space, n: int, what: str = "this game") -> tuple[
        spaces.Box, spaces.Discrete]:
    """The observation and action spaces of one agent over ``n`` seats that each observe ``observation`` and act in
    ``action``: every seat's observation side by side, and ``action.n ** n`` joint actions; a :class:`MarlError`
    where SA cannot work (not Discrete, or too many joint actions)."""
    if not isinstance(action, spaces.Discrete):
        raise MarlError(f"--sharing sa chooses one joint action of Discrete actions; {what} acts in {action}: use "
                        "--sharing fups or nops")
    base = int(action.n)
    size = base ** n
    if size > MAX_JOINT_ACTIONS:
        raise MarlError(f"--sharing sa over {n} seats of {base} actions needs {size:,} joint actions (at most "
                        f"{MAX_JOINT_ACTIONS:,}): use --sharing fups (one shared network) or nops (one per seat)")
    flat = int(np.prod(observation.shape))
    low = np.tile(np.asarray(observation.low, dtype=np.float32).reshape(-1), n)
    high = np.tile(np.asarray(observation.high, dtype=np.float32).reshape(-1), n)
    return spaces.Box(low, high, (n * flat,), np.float32), spaces.Discrete(size)


def regroup(obs: np.ndarray, n: int) -> np.ndarray:
    """Rows seat by seat ``(n * G, *shape)`` -> one row per game ``(G, n * prod(shape))``."""
    o = np.asarray(obs, dtype=np.float32)
    if len(o) % n:
        raise MarlError(f"a joint (SA) policy flies all {n} seats of a game together; it was given {len(o)} seats")
    g = len(o) // n
    return o.reshape(n, g, -1).transpose(1, 0, 2).reshape(g, -1)


class JointPolicy(Policy):
    """A network over a team's joint observation, playing every seat of its games (see the module docstring).

    ``inner`` acts on ``(G, n * obs)`` rows with joint actions; this policy takes the runner's per-seat rows and
    gives per-seat actions. Its ``obs_space`` / ``act_space`` are one seat's; ``seats`` is the team's size."""

    kind = "snapshot"

    def __init__(self, inner: Policy, seats: int, base: int, obs_space: Any, act_space: Any) -> None:
        super().__init__(inner.id, inner.env, obs_space=obs_space, act_space=act_space)
        self.inner, self.seats, self.base = inner, int(seats), int(base)
        self.meta = getattr(inner, "meta", None)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        if mask is not None:
            raise MarlError(f"{self.id} is a joint (SA) policy: it plays games without action masks")
        joint = self.inner.act(regroup(obs, self.seats))
        return decode(joint, self.seats, self.base).reshape(-1)
