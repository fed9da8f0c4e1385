"""Table tennis as a PettingZoo game (seats ``player_0``, ``player_1``): ``from selfplay_cli.envs import tennis_v0``.

``tennis_v0.parallel_env(**options)`` is its ``ParallelEnv``, ``tennis_v0.env(**options)`` the same game through the AEC
API (``raw_env``: without PettingZoo's order check); the options are the game's own (:mod:`selfplay_cli.envs.tennis`,
the docs' games page), a bad one refused in one ``ValueError``. See :mod:`selfplay_cli.envs.zoo`.
"""

from __future__ import annotations

from .tennis.view import TennisParallelEnv
from .zoo import factories

metadata, parallel_env, raw_env, env = factories(TennisParallelEnv, __name__)
