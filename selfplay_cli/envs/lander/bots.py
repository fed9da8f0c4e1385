"""The lander's scripted player: gymnasium's heuristic controller, each lander on its own observation."""

from __future__ import annotations

from typing import Any

import numpy as np

from .config import LEFT, MAIN, N_FEATURES, NOOP, RIGHT


def _todo(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """gymnasium's heuristic's (angle_todo, hover_todo) for a batch of observations ``(k, 8)``, computed in the
    observations' float32 as gymnasium's scalar version does."""
    s = np.asarray(obs, dtype=np.float32).reshape(len(obs), -1)[:, :N_FEATURES]
    x, y, vx, vy, angle, spin, leg0, leg1 = s.T
    angle_targ = np.clip(x * 0.5 + vx * 1.0, -0.4, 0.4)  # point toward the centre, at most 0.4 rad
    hover_targ = 0.55 * np.abs(x)  # the height to hold grows with the horizontal offset
    angle_todo = (angle_targ - angle) * 0.5 - spin * 1.0
    hover_todo = (hover_targ - y) * 0.5 - vy * 0.5
    contact = (leg0 != 0) | (leg1 != 0)  # on the ground: only slow the fall
    angle_todo = np.where(contact, np.float32(0.0), angle_todo)
    hover_todo = np.where(contact, -vy * 0.5, hover_todo)
    return angle_todo, hover_todo


def heuristic_rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
    """Discrete actions ``(k,)`` of gymnasium's heuristic for observations ``(k, 8)`` (deterministic)."""
    angle_todo, hover_todo = _todo(obs)
    a = np.where(angle_todo < -0.05, RIGHT, np.where(angle_todo > 0.05, LEFT, NOOP))
    return np.where((hover_todo > np.abs(angle_todo)) & (hover_todo > 0.05), MAIN, a).astype(np.int64)


def heuristic_continuous_rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
    """Continuous actions ``(k, 2)`` float32 of gymnasium's heuristic (``continuous=True``)."""
    angle_todo, hover_todo = _todo(obs)
    a = np.stack([hover_todo * 20 - 1, -angle_todo * 20], axis=1)
    return np.clip(a, -1, 1).astype(np.float32)
