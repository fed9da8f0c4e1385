"""The tennis serve-bot's planner, on arrays of balls: the flights it predicts with the game's own physics
(:mod:`.physics`), the contact it aims for, and the stroke (bat normal and velocity) that sends the ball it wants.
:mod:`.flight_one` is the same planner for one ball in Python floats; :mod:`.bots` the rule that uses both."""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from .config import (
    BALL_R,
    E_BAT,
    E_TABLE,
    FLOOR_Y,
    K_DRAG,
    K_MAGNUS,
    MU_BAT,
    MU_TABLE,
    NET_H,
    SPIN_DECAY,
    SPIN_GAIN,
    STICK,
    TABLE_HALF,
    V_MAX,
    G,
)
from .physics import contact

# serve-bot plans with the game's own physics, in its egocentric frame (own end at -x, net at 0): it predicts where
# it will meet the ball, chooses the ball it wants to send (landing x, height over the net, spin), integrates the
# flight to correct its aim for drag and Magnus, and solves the contact model backwards for the bat's normal and
# velocity that produce that ball from the incoming one. It then brings its bat, tilted, to a point behind the
# contact (along the stroke) and swings through the contact point at that velocity.
_PLAN_DT = 0.02
_HALF_DT2 = 0.5 * _PLAN_DT * _PLAN_DT
_DECAY = 1.0 - SPIN_DECAY * _PLAN_DT
_REACH_X = -2.5  # the farthest back the bot meets a ball
_REACH_Y = 1.2  # the highest it meets a ball (its bat reaches 1.6 m): a higher bounce it meets coming down


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


def plan_launch_arrays(x0: np.ndarray, y0: np.ndarray, w: np.ndarray, land_x: np.ndarray, over_y: np.ndarray,
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
