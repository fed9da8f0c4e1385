"""One lander game in plain Python floats around its Box2D world: the batched core's rules, numbers and randomness
(:mod:`selfplay_cli.envs.lander.core`), for the PettingZoo views, which play one game at a time.

numpy pays about a microsecond an operation whatever the size of its arrays, so the core's step for one game (some
hundred operations around one Box2D ``Step``) spends most of its time in overhead; here a lander's step is a few
dozen float operations and the same calls into Box2D. It is the core's step transcribed for one game, and it must
stay so: the tests play both side by side and compare every observation, reward, ending and score bit for bit. What
makes that hold:

- the world is the core's :class:`~.core.LanderWorld` (terrain, landers, contact listener, generator), made from the
  same seed, and the calls into it are the core's, in the same order (the dispersion of every lander drawn at each
  step, flying or not; the impulses in seat order, a lander's main engine before its side engine; the wind; the
  step; the read back);
- every value is an IEEE double computed with the same operations in the same order as the core's float64 arrays
  (a sum or a product is the same number in Python); the engines' sin and cos are numpy's own, called on the
  number, as the core's (with AVX-512 numpy's may differ from ``math``'s in the last bit: numpy issue 23523); the
  wind is the core's ``math`` code;
- options enter the arithmetic as the core's expressions make them (``engine_scale`` multiplies float64 arrays
  there: ``float()`` of it here; the wind's powers multiply Python floats there as here);
- observations are built as the core builds them (float64, clipped to the bounds, then float32), rewards are the
  core's float32 rewards, scores its float64 sums.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np

from .config import (
    CRASHED,
    FLYING,
    LANDED,
    MAIN_ENGINE_POWER,
    OUT,
    SCALE,
    SIDE_ENGINE_AWAY,
    SIDE_ENGINE_HEIGHT,
    SIDE_ENGINE_POWER,
    LanderConfig,
)
from .core import (
    _ANGLE,
    _AWAKE,
    _HIGH64,
    _IMPULSE,
    _LOW64,
    _MAIN_Y,
    _POS_ITERS,
    _POSITION,
    _TIME_STEP,
    _VEL_ITERS,
    _VELOCITY,
    _X,
    _Y,
    LanderWorld,
    read_lander,
)

_LOW, _HIGH = _LOW64.tolist()[:6], _HIGH64.tolist()[:6]  # the legs (0 or 1) are inside their bounds
_np_sin, _np_cos = np.sin, np.cos
_sin, _tanh, _PI = math.sin, math.tanh, math.pi


class ScalarLander:
    """One lander game with the core's rules (see :mod:`selfplay_cli.envs.lander`).

    ``step(actions)`` takes one action per seat (an int in 0..3, or with ``continuous`` a pair of floats; the
    actions of landers no longer flying are ignored, checking them is the caller's) and returns the seats' rewards
    (the core's float32 values, as Python floats); ``observe()`` the seats' observations ``(n_seats, 8)`` float32 (a
    new array). The state is in plain attributes named as the core's arrays, one entry per seat (``result``,
    ``alive``, ``score``, ``state``; ``main_power``, ``side_power``, ``side_dir`` for the renderer) and ``world``,
    the game's :class:`~.core.LanderWorld`.
    """

    __slots__ = ("config", "n_seats", "continuous", "world", "score", "steps", "terminated", "truncated", "over",
                 "alive", "result", "state", "main_power", "side_power", "side_dir", "_rows", "_shaping", "_pos",
                 "_crashed", "_legs", "_scale", "_f32", "_vectors")

    def __init__(self, config: LanderConfig | None = None) -> None:
        self.config = cfg = config or LanderConfig()
        self.n_seats = cfg.landers
        self.continuous = cfg.continuous
        self._scale = float(cfg.engine_scale)  # as it multiplies the core's float64 powers
        self._f32 = struct.Struct(f"{cfg.landers}f")  # packing rounds a double to float32 as numpy's cast does
        self.world: LanderWorld | None = None
        self.reset(0)

    # ----------------------------------------------------------------------------------------------------
    def reset(self, seed: int) -> None:
        """A new game with the given seed (the core's game of that seed, its opening no-op step made)."""
        L = self.n_seats
        if self.world is not None:
            self.world.close()
        self._crashed = [False] * L  # written by the world's contact listener
        self._legs = [[0, 0] for _ in range(L)]
        self.world = w = LanderWorld(self.config, seed, list(range(L)), self._crashed, self._legs)
        self._pos, self._vectors = [], []
        for body in w.bodies:  # (Box2D's position and velocity of each body: references that follow it, as the core's)
            p = _POSITION(body)
            self._pos.append((_X(p), _Y(p), _ANGLE(body)))
            self._vectors.append((p, _VELOCITY(body)))
        self.score = [0.0] * L
        self.steps = 0
        self.terminated = self.truncated = self.over = False
        self.result = [FLYING] * L
        self.alive = [True] * L
        self.state = [[0.0] * 8 for _ in range(L)]
        self._rows = [[0.0] * 8 for _ in range(L)]
        self._shaping = [0.0] * L
        self.main_power, self.side_power, self.side_dir = [0.0] * L, [0.0] * L, [0.0] * L
        self._advance([0.0] * L, [0.0] * L, [0.0] * L, first=True)

    # ----------------------------------------------------------------------------------------------------
    def _powers(self, actions: Any) -> tuple[list[float], list[float], list[float]]:
        """The main engine's power, the side engine's power and its direction per seat (the core's ``_powers``)."""
        main, side, direction = [], [], []
        alive = self.alive
        for i, a in enumerate(actions):
            if self.continuous:
                m, lat = a
                m, lat = min(max(m, -1.0), 1.0), min(max(lat, -1.0), 1.0)
                absl = abs(lat)
                mp, sp = (m + 1.0) * 0.5 if m > 0.0 else 0.0, absl if absl > 0.5 else 0.0
                direction.append(1.0 if lat > 0.0 else -1.0 if lat < 0.0 else lat)
            else:
                mp, sp = (1.0 if a == 2 else 0.0), (1.0 if a == 1 or a == 3 else 0.0)
                direction.append(a - 2.0)
            if not alive[i]:
                mp = sp = 0.0
            elif self._scale != 1.0:
                mp, sp = mp * self._scale, sp * self._scale
            main.append(mp)
            side.append(sp)
        return main, side, direction

    def step(self, actions: Any) -> tuple[float, ...]:
        """One step with each seat's action; the rewards (0 for landers not in play). A finished game stands still
        until :meth:`reset` (as the core's: its rewards are 0, and its ``terminated`` and ``truncated`` say what
        happened on this step: nothing)."""
        if self.over:
            self.terminated = self.truncated = False
            self.main_power, self.side_power = [0.0] * self.n_seats, [0.0] * self.n_seats
            return (0.0,) * self.n_seats
        main, side, direction = self._powers(actions)
        reward = self._advance(main, side, direction)
        self.steps += 1
        ended = not any(self.alive)
        self.terminated = ended
        self.truncated = self.steps >= self.config.max_steps and not ended
        self.over = self.terminated or self.truncated
        return reward

    def _advance(self, main: list[float], side: list[float], direction: list[float],
                 first: bool = False) -> tuple[float, ...]:
        """Fire the engines of the flying landers, step the world, read the landers back and score them (the core's
        ``_advance``, ``_fire``, ``_wind``, ``_read_back`` and ``_end`` for one game)."""
        w, L, alive, pos = self.world, self.n_seats, self.alive, self._pos
        bodies = w.bodies
        d = [(v * 2.0 - 1.0) / SCALE for v in w.rng.random(2 * L).tolist()]
        for i in range(L):
            m, s = main[i], side[i]
            if not (m or s):
                continue
            x, y, angle = pos[i]
            tip0, tip1 = float(_np_sin(angle)), float(_np_cos(angle))
            side0, side1 = -tip1, tip0
            d0, d1 = d[2 * i], d[2 * i + 1]
            if m:  # main engine: gymnasium's impulse, 4 px below the centre, +-2 for randomness
                t = _MAIN_Y + 2 * d0
                ox = tip0 * t + side0 * d1
                oy = -tip1 * t - side1 * d1
                _IMPULSE(bodies[i], (-ox * MAIN_ENGINE_POWER * m, -oy * MAIN_ENGINE_POWER * m), (x + ox, y + oy), True)
            if s:  # side engines (gymnasium's 17 px lever, as the core's)
                u = 3 * d1 + direction[i] * SIDE_ENGINE_AWAY / SCALE
                ox = tip0 * d0 + side0 * u
                oy = -tip1 * d0 - side1 * u
                _IMPULSE(bodies[i], (-ox * SIDE_ENGINE_POWER * s, -oy * SIDE_ENGINE_POWER * s),
                         (x + ox - tip0 * 17 / SCALE, y + oy + tip1 * SIDE_ENGINE_HEIGHT / SCALE), True)
        if self.config.enable_wind:
            self._wind()
        w.world.Step(_TIME_STEP, _VEL_ITERS, _POS_ITERS)
        reward = [0.0] * L
        done = []
        crashed, legs, state, rows, prev, vectors = (self._crashed, self._legs, self.state, self._rows, self._shaping,
                                                     self._vectors)
        for i in range(L):
            if not alive[i]:
                continue
            b = bodies[i]
            x, y, row, shaping = read_lander(b, *vectors[i], legs[i])
            pos[i] = (x, y, row[4])
            state[i] = row
            rows[i] = [lo if z < lo else hi if z > hi else z
                       for z, lo, hi in zip(row[:6], _LOW, _HIGH, strict=True)] + row[6:]
            s0 = row[0]
            rew = shaping - prev[i]
            rew -= main[i] * 0.30
            rew -= side[i] * 0.03
            prev[i] = shaping
            if first:  # gymnasium's reset step: it sets the shaping, its reward is not given
                continue
            crash = crashed[i] or abs(s0) >= 1.0
            rest = not _AWAKE(b)
            if crash:
                rew = -100.0
            if rest:
                rew = +100.0
            reward[i] = rew
            self.score[i] += rew
            if crash or rest:
                done.append((i, rest, s0))
        if first:
            return ()
        self.main_power, self.side_power, self.side_dir = main, side, direction
        for i, rest, x in done:  # the core's _end: how each ended; the crashed and the lost retire
            alive[i] = False
            code = LANDED if rest else OUT if abs(x) >= 1.0 else CRASHED
            self.result[i] = code
            if code != LANDED:
                w.retire(i)
        return self._f32.unpack(self._f32.pack(*reward))

    def _wind(self) -> None:
        """gymnasium's wind and turbulence on each flying lander whose legs are off the ground (the core's
        ``_wind``)."""
        cfg, w = self.config, self.world
        for seat, (body, legs) in enumerate(zip(w.bodies, self._legs, strict=True)):
            if not self.alive[seat] or legs[0] or legs[1]:
                continue
            i, j = w.wind_idx[seat], w.torque_idx[seat]
            wind = _tanh(_sin(0.02 * i) + _sin(_PI * 0.01 * i)) * cfg.wind_power
            torque = _tanh(_sin(0.02 * j) + _sin(_PI * 0.01 * j)) * cfg.turbulence_power
            w.wind_idx[seat], w.torque_idx[seat] = i + 1, j + 1
            body.ApplyForceToCenter((wind, 0.0), True)
            body.ApplyTorque(torque, True)

    # ----------------------------------------------------------------------------------------------------
    def observe(self) -> np.ndarray:
        """Each seat's 8 values ``(n_seats, 8)`` float32, clipped to the declared bounds; a lander that has ended
        shows its last observation."""
        return np.array(self._rows, dtype=np.float32)
