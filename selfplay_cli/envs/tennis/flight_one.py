"""The tennis serve-bot's planner (:mod:`.flight`) for one ball at a time, in Python floats: the same decisions, bit for
bit (see the note below)."""

from __future__ import annotations

import math

import numpy as np

from .config import (
    BALL_R,
    DT,
    E_BAT,
    E_TABLE,
    FLOOR_Y,
    MU_BAT,
    MU_TABLE,
    NET_H,
    OMEGA_MAX,
    SPIN_GAIN,
    STICK,
    TABLE_HALF,
    V_MAX,
    G,
)
from .flight import _DECAY, _HALF_DT2, _PLAN_DT, _REACH_X, _REACH_Y
from .physics import clip_one, contact_one, max_one, min_one

# ---------------------------------------------------------------------------------------------------------------
# One observation at a time, in Python floats: the same decisions, bit for bit.
#
# numpy pays about a microsecond an operation whatever the size of its arrays, and the planner's flights are some
# thousands of operations: planning a few strokes on arrays spent a call in numpy's overhead (5 to 15 ms, whatever
# the rows). Below, each function of the planner above is transcribed for one observation in plain floats: the same
# operations in the same order on IEEE doubles (a sum or a product is the same number in Python as in a float64
# array; ``math.sqrt`` is correctly rounded, as ``np.sqrt``), numpy's own arctan2, cos, sin and hypot called on the
# numbers (a C library's may round differently) and numpy's clip, maximum and minimum rewritten with their rules
# (:func:`.physics.clip_one`). The loops of a flight stop where the one ball stops (the arrays' loops run on for the
# others, whose results are not used). A call plans one at a time up to _PLANS_ONE_BY_ONE strokes (a stroke costs
# about 0.1 ms so), on arrays beyond. tests/test_tennis_bot.py keeps the rule as it was before these paths and
# compares actions bit for bit, one by one and in batches, and the flights' numbers.
_TURN = DT * OMEGA_MAX
_STROKE_MAX = 0.8 * V_MAX
_LANDING_STEPS = int(1.6 / _PLAN_DT)


def _fly_one(x: float, y: float, vx: float, vy: float, w: float, kd: float, km: float,
             full: bool = False) -> tuple[float, ...]:
    """:func:`_fly_to_landing` of one ball (``t_max`` 1.6 s)."""
    y_net, x_land, vx_land, vy_land, down = -1.0, x, vx, vy, False
    dt, half = _PLAN_DT, _HALF_DT2
    for _ in range(_LANDING_STEPS):
        speed = math.sqrt(vx * vx + vy * vy)
        ax = -kd * speed * vx - km * w * vy
        ay = -G - kd * speed * vy + km * w * vx
        nx_, ny_ = x + vx * dt + ax * half, y + vy * dt + ay * half
        vx, vy = vx + ax * dt, vy + ay * dt
        if x < 0 and nx_ >= 0:
            y_net = y + (-x / (nx_ - x)) * (ny_ - y)
        if ny_ <= BALL_R and vy < 0:
            gap = y - ny_
            f = clip_one((y - BALL_R) / gap if gap else float(np.float64(y - BALL_R) / np.float64(gap)), 0.0, 1.0)
            x_land, vx_land, vy_land, down = x + f * (nx_ - x), vx, vy, True
            break
        x_land = nx_
        x, y = nx_, ny_
    return (y_net, x_land, vx_land, vy_land, down) if full else (y_net, x_land)


def _parabola_one(x0: float, y0: float, over_y: float, land_x: float) -> tuple[float, float]:
    """:func:`_parabola` of one ball."""
    x1, y1 = max_one(-x0, 0.05), over_y - y0
    x2, y2 = max_one(land_x - x0, x1 + 0.05), BALL_R - y0
    c = min_one((y2 / x2 - y1 / x1) / (x2 - x1), -0.02)
    b = y1 / x1 - c * x1
    vx = math.sqrt(G / (-2.0 * c))
    return vx, clip_one(b * vx, -30.0, 30.0)


