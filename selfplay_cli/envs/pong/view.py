"""Pong's PettingZoo view: one game, played by :class:`~selfplay_cli.envs.pong.scalar.ScalarPong` (the batched core's
rules in plain Python floats, bit for bit the same game: ~10x faster than a batch of one), with observations of
coordinates or, with ``obs_mode=rgb``, of the rendered court."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from ..view import OneGameView, SavedState
from .config import AGENTS, action_space, make_config, observation_space
from .core import PongCore
from .render import PongRenderer
from .scalar import ScalarPong


class PongParallelEnv(SavedState, OneGameView):
    """Two-player Pong with agents ``left`` and ``right``; see :mod:`selfplay_cli.envs.pong` for the rules.

    ``reset(seed=s)`` makes the game reproducible; later resets without a seed draw fresh game seeds from a
    generator seeded by ``s``. Rewards are +1/-1 per point (plus ``r_for_hit`` per touch). Infos carry the
    score, the seat's touches and the game's seed. The game is the batched core's game ``game_seed``, step for step.
    """

    metadata = {"name": "marl_pong_v0", "render_modes": ["rgb_array"], "render_fps": 60,
                "is_parallelizable": True}
    game_name = "pong"
    renderer = PongRenderer

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self._check_render_mode(render_mode)
        config = make_config(**options)
        self._setup(render_mode, config, AGENTS, observation_space(config), action_space(config))
        self.game = ScalarPong(self.config)
        self._rgb = self.config.obs_mode == "rgb"

    def _start(self, seed: int) -> None:
        self.game.reset(seed)

    def _play(self, actions: dict[str, Any]) -> tuple[float, float]:
        a0, a1 = int(actions.get("left", 0)), int(actions.get("right", 0))
        if not (0 <= a0 < 3 and 0 <= a1 < 3):
            raise ValueError(f"pong actions are 0 (stay), 1 (up), 2 (down); got {actions}")
        return self.game.step(a0, a1)

    def _observe(self) -> Any:
        if self._rgb:
            frame = self.render_frame()
            return frame, np.ascontiguousarray(frame[:, ::-1])
        return self.game.observe()

    def _ended(self, seat: int) -> bool:
        return self.game.terminated

    def _cut(self) -> bool:
        return self.game.truncated

    def _info(self, seat: int) -> dict[str, Any]:
        g = self.game
        if seat == 0:
            return {"score": (int(g.s0), int(g.s1)), "touches": g.hits0, "seed": self.game_seed}
        return {"score": (int(g.s1), int(g.s0)), "touches": g.hits1, "seed": self.game_seed}

    @property
    def core(self) -> PongCore:
        """A one-game batched core holding this game's exact state (a copy: stepping it does not move this game)."""
        core = PongCore(1, self.config)
        core.set_state(self.game.get_state())
        return core

    def _scene(self) -> SimpleNamespace:
        """What the renderer reads of a core, for this one game."""
        g = self.game
        return SimpleNamespace(paddle=np.array([[g.p0], [g.p1]]), bx=np.array([g.bx]), by=np.array([g.by]),
                               score=np.array([[g.s0], [g.s1]]))

    def state(self) -> np.ndarray:
        """The global state: the left seat's latest observation frame (world-complete)."""
        return self.game.latest()
