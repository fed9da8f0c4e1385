"""The tennis game's scripted player, ``serve-bot``: it plans with the game's own physics (:mod:`.physics`)."""

from __future__ import annotations

import functools
import math
import struct
from typing import Any

import numpy as np

from ..rng import GOLDEN, M1, M2, MASK, UNIT, mix64, to_unit
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
from .physics import clip_one, contact, contact_one, max_one, min_one

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


def _integrate(rec: np.ndarray, steps: int, kd: float, km: float, kw: np.ndarray | None,
               done: Any) -> int:
    """Steps of the planner's flights at 20 ms in the record ``rec`` ``(steps + 1, slots, 2, n)``: ``rec[t]`` holds
    the positions, velocities and accelerations (``(2, n)`` each) before step ``t``, and, when ``kw`` is None (the
    spin decays), ``(w, -w)`` in a fourth slot. ``rec[0]``'s positions, velocities (and spins) are given; a step
    is :func:`accel` (its acceleration kept in ``rec[t]``), then ``x + v dt + a dt^2 / 2``, ``v + a dt`` and the
    spin's decay. ``kw``: ``km * (w, -w)`` of a spin that does not decay. After step ``t``, ``done(t + 1)`` is
    asked whether the record ``rec[t + 1]`` ends the flights; returns the steps taken.

    A few array operations a step for all the flights (numpy's cost is per operation, the more so when it must
    broadcast: operands of one shape, constants as 0-d arrays): the numbers are those of :func:`accel` and of the
    step, operation for operation, reordered only where IEEE arithmetic gives the same result (``(-a) b = -(a b)``,
    ``a - b = a + (-b)``, ``a b = b a``)."""
    n = rec.shape[-1]
    sq, s, mag, t4 = np.empty((2, n)), np.empty(n), np.empty((2, n)), np.empty((2, 2, n))
    sq_x, sq_y, mag_y, mag_x = sq[0], sq[1], mag[0], mag[1]
    nkd, g, dt, half, km_, decay = (np.array(c) for c in (-kd, G, _PLAN_DT, _HALF_DT2, km, _DECAY))
    mul, add, sub, sqrt = np.multiply, np.add, np.subtract, np.sqrt
    spins = kw is None
    for t in range(steps):
        r, r1 = rec[t], rec[t + 1]
        v, a = r[1], r[2]
        vx, vy = v
        ax, ay = a
        mul(v, v, sq)
        add(sq_x, sq_y, s)
        sqrt(s, s)
        mul(s, nkd, s)  # -kd |v|
        mul(vx, s, ax)  # drag
        mul(vy, s, ay)
        sub(ay, g, ay)
        if spins:
            mul(r[3], km_, mag)
            mul(v, mag, mag)  # Magnus: (km w vx, -km w vy) = (ay, ax)
        else:
            mul(v, kw, mag)
        add(ax, mag_x, ax)
        add(ay, mag_y, ay)
        mul(r[1:3], dt, t4)
        p1 = r1[0:2]
        add(r[0:2], t4, p1)  # x + v dt, v + a dt
        mul(a, half, sq)
        add(p1[0], sq, p1[0])
        if spins:
            mul(r[3], decay, r1[3])
        if done(t + 1):
            return t + 1
    return steps


