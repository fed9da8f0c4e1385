"""The PettingZoo ``ParallelEnv`` view of Pong: one game of the batched core."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .pong import HEIGHT, N_FEATURES, WIDTH, PongConfig, PongCore, make_config

AGENTS = ("left", "right")


def observation_space(config: PongConfig) -> spaces.Box:
    if config.obs_mode == "rgb":
        return spaces.Box(0, 255, shape=(HEIGHT, WIDTH, 3), dtype=np.uint8)
    return spaces.Box(-1.0, 1.0, shape=(config.frame_stack, N_FEATURES), dtype=np.float32)


def action_space(config: PongConfig) -> spaces.Discrete:
    return spaces.Discrete(3)


class PongParallelEnv(ParallelEnv):
    """Two-player Pong with agents ``left`` and ``right``; see :mod:`selfplay_cli.envs.pong` for the rules.

    ``reset(seed=s)`` makes the game reproducible; later resets without a seed draw fresh game seeds from a
    generator seeded by ``s``. Rewards are +1/-1 per point (plus ``r_for_hit`` per touch). Infos carry the
    score, the seat's touches and the game's seed.
    """

    metadata = {"name": "marl_pong_v0", "render_modes": ["rgb_array"], "render_fps": 60,
                "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"pong renders only 'rgb_array' (offscreen), not {render_mode!r}")
        self.config = make_config(**options)
        self.render_mode = render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self.core = PongCore(1, self.config)
        self._obs_space = observation_space(self.config)
        self._act_space = action_space(self.config)
        self._seeds = np.random.default_rng()
        self._renderer = None
        self.game_seed: int | None = None

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._seeds = np.random.default_rng(seed)
            self.game_seed = int(seed)
        else:
            self.game_seed = int(self._seeds.integers(2**62))
        self.core.reset([0], [self.game_seed])
        self.agents = list(self.possible_agents)
        return self._observations(), self._infos()

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        a = np.array([[int(actions.get(agent, 0))] for agent in self.possible_agents], dtype=np.int64)
        if not ((a >= 0) & (a < 3)).all():
            raise ValueError(f"pong actions are 0 (stay), 1 (up), 2 (down); got {actions}")
        rewards = self.core.step(a)
        obs = self._observations()
        term, trunc = bool(self.core.terminated[0]), bool(self.core.truncated[0])
        agents = self.agents
        out = (
            obs,
            {ag: float(rewards[i, 0]) for i, ag in enumerate(agents)},
            dict.fromkeys(agents, term),
            dict.fromkeys(agents, trunc),
            self._infos(),
        )
        if term or trunc:
            self.agents = []
        return out

    def _observations(self) -> dict[str, np.ndarray]:
        if self.config.obs_mode == "rgb":
            frame = self.render_frame()
            return {"left": frame, "right": np.ascontiguousarray(frame[:, ::-1])}
        obs = self.core.observe()
        return {ag: obs[i, 0] for i, ag in enumerate(self.possible_agents)}

    def _infos(self) -> dict[str, dict]:
        c = self.core
        return {
            ag: {"score": (int(c.score[i, 0]), int(c.score[1 - i, 0])), "touches": int(c.hits[i, 0]),
                 "seed": self.game_seed}
            for i, ag in enumerate(self.possible_agents)
        }

    def render_frame(self) -> np.ndarray:
        if self._renderer is None:
            from .pong_render import PongRenderer

            self._renderer = PongRenderer()
        return self._renderer.draw(self.core, 0)

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self.render_frame()
        return None

    def state(self) -> np.ndarray:
        """The global state: the left seat's latest observation frame (world-complete)."""
        return self.core.observe()[0, 0, -1].copy()

    def get_state(self) -> dict[str, Any]:
        """Exact state of the game (physics, score, RNG counters and observation history)."""
        return {"core": self.core.get_state(), "agents": list(self.agents), "game_seed": self.game_seed}

    def set_state(self, state: dict[str, Any]) -> None:
        self.core.set_state(state["core"])
        self.agents = list(state["agents"])
        self.game_seed = state["game_seed"]

    def close(self) -> None:
        self._renderer = None
