"""The serve-bot decides as it did before its fast paths (one observation at a time in Python floats; the flights of
many integrated as a record and read afterwards): the same observations give the same actions, bit for bit.

The oracle is the rule as it was (selfplay_cli/envs/tennis/bots.py at 33fb7b6, its docstrings left out), kept here
unchanged: a deliberate change of how the bot plays changes it too. The observations are a few hundred from its games
(against itself and against random play, in each serve mode, with the bounce serve), the same moved a little (the
ball's position, velocity and spin) and a few made by hand (a ball at the net, a toss that has fallen through the
striking height, a ball going long, bounces above reach); the rule is compared one observation at a time, in batches
that plan one at a time and in batches that plan on arrays."""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
import pytest

from selfplay_cli.envs.rng import GOLDEN, mix64, to_unit
from selfplay_cli.envs.tennis import bots, flight, flight_one
from selfplay_cli.envs.tennis.bots import plan_launch, serve_bot_rule_for
from selfplay_cli.envs.tennis.config import (
    ANGLE_MAX,
    BALL_R,
    BALL_SPIN,
    BALL_VX,
    BALL_VY,
    BALL_X,
    BALL_Y,
    BAT_ANGLE,
    BAT_X,
    BAT_Y,
    DT,
    E_BAT,
    E_TABLE,
    FLOOR_Y,
    HOME_X,
    HOME_Y,
    I_SERVE,
    INCOMING,
    K_DRAG,
    K_MAGNUS,
    MU_BAT,
    MU_TABLE,
    MY_TURN,
    N_FEATURES,
    NET_H,
    OBS_HIGH,
    OBS_LOW,
    OMEGA_MAX,
    SERVE_MODES,
    SPIN_DECAY,
    SPIN_GAIN,
    SPIN_SCALE,
    STICK,
    TABLE_HALF,
    THEY_SERVE,
    V_MAX,
    VEL_SCALE,
    G,
    TennisConfig,
)
from selfplay_cli.envs.tennis.core import TennisCore
from selfplay_cli.envs.tennis.physics import accel, contact

# ---------------------------------------------------------------------------------------------------------------
# The oracle: the serve-bot's rule before its fast paths
_PLAN_DT = 0.02
_SWING = 0.08  # s: the stroke's length before the contact
_GAP = 0.003  # at the planned instant the bat's face is this far short of the ball (it touches just before)
_REACH_X = -2.5  # the farthest back the bot meets a ball
_REACH_Y = 1.2  # the highest it meets a ball (its bat reaches 1.6 m): a higher bounce it meets coming down
_WAIT = ((-2.3, -1.3), (0.0, 1.2), (-1.4, 1.4))  # randomized modes: where (x, y, tilt) it may wait for a serve
# randomized modes: the return's pace follows the incoming ball's speed at the contact, from _PACE[0] m/s (a
# slow ball: landing _MIRROR_LAND[0] past the net, _MIRROR_CLEAR[0] over it) to _PACE[1] and faster (deep and low)
_PACE = (4.0, 9.0)
_MIRROR_LAND = (0.6, 1.15)
_MIRROR_CLEAR = (0.20, 0.05)
_MIRROR_TOPSPIN = 120.0  # rad/s of topspin on the fastest returns in spin mode


def old_unit_hash(x: np.ndarray, salt: int) -> np.ndarray:
    bits = np.asarray(x, dtype=np.float32).view(np.uint32).astype(np.uint64)
    return to_unit(mix64(bits * np.uint64(GOLDEN) + np.uint64(salt)))


def old_fly_to_landing(x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray, kd: float,
                    km: float, t_max: float = 1.6, full: bool = False) -> tuple[np.ndarray, ...]:
    x, y, vx, vy, w = (np.array(a, dtype=np.float64) for a in np.broadcast_arrays(x, y, vx, vy, w))
    y_net = np.full(x.shape, -1.0)
    x_land, vx_land, vy_land = x.copy(), vx.copy(), vy.copy()
    flying = np.ones(x.shape, dtype=bool)
    dt, half = _PLAN_DT, 0.5 * _PLAN_DT * _PLAN_DT
    for _ in range(int(t_max / dt)):
        ax, ay = accel(vx, vy, w, kd, km)
        nx_, ny_ = x + vx * dt + ax * half, y + vy * dt + ay * half
        vx, vy = vx + ax * dt, vy + ay * dt
        cross = flying & (x < 0) & (nx_ >= 0)
        y_net = np.where(cross, y + (-x / np.where(cross, nx_ - x, 1.0)) * (ny_ - y), y_net)
        down = flying & (ny_ <= BALL_R) & (vy < 0)
        f = np.clip((y - BALL_R) / np.where(down, y - ny_, 1.0), 0.0, 1.0)
        x_land = np.where(down, x + f * (nx_ - x), np.where(flying, nx_, x_land))
        if full:
            vx_land, vy_land = np.where(down, vx, vx_land), np.where(down, vy, vy_land)
        flying &= ~down
        x, y = nx_, ny_
        if not flying.any():
            break
    return (y_net, x_land, vx_land, vy_land, ~flying) if full else (y_net, x_land)


