"""Multi-agent Lunar Lander (seed 001's game, re-implemented): gymnasium's LunarLander rules for 1 to 8 landers.

This module is the game's declaration: its constants, its options (:class:`LanderConfig`), each seat's spaces and
the scripted players' rules. The physics (one Box2D world per game, N games stepped at once) is
:class:`~selfplay_cli.envs.lander_core.LanderCore`; the PettingZoo views are in :mod:`.lander_env` and the renderer
in :mod:`.lander_render`.

Rules, per game:

* One Box2D world: gymnasium's moon (11 chunks of random height, a flat helipad in the middle between the flags),
  gravity ``gravity``, and ``landers`` landers spread evenly across the top (lander ``i`` of ``N`` starts at
  ``x = (i + 1) / (N + 1)`` of the width; one lander starts where gymnasium's does), each pushed by its own random
  initial force. Each lander is gymnasium's: a body and two spring-loaded legs.
* Collisions: a lander collides with the moon and with the other landers (gymnasium's lone lander collides with the
  moon only). Anything touching a lander's BODY (the moon, another lander's body or legs) crashes it; legs touching
  legs do not. A leg's ground contact (observation and reward) is a contact with the moon only, and lasts while
  the leg touches any part of it. gymnasium keeps a flag that any contact's end clears, so a leg standing across
  two terrain edges reads "off the ground" when it leaves one of them (measured: 14 of 30 heuristic landings meet
  it); ``gym_leg_contact=True`` keeps gymnasium's flag, for exact comparisons.
* Actions per lander: ``Discrete(4)`` (0 no-op, 1 left engine, 2 main engine, 3 right engine), or with
  ``continuous=True`` a ``Box(-1, 1, (2,))``: main throttle (off at <= 0, else 50% to 100% power) and lateral
  (-1..-0.5 left engine, 0.5..1 right, off between), as gymnasium.
* Observation per lander, gymnasium's 8 values: x and y relative to the helipad, x and y velocity, angle, angular
  velocity, leg 0 and leg 1 contact (clipped to the declared bounds, which a lander meets only far outside play).
* Reward per lander, gymnasium's: the change of the shaping ``-100 |position| - 100 |velocity| - 100 |angle| + 10
  per leg on the ground``, minus 0.3 per frame of main engine and 0.03 per frame of side engine (scaled by the
  throttle); a crash or leaving the screen sideways (``|x| >= 1``) makes the step's reward -100, coming to rest
  (the body asleep) +100.
* Each lander ends on its own (crash, out of bounds, at rest) and from then on does not act and earns nothing; a
  crashed lander is a wreck that falls to the moon and touches no lander again, a lost one leaves the world, a
  landed one stays on the ground for the others to avoid. The game ends when every lander has ended (terminated)
  or after ``max_steps`` steps (truncated). All seats are one team: the team's return is the sum of the landers'
  returns.
* Wind and turbulence (``enable_wind``): gymnasium's, ``tanh(sin(2 k t) + sin(pi k t))`` times ``wind_power``
  (force) and ``turbulence_power`` (torque), on each lander whose legs do not touch the ground.
* ``engine_scale`` multiplies each engine's impulse and its fuel cost (1: gymnasium's); the AEC view, where a
  lander acts once every N physics steps, sets it to N so that the landers can still fly (seed 001 found the AEC
  game unsolvable from 3 landers without it).

With ``landers=1`` the game is gymnasium's ``LunarLander-v3``: the same random draws in the same order from a
generator seeded alike, the same impulses, observations and rewards; with ``gym_leg_contact=True`` too, step for
step and bit for bit (tests/test_lander.py compares them).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np
from gymnasium import spaces

# gymnasium's LunarLander constants (pixels are divided by SCALE to give Box2D metres)
FPS = 50
SCALE = 30.0
MAIN_ENGINE_POWER = 13.0
SIDE_ENGINE_POWER = 0.6
INITIAL_RANDOM = 1000.0
LANDER_POLY = ((-14, +17), (-17, 0), (-17, -10), (+17, -10), (+17, 0), (+14, +17))
LEG_AWAY = 20
LEG_DOWN = 18
LEG_W, LEG_H = 2, 8
LEG_SPRING_TORQUE = 40
SIDE_ENGINE_HEIGHT = 14
SIDE_ENGINE_AWAY = 12
MAIN_ENGINE_Y_LOCATION = 4
VIEWPORT_W = 600
VIEWPORT_H = 400
W = VIEWPORT_W / SCALE  # the world's width and height in metres
H = VIEWPORT_H / SCALE
CHUNKS = 11
HELIPAD_Y = H / 4
MAX_LANDERS = 8

NOOP, LEFT, MAIN, RIGHT = 0, 1, 2, 3
ACTION_NAMES = ("noop", "left", "main", "right")
FEATURE_NAMES = ("x", "y", "vx", "vy", "angle", "angular_velocity", "leg0_contact", "leg1_contact")
N_FEATURES = 8

# How each lander ended (LanderCore.result): still flying, landed (at rest), crashed, out of bounds
FLYING, LANDED, CRASHED, OUT = 0, 1, 2, 3
RESULT_NAMES = ("flying", "landed", "crashed", "out")

OBS_LOW = np.array([-2.5, -2.5, -10.0, -10.0, -2 * math.pi, -10.0, -0.0, -0.0], dtype=np.float32)
OBS_HIGH = np.array([2.5, 2.5, 10.0, 10.0, 2 * math.pi, 10.0, 1.0, 1.0], dtype=np.float32)


@dataclass(frozen=True)
class LanderConfig:
    """Options of one lander game (the defaults: gymnasium's lander, two of them, 1000 steps)."""

    landers: int = 2  # landers in one world (1 to 8)
    continuous: bool = False  # Box(-1, 1, (2,)) actions instead of Discrete(4)
    gravity: float = -10.0  # (-12, 0), as gymnasium
    enable_wind: bool = False
    wind_power: float = 15.0  # gymnasium recommends 0 to 20
    turbulence_power: float = 1.5  # gymnasium recommends 0 to 2
    max_steps: int = 1000  # time limit in steps (gymnasium's TimeLimit of LunarLander-v3)
    engine_scale: float = 1.0  # multiplies engine impulses and fuel costs (the AEC view sets it to `landers`)
    gym_leg_contact: bool = False  # gymnasium's leg flag (lost when a leg leaves one of two edges it touches)

    def __post_init__(self) -> None:
        for f in fields(self):  # the declared types, from Python too
            value, kind = getattr(self, f.name), {"int": int, "float": float, "bool": bool}.get(str(f.type))
            if kind is bool and not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"lander option {f.name} wants true or false, not {value!r}")
            if kind is int and (isinstance(value, bool) or not isinstance(value, (int, np.integer))):
                raise ValueError(f"lander option {f.name} wants a whole number, not {value!r}")
            if kind is float and (isinstance(value, bool) or not isinstance(value, (int, float, np.floating))
                                  or not math.isfinite(value)):
                raise ValueError(f"lander option {f.name} wants a finite number, not {value!r}")
        if not 1 <= self.landers <= MAX_LANDERS:
            raise ValueError(f"landers must lie between 1 and {MAX_LANDERS}, not {self.landers}")
        if not -12.0 < self.gravity < 0.0:
            raise ValueError(f"gravity must lie strictly between -12 and 0, not {self.gravity}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, not {self.max_steps}")
        if self.wind_power < 0 or self.turbulence_power < 0:
            raise ValueError("wind_power and turbulence_power must not be negative")
        if not 0.0 < self.engine_scale <= 2 * MAX_LANDERS:
            raise ValueError(f"engine_scale must lie in (0, {2 * MAX_LANDERS}], not {self.engine_scale}")

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def make_config(**options: Any) -> LanderConfig:
    """A config from keyword options, with a clear error for an unknown option."""
    known = set(LanderConfig.__dataclass_fields__)
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown lander option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    return replace(LanderConfig(), **options)


