"""The tennis game's PettingZoo ``ParallelEnv`` view: one game, played by
:class:`~selfplay_cli.envs.tennis.scalar.ScalarTennis` (the batched core's rules in plain Python floats, bit for bit
the same game: several times faster than a batch of one)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..view import OneGameView, SavedState
from .config import AGENTS, FPS, REASON_NAMES, SURFACE_NAMES, TennisConfig, action_space, make_config, observation_space
from .core import TennisCore
from .render import TennisRenderer
from .scalar import ScalarTennis


class TennisParallelEnv(SavedState, OneGameView):
    """Two table-tennis players, ``player_0`` (the -x end) and ``player_1``; see :mod:`selfplay_cli.envs.tennis`.

    Both act at every step (50 a second). Rewards are each seat's: the point rewards (zero-sum) and the hit
    shaping. ``reset(seed=s)`` makes the game reproducible (it is the batched core's game with seed ``s``, step for
    step); later resets without a seed draw game seeds from a generator seeded by ``s``. Infos carry the score (own
    first), the last point's reason and winner, the last hitter, the last surface, whose turn it is, and the game's
    seed. A seat not given an action stands still.
    """

    metadata = {"name": "marl_tennis_v0", "render_modes": ["rgb_array"], "render_fps": FPS, "is_parallelizable": True}
    game_name = "tennis"
    renderer = TennisRenderer

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self._check_render_mode(render_mode)
        config: TennisConfig = make_config(**options)
        self._setup(render_mode, config, AGENTS, observation_space(config), action_space(config))
        self.game = ScalarTennis(config)
        self._noop: list = [1, 1, 1] if config.discrete else [0.0, 0.0, 0.0]  # no action: stand still

    def _action(self, agent: str, action: Any) -> list:
        if self.config.discrete:
            a = np.asarray(action).reshape(-1)
            if a.shape != (3,) or not np.isin(a, (0, 1, 2)).all():
                raise ValueError(f"{agent}: a discrete tennis action is 3 of 0, 1, 2 (-1, 0, +1), not {action!r}")
            return a.astype(np.int64).tolist()
        a = np.asarray(action, dtype=np.float32).reshape(-1)
        if a.shape != (3,) or not np.isfinite(a).all():
            raise ValueError(f"{agent}: a tennis action is 3 finite numbers in [-1, 1], not {action!r}")
        return a.tolist()

    def _start(self, seed: int) -> None:
        self.game.reset(seed)

    def _play(self, actions: dict[str, Any]) -> tuple[float, float]:
        acts = [self._noop, self._noop]
        for agent in self.agents:
            if agent in actions:
                acts[self._index[agent]] = self._action(agent, actions[agent])
        return self.game.step(acts[0], acts[1])

    def _observe(self) -> np.ndarray:
        return self.game.observe()

    def _ended(self, seat: int) -> bool:
        return self.game.terminated

    def _cut(self) -> bool:
        return self.game.truncated

    def _info(self, seat: int) -> dict[str, Any]:
        g = self.game
        return {"score": (int(g.score[seat]), int(g.score[1 - seat])), "point_reason": REASON_NAMES[g.reason],
                "point_winner": g.winner, "last_hitter": g.hitter, "last_surface": SURFACE_NAMES[g.surface],
                "turn": g.turn, "seed": self.game_seed}

    @property
    def core(self) -> TennisCore:
        """A one-game batched core holding this game's exact state (a copy: stepping it does not move this game)."""
        core = TennisCore(1, self.game.config)
        core.set_state(self.game.get_state())
        return core

    def _scene(self) -> TennisCore:
        return self.core

    def state(self) -> np.ndarray:
        """The global state: player_0's observation (it sees the whole world)."""
        return self.game.observe()[0]
