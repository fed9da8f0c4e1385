"""Two-paddle Pong, registered as ``pong``: its declaration (:data:`PONG`) and its modules.

``config`` the court's constants, the options (:class:`~.config.PongConfig`), the seats and their spaces; ``core``
the batched core (N games in numpy arrays); ``scalar`` one game in plain Python floats, bit for bit the core's, which
the PettingZoo view plays (``view``); ``render`` the offscreen renderer; ``bots`` the scripted players' rules.

Court 800x400, paddles 10x70 at 20 px from each wall, ball radius 10, paddle speed 8, serve speed 10.
Every serve starts from the centre toward a random point of a random paddle, with both paddles re-placed at
random. A point counts only if the scorer touched the ball in that rally (otherwise the ball is re-served).
First to ``points_to_win`` (21) wins.

Two rule sets:

``rules="classic"`` (default)
    Skill decides points. The bounce angle off a paddle depends on where the ball meets it (up to
    ``max_bounce_deg`` from the horizontal), each hit speeds the ball up by ``speedup`` px/step up to
    ``max_speed``, collisions are swept (a fast ball cannot tunnel through a paddle), the ball reflects off the
    top and bottom walls, and paddles clamp at the walls.
``rules="seed"``
    The original game's physics exactly as printed: a paddle hit only flips the horizontal velocity (so a
    ball-tracking paddle never misses and two trackers rally forever), a wall hit flips the vertical velocity
    without moving the ball, a paddle move that would leave the court is refused. Kept for comparison.

Under both rules a rally longer than ``max_rally_steps`` ends the point as a draw: nobody scores and the ball is
re-served (so leading and then rallying forever earns nothing). A game longer than ``max_steps`` (18,000 steps,
five minutes at 60 frames a second) is truncated and decided by the score at that moment: between players who
return nearly every ball a game to 21 would otherwise last half an hour (~50,000 steps between two trained
snapshots), which no one watches and no rating needs.

Randomness is counter-based (:mod:`selfplay_cli.envs.rng`): a game plays the same alone or in a batch, and its
seed reproduces it.

Seats: 0 is the left paddle, 1 the right. Actions per seat: 0 stay, 1 up, 2 down.
Observations are egocentric: each seat sees the court from its own side (x mirrored for the right seat), so a
policy trained on one side plays either side.
"""

from __future__ import annotations

from ..bots import BotSpec, random_rule
from ..contract import EnvSpec
from .bots import cpu_rule
from .config import AGENTS, action_space, make_config, observation_space
from .core import make_batched_core
from .render import PongRenderer
from .view import PongParallelEnv

PONG = EnvSpec(
    name="pong",
    description="Two-paddle Pong, first to 21 (seed 000), egocentric coordinate observations",
    agents=AGENTS,
    make_config=make_config,
    make_core=make_batched_core,
    make_parallel=PongParallelEnv,
    observation_space=observation_space,
    action_space=action_space,
    make_renderer=PongRenderer,
    bots={
        "random": BotSpec("random", "uniformly random stay/up/down", random_rule(action_space(None))),
        "cpu": BotSpec("cpu", "seed 000's ball tracker: moves toward the ball's height",
                       lambda obs, rng: cpu_rule(obs)),
    },
    # The frames a policy sees (the bots read the latest one alone) and the touch reward (the score stays the
    # points) leave the game as it is: one ladder for them all, where 4 frames can be weighed against 8.
    neutral_options=("frame_stack", "obs_mode", "r_for_hit"),
)
"""Pong's declaration (registered as ``pong``)."""