def old_parabola(x0: np.ndarray, y0: np.ndarray, over_y: np.ndarray, land_x: np.ndarray) -> tuple[np.ndarray, ...]:
    x1, y1 = np.maximum(-x0, 0.05), over_y - y0
    x2, y2 = np.maximum(land_x - x0, x1 + 0.05), BALL_R - y0
    c = np.minimum((y2 / x2 - y1 / x1) / (x2 - x1), -0.02)
    b = y1 / x1 - c * x1
    vx = np.sqrt(G / (-2.0 * c))
    return vx, np.clip(b * vx, -30.0, 30.0)


def old_plan_launch(x0: np.ndarray, y0: np.ndarray, w: np.ndarray, land_x: np.ndarray, over_y: np.ndarray,
                kd: float = K_DRAG, km: float = K_MAGNUS, iterations: int = 2) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, w = (np.asarray(a, dtype=np.float64) for a in (x0, y0, w))
    land_x, over_y = np.asarray(land_x, dtype=np.float64), np.asarray(over_y, dtype=np.float64)
    aim_x, aim_y = land_x.copy(), over_y.copy()
    for _ in range(iterations):
        vx, vy = old_parabola(x0, y0, aim_y, aim_x)
        got_y, got_x = old_fly_to_landing(x0, y0, vx, vy, w, kd, km)
        got_y = np.where(got_y < 0, np.minimum(y0, NET_H) - 0.2, got_y)  # fell short of the net: aim higher
        aim_x = np.clip(aim_x + (land_x - got_x), 0.05, 3.0)
        aim_y = np.clip(aim_y + (over_y - got_y), y0 - 1.0, 2.0)
    return old_parabola(x0, y0, aim_y, aim_x)


def old_serve_flights(x0: np.ndarray, y0: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray, kd: float,
                   km: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    _, bounce_x, bvx, bvy, down = old_fly_to_landing(x0, y0, vx, vy, w, kd, km, full=True)
    own = down & (bounce_x >= -TABLE_HALF) & (bounce_x <= 0.0)
    zero = np.zeros(bvx.shape)
    vx2, vy2, w2 = contact(bvx, bvy, np.broadcast_to(w, bvx.shape), zero, zero + 1.0, 0.0, 0.0, E_TABLE, MU_TABLE)
    y_net, land_x, _, _, down2 = old_fly_to_landing(bounce_x, BALL_R, vx2, vy2, w2, kd, km, full=True)
    return (np.where(own, bounce_x, np.nan), np.where(own, y_net, -1.0),
            np.where(own & down2, land_x, np.nan))


_SERVE_VX = np.linspace(1.0, 7.0, 13)  # the bounce serve's launch velocities the planner tries (m/s)
_SERVE_VY = np.linspace(-5.0, 1.0, 13)


def old_plan_bounce_serve(x0: np.ndarray, y0: np.ndarray, w: np.ndarray, land_x: np.ndarray, over_y: np.ndarray,
                      vin_x: np.ndarray, vin_y: np.ndarray, w_in: np.ndarray, kd: float = K_DRAG,
                      km: float = K_MAGNUS) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, w, land_x, over_y, vin_x, vin_y, w_in = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (
        x0, y0, w, land_x, over_y, vin_x, vin_y, w_in))
    vx0, vy0 = np.meshgrid(_SERVE_VX, _SERVE_VY, indexing="ij")
    gx, gy = vx0.reshape(1, -1), vy0.reshape(1, -1)
    step_x, step_y = _SERVE_VX[1] - _SERVE_VX[0], _SERVE_VY[1] - _SERVE_VY[0]
    best_vx, best_vy = np.zeros(len(x0)), np.zeros(len(x0))
    for _ in range(3):
        cand_x = np.broadcast_to(gx, (len(x0), gx.shape[1])) + best_vx[:, None]
        cand_y = np.broadcast_to(gy, (len(x0), gy.shape[1])) + best_vy[:, None]
        b, yn, lx = old_serve_flights(x0[:, None], y0[:, None], cand_x, cand_y, w[:, None], kd, km)
        legal = ~np.isnan(b) & (yn >= NET_H + BALL_R + 0.08) & (lx > 0.05) & (lx < TABLE_HALF - 0.03)
        _, _, bvx, bvy = old_solve_stroke(vin_x[:, None], vin_y[:, None], w_in[:, None], cand_x, cand_y, w[:, None])
        legal &= np.maximum(np.abs(bvx), np.abs(bvy)) <= 0.8 * V_MAX
        cost = (np.nan_to_num(lx, nan=10.0) - land_x[:, None]) ** 2 + 0.5 * (yn - over_y[:, None]) ** 2
        cost = np.where(legal, cost, cost + 100.0)
        pick = np.argmin(cost, axis=1)
        rows = np.arange(len(x0))
        best_vx, best_vy = cand_x[rows, pick], cand_y[rows, pick]
        # a finer grid around the best: one cell of the last grid either way, in thirds
        fx, fy = np.meshgrid(np.linspace(-step_x, step_x, 7), np.linspace(-step_y, step_y, 7), indexing="ij")
        gx, gy = fx.reshape(1, -1), fy.reshape(1, -1)
        step_x, step_y = step_x / 3.0, step_y / 3.0
    return best_vx, best_vy


