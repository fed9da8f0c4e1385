"""Multi-agent Lunar Lander as a PettingZoo game (seats ``lander_0`` ..): ``from selfplay_cli.envs import lander_v0``.

``lander_v0.parallel_env(**options)`` is its ``ParallelEnv``, ``lander_v0.env(**options)`` the same game through the AEC
API (``raw_env``: without PettingZoo's order check); the options are the game's own (:mod:`selfplay_cli.envs.lander`,
the docs' games page), a bad one refused in one ``ValueError``. See :mod:`selfplay_cli.envs.zoo`.

``env()`` is the parallel game seen one lander at a time (the world steps once every lander has acted), not
the sequential game of :class:`~selfplay_cli.envs.lander.view.LanderAECEnv` (the world steps after each lander).
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv

from .lander.view import LanderParallelEnv
from .zoo import aec_of, module_metadata, wrapped

metadata = module_metadata(LanderParallelEnv)


def parallel_env(render_mode: str | None = None, **options: Any) -> LanderParallelEnv:
    """The game's PettingZoo ``ParallelEnv`` (render mode ``None`` or ``"rgb_array"``)."""
    return LanderParallelEnv(render_mode=render_mode, **options)


def raw_env(render_mode: str | None = None, **options: Any) -> AECEnv:
    """The same game through PettingZoo's AEC API (``parallel_to_aec``)."""
    return aec_of(parallel_env(render_mode, **options))


def env(render_mode: str | None = None, **options: Any) -> AECEnv:
    """``raw_env`` behind PettingZoo's order check, as PettingZoo's own ``env()`` factories give."""
    return wrapped(raw_env(render_mode, **options))
