"""Pong's scripted players' rules. They see only the observation (flattened or not) of their own seat."""

from __future__ import annotations

import numpy as np

from .config import DOWN, HEIGHT, N_FEATURES, PADDLE_H, PADDLE_Y_MAX, STAY, UP


def cpu_rule(obs: np.ndarray) -> np.ndarray:
    """The ``cpu`` player, a ball tracker: move (at paddle speed 8) toward the ball's height, from the latest frame."""
    last = np.asarray(obs, dtype=np.float32).reshape(len(obs), -1)[:, -N_FEATURES:]
    ball_y = (last[:, 1] + 1) * (HEIGHT / 2)
    centre = (last[:, 2] + 1) * (PADDLE_Y_MAX / 2) + PADDLE_H // 2
    return np.where(centre < ball_y - 1e-3, DOWN, np.where(centre > ball_y + 1e-3, UP, STAY)).astype(np.int64)
