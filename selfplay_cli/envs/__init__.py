"""Games: batched numpy cores, their PettingZoo views, the PettingZoo adapter for users' games, renderers, the
scripted players' rules, and the registry with the game contract.

Importing this package registers the built-in games. ``get_env(name)`` also finds games of installed packages
(entry-point group ``selfplay_cli.envs``) and a user's PettingZoo game named ``module:factory`` or ``module``.
"""

from __future__ import annotations

from . import lander_env, pong, pong_env, tennis_env
from .loading import env_names, get_env, known_env
from .options import GameOption, GameOptions, game_options
from .registry import (
    KINDS,
    TURNS,
    BatchedCore,
    BotSpec,
    EnvError,
    EnvSpec,
    IllegalActionError,
    SeatSpace,
    UnknownEnvError,
    check_spaces,
    describe_space,
    random_bot,
    random_rule,
    register,
)


def _pong_renderer():
    from .pong_render import PongRenderer

    return PongRenderer()


register(
    EnvSpec(
        name="pong",
        description="Two-paddle Pong, first to 21 (seed 000), egocentric coordinate observations",
        agents=pong_env.AGENTS,
        make_config=pong.make_config,
        make_core=pong.make_batched_core,
        make_parallel=pong_env.PongParallelEnv,
        observation_space=pong_env.observation_space,
        action_space=pong_env.action_space,
        make_renderer=_pong_renderer,
        bots={
            "random": BotSpec("random", "uniformly random stay/up/down", random_rule(pong_env.action_space(None))),
            "cpu": BotSpec("cpu", "seed 000's ball tracker: moves toward the ball's height",
                           lambda obs, rng: pong.cpu_rule(obs)),
        },
        # The frames a policy sees (the bots read the latest one alone) and the touch reward (the score stays the
        # points) leave the game as it is: one ladder for them all, where 4 frames can be weighed against 8.
        neutral_options=("frame_stack", "obs_mode", "r_for_hit"),
    )
)
register(lander_env.LANDER)
register(tennis_env.TENNIS)

__all__ = ["KINDS", "TURNS", "BatchedCore", "BotSpec", "EnvError", "EnvSpec", "GameOption", "GameOptions",
           "IllegalActionError", "SeatSpace", "UnknownEnvError", "check_spaces", "describe_space", "env_names",
           "game_options", "get_env", "known_env", "random_bot", "random_rule", "register"]
