"""The tennis game's scripted player, ``serve-bot``: it plans with the game's own physics (:mod:`.physics`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..rng import GOLDEN, mix64, to_unit
from .config import (
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
from .physics import accel, contact

#
# serve-bot plans with the game's own physics, in its egocentric frame (own end at -x, net at 0): it predicts where
# it will meet the ball, chooses the ball it wants to send (landing x, height over the net, spin), integrates the
# flight to correct its aim for drag and Magnus, and solves the contact model backwards for the bat's normal and
# velocity that produce that ball from the incoming one. It then brings its bat, tilted, to a point behind the
# contact (along the stroke) and swings through the contact point at that velocity.
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


def _unit_hash(x: np.ndarray, salt: int) -> np.ndarray:
    """Uniform [0, 1) numbers from the bits of float32 values (SplitMix64), one per value and salt."""
    bits = np.asarray(x, dtype=np.float32).view(np.uint32).astype(np.uint64)
    return to_unit(mix64(bits * np.uint64(GOLDEN) + np.uint64(salt)))


def _fly_to_landing(x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray, kd: float,
                    km: float, t_max: float = 1.6, full: bool = False) -> tuple[np.ndarray, ...]:
    """Flights from (x, y) toward +x: the height at which each crosses the net's plane (below the table's surface
    if it falls short of it) and where it comes down to the table's height (its x when it stops, if it does not
    within ``t_max``). Integrated at 20 ms, second order in the step. ``full``: also the velocity it comes down
    with and whether it came down within ``t_max``."""
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


def _parabola(x0: np.ndarray, y0: np.ndarray, over_y: np.ndarray, land_x: np.ndarray) -> tuple[np.ndarray, ...]:
    """The launch velocity of the drag-free path from (x0, y0) over (0, over_y) down to (land_x, ball radius). A
    ball at the net is planned from 5 cm behind it and the launch kept within 30 m/s upward or downward (a bot at
    the net otherwise asks its flight model for speeds that overflow it)."""
    x1, y1 = np.maximum(-x0, 0.05), over_y - y0
    x2, y2 = np.maximum(land_x - x0, x1 + 0.05), BALL_R - y0
    c = np.minimum((y2 / x2 - y1 / x1) / (x2 - x1), -0.02)
    b = y1 / x1 - c * x1
    vx = np.sqrt(G / (-2.0 * c))
    return vx, np.clip(b * vx, -30.0, 30.0)


def plan_launch(x0: np.ndarray, y0: np.ndarray, w: np.ndarray, land_x: np.ndarray, over_y: np.ndarray,
                kd: float = K_DRAG, km: float = K_MAGNUS, iterations: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The velocity to give a ball with spin ``w`` at (x0 < 0, y0) so that it crosses the net's plane at height
    ``over_y`` and comes down at ``land_x``, with drag and Magnus: the drag-free parabola through those points, its
    aim points moved by what the real flight (integrated) missed them by, ``iterations`` times."""
    x0, y0, w = (np.asarray(a, dtype=np.float64) for a in (x0, y0, w))
    land_x, over_y = np.asarray(land_x, dtype=np.float64), np.asarray(over_y, dtype=np.float64)
    aim_x, aim_y = land_x.copy(), over_y.copy()
    for _ in range(iterations):
        vx, vy = _parabola(x0, y0, aim_y, aim_x)
        got_y, got_x = _fly_to_landing(x0, y0, vx, vy, w, kd, km)
        got_y = np.where(got_y < 0, np.minimum(y0, NET_H) - 0.2, got_y)  # fell short of the net: aim higher
        aim_x = np.clip(aim_x + (land_x - got_x), 0.05, 3.0)
        aim_y = np.clip(aim_y + (over_y - got_y), y0 - 1.0, 2.0)
    return _parabola(x0, y0, aim_y, aim_x)