def old_solve_stroke(vin_x: np.ndarray, vin_y: np.ndarray, w_in: np.ndarray, vout_x: np.ndarray, vout_y: np.ndarray,
                 w_out: np.ndarray) -> tuple[np.ndarray, ...]:
    dx, dy = vout_x - vin_x, vout_y - vin_y
    size = np.sqrt(dx * dx + dy * dy)
    tang = -(w_out - w_in) / SPIN_GAIN  # the tangential velocity change the spin needs (= jt)
    most = MU_BAT * size / math.sqrt(1.0 + MU_BAT * MU_BAT) * 0.95
    tang = np.clip(tang, -most, most)
    norm = np.sqrt(np.maximum(size * size - tang * tang, 1e-12))
    alpha = np.arctan2(dy, dx) - np.arctan2(tang, norm)
    nx, ny = np.cos(alpha), np.sin(alpha)
    tx, ty = -ny, nx
    slip = -tang / STICK
    vt = slip + BALL_R * w_in  # the ball's tangential speed relative to the bat before the contact
    vn = -norm / (1.0 + E_BAT)
    bn = (vin_x * nx + vin_y * ny) - vn
    bt = (vin_x * tx + vin_y * ty) - vt
    return nx, ny, bn * nx + bt * tx, bn * ny + bt * ty


def old_predict_contact(x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray,
                     bounced: np.ndarray, kd: float, km: float, t_max: float = 1.6) -> tuple[np.ndarray, ...]:
    x, y, vx, vy, w = (np.array(a, dtype=np.float64) for a in (x, y, vx, vy, w))
    bounced = np.array(bounced, dtype=bool)
    k = len(x)
    far_bounced = np.zeros(k, dtype=bool)  # a ball may bounce once on the other half on its way (a bounce serve)
    found = np.zeros(k, dtype=bool)
    alive = np.ones(k, dtype=bool)
    out = np.zeros((6, k))
    out[0] = t_max
    t = 0.0
    decay, half = 1.0 - SPIN_DECAY * _PLAN_DT, 0.5 * _PLAN_DT * _PLAN_DT
    # a ball already on its way down after its bounce is met now
    now = bounced & (vy <= 0) & (y <= _REACH_Y)
    if now.any():
        found[now] = True
        out[:, now] = np.stack([np.zeros(now.sum()), x[now], y[now], vx[now], vy[now], w[now]])
        alive &= ~now
    for _ in range(int(t_max / _PLAN_DT)):
        if not alive.any():
            break
        t += _PLAN_DT
        ax, ay = accel(vx, vy, w, kd, km)
        x = x + vx * _PLAN_DT + ax * half
        y = y + vy * _PLAN_DT + ay * half
        vx = vx + ax * _PLAN_DT
        vy = vy + ay * _PLAN_DT
        w = w * decay
        hit = alive & ~bounced & (y < BALL_R) & (vy < 0) & (np.abs(x) <= TABLE_HALF)
        if hit.any():
            mine = hit & (x < 0)
            far = hit & ~mine & ~far_bounced & (vx < 0)  # a bounce serve's bounce on the server's half
            if far.any():
                zero = np.zeros(far.sum())
                vx[far], vy[far], w[far] = contact(vx[far], vy[far], w[far], zero, zero + 1.0, 0.0, 0.0, E_TABLE,
                                                   MU_TABLE)
                y[far] = 2 * BALL_R - y[far]
                far_bounced |= far
            alive &= ~(hit & ~mine & ~far)  # lands on the other half: not mine to play
            if mine.any():
                zero = np.zeros(mine.sum())
                vx[mine], vy[mine], w[mine] = contact(vx[mine], vy[mine], w[mine], zero, zero + 1.0, 0.0, 0.0,
                                                      E_TABLE, MU_TABLE)
                y[mine] = 2 * BALL_R - y[mine]
                bounced |= mine
        dead = alive & ((y < 0) & ((np.abs(x) < TABLE_HALF) | ~bounced) | (y < FLOOR_Y + 0.3))
        alive &= ~dead
        meet = alive & bounced & (((vy <= 0) & (y <= _REACH_Y)) | (x <= _REACH_X))
        if meet.any():
            found[meet] = True
            out[:, meet] = np.stack([np.full(meet.sum(), t), x[meet], y[meet], vx[meet], vy[meet], w[meet]])
            alive &= ~meet
    return (found, *out)


