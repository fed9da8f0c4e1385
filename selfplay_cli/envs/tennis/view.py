"""The tennis game's PettingZoo ``ParallelEnv`` view: one game of :class:`~selfplay_cli.envs.tennis.core.TennisCore`."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..view import CoreGame, OneGameView
from .config import AGENTS, FPS, REASON_NAMES, SURFACE_NAMES, TennisConfig, action_space, make_config, observation_space
from .core import TennisCore
from .render import TennisRenderer


class TennisParallelEnv(CoreGame, OneGameView):
    """Two table-tennis players, ``player_0`` (the -x end) and ``player_1``; see :mod:`selfplay_cli.envs.tennis`.

    Both act at every step (50 a second). Rewards are each seat's: the point rewards (zero-sum) and the hit
    shaping. ``reset(seed=s)`` makes the game reproducible (it is the batched core's game with seed ``s``); later
    resets without a seed draw game seeds from a generator seeded by ``s``. Infos carry the score (own first), the
    last point's reason and winner, the last hitter, the last surface, whose turn it is, and the game's seed.
    """

    metadata = {"name": "marl_tennis_v0", "render_modes": ["rgb_array"], "render_fps": FPS, "is_parallelizable": True}
    game_name = "tennis"
    renderer = TennisRenderer

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self._check_render_mode(render_mode)
        config: TennisConfig = make_config(**options)
        self._setup(render_mode, config, AGENTS, observation_space(config), action_space(config))
        dtype = np.int64 if config.discrete else np.float32
        self._setup_core(TennisCore(1, config),
                         np.zeros((2, 1, 3), dtype=dtype) + (1 if config.discrete else 0))  # no action: stand still

    def _action(self, agent: str, action: Any) -> np.ndarray:
        if self.config.discrete:
            a = np.asarray(action).reshape(-1)
            if a.shape != (3,) or not np.isin(a, (0, 1, 2)).all():
                raise ValueError(f"{agent}: a discrete tennis action is 3 of 0, 1, 2 (-1, 0, +1), not {action!r}")
            return a.astype(np.int64)
        a = np.asarray(action, dtype=np.float32).reshape(-1)
        if a.shape != (3,) or not np.isfinite(a).all():
            raise ValueError(f"{agent}: a tennis action is 3 finite numbers in [-1, 1], not {action!r}")
        return a

    def _info(self, seat: int) -> dict[str, Any]:
        c = self.core
        return {"score": (int(c.score[seat, 0]), int(c.score[1 - seat, 0])),
                "point_reason": REASON_NAMES[int(c.reason[0])], "point_winner": int(c.winner[0]),
                "last_hitter": int(c.hitter[0]), "last_surface": SURFACE_NAMES[int(c.surface[0])],
                "turn": int(c.turn[0]), "seed": self.game_seed}

    def state(self) -> np.ndarray:
        """The global state: player_0's observation (it sees the whole world)."""
        return self.core.observe()[0, 0]