def _serve_flights(x0: np.ndarray, y0: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray, kd: float,
                   km: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounce serves from (x0 < 0, y0) launched at (vx, vy) with spin w: where each first comes down to the table
    (its bounce, NaN if not on the server's half), the height at which it then crosses the net's plane (-1 if it
    does not) and where it comes down next (NaN if it does not): two of :func:`_fly_to_landing`'s flights, the
    bounce between them by the game's own contact model."""
    _, bounce_x, bvx, bvy, down = _fly_to_landing(x0, y0, vx, vy, w, kd, km, full=True)
    own = down & (bounce_x >= -TABLE_HALF) & (bounce_x <= 0.0)
    zero = np.zeros(bvx.shape)
    vx2, vy2, w2 = contact(bvx, bvy, np.broadcast_to(w, bvx.shape), zero, zero + 1.0, 0.0, 0.0, E_TABLE, MU_TABLE)
    y_net, land_x, _, _, down2 = _fly_to_landing(bounce_x, BALL_R, vx2, vy2, w2, kd, km, full=True)
    return (np.where(own, bounce_x, np.nan), np.where(own, y_net, -1.0),
            np.where(own & down2, land_x, np.nan))


_SERVE_VX = np.linspace(1.0, 7.0, 13)  # the bounce serve's launch velocities the planner tries (m/s)
_SERVE_VY = np.linspace(-5.0, 1.0, 13)


def plan_bounce_serve(x0: np.ndarray, y0: np.ndarray, w: np.ndarray, land_x: np.ndarray, over_y: np.ndarray,
                      vin_x: np.ndarray, vin_y: np.ndarray, w_in: np.ndarray, kd: float = K_DRAG,
                      km: float = K_MAGNUS) -> tuple[np.ndarray, np.ndarray]:
    """The launch velocity of a serve under table tennis's rule (``serve_bounce``): from (x0 < 0, y0) with spin
    ``w`` it bounces on the server's own half, then crosses the net's plane near ``over_y`` (at least a ball's
    radius and 8 cm over the net in the planner's coarser flight: the game's comes out a few cm lower) and comes
    down near ``land_x`` on the receiver's half, struck from a toss moving at (vin_x, vin_y) with spin ``w_in`` by
    a bat no faster than 80% of its top speed. A search over a grid of launch velocities, then two finer ones
    around the best, each flight integrated with its bounce."""
    x0, y0, w, land_x, over_y, vin_x, vin_y, w_in = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (
        x0, y0, w, land_x, over_y, vin_x, vin_y, w_in))
    vx0, vy0 = np.meshgrid(_SERVE_VX, _SERVE_VY, indexing="ij")
    gx, gy = vx0.reshape(1, -1), vy0.reshape(1, -1)
    step_x, step_y = _SERVE_VX[1] - _SERVE_VX[0], _SERVE_VY[1] - _SERVE_VY[0]
    best_vx, best_vy = np.zeros(len(x0)), np.zeros(len(x0))
    for _ in range(3):
        cand_x = np.broadcast_to(gx, (len(x0), gx.shape[1])) + best_vx[:, None]
        cand_y = np.broadcast_to(gy, (len(x0), gy.shape[1])) + best_vy[:, None]
        b, yn, lx = _serve_flights(x0[:, None], y0[:, None], cand_x, cand_y, w[:, None], kd, km)
        legal = ~np.isnan(b) & (yn >= NET_H + BALL_R + 0.08) & (lx > 0.05) & (lx < TABLE_HALF - 0.03)
        _, _, bvx, bvy = solve_stroke(vin_x[:, None], vin_y[:, None], w_in[:, None], cand_x, cand_y, w[:, None])
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


def solve_stroke(vin_x: np.ndarray, vin_y: np.ndarray, w_in: np.ndarray, vout_x: np.ndarray, vout_y: np.ndarray,
                 w_out: np.ndarray) -> tuple[np.ndarray, ...]:
    """The bat's face normal (toward the ball) and velocity that turn the ball (vin, w_in) into (vout, w_out) under
    :func:`contact` with the bat's restitution and friction (the bat not turning at the contact).

    The change of velocity has a normal part ``(1 + e) |v_n|`` and a tangential part ``-0.4 u`` fixed by the spin
    wanted (``w_out - w_in = -1.5 / r`` times it), which sets the normal's direction; the relative normal and
    tangential speeds then give the bat's velocity. Spin beyond what the rubber's friction can give is reduced.
    Returns ``nx, ny, bat_vx, bat_vy``."""
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


def _predict_contact(x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray,
                     bounced: np.ndarray, kd: float, km: float, t_max: float = 1.6) -> tuple[np.ndarray, ...]:
    """Where to meet an incoming ball: its flight (with a bounce on my half, x < 0) to the top of its bounce (if
    that is above ``_REACH_Y``, to where it comes down through it), or to where it passes ``_REACH_X``. Returns
    found, time, x, y, vx, vy, w (found False: it will not bounce on my half, so it must not be touched)."""
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


def _swing(o: np.ndarray, sel: np.ndarray, t_c: np.ndarray, px: np.ndarray, py: np.ndarray, vin_x: np.ndarray,
           vin_y: np.ndarray, w_in: np.ndarray, land_x: np.ndarray, over_y: np.ndarray, w_out: np.ndarray,
           kd: float, km: float, act: np.ndarray, bounce: bool = False) -> None:
    """Write into ``act[sel]`` the stroke that meets the ball at (px, py) in ``t_c`` seconds and sends it to land
    at ``land_x`` over the net at ``over_y`` with spin ``w_out`` (``bounce``: a serve bouncing on the own half
    first, :func:`plan_bounce_serve`). A ball met high near the net cannot come down that steeply and still fall as
    a ball falls: it crosses the net at least 5 cm above the straight line from the contact to the landing point (a
    smash, not a stroke faster than any bat)."""
    if bounce:  # (the planner keeps to what the bat can swing)
        vx, vy = plan_bounce_serve(px, py, w_out, land_x, over_y, vin_x, vin_y, w_in, kd, km)
    else:
        line_y = py + (BALL_R - py) * (-px) / np.maximum(land_x - px, 1e-3)  # the straight line's height at the net
        over_y = np.maximum(over_y, line_y + 0.05)
        vx, vy = plan_launch(px, py, w_out, land_x, over_y, kd, km)
        for _ in range(2):  # a stroke faster than the bat can swing: a slower ball, higher over the net
            bvx, bvy = solve_stroke(vin_x, vin_y, w_in, vx, vy, w_out)[2:]
            fast = np.flatnonzero(np.maximum(np.abs(bvx), np.abs(bvy)) > 0.8 * V_MAX)
            if not fast.size:
                break
            over_y = over_y.copy()
            over_y[fast] += 0.1
            vx[fast], vy[fast] = plan_launch(px[fast], py[fast], w_out[fast], land_x[fast], over_y[fast], kd, km)
    nx, ny, bvx, bvy = solve_stroke(vin_x, vin_y, w_in, vx, vy, w_out)
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


def serve_bot_rule_for(mode: str = "fixed", drag: float = 1.0, magnus: float = 1.0, discrete: bool = False,
                       spin_read: float = 0.6, return_spin: float = 0.0, return_land: float = 0.75,
                       bounce: bool = False):
    """The serve-bot's rule ``rule(obs, rng=None, mask=None) -> actions`` for observations ``(k, 25)``.

    Serving, it strikes the toss (the game tosses) as it falls through a chosen height, sending the ball to land on the
    receiver's half: ``fixed`` always the same serve (0.8 m past the net, 12 cm over it, no spin), ``velocity`` a random
    landing point, height over the net and contact height (so a random speed and arc), ``spin`` random top- or backspin
    up to 120 rad/s (19 turns a second), ``mixed`` either of the two randomized serves, half each. A serve's random
    choices are a hash of the toss's place (drawn by the game for every serve and fixed while the toss is in the air),
    so a stateless rule keeps to one plan for the whole serve and a game's serves are reproducible by its seed.
    Receiving, it waits for the ball to bounce on its half, meets it at the top of its bounce (or, bouncing above 1.2 m,
    coming down through 1.2 m) and sends it back to the middle of the other half, 15 cm over the net (higher if met high
    near the net), without spin; in the randomized modes (practice) at the pace it came instead: a ball met at 4 m/s or
    slower goes back short (0.6 m past the net) and 20 cm over it, one at 9 m/s or faster deep (1.15 m) and 5 cm over,
    in ``spin`` and ``mixed`` modes with topspin growing with the pace (planned up to 120 rad/s), so a learner practises
    returning the pace it plays. A ball past the end of its half without a bounce there (going long) it dodges, moving
    its bat up or down away from it (standing in its path would be a volley, the bot's fault). Otherwise it goes back to
    its place behind the table; in the randomized modes (practice) it waits for the opponent's serve at a random place
    1.3 to 2.3 m behind the net and 0 to 1.2 m above the table, its face tilted up to 1.4 rad either way (a hash of the
    toss's place), so a learner's serve cannot come to depend on where its receiver stands.
    Its weakness, so that it can be beaten: it misjudges spin, planning with ``spin_read`` (60%) of the spin it
    sees: against itself ~2% of its returns fail (~60 hits a point), but of balls with 200-300 rad/s of topspin it
    returns about a quarter, where reading spin right it returns them all (tests/test_tennis.py). ``return_spin``
    and ``return_land`` change its returns (for experiments). Deterministic: ``rng`` is not used. With
    ``discrete`` each axis is -1, 0 or +1 (the sign of the continuous action beyond a quarter), a much weaker
    player."""
    if mode not in SERVE_MODES:  # (an unknown mode would otherwise serve as one of the others)
        raise ValueError(f"serve_mode must be one of {', '.join(SERVE_MODES)}, not {mode!r}")
    kd, km = K_DRAG * drag, K_MAGNUS * magnus

    def rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float64).reshape(len(obs), N_FEATURES)
        act = _go_home(o, mode)
        serve = o[:, I_SERVE] > 0.5
        if serve.any():
            _serve(o, serve, mode, kd, km, bounce, act)
        dodge = _dodge(o, act)
        receive = ((o[:, INCOMING] > 0.5) | (o[:, MY_TURN] > 0.5)) & ~dodge
        if receive.any():
            _receive(o, receive, mode, kd, km, spin_read, return_spin, return_land, act)
        act = np.clip(act, -1.0, 1.0)
        if discrete:
            return (np.where(act > 0.25, 2, np.where(act < -0.25, 0, 1))).astype(np.int64)
        return act.astype(np.float32)

    return rule