def _fly_to_landing(x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray, kd: float,
                    km: float, t_max: float = 1.6, full: bool = False) -> tuple[np.ndarray, ...]:
    """Flights from (x, y) toward +x: the height at which each crosses the net's plane (below the table's surface
    if it falls short of it) and where it comes down to the table's height (its x when it stops, if it does not
    within ``t_max``). Integrated at 20 ms, second order in the step. ``full``: also the velocity it comes down
    with and whether it came down within ``t_max``.

    The flights are integrated first (:func:`_integrate`, until all have come down), and the crossing and the
    landing read from the record afterwards; the same numbers as stepping each flight and testing it as it goes."""
    x, y, vx, vy, w = (np.asarray(a, dtype=np.float64) for a in (x, y, vx, vy, w))
    if not x.shape == y.shape == vx.shape == vy.shape == w.shape:
        x, y, vx, vy, w = np.broadcast_arrays(x, y, vx, vy, w)
    shape, n = x.shape, x.size
    if n > _FLIGHT_CHUNK:  # (a record of 24 numbers a step and a flight: keep it within memory)
        parts = [_fly_to_landing(*(a.reshape(-1)[i:i + _FLIGHT_CHUNK] for a in (x, y, vx, vy, w)), kd, km, t_max,
                                 full) for i in range(0, n, _FLIGHT_CHUNK)]
        return tuple(np.concatenate(p).reshape(shape) for p in zip(*parts, strict=True))
    steps = int(t_max / _PLAN_DT)
    if steps < 1:  # (no step: nothing crossed, nothing came down)
        stay = (np.full(shape, -1.0), x.copy(), vx.copy(), vy.copy(), np.zeros(shape, dtype=bool))
        return stay if full else stay[:2]
    rec = np.empty((steps + 1, 3, 2, n))
    rec[0, 0, 0], rec[0, 0, 1], rec[0, 1, 0], rec[0, 1, 1] = (a.reshape(-1) for a in (x, y, vx, vy))
    w = w.reshape(-1)
    kw = np.stack([km * w, km * -w])
    down = np.zeros(n, dtype=bool)

    def all_down(i: int) -> bool:  # every 4 steps (coming down in the last one: it came down)
        if i % 4:
            return False
        r = rec[i]
        down[...] |= (r[0, 1] <= BALL_R) & (r[1, 1] < 0)
        return bool(down.all())

    ran = _integrate(rec, steps, kd, km, kw, all_down)
    # rec[i]: after i steps. A flight comes down in the first step that ends at or below the table's height moving
    # down; it crosses the net in the last step before then that goes from x < 0 to x >= 0
    px, py = rec[:ran + 1, 0, 0], rec[:ran + 1, 0, 1]
    landing = (py[1:] <= BALL_R) & (rec[1:ran + 1, 1, 1] < 0)
    came = landing.any(axis=0)
    first = np.where(came, landing.argmax(axis=0), ran - 1)
    crosses = (px[:-1] < 0) & (px[1:] >= 0) & (np.arange(ran)[:, None] <= first)
    crossed = crosses.any(axis=0)
    last = ran - 1 - crosses[::-1].argmax(axis=0)
    cols = np.arange(n)
    x0, x1, y0, y1 = px[last, cols], px[last + 1, cols], py[last, cols], py[last + 1, cols]
    y_net = np.where(crossed, y0 + (-x0 / np.where(crossed, x1 - x0, 1.0)) * (y1 - y0), -1.0)
    x0, x1, y0, y1 = px[first, cols], px[first + 1, cols], py[first, cols], py[first + 1, cols]
    f = np.clip((y0 - BALL_R) / np.where(came, y0 - y1, 1.0), 0.0, 1.0)
    x_land = np.where(came, x0 + f * (x1 - x0), px[ran])
    if not full:
        return y_net.reshape(shape), x_land.reshape(shape)
    vx_land = np.where(came, rec[first + 1, 1, 0, cols], vx.reshape(-1))
    vy_land = np.where(came, rec[first + 1, 1, 1, cols], vy.reshape(-1))
    return tuple(a.reshape(shape) for a in (y_net, x_land, vx_land, vy_land, came))