def old_swing(o: np.ndarray, sel: np.ndarray, t_c: np.ndarray, px: np.ndarray, py: np.ndarray, vin_x: np.ndarray,
           vin_y: np.ndarray, w_in: np.ndarray, land_x: np.ndarray, over_y: np.ndarray, w_out: np.ndarray,
           kd: float, km: float, act: np.ndarray, bounce: bool = False) -> None:
    if bounce:  # (the planner keeps to what the bat can swing)
        vx, vy = old_plan_bounce_serve(px, py, w_out, land_x, over_y, vin_x, vin_y, w_in, kd, km)
    else:
        line_y = py + (BALL_R - py) * (-px) / np.maximum(land_x - px, 1e-3)  # the straight line's height at the net
        over_y = np.maximum(over_y, line_y + 0.05)
        vx, vy = old_plan_launch(px, py, w_out, land_x, over_y, kd, km)
        for _ in range(2):  # a stroke faster than the bat can swing: a slower ball, higher over the net
            bvx, bvy = old_solve_stroke(vin_x, vin_y, w_in, vx, vy, w_out)[2:]
            fast = np.flatnonzero(np.maximum(np.abs(bvx), np.abs(bvy)) > 0.8 * V_MAX)
            if not fast.size:
                break
            over_y = over_y.copy()
            over_y[fast] += 0.1
            vx[fast], vy[fast] = old_plan_launch(px[fast], py[fast], w_out[fast], land_x[fast], over_y[fast], kd, km)
    nx, ny, bvx, bvy = old_solve_stroke(vin_x, vin_y, w_in, vx, vy, w_out)
    # The face: the normal toward the ball, or the back face's tilt if that one faces the ball
    angle = np.arctan2(ny, nx)
    angle = np.where(angle > ANGLE_MAX, angle - math.pi, np.where(angle < -ANGLE_MAX, angle + math.pi, angle))
    cx, cy = px - (BALL_R + _GAP) * nx, py - (BALL_R + _GAP) * ny  # the bat's centre at the contact
    bx, by = o[sel, BAT_X], o[sel, BAT_Y]
    far = t_c > _SWING
    lead = np.where(far, _SWING, t_c)
    want_x, want_y = cx - bvx * lead, cy - bvy * lead  # where the bat should be now (or wait, while far)
    step = np.maximum(t_c, DT)
    cmd_x = np.where(far, (want_x - bx) / DT, bvx + (want_x - bx) / step)
    cmd_y = np.where(far, (want_y - by) / DT, bvy + (want_y - by) / step)
    act[sel, 0] = cmd_x / V_MAX
    act[sel, 1] = cmd_y / V_MAX
    act[sel, 2] = (angle - o[sel, BAT_ANGLE]) / (DT * OMEGA_MAX)


def old_serve_bot_rule_for(mode: str = "fixed", drag: float = 1.0, magnus: float = 1.0, discrete: bool = False,
                       spin_read: float = 0.6, return_spin: float = 0.0, return_land: float = 0.75,
                       bounce: bool = False):
    if mode not in SERVE_MODES:  # (an unknown mode would otherwise serve as one of the others)
        raise ValueError(f"serve_mode must be one of {', '.join(SERVE_MODES)}, not {mode!r}")
    kd, km = K_DRAG * drag, K_MAGNUS * magnus

    def rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float64).reshape(len(obs), N_FEATURES)
        act = old_go_home(o, mode)
        serve = o[:, I_SERVE] > 0.5
        if serve.any():
            old_serve(o, serve, mode, kd, km, bounce, act)
        dodge = old_dodge(o, act)
        receive = ((o[:, INCOMING] > 0.5) | (o[:, MY_TURN] > 0.5)) & ~dodge
        if receive.any():
            old_receive(o, receive, mode, kd, km, spin_read, return_spin, return_land, act)
        act = np.clip(act, -1.0, 1.0)
        if discrete:
            return (np.where(act > 0.25, 2, np.where(act < -0.25, 0, 1))).astype(np.int64)
        return act.astype(np.float32)

    return rule


