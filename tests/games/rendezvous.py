"""Rendezvous: three agents on a square meet as fast as they can, a cooperative PettingZoo parallel game.

Each agent starts at a random point of [-1, 1]^2 (drawn from the seed) and moves each step by ``speed`` times its
action, a velocity in Box(-1, 1, (2,)), staying inside the square. Observation (per agent, (7,) float32): its own
position, the other two agents' positions relative to it (in seat order), and the share of the game still to play.
Every agent gets the team reward each step: minus the spread, the mean distance of the agents from their
centroid. A game lasts ``max_cycles`` (50) steps, then all agents are truncated. ``render_mode="rgb_array"``
draws the square and the agents (64 x 64).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

SIZE = 64
COLOURS = ((220, 40, 40), (40, 160, 40), (40, 40, 220))


class Rendezvous(ParallelEnv):
    metadata = {"name": "rendezvous_v0", "render_modes": ["rgb_array"], "render_fps": 10,
                "is_parallelizable": True, "marl_kind": "cooperative",
                "marl_description": "three agents meet on a square, Box actions, cooperative (tests/games)"}

    def __init__(self, max_cycles: int = 50, speed: float = 0.1, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"rendezvous renders only 'rgb_array', not {render_mode!r}")
        if int(max_cycles) != max_cycles or max_cycles < 1 or not 0 < speed <= 1:
            raise ValueError("max_cycles must be a whole number >= 1 and speed lie in (0, 1]")
        self.max_cycles, self.speed, self.render_mode = int(max_cycles), float(speed), render_mode
        self.possible_agents = ["a0", "a1", "a2"]
        self.agents: list[str] = []
        self._obs_space = spaces.Box(np.array([-1, -1, -2, -2, -2, -2, 0], dtype=np.float32),
                                     np.array([1, 1, 2, 2, 2, 2, 1], dtype=np.float32), dtype=np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._rng = np.random.default_rng()
        self.pos = np.zeros((3, 2))
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def _observations(self) -> dict[str, np.ndarray]:
        left = 1.0 - self.t / self.max_cycles
        out = {}
        for i, agent in enumerate(self.possible_agents):
            others = [self.pos[j] - self.pos[i] for j in range(3) if j != i]
            out[agent] = np.concatenate([self.pos[i], *others, [left]]).astype(np.float32)
        return out

    def spread(self) -> float:
        return float(np.linalg.norm(self.pos - self.pos.mean(axis=0), axis=1).mean())

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.pos = self._rng.uniform(-1.0, 1.0, (3, 2))
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        for i, agent in enumerate(self.possible_agents):
            a = np.clip(np.asarray(actions.get(agent, (0.0, 0.0)), dtype=np.float64).reshape(2), -1.0, 1.0)
            self.pos[i] = np.clip(self.pos[i] + self.speed * a, -1.0, 1.0)
        self.t += 1
        reward = -self.spread()
        over = self.t >= self.max_cycles
        agents = self.agents
        out = (self._observations(), dict.fromkeys(agents, reward), dict.fromkeys(agents, False),
               dict.fromkeys(agents, over), {a: {} for a in agents})
        if over:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((SIZE, SIZE, 3), 240, dtype=np.uint8)
        yy, xx = np.mgrid[0:SIZE, 0:SIZE]
        for (x, y), colour in zip(self.pos, COLOURS, strict=True):
            cx, cy = (x + 1) / 2 * (SIZE - 1), (1 - (y + 1) / 2) * (SIZE - 1)
            img[(xx - cx) ** 2 + (yy - cy) ** 2 <= 9] = colour
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Rendezvous:
    """A new game; options: ``max_cycles`` (50), ``speed`` (0.1), ``render_mode``."""
    return Rendezvous(**options)
