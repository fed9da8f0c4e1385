"""Reach: two agents each steer a point to a goal of its own, the suite's reaching task as a PettingZoo parallel game.

The rules of ``tests/test_sac.py``'s ``Reach``, one per agent: a point p and a goal g drawn from the seed in
[-1, 1]^2; each step p moves by 0.2 times the action (Box(-1, 1, (2,))), staying inside the square; observation
(p, g - p), (4,) float32; reward minus the distance to the goal. After ``max_cycles`` (20) steps the game is cut
short (truncated). The goal is anywhere, so an agent that ignores what it sees cannot get there. Cooperative: the
two agents' returns are the team's.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv


class Reach(ParallelEnv):
    metadata = {"name": "reach_v0", "render_modes": [], "is_parallelizable": True, "marl_kind": "cooperative",
                "marl_description": "two agents each steer a point to its own goal, Box actions (tests/games)"}

    def __init__(self, max_cycles: int = 20) -> None:
        if int(max_cycles) != max_cycles or max_cycles < 1:
            raise ValueError("max_cycles must be a whole number >= 1")
        self.max_cycles = int(max_cycles)
        self.possible_agents = ["a0", "a1"]
        self.agents: list[str] = []
        self._obs_space = spaces.Box(-3.0, 3.0, (4,), dtype=np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._rng = np.random.default_rng()
        self.p = np.zeros((2, 2))
        self.g = np.zeros((2, 2))
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def _observations(self) -> dict[str, np.ndarray]:
        return {a: np.concatenate([self.p[i], self.g[i] - self.p[i]]).astype(np.float32)
                for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.p, self.g = self._rng.uniform(-1.0, 1.0, (2, 2)), self._rng.uniform(-1.0, 1.0, (2, 2))
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        for i, agent in enumerate(self.possible_agents):
            a = np.clip(np.asarray(actions.get(agent, (0.0, 0.0)), dtype=np.float64).reshape(2), -1.0, 1.0)
            self.p[i] = np.clip(self.p[i] + 0.2 * a, -1.0, 1.0)
        self.t += 1
        dist = np.linalg.norm(self.g - self.p, axis=1)
        over = self.t >= self.max_cycles
        agents = self.agents
        out = (self._observations(), {a: float(-dist[i]) for i, a in enumerate(agents)},
               dict.fromkeys(agents, False), dict.fromkeys(agents, over), {a: {} for a in agents})
        if over:
            self.agents = []
        return out

    def render(self) -> None:
        return None

    def close(self) -> None:
        """Nothing to release."""


def parallel_env(**options) -> Reach:
    """A new game; options: ``max_cycles`` (20)."""
    return Reach(**options)
