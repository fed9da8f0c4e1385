"""One Pong game in plain Python floats: the same rules, numbers and randomness as the batched core
(:mod:`selfplay_cli.envs.pong.core`), for the PettingZoo view, which plays one game at a time.

numpy pays ~1 us per operation whatever the size of the array, so a batch of one spends its time in overhead; here
a step is a few dozen float operations. It is the core's step transcribed line by line, and it must stay so: the
tests play both side by side and compare every observation, reward and score bit for bit. What makes that hold:

- every value is an IEEE double computed with the same operations in the same order as the core's float64 arrays;
  the transcendental functions of a paddle hit (hypot, arctan2, cos, sin) are numpy's own, called on the scalar;
- the serve's randomness is the same counter-based SplitMix64 hash, in Python integers masked to 64 bits
  (:mod:`selfplay_cli.envs.rng`'s ``*_int`` functions);
- observations are float32 like the core's: ``f32(f32(x * scale) - offset)``. ``struct``'s ``f`` format rounds a
  double to the nearest float32 (as numpy's cast does), and the subtraction done in double and then rounded gives
  the float32 subtraction's result (a double has more than 2 x 24 + 2 bits, so the double rounding is harmless).
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np

from ..rng import game_key_int, uniform_int
from .config import (
    BALL_R,
    HEIGHT,
    LEFT_FACE,
    N_FEATURES,
    PADDLE_H,
    PADDLE_W,
    PADDLE_X,
    PADDLE_Y_MAX,
    RIGHT_FACE,
    SERVE_SPEED,
    WIDTH,
    PongConfig,
)

_MOVE = (0.0, -8.0, 8.0)  # stay, up, down (PADDLE_SPEED 8)

_F6 = struct.Struct("6f")
_F12 = struct.Struct("12f")
_FRAME_BYTES = 2 * N_FEATURES * 4  # both seats' frames, float32

_hypot, _arctan2, _cos, _sin = np.hypot, np.arctan2, np.cos, np.sin


class ScalarPong:
    """One game of Pong with the core's rules (see :mod:`selfplay_cli.envs.pong`). Seat 0 is the left paddle.

    ``step(a0, a1)`` returns the two rewards; ``observe()`` the two seats' stacked observations ``(k, 6)``
    float32 (new arrays); the state is in plain attributes (``bx``, ``by``, ``vx``, ``vy``, ``p0``, ``p1``, scores
    ``s0``/``s1``, ...) and :meth:`get_state` / :meth:`set_state` speak the core's format for one game.
    """

    __slots__ = ("config", "k", "bx", "by", "vx", "vy", "p0", "p1", "s0", "s1", "t0", "t1", "hits0", "hits1",
                 "rally_steps", "steps", "serves", "key", "drawn_rallies", "terminated", "truncated", "_seed_rules",
                 "_max_angle", "_max_deflect", "_speedup", "_max_speed", "_r_hit", "_to_win", "_max_rally",
                 "_max_steps", "_sx", "_sy", "_sp", "_sv", "_buf", "_ring", "_head")

    def __init__(self, config: PongConfig | None = None) -> None:
        cfg = self.config = config or PongConfig()
        self.k = cfg.frame_stack
        self._seed_rules = cfg.rules == "seed"
        self._max_angle = float(np.radians(cfg.max_bounce_deg))
        self._max_deflect = float(np.radians(cfg.max_deflect_deg))
        self._speedup, self._max_speed = float(cfg.speedup), float(cfg.max_speed)
        self._r_hit = float(np.float32(cfg.r_for_hit)) if cfg.r_for_hit else 0.0
        self._to_win, self._max_rally, self._max_steps = cfg.points_to_win, cfg.max_rally_steps, cfg.max_steps
        self._sx, self._sy, self._sp = 2 / WIDTH, 2 / HEIGHT, 2 / PADDLE_Y_MAX
        self._sv = 1.0 / cfg.velocity_scale
        # The last k frames of both seats in a ring kept twice over, as the core keeps them: ring position i and
        # i + k hold the same frame, so the k newest (oldest first) are positions head + 1 .. head + k.
        self._buf = bytearray(2 * self.k * _FRAME_BYTES)
        self._ring = np.frombuffer(self._buf, dtype=np.float32).reshape(2 * self.k, 2, N_FEATURES)
        self._head = 0
        self.reset(0)

    # ----------------------------------------------------------------------------------------------------
    def reset(self, seed: int) -> None:
        if not -(2**63) <= int(seed) < 2**63:
            raise OverflowError(f"a pong seed must fit in 64 signed bits, not {seed}")
        self.key = game_key_int(seed)
        self.s0 = self.s1 = 0.0
        self.hits0 = self.hits1 = 0
        self.drawn_rallies = self.steps = self.serves = 0
        self.terminated = self.truncated = False
        self._serve()
        self._head = 0
        frame = self._frame()
        for p in range(2 * self.k):
            _F12.pack_into(self._buf, p * _FRAME_BYTES, *frame)

    def _serve(self) -> None:
        base = self.serves * 4
        key = self.key
        u0, u1, u2, u3 = (uniform_int(key, base + i) for i in range(4))
        p0 = float(int(u0 * (PADDLE_Y_MAX + 1)))  # floor of a non-negative number
        p1 = float(int(u1 * (PADDLE_Y_MAX + 1)))
        to_left = u2 < 0.5
        target_y = (p0 if to_left else p1) + u3 * PADDLE_H
        dx = (PADDLE_X + PADDLE_W // 2 - WIDTH // 2) if to_left else (WIDTH - PADDLE_X - PADDLE_W // 2 - WIDTH // 2)
        dy = target_y - HEIGHT // 2
        norm = math.sqrt(dx * dx + dy * dy)  # correctly rounded, as np.sqrt
        self.p0, self.p1 = p0, p1
        self.bx, self.by = float(WIDTH // 2), float(HEIGHT // 2)
        self.vx = SERVE_SPEED * dx / norm
        self.vy = SERVE_SPEED * dy / norm
        self.t0 = self.t1 = False
        self.rally_steps = 0
        self.serves += 1

    # ----------------------------------------------------------------------------------------------------
    def step(self, a0: int, a1: int) -> tuple[float, float]:
        """Advance the game one step with the seats' actions (0 stay, 1 up, 2 down); returns their rewards."""
        if self._seed_rules:
            p = self.p0 + _MOVE[a0]
            if 0 <= p <= PADDLE_Y_MAX:
                self.p0 = p
            p = self.p1 + _MOVE[a1]
            if 0 <= p <= PADDLE_Y_MAX:
                self.p1 = p
        else:
            p = self.p0 + _MOVE[a0]
            self.p0 = 0.0 if p < 0.0 else (330.0 if p > PADDLE_Y_MAX else p)
            p = self.p1 + _MOVE[a1]
            self.p1 = 0.0 if p < 0.0 else (330.0 if p > PADDLE_Y_MAX else p)
        bx = self.bx = self.bx + self.vx
        by = self.by = self.by + self.vy
        self.terminated = False
        if self._seed_rules:
            rewards = self._seed_events()
        elif bx < LEFT_FACE + BALL_R or bx > RIGHT_FACE - BALL_R or by < BALL_R or by > HEIGHT - BALL_R:
            rewards = self._classic_events()
        else:
            rewards = (0.0, 0.0)
        self.rally_steps += 1
        self.steps += 1
        if self._max_rally and self.rally_steps >= self._max_rally:
            self.drawn_rallies += 1
            self._serve()
        self.truncated = bool(self._max_steps) and self.steps >= self._max_steps and not self.terminated
        self._record()
        return rewards

    def _seed_events(self) -> tuple[float, float]:
        bx, by = self.bx, self.by
        if by - BALL_R <= 0 or by + BALL_R >= HEIGHT:
            self.vy = -self.vy
        left_edge = bx - BALL_R
        hit0 = PADDLE_X < left_edge < LEFT_FACE and self.p0 < by < self.p0 + PADDLE_H
        right_edge = bx + BALL_R
        hit1 = RIGHT_FACE < right_edge < WIDTH - PADDLE_X and self.p1 < by < self.p1 + PADDLE_H
        if hit0:
            self.vx = -self.vx
        if hit1:
            self.vx = -self.vx
        r0 = r1 = 0.0
        if hit0:
            self.t0 = True
            self.hits0 += 1
            r0 = self._r_hit
        if hit1:
            self.t1 = True
            self.hits1 += 1
            r1 = self._r_hit
        if bx < 0 or bx > WIDTH:
            return self._point(r0, r1)
        return r0, r1

    def _classic_events(self) -> tuple[float, float]:
        y = self.by
        if y < BALL_R:
            self.by = 2 * BALL_R - self.by
            self.vy = abs(self.vy)
        if y > HEIGHT - BALL_R:
            self.by = 2 * (HEIGHT - BALL_R) - self.by
            self.vy = -abs(self.vy)
        x, v = self.bx, self.vx
        before = x - v
        r0 = r1 = 0.0
        left = x < LEFT_FACE + BALL_R and v < 0 and before >= LEFT_FACE + BALL_R
        right = x > RIGHT_FACE - BALL_R and v > 0 and before <= RIGHT_FACE - BALL_R
        if left or right:
            top = self.p1 if right else self.p0
            if top - BALL_R <= self.by <= top + PADDLE_H + BALL_R:
                self.bx = (2 * (RIGHT_FACE - BALL_R) if right else 2 * (LEFT_FACE + BALL_R)) - self.bx
                self._deflect(top, right)
                if right:
                    self.t1 = True
                    self.hits1 += 1
                    r1 = self._r_hit
                else:
                    self.t0 = True
                    self.hits0 += 1
                    r0 = self._r_hit
        if self.bx < 0 or self.bx > WIDTH:
            return self._point(r0, r1)
        return r0, r1

    def _deflect(self, top: float, right: bool) -> None:
        centre = top + PADDLE_H / 2
        offset = (self.by - centre) / (PADDLE_H / 2 + BALL_R)
        offset = -1.0 if offset < -1.0 else (1.0 if offset > 1.0 else offset)
        vx, vy = self.vx, self.vy
        speed = float(_hypot(vx, vy)) + self._speedup
        if speed > self._max_speed:
            speed = self._max_speed
        angle = float(_arctan2(vy, abs(vx))) + offset * self._max_deflect
        m = self._max_angle
        angle = -m if angle < -m else (m if angle > m else angle)
        away = speed * float(_cos(angle))
        self.vx = -away if right else away
        self.vy = speed * float(_sin(angle))

    def _point(self, r0: float, r1: float) -> tuple[float, float]:
        if self.bx < 0:
            if self.t1:
                self.s1 += 1
                r0, r1 = -1.0, 1.0
        elif self.t0:
            self.s0 += 1
            r0, r1 = 1.0, -1.0
        self.terminated = max(self.s0, self.s1) >= self._to_win
        self._serve()
        return r0, r1

    # ----------------------------------------------------------------------------------------------------
    def _frame(self) -> tuple[float, ...]:
        """Both seats' normalised views of the current frame (12 values, left then right), exactly as float32."""
        a0, a1, a2, a3, a4, a5 = _F6.unpack(_F6.pack(self.bx * self._sx, self.by * self._sy, self.p0 * self._sp,
                                                      self.p1 * self._sp, self.vx * self._sv, self.vy * self._sv))
        l0, l1, l2, l3 = a0 - 1.0, a1 - 1.0, a2 - 1.0, a3 - 1.0
        return l0, l1, l2, l3, a4, a5, -l0, l1, l3, l2, -a4, a5

    def _record(self) -> None:
        k = self.k
        head = self._head = (self._head + 1) % k
        frame = self._frame()
        _F12.pack_into(self._buf, head * _FRAME_BYTES, *frame)
        _F12.pack_into(self._buf, (head + k) * _FRAME_BYTES, *frame)

    def observe(self) -> np.ndarray:
        """Both seats' stacked observations, ``(2, k, 6)`` float32 in a new array, oldest frame first."""
        h = self._head
        return self._ring[h + 1 : h + 1 + self.k].transpose(1, 0, 2).copy()

    def latest(self) -> np.ndarray:
        """The left seat's newest frame, ``(6,)`` float32 (a copy)."""
        return self._ring[self._head, 0].copy()

    # ----------------------------------------------------------------------------------------------------
    def get_state(self) -> dict[str, Any]:
        """The game's exact state in :meth:`selfplay_cli.envs.pong.core.PongCore.get_state`'s format for one game."""
        h = self._head
        return {
            "bx": np.array([self.bx]), "by": np.array([self.by]), "vx": np.array([self.vx]),
            "vy": np.array([self.vy]), "paddle": np.array([[self.p0], [self.p1]]),
            "score": np.array([[self.s0], [self.s1]]), "touched": np.array([[self.t0], [self.t1]]),
            "rally_steps": np.array([self.rally_steps]), "steps": np.array([self.steps]),
            "serves": np.array([self.serves]), "key": np.array([self.key], dtype=np.uint64),
            "hits": np.array([[self.hits0], [self.hits1]]), "drawn_rallies": np.array([self.drawn_rallies]),
            "terminated": np.array([self.terminated]), "truncated": np.array([self.truncated]),
            "frames": self._ring[h + 1 : h + 1 + self.k, 0][None].copy(),
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state of :meth:`get_state`'s format (from this class or a one-game slice of the core's)."""
        def one(name: str, row: int | None = None) -> Any:
            a = np.asarray(state[name])
            return (a[row] if row is not None else a).reshape(-1)[0].item()

        frames = np.asarray(state["frames"], dtype=np.float32).reshape(-1, N_FEATURES)
        if len(frames) != self.k:
            raise ValueError(f"state has {len(frames)} frames, this game stacks {self.k}")
        self.bx, self.by, self.vx, self.vy = (float(one(n)) for n in ("bx", "by", "vx", "vy"))
        self.p0, self.p1 = float(one("paddle", 0)), float(one("paddle", 1))
        self.s0, self.s1 = float(one("score", 0)), float(one("score", 1))
        self.t0, self.t1 = bool(one("touched", 0)), bool(one("touched", 1))
        self.hits0, self.hits1 = int(one("hits", 0)), int(one("hits", 1))
        self.rally_steps, self.steps, self.serves = int(one("rally_steps")), int(one("steps")), int(one("serves"))
        self.key, self.drawn_rallies = int(one("key")), int(one("drawn_rallies"))
        self.terminated, self.truncated = bool(one("terminated")), bool(one("truncated"))
        mirrored = frames[:, [0, 1, 3, 2, 4, 5]] * np.array([-1, 1, 1, 1, -1, 1], dtype=np.float32)
        self._head = self.k - 1  # window = positions k .. 2k - 1 and 0 .. k - 1
        self._ring[: self.k, 0] = frames
        self._ring[self.k :, 0] = frames
        self._ring[: self.k, 1] = mirrored
        self._ring[self.k :, 1] = mirrored
