"""Multi-agent Lunar Lander as a PettingZoo game (seats ``lander_0`` ..): ``from selfplay_cli.envs import lander_v0``.

``lander_v0.parallel_env(**options)`` is its ``ParallelEnv``, ``lander_v0.env(**options)`` the same game through the AEC
API (``raw_env``: without PettingZoo's order check); the options are the game's own (:mod:`selfplay_cli.envs.lander`,
the docs' games page), a bad one refused in one ``ValueError``. See :mod:`selfplay_cli.envs.zoo`.

``env()`` is the parallel game seen one lander at a time (the world steps once every lander has acted), not
the sequential game of :class:`~selfplay_cli.envs.lander.view.LanderAECEnv` (the world steps after each lander).
"""

from __future__ import annotations

from .lander.view import LanderParallelEnv
from .zoo import factories

metadata, parallel_env, raw_env, env = factories(LanderParallelEnv, __name__)