def old_ball(o: np.ndarray) -> tuple[np.ndarray, ...]:
    return (o[:, BALL_X], o[:, BALL_Y], o[:, BALL_VX] * VEL_SCALE, o[:, BALL_VY] * VEL_SCALE,
            o[:, BALL_SPIN] * SPIN_SCALE)


def old_go_home(o: np.ndarray, mode: str) -> np.ndarray:
    k = len(o)
    act = np.zeros((k, 3))
    home_x, home_y, home_a = np.full(k, HOME_X), np.full(k, HOME_Y), np.zeros(k)
    if mode != "fixed":
        t = o[:, THEY_SERVE] > 0.5
        for arr, (low, high), salt in zip((home_x, home_y, home_a), _WAIT, (4, 5, 6), strict=True):
            arr[t] = low + (high - low) * old_unit_hash(o[t, BALL_X], salt)
    act[:, 0] = np.clip((home_x - o[:, BAT_X]) * 4.0, -2.0, 2.0) / V_MAX
    act[:, 1] = np.clip((home_y - o[:, BAT_Y]) * 4.0, -2.0, 2.0) / V_MAX
    act[:, 2] = (home_a - o[:, BAT_ANGLE]) / (DT * OMEGA_MAX)
    return act


def old_serve(o: np.ndarray, s: np.ndarray, mode: str, kd: float, km: float, bounce: bool, act: np.ndarray) -> None:
    px, py, _, vy, w = old_ball(o)
    u1, u2, u3 = (old_unit_hash(o[s, BALL_X], salt) for salt in (1, 2, 3))
    m = s.sum()
    if mode == "fixed":
        land, clear, spin, height = np.full(m, 0.8), np.full(m, 0.12), np.zeros(m), np.full(m, 0.3)
    else:  # velocity, spin, or (mixed) either, drawn per serve
        spun = old_unit_hash(o[s, BALL_X], 7) < 0.5 if mode == "mixed" else np.full(m, mode == "spin")
        land = np.where(spun, 0.45 + 0.5 * u1, 0.35 + 0.65 * u1)
        clear = np.where(spun, 0.10 + 0.10 * u2, 0.04 + 0.26 * u2)
        spin = np.where(spun, (2 * u3 - 1) * 120.0, 0.0)
        height = np.where(spun, 0.3, 0.22 + 0.2 * u3)
    y, v = py[s], vy[s]
    disc = v * v + 2 * G * (y - height)
    t_c = np.where(disc >= 0, (v + np.sqrt(np.maximum(disc, 0.0))) / G, np.maximum(v, 0.0) / G)
    hy = np.where(disc >= 0, height, y + v * t_c - 0.5 * G * t_c * t_c)
    old_swing(o, s, t_c, px[s], hy, np.zeros(m), v - G * t_c, w[s], land, NET_H + clear, spin, kd, km, act, bounce)


def old_dodge(o: np.ndarray, act: np.ndarray) -> np.ndarray:
    px, py, vx, _, _ = old_ball(o)
    dodge = (o[:, INCOMING] > 0.5) & (px < -TABLE_HALF) & (vx < 0.0)
    if dodge.any():
        act[dodge, 0] = 0.0
        act[dodge, 1] = np.where(o[dodge, BAT_Y] > py[dodge], 1.0, -1.0)
        act[dodge, 2] = -o[dodge, BAT_ANGLE] / (DT * OMEGA_MAX)
    return dodge


def old_receive(o: np.ndarray, receive: np.ndarray, mode: str, kd: float, km: float, spin_read: float,
             return_spin: float, return_land: float, act: np.ndarray) -> None:
    px, py, vx, vy, w = old_ball(o)
    r = np.flatnonzero(receive)
    found, t_c, cx, cy, cvx, cvy, cw = old_predict_contact(px[r], py[r], vx[r], vy[r], w[r] * spin_read,
                                                        o[r, MY_TURN] > 0.5, kd, km)
    if not found.any():
        return
    sel = np.zeros(len(o), dtype=bool)
    sel[r[found]] = True
    f = found
    n = f.sum()
    land, over, spin = np.full(n, return_land), np.full(n, NET_H + 0.15), np.full(n, return_spin)
    if mode != "fixed":  # practice: the ball goes back at the pace it came (spin, mixed: with topspin)
        pace = np.clip((np.hypot(cvx[f], cvy[f]) - _PACE[0]) / (_PACE[1] - _PACE[0]), 0.0, 1.0)
        land = _MIRROR_LAND[0] + (_MIRROR_LAND[1] - _MIRROR_LAND[0]) * pace
        over = NET_H + _MIRROR_CLEAR[0] + (_MIRROR_CLEAR[1] - _MIRROR_CLEAR[0]) * pace
        if mode in ("spin", "mixed"):
            spin = -_MIRROR_TOPSPIN * pace
    old_swing(o, sel, t_c[f], cx[f], cy[f], cvx[f], cvy[f], cw[f], land, over, spin, kd, km, act)


