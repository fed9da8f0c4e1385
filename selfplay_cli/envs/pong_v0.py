"""Two-paddle Pong as a PettingZoo game (seats ``left``, ``right``): ``from selfplay_cli.envs import pong_v0``.

``pong_v0.parallel_env(**options)`` is its ``ParallelEnv``, ``pong_v0.env(**options)`` the same game through the AEC
API (``raw_env``: without PettingZoo's order check); the options are the game's own (:mod:`selfplay_cli.envs.pong`, the
docs' games page), a bad one refused in one ``ValueError``. See :mod:`selfplay_cli.envs.zoo`.
"""

from __future__ import annotations

from .pong.view import PongParallelEnv
from .zoo import factories

metadata, parallel_env, raw_env, env = factories(PongParallelEnv, __name__)
