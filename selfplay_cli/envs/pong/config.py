"""Pong's declaration: the court's constants, the options (:class:`PongConfig`), the seats and their spaces."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Literal

import numpy as np
from gymnasium import spaces

WIDTH, HEIGHT = 800, 400
PADDLE_W, PADDLE_H = 10, 70
PADDLE_X = 20  # gap between a wall and its paddle
BALL_R = 10
PADDLE_SPEED = 8
SERVE_SPEED = 10.0

LEFT_FACE = PADDLE_X + PADDLE_W  # 30: the face of the left paddle
RIGHT_FACE = WIDTH - PADDLE_X - PADDLE_W  # 770
PADDLE_Y_MAX = HEIGHT - PADDLE_H  # 330

MAX_FRAME_STACK = 1024  # stacked frames an observation may hold (a crafted file must not ask for gigabytes)

STAY, UP, DOWN = 0, 1, 2
ACTION_NAMES = ("stay", "up", "down")
N_FEATURES = 6  # ball x, ball y, own paddle y, opponent paddle y, ball vx, ball vy
FEATURE_NAMES = ("ball_x", "ball_y", "own_y", "opp_y", "ball_vx", "ball_vy")

@dataclass(frozen=True)
class PongConfig:
    """Rules and observation options of one Pong game (the defaults are the game `marl` trains on)."""

    rules: Literal["classic", "seed"] = "classic"
    points_to_win: int = 21
    frame_stack: int = 8  # observation frames a policy sees, oldest first
    obs_mode: Literal["coords", "rgb"] = "coords"
    r_for_hit: float = 0.0  # optional shaping reward for touching the ball
    max_bounce_deg: float = 60.0  # classic: steepest angle a ball leaves a paddle at (from the horizontal)
    max_deflect_deg: float = 45.0  # classic: turn given by a hit at the very edge of a paddle
    speedup: float = 0.5  # classic: px/step added to the ball speed by each paddle hit
    max_speed: float = 16.0  # classic: speed cap (px/step)
    max_rally_steps: int = 3000  # 0 = no cap
    max_steps: int = 18_000  # a game's time limit: 5 minutes at 60 frames a second (0 = no cap)

    def __post_init__(self) -> None:
        for f in fields(self):  # the declared types, from Python too (a float where a count goes is refused)
            value, kind = getattr(self, f.name), {"int": int, "float": float}.get(str(f.type))
            if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
                raise ValueError(f"pong option {f.name} wants a whole number, not {value!r}")
            if kind is float and (isinstance(value, bool) or not isinstance(value, (int, float)) or value != value
                                  or value in (float("inf"), float("-inf"))):
                raise ValueError(f"pong option {f.name} wants a finite number, not {value!r}")
        if self.rules not in ("classic", "seed"):
            raise ValueError(f"pong rules must be 'classic' or 'seed', not {self.rules!r}")
        if self.obs_mode not in ("coords", "rgb"):
            raise ValueError(f"pong obs_mode must be 'coords' or 'rgb', not {self.obs_mode!r}")
        if self.points_to_win < 1:
            raise ValueError(f"points_to_win must be at least 1, not {self.points_to_win}")
        if not 1 <= self.frame_stack <= MAX_FRAME_STACK:
            raise ValueError(f"frame_stack must lie between 1 and {MAX_FRAME_STACK}, not {self.frame_stack}")
        if not SERVE_SPEED <= self.max_speed <= 2 * (BALL_R + PADDLE_W) + SERVE_SPEED:
            raise ValueError(f"max_speed must lie in [{SERVE_SPEED}, 40], not {self.max_speed}")
        if not 0.0 <= self.max_bounce_deg < 80.0:
            raise ValueError(f"max_bounce_deg must lie in [0, 80), not {self.max_bounce_deg}")
        if self.speedup < 0 or self.max_rally_steps < 0 or self.max_steps < 0:
            raise ValueError("speedup, max_rally_steps and max_steps must not be negative")

    @property
    def velocity_scale(self) -> float:
        """Largest velocity component: observations divide velocities by it."""
        return SERVE_SPEED if self.rules == "seed" else self.max_speed

def make_config(**options: Any) -> PongConfig:
    """A config from keyword options, with a clear error for an unknown option."""
    known = set(PongConfig.__dataclass_fields__)
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown pong option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    return replace(PongConfig(), **options)


AGENTS = ("left", "right")


def observation_space(config: PongConfig) -> spaces.Box:
    if config.obs_mode == "rgb":
        return spaces.Box(0, 255, shape=(HEIGHT, WIDTH, 3), dtype=np.uint8)
    return spaces.Box(-1.0, 1.0, shape=(config.frame_stack, N_FEATURES), dtype=np.float32)


def action_space(config: PongConfig) -> spaces.Discrete:
    return spaces.Discrete(3)