def agents(n: int) -> tuple[str, ...]:
    return tuple(f"lander_{i}" for i in range(n))


AGENTS = agents(LanderConfig().landers)


def observation_space(config: LanderConfig | None = None) -> spaces.Box:
    return spaces.Box(OBS_LOW, OBS_HIGH, dtype=np.float32)


def action_space(config: LanderConfig | None = None) -> spaces.Space:
    if config is not None and config.continuous:
        return spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
    return spaces.Discrete(4)


# --------------------------------------------------------------------------------------------------------------
# The scripted player: gymnasium's heuristic controller, each lander on its own observation
def _todo(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """gymnasium's heuristic's (angle_todo, hover_todo) for a batch of observations ``(k, 8)``, computed in the
    observations' float32 as gymnasium's scalar version does."""
    s = np.asarray(obs, dtype=np.float32).reshape(len(obs), -1)[:, :N_FEATURES]
    x, y, vx, vy, angle, spin, leg0, leg1 = s.T
    angle_targ = np.clip(x * 0.5 + vx * 1.0, -0.4, 0.4)  # point toward the centre, at most 0.4 rad
    hover_targ = 0.55 * np.abs(x)  # the height to hold grows with the horizontal offset
    angle_todo = (angle_targ - angle) * 0.5 - spin * 1.0
    hover_todo = (hover_targ - y) * 0.5 - vy * 0.5
    contact = (leg0 != 0) | (leg1 != 0)  # on the ground: only slow the fall
    angle_todo = np.where(contact, np.float32(0.0), angle_todo)
    hover_todo = np.where(contact, -vy * 0.5, hover_todo)
    return angle_todo, hover_todo


def heuristic_rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
    """Discrete actions ``(k,)`` of gymnasium's heuristic for observations ``(k, 8)`` (deterministic)."""
    angle_todo, hover_todo = _todo(obs)
    a = np.where(angle_todo < -0.05, RIGHT, np.where(angle_todo > 0.05, LEFT, NOOP))
    return np.where((hover_todo > np.abs(angle_todo)) & (hover_todo > 0.05), MAIN, a).astype(np.int64)


def heuristic_continuous_rule(obs: np.ndarray, rng: Any = None, mask: Any = None) -> np.ndarray:
    """Continuous actions ``(k, 2)`` float32 of gymnasium's heuristic (``continuous=True``)."""
    angle_todo, hover_todo = _todo(obs)
    a = np.stack([hover_todo * 20 - 1, -angle_todo * 20], axis=1)
    return np.clip(a, -1, 1).astype(np.float32)