_FLIGHT_CHUNK = 4096


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
    if max(a.size for a in (x0, y0, w, land_x, over_y)) <= _ONE_BY_ONE:  # a few: one at a time (the same numbers)
        args = np.broadcast_arrays(x0, y0, w, land_x, over_y)
        planned = [_plan_launch_one(*row, float(kd), float(km), iterations)
                   for row in zip(*(a.reshape(-1).tolist() for a in args), strict=True)]
        vx, vy = (np.array([p[i] for p in planned], dtype=np.float64).reshape(args[0].shape) for i in (0, 1))
        return vx, vy
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
    found, time, x, y, vx, vy, w (found False: it will not bounce on my half, so it must not be touched).

    Stepped at 20 ms, the spin decaying. The flights are integrated (:func:`_integrate`) until each meets its first
    event (a bounce, the ball dead, the contact) and the events read from the record; the balls that bounced go on
    from there, each from its own step, until none is left (a ball bounces twice at most: a bounce serve on the
    server's half, then on mine). The same numbers as stepping each ball and testing it as it goes."""
    x, y, vx, vy, w = (np.array(a, dtype=np.float64) for a in (x, y, vx, vy, w))
    bounced = np.array(bounced, dtype=bool)
    k = len(x)
    found = np.zeros(k, dtype=bool)
    out = np.zeros((6, k))
    out[0] = t_max
    # a ball already on its way down after its bounce is met now
    now = bounced & (vy <= 0) & (y <= _REACH_Y)
    found[now] = True
    out[0, now] = 0.0
    out[1:, now] = x[now], y[now], vx[now], vy[now], w[now]
    steps = int(t_max / _PLAN_DT)
    times = _step_times(steps)
    rows = np.flatnonzero(~now)
    start = np.zeros(rows.size, dtype=np.int64)  # the steps each ball has flown
    far_bounced = np.zeros(rows.size, dtype=bool)  # a ball may bounce once on the other half (a bounce serve)
    bounced = bounced[rows]
    state = [a[rows] for a in (x, y, vx, vy, w)]
    while rows.size:
        m, span = rows.size, steps - int(start.min())
        rec = np.empty((span + 1, 4, 2, m))
        rec[0, 0], rec[0, 1], rec[0, 3] = state[:2], state[2:4], (state[4], -state[4])
        first = _first_events(rec, span, steps - start, bounced, kd, km)
        go = first >= 0
        if not go.any():
            break
        i, j = np.flatnonzero(go), first[go]
        r = rec[j + 1, :, :, i].transpose(1, 2, 0)  # the state after each ball's event step
        bx, by, bvx, bvy, bw = r[0, 0].copy(), r[0, 1].copy(), r[1, 0].copy(), r[1, 1].copy(), r[3, 0].copy()
        b, fb = bounced[i], far_bounced[i]
        hit = ~b & (by < BALL_R) & (bvy < 0) & (np.abs(bx) <= TABLE_HALF)
        mine = hit & (bx < 0)
        far = hit & ~mine & ~fb & (bvx < 0)  # a bounce serve's bounce on the server's half
        for sel in (far, mine):
            if sel.any():
                zero = np.zeros(sel.sum())
                bvx[sel], bvy[sel], bw[sel] = contact(bvx[sel], bvy[sel], bw[sel], zero, zero + 1.0, 0.0, 0.0,
                                                      E_TABLE, MU_TABLE)
                by[sel] = 2 * BALL_R - by[sel]
        fb = fb | far
        b = b | mine
        alive = ~(hit & ~mine & ~far)  # lands on the other half: not mine to play
        ax = np.abs(bx)
        alive &= ~(((by < 0) & ((ax < TABLE_HALF) | ~b)) | (by < FLOOR_Y + 0.3))
        meet = alive & b & (((bvy <= 0) & (by <= _REACH_Y)) | (bx <= _REACH_X))
        g = rows[i[meet]]
        found[g] = True
        out[:, g] = times[start[i[meet]] + j[meet]], bx[meet], by[meet], bvx[meet], bvy[meet], bw[meet]
        on = alive & ~meet & (mine | far)  # bounced: they fly on from the next step
        keep = i[on]
        rows, start = rows[keep], start[keep] + j[on] + 1
        bounced, far_bounced = b[on], fb[on]
        state = [bx[on], by[on], bvx[on], bvy[on], bw[on]]
    return (found, *out)


def _first_events(rec: np.ndarray, span: int, left: np.ndarray, bounced: np.ndarray, kd: float,
                  km: float) -> np.ndarray:
    """The flights of :func:`_predict_contact` from ``rec[0]`` (:func:`_integrate`'s record, the spin decaying),
    each with ``left`` steps it may still take, until each meets its first event (:func:`_events`): the step of
    each one's (-1: none)."""
    m = rec.shape[-1]
    first = np.full(m, -1)
    unmet = np.ones(m, dtype=bool)
    lmin, every = int(left.min()), bool(bounced.all())
    none = not every and not bounced.any()
    inf = np.array(np.inf)

    def met(i: int) -> bool:  # the step i - 1 (to the record i): which balls meet their first event
        r = rec[i]
        # (a quick look first: none can be at an event if those that have not met one are all above the lowest
        # height of an event and, all bounced, rising, above the height of the dead and short of the farthest point)
        if none and np.minimum.reduce(r[0, 1], where=unmet, initial=inf) >= _LOW_EVENT:
            return False
        if every and (np.minimum.reduce(r[1, 1], where=unmet, initial=inf) > 0
                      and np.minimum.reduce(r[0, 1], where=unmet, initial=inf) >= _DEAD_Y
                      and np.minimum.reduce(r[0, 0], where=unmet, initial=inf) > _REACH_X):
            return False
        e = _events(r[0, 0], r[0, 1], r[1, 1], bounced, every)
        if lmin < i:  # (some balls have no steps left)
            e &= left >= i
        e &= unmet
        if e.any():
            first[e] = i - 1
            unmet[e] = False
            return not (unmet & (left > i)).any()
        return i >= lmin and not (unmet & (left > i)).any()

    _integrate(rec, span, kd, km, None, met)
    return first


def _events(x: np.ndarray, y: np.ndarray, vy: np.ndarray, bounced: np.ndarray, every: bool) -> np.ndarray:
    """Whether a ball of :func:`_predict_contact` at (x, y) moving up at vy meets an event there, its bounce or the
    end of its flight: it comes down on the table without having bounced on my half, or it is dead (below the
    table's surface over the table, or not yet bounced on my half; or near the floor), or it can be met (bounced on
    my half: coming down within reach, or passing the farthest point back). ``bounced`` per ball; ``every``: all
    have bounced (shorter formulas when the balls agree)."""
    if not every and not bounced.any():  # (not bounced, dead is y < 0 or y < FLOOR_Y + 0.3)
        return ((y < BALL_R) & (vy < 0) & (np.abs(x) <= TABLE_HALF)) | (y < _DEAD_Y)
    dead_bounced = ((y < 0) & (np.abs(x) < TABLE_HALF)) | (y < FLOOR_Y + 0.3)
    meet = ((vy <= 0) & (y <= _REACH_Y)) | (x <= _REACH_X)
    if every:
        return dead_bounced | meet
    return np.where(bounced, dead_bounced | meet,
                    ((y < BALL_R) & (vy < 0) & (np.abs(x) <= TABLE_HALF)) | (y < _DEAD_Y))


_DEAD_Y = max(0.0, FLOOR_Y + 0.3)  # below this height a ball of _predict_contact may be dead
_LOW_EVENT = max(BALL_R, _DEAD_Y)  # and one that has not bounced on my half has no event above this


@functools.cache
def _step_times(steps: int) -> np.ndarray:
    """The time after each of ``steps`` planning steps, summed step by step (as a loop adds them up; read only)."""
    times, t = [], 0.0
    for _ in range(steps):
        t += _PLAN_DT
        times.append(t)
    out = np.array(times)
    out.flags.writeable = False
    return out


def _swing(o: np.ndarray, rows: np.ndarray, t_c: np.ndarray, px: np.ndarray, py: np.ndarray, vin_x: np.ndarray,
           vin_y: np.ndarray, w_in: np.ndarray, land_x: np.ndarray, over_y: np.ndarray, w_out: np.ndarray,
           kd: float, km: float, act: np.ndarray, bounce: bool = False) -> None:
    """Write into ``act[rows]`` the strokes that meet the ball at (px, py) in ``t_c`` seconds and send it to land
    at ``land_x`` over the net at ``over_y`` with spin ``w_out`` (``bounce``: a serve bouncing on the own half
    first, :func:`plan_bounce_serve`). A ball met high near the net cannot come down that steeply and still fall as
    a ball falls: it crosses the net at least 5 cm above the straight line from the contact to the landing point (a
    smash, not a stroke faster than any bat)."""
    stroke = None
    if bounce:  # (the planner keeps to what the bat can swing)
        vx, vy = plan_bounce_serve(px, py, w_out, land_x, over_y, vin_x, vin_y, w_in, kd, km)
    else:
        line_y = py + (BALL_R - py) * (-px) / np.maximum(land_x - px, 1e-3)  # the straight line's height at the net
        over_y = np.maximum(over_y, line_y + 0.05)
        vx, vy = plan_launch(px, py, w_out, land_x, over_y, kd, km)
        for _ in range(2):  # a stroke faster than the bat can swing: a slower ball, higher over the net
            stroke = solve_stroke(vin_x, vin_y, w_in, vx, vy, w_out)
            bvx, bvy = stroke[2:]
            fast = np.flatnonzero(np.maximum(np.abs(bvx), np.abs(bvy)) > 0.8 * V_MAX)
            if not fast.size:
                break
            stroke = None
            over_y = over_y.copy()
            over_y[fast] += 0.1
            vx[fast], vy[fast] = plan_launch(px[fast], py[fast], w_out[fast], land_x[fast], over_y[fast], kd, km)
    if stroke is None:  # (else the last one found is this launch's)
        stroke = solve_stroke(vin_x, vin_y, w_in, vx, vy, w_out)
    nx, ny, bvx, bvy = stroke
    # The face: the normal toward the ball, or the back face's tilt if that one faces the ball
    angle = np.arctan2(ny, nx)
    angle = np.where(angle > ANGLE_MAX, angle - math.pi, np.where(angle < -ANGLE_MAX, angle + math.pi, angle))
    cx, cy = px - (BALL_R + _GAP) * nx, py - (BALL_R + _GAP) * ny  # the bat's centre at the contact
    bx, by = o[rows, BAT_X], o[rows, BAT_Y]
    far = t_c > _SWING
    lead = np.where(far, _SWING, t_c)
    want_x, want_y = cx - bvx * lead, cy - bvy * lead  # where the bat should be now (or wait, while far)
    step = np.maximum(t_c, DT)
    cmd_x = np.where(far, (want_x - bx) / DT, bvx + (want_x - bx) / step)
    cmd_y = np.where(far, (want_y - by) / DT, bvy + (want_y - by) / step)
    act[rows, 0] = cmd_x / V_MAX
    act[rows, 1] = cmd_y / V_MAX
    act[rows, 2] = (angle - o[rows, BAT_ANGLE]) / (DT * OMEGA_MAX)


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

    one = _Rows(mode, kd, km, bounce, spin_read, return_spin, return_land)

    def rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float64).reshape(len(obs), N_FEATURES)
        if len(o) <= _ONE_BY_ONE:  # a few observations: one at a time in Python floats (the same actions)
            act = np.array(one.rule(o.tolist()), dtype=np.float64).reshape(len(o), 3)
        else:
            act = _go_home(o, mode)
            dodge = _dodge(o, act)
            serve = np.flatnonzero((o[:, I_SERVE] > 0.5) & ~dodge)
            receive = np.flatnonzero(((o[:, INCOMING] > 0.5) | (o[:, MY_TURN] > 0.5)) & ~dodge)
            if serve.size + receive.size <= _PLANS_ONE_BY_ONE:  # a few strokes to plan: one at a time
                if serve.size:
                    act[serve] = one.serves(o[serve].tolist())
                for i, row in zip(receive.tolist(), o[receive].tolist(), strict=True):
                    a = one.receive(row)
                    if a is not None:
                        act[i] = a
            else:  # the serves and the returns planned together (a ball to meet: its return, not a serve)
                met, returns = _receive(o, receive, mode, kd, km, spin_read, return_spin, return_land)
                serving = np.zeros(len(o), dtype=bool)
                serving[serve] = True
                serving[met] = False
                serve = np.flatnonzero(serving)
                serves = _serve(o, serve, mode)
                if bounce and serve.size:
                    _swing(o, serve, *serves, kd, km, act, bounce=True)
                    serve, serves = serve[:0], tuple(a[:0] for a in serves)
                if serve.size or met.size:
                    _swing(o, np.concatenate([serve, met]),
                           *(np.concatenate(pair) for pair in zip(serves, returns, strict=True)), kd, km, act)
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