def _ball(o: np.ndarray) -> tuple[np.ndarray, ...]:
    """The ball's position, velocity (m/s) and spin (rad/s) in observations ``o`` ``(k, 25)``."""
    return (o[:, BALL_X], o[:, BALL_Y], o[:, BALL_VX] * VEL_SCALE, o[:, BALL_VY] * VEL_SCALE,
            o[:, BALL_SPIN] * SPIN_SCALE)


def _go_home(o: np.ndarray, mode: str) -> np.ndarray:
    """The actions ``(k, 3)`` that take each bat back to its waiting place, upright and unhurried (never chasing the
    ball just struck); in the randomized modes (practice) it waits for the opponent's serve at a random place (a hash
    of the toss's)."""
    k = len(o)
    act = np.zeros((k, 3))
    home_x, home_y, home_a = np.full(k, HOME_X), np.full(k, HOME_Y), np.zeros(k)
    if mode != "fixed":
        t = o[:, THEY_SERVE] > 0.5
        for arr, (low, high), salt in zip((home_x, home_y, home_a), _WAIT, (4, 5, 6), strict=True):
            arr[t] = low + (high - low) * _unit_hash(o[t, BALL_X], salt)
    act[:, 0] = np.clip((home_x - o[:, BAT_X]) * 4.0, -2.0, 2.0) / V_MAX
    act[:, 1] = np.clip((home_y - o[:, BAT_Y]) * 4.0, -2.0, 2.0) / V_MAX
    act[:, 2] = (home_a - o[:, BAT_ANGLE]) / (DT * OMEGA_MAX)
    return act


