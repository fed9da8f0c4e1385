"""One tennis game in plain Python floats: the batched core's rules, numbers and randomness
(:mod:`selfplay_cli.envs.tennis.core`), for the PettingZoo view, which plays one game at a time.

numpy pays about a microsecond an operation whatever the size of its arrays, so the core's step for one game (a few
hundred operations: the bats, 4 substeps of flight and contact tests, the rules) spends its time in overhead; here
a step is a few hundred float operations. It is the core's step transcribed for one game, and it must stay so: the
tests play both side by side and compare every observation, reward, score and state bit for bit. What makes that
hold:

- every value is an IEEE double computed with the same operations in the same order as the core's float64 arrays
  (a sum or a product is the same number in Python); numpy's clip, maximum and minimum are
  :func:`~.physics.clip_one`, :func:`~.physics.max_one`, :func:`~.physics.min_one`; ``math.sqrt`` is correctly
  rounded as ``np.sqrt`` is; the bats' cos and sin are numpy's own, called on the numbers;
- options enter the arithmetic as the core's expressions make them (``float()`` of the same expression: an option
  given as a numpy float32 makes float32 numbers there too);
- the randomness is the same counter-based SplitMix64 hash, in Python integers (:mod:`selfplay_cli.envs.rng`'s
  ``*_int`` functions);
- observations are built as the core builds them (float64, clipped to the bounds, then float32), from the same
  numbers; rewards are the core's float32 rewards.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..rng import game_key_int, uniform_int
from .config import (
    ANGLE_MAX,
    BALL_R,
    BAT_0,
    DOUBLE_BOUNCE,
    DOUBLE_HIT,
    DT,
    E_BAT,
    E_TABLE,
    FLOOR_Y,
    HIT_COOLDOWN,
    HIT_OUT,
    HOME_X,
    HOME_Y,
    INTO_NET,
    K_DRAG,
    K_MAGNUS,
    LIVE_OPTIONS,
    MISSED_SERVE,
    MU_BAT,
    MU_TABLE,
    N_FEATURES,
    NET,
    NET_GAP,
    NET_H,
    NO_POINT,
    NONE,
    NOT_RETURNED,
    OBS_HIGH,
    OBS_LOW,
    OMEGA_MAX,
    OUT,
    OWN_HALF,
    SERVE_NO_BOUNCE,
    SPIN_DECAY,
    SPIN_SCALE,
    SUBSTEPS,
    TABLE_0,
    TABLE_HALF,
    TOSS_VY,
    TOSS_X,
    TOSS_Y,
    V_MAX,
    VEL_SCALE,
    VOLLEY,
    X_BACK,
    X_OUT,
    Y_HIGH,
    Y_LOW,
    G,
    H,
    TennisConfig,
)
from .core import TennisCore
from .physics import clip_one, contact_one, max_one, min_one

_NEVER = 1e9  # time since the last hit, before any (the core's)
_PER_DT = 1.0 / DT
_TILT, _MOVE = OMEGA_MAX * DT, V_MAX * DT
_SPIN_KEEP = 1.0 - SPIN_DECAY * H
_FRACTIONS = tuple((k / SUBSTEPS, (k + 1) / SUBSTEPS) for k in range(SUBSTEPS))
_VS, _RATE, _SPIN = 1.0 / VEL_SCALE, 1.0 / OMEGA_MAX, 1.0 / SPIN_SCALE
_LOW64, _HIGH64 = OBS_LOW.astype(np.float64), OBS_HIGH.astype(np.float64)
_OFFSET = BALL_R + 1e-4  # a struck ball is put this far off the bat's face
_cos, _sin = np.cos, np.sin


class ScalarTennis:
    """One game of tennis with the core's rules (see :mod:`selfplay_cli.envs.tennis`). Seat 0 plays from the -x end.

    ``step(a0, a1)`` returns the two seats' rewards (the core's float32 values, as Python floats); ``observe()``
    the two seats' observations ``(2, 25)`` float32 (a new array). The state is in plain attributes named as the
    core's arrays (``ball`` and the two ``bats`` are lists: x, y, vx, vy, spin; x, y, vx, vy, angle, rate; the
    per-seat records are pairs); :meth:`get_state` / :meth:`set_state` speak the core's format for one game, and
    :meth:`set_options` changes the live options as the core's does.
    """

    __slots__ = ("config", "discrete", "ball", "bats", "score", "steps", "terminated", "truncated", "over", "key",
                 "first_server", "server", "tossing", "hitter", "landed", "serve_shot", "serve_bounced", "since_hit",
                 "clock", "surface", "reason", "winner", "serves", "serves_in", "returns", "returns_in", "half",
                 "_kd", "_km", "_reach", "_half", "_length", "_late", "_serve_time", "_hit", "_return", "_point",
                 "_to_win", "_max_steps", "_jitter", "_bounce", "_trig", "_rewards", "_point_over")

    def __init__(self, config: TennisConfig | None = None) -> None:
        self.config = config or TennisConfig()
        self.discrete = self.config.discrete
        self._apply_config()
        self.reset(0)

    def _apply_config(self) -> None:
        """The options as the core's arithmetic uses them (its expressions, as floats)."""
        cfg = self.config
        half = 0.5 * cfg.bat_length
        self.half = half
        self._half = float(half)
        self._reach = float(half + 0.5 * BALL_R)
        self._length = float(2.0 * half)
        self._kd, self._km = float(K_DRAG * cfg.drag), float(K_MAGNUS * cfg.magnus)
        self._late = float(cfg.serve_time - 1e-9)
        self._serve_time = float(cfg.serve_time)
        self._hit, self._return, self._point = float(cfg.hit_reward), float(cfg.return_reward), float(cfg.point_reward)
        self._to_win, self._max_steps = cfg.points_to_win, cfg.max_steps
        self._jitter, self._bounce = float(cfg.toss_jitter), bool(cfg.serve_bounce)

    def set_options(self, **values: Any) -> None:
        """:meth:`TennisCore.set_options` of this game."""
        other = sorted(set(values) - set(LIVE_OPTIONS))
        if other:
            raise ValueError(f"set_options changes only {', '.join(LIVE_OPTIONS)}, not {', '.join(other)}")
        self.config = replace(self.config, **values)
        self._apply_config()

    # ----------------------------------------------------------------------------------------------------
    def reset(self, seed: int) -> None:
        """A new game with the given seed (the core's game of that seed)."""
        if not -(2**63) <= int(seed) < 2**63:
            raise OverflowError(f"a tennis seed must fit in 64 signed bits, not {seed}")
        self.key = game_key_int(seed)
        self.first_server = 1 if uniform_int(self.key, 0) >= 0.5 else 0
        self.score = [0.0, 0.0]
        self.steps = 0
        self.terminated = self.truncated = self.over = False
        self.reason, self.winner, self.surface = NO_POINT, -1, NONE
        self.serves, self.serves_in, self.returns, self.returns_in = [0, 0], [0, 0], [0, 0], [0, 0]
        self._trig = [None, None]
        self._new_point()

    def _new_point(self) -> None:
        points = int(self.score[0] + self.score[1])
        deuce = 2 * (self._to_win - 1)
        turn = points // 2 if points < deuce else deuce // 2 + (points - deuce)
        server = self.server = self.first_server if turn % 2 == 0 else 1 - self.first_server
        u = uniform_int(self.key, 1 + points)
        forward = 1.0 if server == 0 else -1.0
        self.ball = [forward * (TOSS_X + (2.0 * u - 1.0) * self._jitter), TOSS_Y, 0.0, TOSS_VY, 0.0]
        self.bats = [[HOME_X, HOME_Y, 0.0, 0.0, 0.0, 0.0], [-1.0 * HOME_X, HOME_Y, 0.0, 0.0, 0.0, 0.0]]
        self.tossing = True
        self.hitter = -1
        self.landed = self.serve_shot = self.serve_bounced = False
        self.since_hit = _NEVER
        self.clock = 0.0

    @property
    def turn(self) -> int:
        """The seat that must hit the ball next (the server while the toss is in the air)."""
        return self.server if self.tossing else 1 - self.hitter

    # ----------------------------------------------------------------------------------------------------
    def _trig_of(self, seat: int, angle: float) -> tuple[float, float]:
        """cos and sin of a bat's angle (numpy's), kept for the angle the bat keeps into the next step."""
        kept = self._trig[seat]
        if kept is not None and kept[0] is angle:
            return kept[1], kept[2]
        c, s = float(_cos(angle)), float(_sin(angle))
        self._trig[seat] = (angle, c, s)
        return c, s

    def step(self, a0: Any, a1: Any) -> tuple[float, float]:
        """One step with each seat's action (3 floats in [-1, 1], or 3 of 0, 1, 2 with ``discrete``), checked by
        the caller; returns the two rewards."""
        running = not self.over
        self._rewards = [0.0, 0.0]
        self._point_over = False
        motion = []
        for seat, act in ((0, a0), (1, a1)):
            if self.discrete:
                u, v, r = (float(a) - 1.0 for a in act)
            else:
                u, v, r = (clip_one(float(a), -1.0, 1.0) for a in act)
            sig = 1.0 if seat == 0 else -1.0
            bat = self.bats[seat]
            x0, y0, ang0 = bat[0], bat[1], bat[4]
            ang1 = clip_one(ang0 + r * _TILT, -ANGLE_MAX, ANGLE_MAX)
            cos1, sin1 = float(_cos(ang1)), float(_sin(ang1))
            ego = min_one(max_one(sig * x0 + u * _MOVE, -X_BACK), -(NET_GAP + self._half * abs(sin1)))
            x1 = sig * ego
            y1 = clip_one(y0 + v * _MOVE, Y_LOW, Y_HIGH)
            if running:
                bat[0], bat[1], bat[4] = x1, y1, ang1
                bat[2] = clip_one((x1 - x0) * _PER_DT, -V_MAX, V_MAX)
                bat[3] = clip_one((y1 - y0) * _PER_DT, -V_MAX, V_MAX)
                bat[5] = (ang1 - ang0) * _PER_DT
            else:
                x1, y1, ang1 = x0, y0, ang0
                cos1, sin1 = self._trig_of(seat, ang0)
            cos0, sin0 = self._trig_of(seat, ang0)
            self._trig[seat] = (ang1, cos1, sin1)
            motion.append((sig, x0, y0, x1 - x0, y1 - y0, cos0, sin0, cos1 - cos0, sin1 - sin0))
        live = running
        for fa, fb in _FRACTIONS:
            if live:
                self._substep(fa, fb, motion)
                live = not self._point_over
            else:
                self.since_hit += H
        # The serve clock
        if self.tossing and live:
            self.clock += DT
            if self.clock >= self._late:
                self._award(1 - self.server, MISSED_SERVE)
        rewards = self._rewards
        if self._point_over:
            w = self.winner
            self.score[w] += 1.0
            rewards[w] += self._point
            rewards[1 - w] -= self._point
            a, b = self.score[w], self.score[1 - w]
            if a >= self._to_win and a - b >= 2:
                self.terminated = True
            else:
                self._new_point()
        if running:
            self.steps += 1
        self.truncated = self.steps >= self._max_steps and running and not self.terminated
        self.terminated = self.terminated and running
        self.over = self.over or self.terminated or self.truncated
        return float(np.float32(rewards[0])), float(np.float32(rewards[1]))

    def _substep(self, fa: float, fb: float, motion: list) -> None:
        """One physics substep of the ball in play: flight, then the bats, net, table and the room."""
        b = self.ball
        px, py, vx, vy, w = b
        kd, km = self._kd, self._km
        speed = math.sqrt(vx * vx + vy * vy)
        ax = -kd * speed * vx - km * w * vy
        ay = -G - kd * speed * vy + km * w * vx
        nvx, nvy = vx + ax * H, vy + ay * H
        bx, by = px + nvx * H, py + nvy * H
        b[0], b[1], b[2], b[3], b[4] = bx, by, nvx, nvy, w * _SPIN_KEEP
        self.since_hit += H
        # --- bats: the ball's path against each bat's line, the bat moving and turning through the substep
        near = []
        for seat, (sig, x0, y0, dx, dy, cos0, sin0, dcos, dsin) in enumerate(motion):
            cxa, cya, cxb, cyb = x0 + dx * fa, y0 + dy * fa, x0 + dx * fb, y0 + dy * fb
            ca, sa, cb, sb = cos0 + dcos * fa, sin0 + dsin * fa, cos0 + dcos * fb, sin0 + dsin * fb
            d0 = (px - cxa) * (sig * ca) + (py - cya) * sa
            d1 = (bx - cxb) * (sig * cb) + (by - cyb) * sb
            side = 1.0 if d0 >= 0.0 else -1.0
            if side * d1 < BALL_R:
                near.append((seat, sig, side, d0, d1, cxa, cya, cxb, cyb, cb, sb))
        if near and self._bats(near, px, py):
            return
        # --- net, table, room (what a bat did not just touch)
        if by < NET_H + BALL_R:
            crossed = (px < 0.0) != (bx < 0.0)
            if crossed or abs(bx) < BALL_R:
                if crossed:
                    f = clip_one(px / (px - bx), 0.0, 1.0)
                    y_at = py + f * (by - py)
                else:
                    y_at = by
                if y_at >= 0.0:  # below the table's surface the ball was already dead
                    b[0] = 0.0
                    self.surface = NET
                    self._ended_by(INTO_NET)
                    return
        if by < BALL_R and py >= BALL_R and b[3] < 0.0 and abs(bx) <= TABLE_HALF:
            b[2], b[3], b[4] = contact_one(b[2], b[3], b[4], 0.0, 1.0, 0.0, 0.0, E_TABLE, MU_TABLE)
            b[1] = max_one(2.0 * BALL_R - by, BALL_R)
            half = 1 if bx >= 0.0 else 0
            self.surface = TABLE_0 + half
            self._table(half)
            return
        if by <= FLOOR_Y + BALL_R or abs(bx) > X_OUT or (by < 0.0 and abs(bx) < TABLE_HALF):
            self.surface = OUT
            self._ended_by(HIT_OUT)

    def _bats(self, near: list, px: float, py: float) -> bool:
        """Resolve the bat contacts among the candidates ``near`` (seat 0's first); whether a bat hit the ball."""
        b = self.ball
        for seat, sig, s, d0, d1, cxa, cya, cxb, cyb, cb, sb in near:
            sd0, sd1 = s * d0, s * d1
            f = clip_one((sd0 - BALL_R) / max_one(sd0 - sd1, 1e-12) if sd0 > BALL_R else 1.0, 0.0, 1.0)
            norm = math.sqrt(cb * cb + sb * sb)
            inv = 1.0 / norm if norm else float(np.float64(1.0) / np.float64(norm))
            nx, ny = sig * cb * inv, sb * inv  # the face normal at the substep's end
            tx, ty = -ny, nx
            cx = cxa + f * (cxb - cxa)
            cy = cya + f * (cyb - cya)
            qx = px + f * (b[0] - px)
            qy = py + f * (b[1] - py)
            tau = (qx - cx) * tx + (qy - cy) * ty
            bat = self.bats[seat]
            omega = sig * bat[5]  # the face's turn rate in the world
            cvx = bat[2] - omega * tau * nx  # the contact point's velocity
            cvy = bat[3] - omega * tau * ny
            if not (abs(tau) <= self._reach and s * ((b[2] - cvx) * nx + (b[3] - cvy) * ny) < 0.0):
                continue
            b[2], b[3], b[4] = contact_one(b[2], b[3], b[4], s * nx, s * ny, cvx, cvy, E_BAT, MU_BAT)
            tau = clip_one(tau, -self._half, self._half)
            b[0] = cxb + tau * tx + s * nx * _OFFSET
            b[1] = cyb + tau * ty + s * ny * _OFFSET
            self._bat(seat)
            return True
        return False

    # ----------------------------------------------------------------------------------------------------
    # The rules (the core's, for one game)
    def _award(self, winner: int, reason: int) -> None:
        self.winner = winner
        self.reason = reason
        self._point_over = True

    def _legal_hit(self, seat: int, serve: bool) -> None:
        self.hitter = seat
        self.landed = False
        self.serve_shot = serve
        self.serve_bounced = False
        self.since_hit = 0.0
        self.tossing = False
        (self.serves if serve else self.returns)[seat] += 1
        if self._hit:
            self._rewards[seat] += self._hit

    def _bat(self, seat: int) -> None:
        hitter, toss, landed = self.hitter, self.tossing, self.landed
        same = hitter == seat
        stroke = same and not toss and self.since_hit < HIT_COOLDOWN  # the same stroke still: physics only
        if not stroke:
            self.surface = BAT_0 + seat
        if toss:
            if seat == self.server:
                self._legal_hit(seat, True)
            else:
                self._award(self.server, VOLLEY)
        elif not stroke:
            if same:
                if landed:
                    self._award(seat, NOT_RETURNED)
                else:
                    self._award(1 - seat, DOUBLE_HIT)
            elif landed:
                self._legal_hit(seat, False)
            else:
                self._award(hitter, VOLLEY)

    def _table(self, half: int) -> None:
        h = self.hitter
        if self.tossing:
            self._award(1 - self.server, MISSED_SERVE)
            return
        if self._bounce and self.serve_shot and not self.serve_bounced:  # a serve's first bounce: the own half
            if half == h:
                self.serve_bounced = True
            else:
                self._award(1 - h, SERVE_NO_BOUNCE)
            return
        if self.landed:
            self._award(h, DOUBLE_BOUNCE if half != h else NOT_RETURNED)
        elif half != h:
            self.landed = True
            if self.serve_shot:
                self.serves_in[h] += 1
            else:
                self.returns_in[h] += 1
            if self._return:  # the stroke landed on the opponent's half (practice)
                self._rewards[h] += self._return
        else:
            self._award(1 - h, OWN_HALF)

    def _ended_by(self, fault: int) -> None:
        if self.tossing:
            self._award(1 - self.server, MISSED_SERVE)
        elif self.landed:
            self._award(self.hitter, NOT_RETURNED)
        else:
            self._award(1 - self.hitter, fault)

    # ----------------------------------------------------------------------------------------------------
    def observe(self) -> np.ndarray:
        """Each seat's 25 egocentric values ``(2, 25)`` float32, clipped to the declared bounds (the core's)."""
        bx, by, bvx, bvy, bw = self.ball
        tossing, hitter, landed = self.tossing, self.hitter, self.landed
        left = 1.0 - self.clock / self._serve_time if tossing else 0.0
        values = []
        for me in (0, 1):
            sig = 1.0 if me == 0 else -1.0
            mine_bat, other = self.bats[me], self.bats[1 - me]
            play = not tossing
            mine = play and hitter == me
            theirs = play and hitter == 1 - me
            toss = tossing and self.server == me
            values += (sig * mine_bat[0], mine_bat[1], sig * mine_bat[2] * _VS, mine_bat[3] * _VS, mine_bat[4],
                       mine_bat[5] * _RATE,
                       sig * other[0], other[1], sig * other[2] * _VS, other[3] * _VS, other[4], other[5] * _RATE,
                       sig * bx, by, sig * bvx * _VS, bvy * _VS, sig * bw * _SPIN,
                       theirs and not landed, theirs and landed, mine and not landed, mine and landed,
                       toss, tossing and not toss, left, self._length)
        obs = np.array(values, dtype=np.float64).reshape(2, N_FEATURES)
        np.clip(obs, _LOW64, _HIGH64, out=obs)
        return obs.astype(np.float32)

    # ----------------------------------------------------------------------------------------------------
    _PAIRS = ("score", "serves", "serves_in", "returns", "returns_in")
    _INT8 = ("first_server", "server", "hitter", "surface", "reason", "winner")
    _FLAGS = ("terminated", "truncated", "over", "tossing", "landed", "serve_shot", "serve_bounced")

    def get_state(self) -> dict[str, np.ndarray]:
        """The game's exact state in :meth:`TennisCore.get_state`'s format for one game."""
        state = {"ball": np.array(self.ball).reshape(5, 1), "bat": np.array(self.bats).T.reshape(6, 2, 1),
                 "steps": np.array([self.steps], dtype=np.int64), "key": np.array([self.key], dtype=np.uint64),
                 "since_hit": np.array([self.since_hit]), "clock": np.array([self.clock])}
        for name in self._PAIRS:
            state[name] = np.array(getattr(self, name), dtype=np.float64 if name == "score" else np.int64)[:, None]
        for name in self._INT8:
            state[name] = np.array([getattr(self, name)], dtype=np.int8)
        for name in self._FLAGS:
            state[name] = np.array([getattr(self, name)], dtype=bool)
        return {name: state[name] for name in TennisCore._STATE}

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state of :meth:`get_state`'s format (from this class or a one-game slice of the core's)."""
        self.ball = [float(v) for v in np.asarray(state["ball"], dtype=np.float64).reshape(5)]
        bat = np.asarray(state["bat"], dtype=np.float64).reshape(6, 2)
        self.bats = [[float(v) for v in bat[:, 0]], [float(v) for v in bat[:, 1]]]
        self.steps = int(np.asarray(state["steps"]).reshape(-1)[0])
        self.key = int(np.asarray(state["key"], dtype=np.uint64).reshape(-1)[0])
        self.since_hit = float(np.asarray(state["since_hit"]).reshape(-1)[0])
        self.clock = float(np.asarray(state["clock"]).reshape(-1)[0])
        for name in self._PAIRS:
            cast = float if name == "score" else int
            setattr(self, name, [cast(v) for v in np.asarray(state[name]).reshape(2)])
        for name in self._INT8:
            setattr(self, name, int(np.asarray(state[name]).reshape(-1)[0]))
        for name in self._FLAGS:
            setattr(self, name, bool(np.asarray(state[name]).reshape(-1)[0]))
        self._trig = [None, None]