def _plan_launch_one(x0: float, y0: float, w: float, land_x: float, over_y: float, kd: float, km: float,
                     iterations: int = 2) -> tuple[float, float]:
    """:func:`plan_launch` of one ball."""
    aim_x, aim_y = land_x, over_y
    for _ in range(iterations):
        vx, vy = _parabola_one(x0, y0, aim_y, aim_x)
        got_y, got_x = _fly_one(x0, y0, vx, vy, w, kd, km)
        if got_y < 0:
            got_y = min_one(y0, NET_H) - 0.2
        aim_x = clip_one(aim_x + (land_x - got_x), 0.05, 3.0)
        aim_y = clip_one(aim_y + (over_y - got_y), y0 - 1.0, 2.0)
    return _parabola_one(x0, y0, aim_y, aim_x)


_MOST = math.sqrt(1.0 + MU_BAT * MU_BAT)


def _solve_stroke_one(vin_x: float, vin_y: float, w_in: float, vout_x: float, vout_y: float,
                      w_out: float) -> tuple[float, float, float, float]:
    """:func:`solve_stroke` of one ball."""
    dx, dy = vout_x - vin_x, vout_y - vin_y
    size = math.sqrt(dx * dx + dy * dy)
    tang = -(w_out - w_in) / SPIN_GAIN
    most = MU_BAT * size / _MOST * 0.95
    tang = clip_one(tang, -most, most)
    norm = math.sqrt(max_one(size * size - tang * tang, 1e-12))
    alpha = float(np.arctan2(dy, dx)) - float(np.arctan2(tang, norm))
    nx, ny = float(np.cos(alpha)), float(np.sin(alpha))
    tx, ty = -ny, nx
    slip = -tang / STICK
    vt = slip + BALL_R * w_in
    vn = -norm / (1.0 + E_BAT)
    bn = (vin_x * nx + vin_y * ny) - vn
    bt = (vin_x * tx + vin_y * ty) - vt
    return nx, ny, bn * nx + bt * tx, bn * ny + bt * ty


def _predict_contact_one(x: float, y: float, vx: float, vy: float, w: float, bounced: bool, kd: float,
                         km: float) -> tuple[float, ...] | None:
    """:func:`_predict_contact` of one ball (``t_max`` 1.6 s): ``(time, x, y, vx, vy, w)``, or None (not found)."""
    if bounced and vy <= 0 and y <= _REACH_Y:
        return 0.0, x, y, vx, vy, w
    far_bounced, t, dt, half, decay = False, 0.0, _PLAN_DT, _HALF_DT2, _DECAY
    for _ in range(_LANDING_STEPS):
        t += dt
        speed = math.sqrt(vx * vx + vy * vy)
        ax = -kd * speed * vx - km * w * vy
        ay = -G - kd * speed * vy + km * w * vx
        x = x + vx * dt + ax * half
        y = y + vy * dt + ay * half
        vx = vx + ax * dt
        vy = vy + ay * dt
        w = w * decay
        if not bounced and y < BALL_R and vy < 0 and abs(x) <= TABLE_HALF:
            if x < 0:
                vx, vy, w = contact_one(vx, vy, w, 0.0, 1.0, 0.0, 0.0, E_TABLE, MU_TABLE)
                y = 2 * BALL_R - y
                bounced = True
            elif not far_bounced and vx < 0:  # a bounce serve's bounce on the server's half
                vx, vy, w = contact_one(vx, vy, w, 0.0, 1.0, 0.0, 0.0, E_TABLE, MU_TABLE)
                y = 2 * BALL_R - y
                far_bounced = True
            else:
                return None
        if (y < 0 and (abs(x) < TABLE_HALF or not bounced)) or y < FLOOR_Y + 0.3:
            return None
        if bounced and ((vy <= 0 and y <= _REACH_Y) or x <= _REACH_X):
            return t, x, y, vx, vy, w
    return None