def _serve(o: np.ndarray, s: np.ndarray, mode: str, kd: float, km: float, bounce: bool, act: np.ndarray) -> None:
    """Write into ``act[s]`` the serve of the tosses ``s``: the ball to send (by ``mode``; random choices a hash of
    the toss's place), struck as the toss falls through the chosen height."""
    px, py, _, vy, w = _ball(o)
    u1, u2, u3 = (_unit_hash(o[s, BALL_X], salt) for salt in (1, 2, 3))
    m = s.sum()
    if mode == "fixed":
        land, clear, spin, height = np.full(m, 0.8), np.full(m, 0.12), np.zeros(m), np.full(m, 0.3)
    else:  # velocity, spin, or (mixed) either, drawn per serve
        spun = _unit_hash(o[s, BALL_X], 7) < 0.5 if mode == "mixed" else np.full(m, mode == "spin")
        land = np.where(spun, 0.45 + 0.5 * u1, 0.35 + 0.65 * u1)
        clear = np.where(spun, 0.10 + 0.10 * u2, 0.04 + 0.26 * u2)
        spin = np.where(spun, (2 * u3 - 1) * 120.0, 0.0)
        height = np.where(spun, 0.3, 0.22 + 0.2 * u3)
    y, v = py[s], vy[s]
    disc = v * v + 2 * G * (y - height)
    t_c = np.where(disc >= 0, (v + np.sqrt(np.maximum(disc, 0.0))) / G, np.maximum(v, 0.0) / G)
    hy = np.where(disc >= 0, height, y + v * t_c - 0.5 * G * t_c * t_c)
    _swing(o, s, t_c, px[s], hy, np.zeros(m), v - G * t_c, w[s], land, NET_H + clear, spin, kd, km, act, bounce)


