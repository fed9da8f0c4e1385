"""Spot: two players name where a target is, a two-sides PettingZoo parallel game whose observations are small images.

Each round a red 8x8 block (the target) is drawn in one of the four quadrants of a 16x16x3 uint8 image (the
quadrant drawn from the seed), over a few grey pixels of noise that move every round. Both players see the same
image and name a quadrant (Discrete(4): 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right). A player scores a
point for a right answer; each round's reward is the player's point minus the other's (zero-sum). After
``max_cycles`` (8) rounds the game ends (terminated: it has no other end). The target's place is only in the image,
so a player that does not read it (``random``) is right a quarter of the time, one that does every time.
``render_mode="rgb_array"`` draws the image four times larger (64x64).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

AGENTS = ("p0", "p1")
SIDE = 16
RED = (230, 40, 40)


class Spot(ParallelEnv):
    metadata = {"name": "spot_v0", "render_modes": ["rgb_array"], "render_fps": 4, "is_parallelizable": True,
                "marl_kind": "two-sides",
                "marl_description": "name the quadrant of a red block in a 16x16 image: image observations "
                                    "(tests/games)"}

    def __init__(self, max_cycles: int = 8, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"spot renders only 'rgb_array', not {render_mode!r}")
        if int(max_cycles) != max_cycles or max_cycles < 1:
            raise ValueError("max_cycles must be a whole number >= 1")
        self.max_cycles, self.render_mode = int(max_cycles), render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self._obs_space = spaces.Box(0, 255, (SIDE, SIDE, 3), dtype=np.uint8)
        self._act_space = spaces.Discrete(4)
        self._rng = np.random.default_rng()
        self.image = np.zeros((SIDE, SIDE, 3), dtype=np.uint8)
        self.target = 0
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def _draw(self) -> None:
        """A new round: the target in a quadrant drawn from the game's generator, six grey noise pixels."""
        self.target = int(self._rng.integers(4))
        img = np.zeros((SIDE, SIDE, 3), dtype=np.uint8)
        noise = self._rng.integers(0, SIDE, (6, 2))
        img[noise[:, 0], noise[:, 1]] = 90
        r, c = divmod(self.target, 2)
        half = SIDE // 2
        img[r * half:(r + 1) * half, c * half:(c + 1) * half] = RED
        self.image = img

    def _observations(self) -> dict[str, np.ndarray]:
        return {a: self.image.copy() for a in self.agents}

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.t = 0
        self.agents = self.possible_agents[:]
        self._draw()
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        right = [float(int(actions.get(a, -1)) == self.target) for a in AGENTS]
        rewards = {AGENTS[0]: right[0] - right[1], AGENTS[1]: right[1] - right[0]}
        self.t += 1
        over = self.t >= self.max_cycles
        agents = self.agents
        self._draw()
        out = (self._observations(), rewards, dict.fromkeys(agents, over), dict.fromkeys(agents, False),
               {a: {} for a in agents})
        if over:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return np.repeat(np.repeat(self.image, 4, axis=0), 4, axis=1)

    def close(self) -> None:
        """Nothing to release."""


def parallel_env(**options) -> Spot:
    """A new game; options: ``max_cycles`` (8), ``render_mode``."""
    return Spot(**options)