# ---------------------------------------------------------------------------------------------------------------
# Observations
def _played(config: TennisConfig, games: int, steps: int, seed: int, random_seat: int | None) -> np.ndarray:
    """Every seat's observation at every step of ``games`` games played by the serve-bot (``random_seat`` playing
    uniformly random actions instead), ``(k, 25)``."""
    core = TennisCore(games, config)
    core.reset(np.arange(games), np.arange(seed, seed + games))
    rule = bots.serve_bot_for(config)
    rng = np.random.default_rng(seed)
    seen = []
    for t in range(steps):
        obs = core.observe()
        seen.append(obs.reshape(-1, N_FEATURES))
        acts = np.stack([rule(obs[0]), rule(obs[1])])
        if random_seat is not None:
            acts[random_seat] = (rng.integers(0, 3, acts[random_seat].shape) if config.discrete
                                 else rng.uniform(-1, 1, acts[random_seat].shape))
        core.step(acts)
        done = np.flatnonzero(core.over)
        if done.size:
            core.reset(done, done + 1000 * (t + 1) + seed)
    return np.concatenate(seen)


def _pick(obs: np.ndarray, planned: int, other: int, seed: int) -> np.ndarray:
    """``planned`` observations in which the bot plans a stroke (it serves, or a ball comes to it) and ``other``
    others."""
    rng = np.random.default_rng(seed)
    plan = (obs[:, I_SERVE] > 0.5) | (obs[:, INCOMING] > 0.5) | (obs[:, MY_TURN] > 0.5)
    rows = [rng.choice(np.flatnonzero(p), min(k, int(p.sum())), replace=False)
            for p, k in ((plan, planned), (~plan, other))]
    return obs[np.concatenate(rows)]


def _moved(obs: np.ndarray, seed: int) -> np.ndarray:
    """The observations with the ball's position, velocity and spin moved a little (within the bounds)."""
    rng = np.random.default_rng(seed)
    out = obs.copy()
    out[:, BALL_X:BALL_SPIN + 1] += rng.normal(0.0, [0.1, 0.05, 0.05, 0.05, 0.5], (len(obs), 5)).astype(np.float32)
    return np.clip(out, OBS_LOW, OBS_HIGH)


def _by_hand() -> np.ndarray:
    """Observations made by hand at the edges of the planner: a ball at the net, a toss fallen through the striking
    height (and one under the table's surface), a ball going long past the bat, balls bouncing above reach, met now
    on their way down, coming back over the net, with much spin, a bat tilted to its limits."""
    rows = []

    def row(ball, flags, bat=(HOME_X, HOME_Y, 0.0)):
        o = np.zeros(N_FEATURES, dtype=np.float32)
        o[BALL_X:BALL_SPIN + 1] = ball
        o[BAT_X], o[BAT_Y], o[BAT_ANGLE] = bat
        for f in flags:
            o[f] = 1.0
        o[-1] = 0.15
        rows.append(o)

    for x in (-0.01, -0.05, -0.3):  # at the net, bounced on my half
        row([x, 0.3, -0.1, 0.2, 0.0], [MY_TURN], bat=(-0.1, 0.3, 0.5))
    for y, vy in ((0.4, -0.1), (0.2, -0.3), (-0.05, -0.4), (0.9, 0.2)):  # tosses, some below the striking height
        row([-1.55, y, 0.0, vy, 0.0], [I_SERVE])
    for x in (-1.5, -2.0, -2.6):  # going long without a bounce on my half
        row([x, 0.2, -0.6, -0.1, 0.0], [INCOMING], bat=(x + 0.05, 0.25, -0.4))
    for vy, y in ((0.6, 0.9), (0.3, 1.15), (-0.05, 1.25), (-0.2, 0.5)):  # after the bounce: high, near reach, down
        row([-1.0, y, -0.4, vy, 0.0], [MY_TURN])
    for spin in (-9.0, -3.0, 3.0, 9.0):  # incoming with much spin
        row([0.8, 0.35, -0.8, 0.05, spin], [INCOMING])
    for angle in (-ANGLE_MAX, ANGLE_MAX):
        row([0.8, 0.35, -0.7, 0.0, 0.0], [INCOMING], bat=(-1.8, 0.3, angle))
    row([1.2, 0.1, 0.5, 0.0, 0.0], [INCOMING])  # moving away: it will not come
    row([-1.55, 0.3, 0.0, 0.1, 0.0], [THEY_SERVE])
    return np.clip(np.stack(rows), OBS_LOW, OBS_HIGH)