def _dodge(o: np.ndarray, act: np.ndarray) -> np.ndarray:
    """The bats whose ball is past the end of their half without a bounce there (it can no longer land): out of its
    way, up or down (standing in its path would be a volley). Writes their actions into ``act``; returns them."""
    px, py, vx, _, _ = _ball(o)
    dodge = (o[:, INCOMING] > 0.5) & (px < -TABLE_HALF) & (vx < 0.0)
    if dodge.any():
        act[dodge, 0] = 0.0
        act[dodge, 1] = np.where(o[dodge, BAT_Y] > py[dodge], 1.0, -1.0)
        act[dodge, 2] = -o[dodge, BAT_ANGLE] / (DT * OMEGA_MAX)
    return dodge


def _receive(o: np.ndarray, receive: np.ndarray, mode: str, kd: float, km: float, spin_read: float,
             return_spin: float, return_land: float, act: np.ndarray) -> None:
    """Write into ``act`` the returns of the incoming balls ``receive`` that will bounce on the bot's half: met where
    :func:`_predict_contact` says (reading ``spin_read`` of their spin), sent to ``return_land`` past the net, or in
    the randomized modes (practice) back at the pace they came."""
    px, py, vx, vy, w = _ball(o)
    r = np.flatnonzero(receive)
    found, t_c, cx, cy, cvx, cvy, cw = _predict_contact(px[r], py[r], vx[r], vy[r], w[r] * spin_read,
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
    _swing(o, sel, t_c[f], cx[f], cy[f], cvx[f], cvy[f], cw[f], land, over, spin, kd, km, act)


serve_bot_rule = serve_bot_rule_for()


def serve_bot_for(cfg: TennisConfig):
    """The serve-bot's rule for a game's options (its ``serve_mode``, the air's forces, discrete actions)."""
    return serve_bot_rule_for(cfg.serve_mode, cfg.drag, cfg.magnus, cfg.discrete, bounce=cfg.serve_bounce)
