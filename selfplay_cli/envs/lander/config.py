"""The lander game's declaration: gymnasium's constants, the options (:class:`LanderConfig`), the seats and their
spaces, how a lander ended."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
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
            if kind is not None:  # numpy's numbers as Python's: Box2D's calls take only those (a np.float32 wind
                object.__setattr__(self, f.name, kind(value))  # crashed in ApplyForceToCenter)
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
