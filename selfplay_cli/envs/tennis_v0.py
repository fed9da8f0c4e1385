"""Table tennis as a PettingZoo game (seats ``player_0``, ``player_1``): ``from selfplay_cli.envs import tennis_v0``.

``tennis_v0.parallel_env(**options)`` is its ``ParallelEnv``, ``tennis_v0.env(**options)`` the same game through the AEC
API (``raw_env``: without PettingZoo's order check); the options are the game's own (:mod:`selfplay_cli.envs.tennis`,
the docs' games page), a bad one refused in one ``ValueError``. See :mod:`selfplay_cli.envs.zoo`.
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv

from .tennis.view import TennisParallelEnv
from .zoo import aec_of, module_metadata, wrapped

metadata = module_metadata(TennisParallelEnv)


def parallel_env(render_mode: str | None = None, **options: Any) -> TennisParallelEnv:
    """The game's PettingZoo ``ParallelEnv`` (render mode ``None`` or ``"rgb_array"``)."""
    return TennisParallelEnv(render_mode=render_mode, **options)


def raw_env(render_mode: str | None = None, **options: Any) -> AECEnv:
    """The same game through PettingZoo's AEC API (``parallel_to_aec``)."""
    return aec_of(parallel_env(render_mode, **options))


def env(render_mode: str | None = None, **options: Any) -> AECEnv:
    """``raw_env`` behind PettingZoo's order check, as PettingZoo's own ``env()`` factories give."""
    return wrapped(raw_env(render_mode, **options))
