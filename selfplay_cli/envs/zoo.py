"""marl's built-in games offered the way PettingZoo offers its own: a module per game and version
(``selfplay_cli.envs.pong_v0``, ``lander_v0``, ``tennis_v0``), each with ``parallel_env(render_mode=None,
**options)`` (the game's PettingZoo ``ParallelEnv``: its view), ``raw_env`` (the same game through PettingZoo's
``parallel_to_aec``: the AEC API, every seat acting in turn and the game stepping once all have) and ``env``
(``raw_env`` behind PettingZoo's ``OrderEnforcingWrapper``, as PettingZoo's ``env()`` factories give), and ``metadata``.

The options are the game's own (``marl envs GAME`` lists them; the docs' games page says what each does), checked as the
game checks them: an unknown option or a bad value is one ``ValueError`` naming it. A game's version changes when its
rules change so that the same options and seed no longer play the same game.
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec
from pettingzoo.utils.wrappers import OrderEnforcingWrapper


def aec_of(parallel: ParallelEnv) -> AECEnv:
    """A parallel game through PettingZoo's AEC API (``raw_env``): the same game, one seat acting at a time."""
    return parallel_to_aec(parallel)


def wrapped(raw: AECEnv) -> AECEnv:
    """``env()`` of a game: its ``raw_env`` behind PettingZoo's order check (reset before step, and so on)."""
    return OrderEnforcingWrapper(raw)


def module_metadata(view: type) -> dict[str, Any]:
    """A game module's ``metadata``: its view's (name, render modes, frames a second, ``is_parallelizable``)."""
    return dict(view.metadata)
