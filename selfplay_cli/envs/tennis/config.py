"""The tennis game's declaration: its constants (time, table, ball, bats, observation layout), the options
(:class:`TennisConfig`), the seats and their spaces, the names of surfaces and of why a point ended."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any, Literal

import numpy as np
from gymnasium import spaces

# --------------------------------------------------------------------------------------------------------------
# Time
FPS = 50  # decisions (steps) per second
DT = 1.0 / FPS
SUBSTEPS = 4  # physics substeps per step
H = DT / SUBSTEPS

# Table, net, room (m)
TABLE_HALF = 1.37  # the table runs from -1.37 to 1.37
NET_H = 0.1525
FLOOR_Y = -0.76
X_OUT = 4.5  # a ball this far from the net has left the room

# Ball
G = 9.81
BALL_R = 0.02
BALL_M = 0.0027
AIR_RHO = 1.20
DRAG_CD = 0.40
MAGNUS_CM = 1.0
_AREA = math.pi * BALL_R * BALL_R
K_DRAG = 0.5 * AIR_RHO * DRAG_CD * _AREA / BALL_M  # 1/m: drag acceleration = K_DRAG |v| v
K_MAGNUS = 0.5 * AIR_RHO * _AREA * BALL_R * MAGNUS_CM / BALL_M  # Magnus acceleration = K_MAGNUS w x v
SPIN_DECAY = 0.2  # 1/s, the spin's decay in the air
MAX_SPIN = 1000.0  # rad/s, the most spin a ball keeps (~160 revolutions a second)
INERTIA = 2.0 / 3.0  # thin shell: I = 2/3 m r^2
STICK = INERTIA / (1.0 + INERTIA)  # 0.4: the friction impulse (per unit mass and slip) that stops the slip
SPIN_GAIN = 1.0 / (INERTIA * BALL_R)  # spin change per unit friction impulse per mass

E_TABLE, MU_TABLE = 0.90, 0.40
E_BAT, MU_BAT = 0.85, 1.0

# Bats
BAT_LEN = 0.15
MAX_BAT_SCALE = 5.0
V_MAX = 6.0  # m/s per axis
OMEGA_MAX = 10.0  # rad/s of tilt
ANGLE_MAX = math.pi / 2
BACK = 1.5  # how far behind its end of the table a bat reaches
X_BACK = TABLE_HALF + BACK  # 2.87 m from the net
NET_GAP = 0.02  # the closest any part of a bat comes to the net's plane
Y_LOW, Y_HIGH = -0.4, 1.6
HOME_X, HOME_Y = -1.8, 0.2  # (egocentric) where both bats start each point
HIT_COOLDOWN = 0.04  # s: contacts of one bat this soon after its hit are the same stroke

# Serve
TOSS_X, TOSS_Y, TOSS_VY = -1.55, 0.15, 2.6  # egocentric, for the server

# Observation layout and scales
VEL_SCALE = 10.0  # velocities are observed in units of 10 m/s
SPIN_SCALE = 100.0  # spins in units of 100 rad/s
FEATURE_NAMES = (
    "bat_x", "bat_y", "bat_vx", "bat_vy", "bat_angle", "bat_rate",
    "opp_x", "opp_y", "opp_vx", "opp_vy", "opp_angle", "opp_rate",
    "ball_x", "ball_y", "ball_vx", "ball_vy", "ball_spin",
    "incoming", "my_turn", "outgoing", "landed_there", "i_serve", "they_serve", "serve_clock", "bat_length",
)
N_FEATURES = len(FEATURE_NAMES)
(BAT_X, BAT_Y, BAT_VX, BAT_VY, BAT_ANGLE, BAT_RATE, OPP_X, OPP_Y, OPP_VX, OPP_VY, OPP_ANGLE, OPP_RATE, BALL_X,
 BALL_Y, BALL_VX, BALL_VY, BALL_SPIN, INCOMING, MY_TURN, OUTGOING, LANDED_THERE, I_SERVE, THEY_SERVE, SERVE_CLOCK,
 BAT_LENGTH) = range(N_FEATURES)
_VB, _VBALL, _SB = V_MAX / VEL_SCALE, 40.0 / VEL_SCALE, MAX_SPIN / SPIN_SCALE
OBS_LOW = np.array([-X_BACK, Y_LOW, -_VB, -_VB, -ANGLE_MAX, -1.0,
                    0.0, Y_LOW, -_VB, -_VB, -ANGLE_MAX, -1.0,
                    -X_OUT, FLOOR_Y, -_VBALL, -_VBALL, -_SB,
                    0, 0, 0, 0, 0, 0, 0, 0], dtype=np.float32)
OBS_HIGH = np.array([0.0, Y_HIGH, _VB, _VB, ANGLE_MAX, 1.0,
                     X_BACK, Y_HIGH, _VB, _VB, ANGLE_MAX, 1.0,
                     X_OUT, 6.0, _VBALL, _VBALL, _SB,
                     1, 1, 1, 1, 1, 1, 1, BAT_LEN * MAX_BAT_SCALE], dtype=np.float32)

# The last surface the ball touched (TennisCore.surface)
NONE, TABLE_0, TABLE_1, BAT_0, BAT_1, NET, OUT = range(7)
SURFACE_NAMES = ("none", "table_0", "table_1", "bat_0", "bat_1", "net", "out")
# Why a point ended (TennisCore.reason), said of the player who lost it
(NO_POINT, INTO_NET, HIT_OUT, OWN_HALF, DOUBLE_BOUNCE, DOUBLE_HIT, VOLLEY, MISSED_SERVE,
 NOT_RETURNED, SERVE_NO_BOUNCE) = range(10)
REASON_NAMES = ("none", "net", "out", "own_half", "double_bounce", "double_hit", "volley", "missed_serve",
                "not_returned", "serve_no_bounce")

SERVE_MODES = ("fixed", "velocity", "spin", "mixed")
LIVE_OPTIONS = ("hit_reward", "return_reward", "point_reward", "bat_scale")  # what TennisCore.set_options changes


@dataclass(frozen=True)
class TennisConfig:
    """Options of one tennis game (the defaults: the game marl trains and rates)."""

    discrete: bool = False  # MultiDiscrete([3, 3, 3]) actions (-1/0/+1 per axis) instead of Box(-1, 1, (3,))
    bat_scale: float = 1.0  # the bats' length is 0.15 m times this (curriculum: start large, shrink to 1)
    hit_reward: float = 0.0  # shaping reward for each legal stroke, serve or return (curriculum: start high, decay)
    return_reward: float = 0.0  # shaping reward for a stroke (serve or return) that lands on the opponent's half
    point_reward: float = 1.0  # the winner of a point gets this, the loser its negative
    points_to_win: int = 11  # a game is won at this many points, by 2
    max_steps: int = 6000  # time limit in steps (2 minutes of play at 50 steps a second)
    serve_time: float = 1.5  # seconds the server has to strike the toss
    toss_jitter: float = 0.05  # the toss's place along the table varies by this much (m) either way
    serve_mode: Literal["fixed", "velocity", "spin", "mixed"] = "fixed"  # the serve-bot's serves
    serve_bounce: bool = False  # table tennis's serve: it bounces on the server's half first, then the receiver's
    drag: float = 1.0  # scales the air drag (0: none)
    magnus: float = 1.0  # scales the Magnus force (0: none)

    def __post_init__(self) -> None:
        for f in fields(self):  # the declared types, from Python too
            value, kind = getattr(self, f.name), {"int": int, "float": float, "bool": bool}.get(str(f.type))
            if kind is bool and not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"tennis option {f.name} wants true or false, not {value!r}")
            if kind is int and (isinstance(value, bool) or not isinstance(value, (int, np.integer))):
                raise ValueError(f"tennis option {f.name} wants a whole number, not {value!r}")
            if kind is float and (isinstance(value, bool) or not isinstance(value, (int, float, np.floating))
                                  or not math.isfinite(value)):
                raise ValueError(f"tennis option {f.name} wants a finite number, not {value!r}")
        if not 0.0 < self.bat_scale <= MAX_BAT_SCALE:
            raise ValueError(f"bat_scale must lie in (0, {MAX_BAT_SCALE:g}], not {self.bat_scale}")
        if self.point_reward < 0:
            raise ValueError(f"point_reward must not be negative, not {self.point_reward}")
        if self.points_to_win < 1:
            raise ValueError(f"points_to_win must be at least 1, not {self.points_to_win}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, not {self.max_steps}")
        if not 0.1 <= self.serve_time <= 10.0:
            raise ValueError(f"serve_time must lie between 0.1 and 10 seconds, not {self.serve_time}")
        if not 0.0 <= self.toss_jitter <= 0.15:
            raise ValueError(f"toss_jitter must lie between 0 and 0.15 m, not {self.toss_jitter}")
        if self.serve_mode not in SERVE_MODES:
            raise ValueError(f"serve_mode must be one of {', '.join(SERVE_MODES)}, not {self.serve_mode!r}")
        if not (0.0 <= self.drag <= 5.0 and 0.0 <= self.magnus <= 5.0):
            raise ValueError("drag and magnus scale the air's forces: each must lie between 0 and 5")

    @property
    def bat_length(self) -> float:
        return BAT_LEN * self.bat_scale

def make_config(**options: Any) -> TennisConfig:
    """A config from keyword options, with a clear error for an unknown option."""
    known = set(TennisConfig.__dataclass_fields__)
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown tennis option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    return replace(TennisConfig(), **options)


AGENTS = ("player_0", "player_1")


def observation_space(config: TennisConfig | None = None) -> spaces.Box:
    return spaces.Box(OBS_LOW, OBS_HIGH, dtype=np.float32)


def action_space(config: TennisConfig | None = None) -> spaces.Space:
    if config is not None and config.discrete:
        return spaces.MultiDiscrete([3, 3, 3])
    return spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