def _serve(o: np.ndarray, s: np.ndarray, mode: str) -> tuple[np.ndarray, ...]:
    """The serves of the tosses ``s`` (rows), as :func:`_swing`'s arguments from ``t_c`` to ``w_out``: the ball to
    send (by ``mode``; random choices a hash of the toss's place), struck as the toss falls through the chosen
    height."""
    px, py, _, vy, w = _ball(o)
    u1, u2, u3 = (_unit_hash(o[s, BALL_X], salt) for salt in (1, 2, 3))
    m = len(s)
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
    return t_c, px[s], hy, np.zeros(m), v - G * t_c, w[s], land, NET_H + clear, spin


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


def _receive(o: np.ndarray, r: np.ndarray, mode: str, kd: float, km: float, spin_read: float, return_spin: float,
             return_land: float) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """The returns of the incoming balls ``r`` (rows) that will bounce on the bot's half: those rows, and their
    strokes as :func:`_swing`'s arguments from ``t_c`` to ``w_out``: met where :func:`_predict_contact` says
    (reading ``spin_read`` of their spin), sent to ``return_land`` past the net, or in the randomized modes
    (practice) back at the pace they came."""
    px, py, vx, vy, w = _ball(o)
    f, t_c, cx, cy, cvx, cvy, cw = _predict_contact(px[r], py[r], vx[r], vy[r], w[r] * spin_read,
                                                    o[r, MY_TURN] > 0.5, kd, km)
    n = f.sum()
    land, over, spin = np.full(n, return_land), np.full(n, NET_H + 0.15), np.full(n, return_spin)
    if mode != "fixed":  # practice: the ball goes back at the pace it came (spin, mixed: with topspin)
        pace = np.clip((np.hypot(cvx[f], cvy[f]) - _PACE[0]) / (_PACE[1] - _PACE[0]), 0.0, 1.0)
        land = _MIRROR_LAND[0] + (_MIRROR_LAND[1] - _MIRROR_LAND[0]) * pace
        over = NET_H + _MIRROR_CLEAR[0] + (_MIRROR_CLEAR[1] - _MIRROR_CLEAR[0]) * pace
        if mode in ("spin", "mixed"):
            spin = -_MIRROR_TOPSPIN * pace
    return r[f], (t_c[f], cx[f], cy[f], cvx[f], cvy[f], cw[f], land, over, spin)


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
_ONE_BY_ONE = 8  # a call on at most this many observations: one at a time
_PLANS_ONE_BY_ONE = 48  # a call with at most this many strokes to plan (serves and returns): one at a time
_F32, _U32 = struct.Struct("=f"), struct.Struct("=I")
_TURN = DT * OMEGA_MAX
_STROKE_MAX = 0.8 * V_MAX
_LANDING_STEPS = int(1.6 / _PLAN_DT)
_HALF_DT2 = 0.5 * _PLAN_DT * _PLAN_DT
_DECAY = 1.0 - SPIN_DECAY * _PLAN_DT


