"""The tennis game's scripted player, ``serve-bot``: it plans with the game's own physics (:mod:`.physics`)."""

from __future__ import annotations

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
    HOME_X,
    HOME_Y,
    I_SERVE,
    INCOMING,
    K_DRAG,
    K_MAGNUS,
    MY_TURN,
    N_FEATURES,
    NET_H,
    OMEGA_MAX,
    SERVE_MODES,
    SPIN_SCALE,
    TABLE_HALF,
    THEY_SERVE,
    V_MAX,
    VEL_SCALE,
    G,
    TennisConfig,
)
from .flight import (
    _predict_contact,
    plan_bounce_serve,
    plan_launch_arrays,
    solve_stroke,
)
from .flight_one import _STROKE_MAX, _TURN, _plan_launch_one, _predict_contact_one, _solve_stroke_one
from .physics import clip_one, max_one

_SWING = 0.08  # s: the stroke's length before the contact
_GAP = 0.003  # at the planned instant the bat's face is this far short of the ball (it touches just before)
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


def plan_launch(x0: np.ndarray, y0: np.ndarray, w: np.ndarray, land_x: np.ndarray, over_y: np.ndarray,
                kd: float = K_DRAG, km: float = K_MAGNUS, iterations: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """:func:`.flight.plan_launch_arrays`, one ball at a time in Python floats when there are a few (the same
    numbers: :func:`.flight_one._plan_launch_one`)."""
    x0, y0, w = (np.asarray(a, dtype=np.float64) for a in (x0, y0, w))
    land_x, over_y = np.asarray(land_x, dtype=np.float64), np.asarray(over_y, dtype=np.float64)
    if max(a.size for a in (x0, y0, w, land_x, over_y)) <= _ONE_BY_ONE:
        args = np.broadcast_arrays(x0, y0, w, land_x, over_y)
        planned = [_plan_launch_one(*row, float(kd), float(km), iterations)
                   for row in zip(*(a.reshape(-1).tolist() for a in args), strict=True)]
        vx, vy = (np.array([p[i] for p in planned], dtype=np.float64).reshape(args[0].shape) for i in (0, 1))
        return vx, vy
    return plan_launch_arrays(x0, y0, w, land_x, over_y, kd, km, iterations)


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




# How many observations, and strokes to plan, a call takes one at a time (:mod:`.flight_one`), and arrays beyond.
_ONE_BY_ONE = 8  # a call on at most this many observations: one at a time
_PLANS_ONE_BY_ONE = 48  # a call with at most this many strokes to plan (serves and returns): one at a time
_F32, _U32 = struct.Struct("=f"), struct.Struct("=I")


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
