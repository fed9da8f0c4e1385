"""The ball's physics and the scoring rules shared by the core and the scripted player, who plans with them (numpy
arrays of any shape, float64; the contact and numpy's clip, maximum and minimum also for one ball in Python floats,
the same numbers); see :mod:`selfplay_cli.envs.tennis` for the model."""

from __future__ import annotations

from typing import Any

import numpy as np

from .config import BALL_R, K_DRAG, K_MAGNUS, MAX_SPIN, SPIN_GAIN, STICK, G


def accel(vx: np.ndarray, vy: np.ndarray, w: np.ndarray, kd: float = K_DRAG,
          km: float = K_MAGNUS) -> tuple[np.ndarray, np.ndarray]:
    """The ball's acceleration in flight: gravity, drag ``-kd |v| v`` and Magnus ``km w x v``."""
    speed = np.sqrt(vx * vx + vy * vy)
    return -kd * speed * vx - km * w * vy, -G - kd * speed * vy + km * w * vx


def contact(vx: np.ndarray, vy: np.ndarray, w: np.ndarray, nx: np.ndarray, ny: np.ndarray, cvx: Any, cvy: Any,
            e: float, mu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ball's velocity and spin after an impact on a surface with unit normal ``(nx, ny)`` pointing toward the
    ball, whose contact point moves at ``(cvx, cvy)``: the normal relative velocity reversed times ``e``, and the
    friction impulse that stops the contact point's slip (the ball leaves rolling) unless Coulomb's ``mu`` times
    the normal impulse is less, when the ball slides through."""
    tx, ty = -ny, nx
    rx, ry = vx - cvx, vy - cvy
    vn = rx * nx + ry * ny  # < 0: approaching
    vt = rx * tx + ry * ty
    slip = vt - BALL_R * w
    jn = -(1.0 + e) * vn
    cap = mu * np.abs(jn)
    jt = np.clip(-STICK * slip, -cap, cap)
    w2 = np.clip(w - SPIN_GAIN * jt, -MAX_SPIN, MAX_SPIN)
    return vx + jn * nx + jt * tx, vy + jn * ny + jt * ty, w2


def server_of(first: np.ndarray, points: np.ndarray, points_to_win: int) -> np.ndarray:
    """Who serves after ``points`` points of a game whose first server is ``first``: serves alternate every 2
    points, and every point once both players have ``points_to_win - 1``."""
    deuce = 2 * (points_to_win - 1)
    turn = np.where(points < deuce, points // 2, (deuce // 2) + (points - deuce))
    return np.where(turn % 2 == 0, first, 1 - first).astype(np.int8)


def game_won(score_a: np.ndarray, score_b: np.ndarray, points_to_win: int) -> np.ndarray:
    """Whether a has won: at least ``points_to_win`` points and 2 more than b."""
    return (score_a >= points_to_win) & (score_a - score_b >= 2)


def contact_one(vx: float, vy: float, w: float, nx: float, ny: float, cvx: float, cvy: float, e: float,
                mu: float) -> tuple[float, float, float]:
    """:func:`contact` of one ball in Python floats, the same operations in the same order (the same numbers, bit
    for bit: :func:`clip_one` is numpy's clip)."""
    tx, ty = -ny, nx
    rx, ry = vx - cvx, vy - cvy
    vn = rx * nx + ry * ny
    vt = rx * tx + ry * ty
    slip = vt - BALL_R * w
    jn = -(1.0 + e) * vn
    cap = mu * abs(jn)
    jt = clip_one(-STICK * slip, -cap, cap)
    w2 = clip_one(w - SPIN_GAIN * jt, -MAX_SPIN, MAX_SPIN)
    return vx + jn * nx + jt * tx, vy + jn * ny + jt * ty, w2


def clip_one(x: float, low: float, high: float) -> float:
    """numpy's ``clip`` of one float: ``min(max(x, low), high)`` with its rules for NaN (kept, from either side)."""
    if x == x:
        if not x > low:
            x = low
        if x == x and not x < high:
            x = high
    return x


def max_one(a: float, b: float) -> float:
    """numpy's ``maximum`` of two floats (a NaN wins)."""
    return a if a >= b or a != a else b


def min_one(a: float, b: float) -> float:
    """numpy's ``minimum`` of two floats (a NaN wins)."""
    return a if a <= b or a != a else b