def _unit_hash_one(x: float, salt: int) -> float:
    """:func:`_unit_hash` of one value."""
    try:
        bits = _U32.unpack(_F32.pack(x))[0]
    except OverflowError:  # beyond float32: numpy's cast gives inf
        return float(_unit_hash(np.array([x]), salt)[0])
    z = (bits * GOLDEN + salt) & MASK
    z ^= z >> 30
    z = (z * M1) & MASK
    z ^= z >> 27
    z = (z * M2) & MASK
    return ((z ^ (z >> 31)) >> 11) * UNIT


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


class _Rows:
    """The serve-bot's rule for a few observations, one at a time in Python floats (lists of 25 floats): the same
    actions as the arrays' path (see above)."""

    def __init__(self, mode: str, kd: float, km: float, bounce: bool, spin_read: float, return_spin: float,
                 return_land: float) -> None:
        self.mode, self.bounce = mode, bounce
        self.kd, self.km = float(kd), float(km)  # (a numpy float32 option would make float32 arithmetic here)
        self.spin_read, self.return_spin, self.return_land = float(spin_read), float(return_spin), float(return_land)

    def rule(self, rows: list[list[float]]) -> list[list[float]]:
        """The actions (before the clip to [-1, 1]) of the observations ``rows``, as ``rule`` would write them."""
        acts = [self.home(o) for o in rows]
        serving = [i for i, o in enumerate(rows) if o[I_SERVE] > 0.5]
        if serving:
            for i, a in zip(serving, self.serves([rows[i] for i in serving]), strict=True):
                acts[i] = a
        for i, o in enumerate(rows):
            dodge = self.dodge(o)
            if dodge is not None:
                acts[i] = dodge
            elif o[INCOMING] > 0.5 or o[MY_TURN] > 0.5:
                a = self.receive(o)
                if a is not None:
                    acts[i] = a
        return acts

    def home(self, o: list[float]) -> list[float]:
        """:func:`_go_home` of one observation."""
        home_x, home_y, home_a = HOME_X, HOME_Y, 0.0
        if self.mode != "fixed" and o[THEY_SERVE] > 0.5:
            (lx, hx), (ly, hy), (la, ha) = _WAIT
            bx = o[BALL_X]
            home_x = lx + (hx - lx) * _unit_hash_one(bx, 4)
            home_y = ly + (hy - ly) * _unit_hash_one(bx, 5)
            home_a = la + (ha - la) * _unit_hash_one(bx, 6)
        return [clip_one((home_x - o[BAT_X]) * 4.0, -2.0, 2.0) / V_MAX,
                clip_one((home_y - o[BAT_Y]) * 4.0, -2.0, 2.0) / V_MAX, (home_a - o[BAT_ANGLE]) / _TURN]

    def serves(self, rows: list[list[float]]) -> list[list[float]]:
        """:func:`_serve` of the tossing observations ``rows`` (a bounce serve's launch planned for all at once)."""
        plans = []
        for o in rows:
            px, py, vy, w = o[BALL_X], o[BALL_Y], o[BALL_VY] * VEL_SCALE, o[BALL_SPIN] * SPIN_SCALE
            u1, u2, u3 = (_unit_hash_one(px, salt) for salt in (1, 2, 3))
            if self.mode == "fixed":
                land, clear, spin, height = 0.8, 0.12, 0.0, 0.3
            else:
                spun = _unit_hash_one(px, 7) < 0.5 if self.mode == "mixed" else self.mode == "spin"
                land = 0.45 + 0.5 * u1 if spun else 0.35 + 0.65 * u1
                clear = 0.10 + 0.10 * u2 if spun else 0.04 + 0.26 * u2
                spin = (2 * u3 - 1) * 120.0 if spun else 0.0
                height = 0.3 if spun else 0.22 + 0.2 * u3
            y, v = py, vy
            disc = v * v + 2 * G * (y - height)
            if disc >= 0:
                t_c, hy = (v + math.sqrt(max_one(disc, 0.0))) / G, height
            else:
                t_c = max_one(v, 0.0) / G
                hy = y + v * t_c - 0.5 * G * t_c * t_c
            plans.append((t_c, px, hy, 0.0, v - G * t_c, w, land, NET_H + clear, spin))
        launches: list[Any] = [None] * len(rows)
        if self.bounce:
            t_c, px, hy, vin_x, vin_y, w_in, land, over, spin = (np.array(v) for v in zip(*plans, strict=True))
            vx, vy = plan_bounce_serve(px, hy, spin, land, over, vin_x, vin_y, w_in, self.kd, self.km)
            launches = list(zip(vx.tolist(), vy.tolist(), strict=True))
        return [self.swing(o, *plan, launch=launch) for o, plan, launch in zip(rows, plans, launches, strict=True)]

    def dodge(self, o: list[float]) -> list[float] | None:
        """:func:`_dodge` of one observation: its actions, or None."""
        py = o[BALL_Y]
        if o[INCOMING] > 0.5 and o[BALL_X] < -TABLE_HALF and o[BALL_VX] * VEL_SCALE < 0.0:
            return [0.0, 1.0 if o[BAT_Y] > py else -1.0, -o[BAT_ANGLE] / _TURN]
        return None

    def receive(self, o: list[float]) -> list[float] | None:
        """:func:`_receive` of one observation: its actions, or None (the ball will not bounce on its half)."""
        met = _predict_contact_one(o[BALL_X], o[BALL_Y], o[BALL_VX] * VEL_SCALE, o[BALL_VY] * VEL_SCALE,
                                   o[BALL_SPIN] * SPIN_SCALE * self.spin_read, o[MY_TURN] > 0.5, self.kd, self.km)
        if met is None:
            return None
        t_c, cx, cy, cvx, cvy, cw = met
        land, over, spin = self.return_land, NET_H + 0.15, self.return_spin
        if self.mode != "fixed":
            pace = clip_one((float(np.hypot(cvx, cvy)) - _PACE[0]) / (_PACE[1] - _PACE[0]), 0.0, 1.0)
            land = _MIRROR_LAND[0] + (_MIRROR_LAND[1] - _MIRROR_LAND[0]) * pace
            over = NET_H + _MIRROR_CLEAR[0] + (_MIRROR_CLEAR[1] - _MIRROR_CLEAR[0]) * pace
            if self.mode in ("spin", "mixed"):
                spin = -_MIRROR_TOPSPIN * pace
        return self.swing(o, t_c, cx, cy, cvx, cvy, cw, land, over, spin)

    def swing(self, o: list[float], t_c: float, px: float, py: float, vin_x: float, vin_y: float, w_in: float,
              land_x: float, over_y: float, w_out: float, launch: tuple[float, float] | None = None) -> list[float]:
        """:func:`_swing` of one observation (``launch``: a bounce serve's, planned)."""
        kd, km = self.kd, self.km
        stroke = None
        if launch is not None:
            vx, vy = launch
        else:
            line_y = py + (BALL_R - py) * (-px) / max_one(land_x - px, 1e-3)
            over_y = max_one(over_y, line_y + 0.05)
            vx, vy = _plan_launch_one(px, py, w_out, land_x, over_y, kd, km)
            for _ in range(2):
                stroke = _solve_stroke_one(vin_x, vin_y, w_in, vx, vy, w_out)
                if not max_one(abs(stroke[2]), abs(stroke[3])) > _STROKE_MAX:
                    break
                stroke = None
                over_y += 0.1
                vx, vy = _plan_launch_one(px, py, w_out, land_x, over_y, kd, km)
        nx, ny, bvx, bvy = stroke or _solve_stroke_one(vin_x, vin_y, w_in, vx, vy, w_out)
        angle = float(np.arctan2(ny, nx))
        if angle > ANGLE_MAX:
            angle = angle - math.pi
        elif angle < -ANGLE_MAX:
            angle = angle + math.pi
        cx, cy = px - (BALL_R + _GAP) * nx, py - (BALL_R + _GAP) * ny
        bx, by = o[BAT_X], o[BAT_Y]
        if t_c > _SWING:
            cmd_x, cmd_y = (cx - bvx * _SWING - bx) / DT, (cy - bvy * _SWING - by) / DT
        else:
            step = max_one(t_c, DT)
            cmd_x, cmd_y = bvx + (cx - bvx * t_c - bx) / step, bvy + (cy - bvy * t_c - by) / step
        return [cmd_x / V_MAX, cmd_y / V_MAX, (angle - o[BAT_ANGLE]) / _TURN]


serve_bot_rule = serve_bot_rule_for()


def serve_bot_for(cfg: TennisConfig):
    """The serve-bot's rule for a game's options (its ``serve_mode``, the air's forces, discrete actions)."""
    return serve_bot_rule_for(cfg.serve_mode, cfg.drag, cfg.magnus, cfg.discrete, bounce=cfg.serve_bounce)