@cache
def observations(mode: str, bounce: bool) -> np.ndarray:
    config = TennisConfig(serve_mode=mode, serve_bounce=bounce)
    seed = 17 * SERVE_MODES.index(mode) + 3 * bounce
    played = np.concatenate([_played(config, 6, 250 if bounce else 400, seed, None),
                             _played(config, 6, 150 if bounce else 300, seed + 100, 1)])
    planned, other = (40, 10) if bounce else (150, 30)
    picked = _pick(played, planned, other, seed)
    return np.concatenate([picked, _moved(picked[:planned // 2], seed), _by_hand()])


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.uint32) if a.dtype == np.float32 else a


def assert_same(new, old, obs: np.ndarray, what: str) -> None:
    assert new.dtype == old.dtype and new.shape == old.shape, what
    bad = np.flatnonzero((_bits(new) != _bits(old)).any(axis=1))
    assert not bad.size, f"{what}: {bad.size} of {len(obs)} differ, first {obs[bad[0]]}: {new[bad[0]]} != {old[bad[0]]}"


def compare(obs: np.ndarray, monkeypatch, **options) -> None:
    """The rule with ``options`` against the oracle on ``obs``: one at a time, in batches of a few (planned one at a
    time), in batches planned on arrays (forced) and all at once."""
    old = old_serve_bot_rule_for(**options)(obs)
    new = serve_bot_rule_for(**options)
    one = np.concatenate([new(obs[i:i + 1]) for i in range(len(obs))])
    assert_same(one, old, obs, "one at a time")
    for size in (3, 8, 13, 40):
        got = np.concatenate([new(obs[i:i + size]) for i in range(0, len(obs), size)])
        assert_same(got, old, obs, f"batches of {size}")
    assert_same(new(obs), old, obs, "all at once")
    with monkeypatch.context() as m:  # the arrays' path for every batch above the one-at-a-time call
        m.setattr(bots, "_PLANS_ONE_BY_ONE", 0)
        for size in (9, 40):
            got = np.concatenate([new(obs[i:i + size]) for i in range(0, len(obs), size)])
            assert_same(got, old, obs, f"batches of {size} planned on arrays")
    with monkeypatch.context() as m:  # and one at a time for all
        m.setattr(bots, "_ONE_BY_ONE", 10**9)
        assert_same(new(obs), old, obs, "all at once, one at a time")


# ---------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", SERVE_MODES)
def test_the_serve_bot_decides_as_before_in_each_serve_mode(mode, monkeypatch):
    compare(observations(mode, False), monkeypatch, mode=mode)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["fixed", "mixed"])
def test_the_serve_bot_decides_as_before_with_the_bounce_serve(mode, monkeypatch):
    compare(observations(mode, True), monkeypatch, mode=mode, bounce=True)


@pytest.mark.parametrize("options", [
    {"discrete": True},
    {"spin_read": 1.0, "return_spin": -40.0, "return_land": 1.0},
    {"mode": "spin", "drag": 0.0, "magnus": 2.5},
    {"mode": "velocity", "drag": np.float32(1.3), "magnus": 1, "spin_read": np.float32(0.7)},
])
def test_the_serve_bot_decides_as_before_with_other_options(options, monkeypatch):
    compare(observations(str(options.get("mode", "mixed")), False), monkeypatch, **options)


def _rows(*arrays: np.ndarray):
    """The arrays' elements as Python numbers, a tuple per index."""
    return zip(*(a.tolist() for a in arrays), strict=True)


def test_the_planners_flights_are_the_same_numbers(monkeypatch):
    """The flights integrated as a record and read afterwards against the flights stepped and tested as they go:
    landings, net crossings, contacts, every number, with broadcasting, in chunks and one at a time."""
    rng = np.random.default_rng(5)
    n = 700
    x, y = rng.uniform(-2.6, -0.05, n), rng.uniform(-0.1, 1.4, n)
    vx, vy, w = rng.uniform(-2.0, 14.0, n), rng.uniform(-6.0, 6.0, n), rng.uniform(-400.0, 400.0, n)
    for kd, km in ((K_DRAG, K_MAGNUS), (0.0, 3 * K_MAGNUS)):
        for full in (False, True):
            want = old_fly_to_landing(x, y, vx, vy, w, kd, km, full=full)
            assert all(np.array_equal(a, b) for a, b in zip(flight._fly_to_landing(x, y, vx, vy, w, kd, km, full=full),
                                                            want, strict=True))
            with monkeypatch.context() as m:
                m.setattr(flight, "_FLIGHT_CHUNK", 97)
                got = flight._fly_to_landing(x.reshape(7, 100), y.reshape(7, 100), vx.reshape(7, 100),
                                           vy.reshape(7, 100), w.reshape(7, 100), kd, km, full=full)
            assert all(np.array_equal(a.reshape(-1), b) for a, b in zip(got, want, strict=True))
        # broadcast against a grid, as the bounce serve's planner does
        gx, gy = np.meshgrid(np.linspace(1, 7, 5), np.linspace(-5, 1, 5))
        args = (x[:9, None], y[:9, None], gx.reshape(1, -1), gy.reshape(1, -1), w[:9, None], kd, km)
        assert all(np.array_equal(a, b) for a, b in zip(flight._fly_to_landing(*args, full=True),
                                                        old_fly_to_landing(*args, full=True), strict=True))
        for k in (n, 5, 1):  # arrays, and one at a time
            args = (x[:k], y[:k], w[:k], rng.uniform(0.1, 1.3, k), rng.uniform(0.17, 0.6, k), kd, km)
            assert all(np.array_equal(a, b) for a, b in zip(plan_launch(*args), old_plan_launch(*args), strict=True))
        # one ball at a time in Python floats
        k = 200
        want = old_fly_to_landing(x[:k], y[:k], vx[:k], vy[:k], w[:k], kd, km, full=True)
        got = [flight_one._fly_one(*v, kd, km, full=True) for v in _rows(x[:k], y[:k], vx[:k], vy[:k], w[:k])]
        assert all(np.array_equal(np.array([g[i] for g in got]), want[i]) for i in range(5))
        land, over = rng.uniform(0.1, 1.3, k), rng.uniform(0.17, 0.6, k)
        want = old_plan_launch(x[:k], y[:k], w[:k], land, over, kd, km)
        got = [flight_one._plan_launch_one(*v, kd, km) for v in _rows(x[:k], y[:k], w[:k], land, over)]
        assert all(np.array_equal(np.array([g[i] for g in got]), want[i]) for i in range(2))
        ins = [rng.uniform(-9.0, 9.0, k) for _ in range(4)] + [rng.uniform(-300.0, 300.0, k) for _ in range(2)]
        vin_x, vin_y, vout_x, vout_y, w_in, w_out = ins
        want = old_solve_stroke(vin_x, vin_y, w_in, vout_x, vout_y, w_out)
        got = [flight_one._solve_stroke_one(*v) for v in _rows(vin_x, vin_y, w_in, vout_x, vout_y, w_out)]
        assert all(np.array_equal(np.array([g[i] for g in got]), want[i]) for i in range(4))
    # incoming balls: from the other half or mine, bounced or not, some bounce serves coming over
    x = rng.uniform(-2.4, 2.6, n)
    vx = np.where(x > 0, rng.uniform(-12.0, -1.0, n), rng.uniform(-6.0, 3.0, n))
    bounced = rng.random(n) < 0.3
    for kd, km in ((K_DRAG, K_MAGNUS), (0.5 * K_DRAG, 0.0)):
        want = old_predict_contact(x, y, vx, vy, w, bounced, kd, km)
        got = flight._predict_contact(x, y, vx, vy, w, bounced, kd, km)
        assert want[0].any() and not want[0].all()
        assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
        for i, v in enumerate(_rows(x, y, vx, vy, w, bounced)):
            one = flight_one._predict_contact_one(*v, kd, km)
            assert (one is not None) == want[0][i]
            assert one is None or one == tuple(a[i] for a in want[1:])


def test_one_observation_is_planned_in_python_floats(monkeypatch):
    """A call on a few observations never steps the arrays' flights (their cost is per operation, whatever the rows)."""
    def arrays(*args, **kwargs):
        raise AssertionError("planned on arrays")

    monkeypatch.setattr(flight, "_integrate", arrays)
    obs = observations("mixed", False)
    rule = serve_bot_rule_for("mixed")
    for i in range(0, 120, 3):
        rule(obs[i:i + 1])
        rule(obs[i:i + 3])
