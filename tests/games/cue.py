"""Cue: two players race to answer the cue each is shown, a PettingZoo parallel game whose observations are Discrete.

Each round both players are shown a cue of their own, a number in ``0 .. cues-1`` drawn from the seed (observation
``Discrete(cues)``), and answer with an action of the same range (``Discrete(cues)``). A player who answers its own
cue scores a point; each round's reward is a player's points minus its rival's (zero-sum). After ``rounds`` rounds
(8) the game is over (terminated); the player with more points wins. A player that reads its cue scores every
round; a random one, one round in ``cues``. ``render_mode="rgb_array"`` draws each player's cue and points
(64 x 64).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

SIZE = 64
COLOURS = ((220, 40, 40), (40, 40, 220))


class Cue(ParallelEnv):
    metadata = {"name": "cue_v0", "render_modes": ["rgb_array"], "render_fps": 4, "is_parallelizable": True,
                "marl_description": "answer the cue you are shown, Discrete observations (tests/games)"}

    def __init__(self, cues: int = 4, rounds: int = 8, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"cue renders only 'rgb_array', not {render_mode!r}")
        if int(cues) != cues or cues < 2 or int(rounds) != rounds or rounds < 1:
            raise ValueError("cues must be a whole number >= 2 and rounds a whole number >= 1")
        self.cues, self.rounds, self.render_mode = int(cues), int(rounds), render_mode
        self.possible_agents = ["p0", "p1"]
        self.agents: list[str] = []
        self._space = spaces.Discrete(self.cues)
        self._rng = np.random.default_rng()
        self.cue = np.zeros(2, dtype=np.int64)
        self.points = np.zeros(2, dtype=np.int64)
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._space

    def action_space(self, agent: str) -> spaces.Space:
        return self._space

    def _observations(self) -> dict[str, int]:
        return {a: int(self.cue[i]) for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.cue = self._rng.integers(0, self.cues, 2)
        self.points[:] = 0
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        hits = np.array([int(actions[a]) == int(self.cue[i]) for i, a in enumerate(self.possible_agents)], dtype=int)
        self.points += hits
        self.t += 1
        self.cue = self._rng.integers(0, self.cues, 2)
        over = self.t >= self.rounds
        agents = self.agents
        rewards = {a: float(hits[i] - hits[1 - i]) for i, a in enumerate(agents)}
        out = (self._observations(), rewards, dict.fromkeys(agents, over), dict.fromkeys(agents, False),
               {a: {} for a in agents})
        if over:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((SIZE, SIZE, 3), 240, dtype=np.uint8)
        width = SIZE // self.cues
        for i, colour in enumerate(COLOURS):
            top = i * SIZE // 2
            img[top + 4:top + 16, self.cue[i] * width:(self.cue[i] + 1) * width - 1] = colour  # the cue shown
            img[top + 20:top + 28, 0:min(SIZE, 4 * int(self.points[i]))] = colour  # the points so far
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Cue:
    """A new game; options: ``cues`` (4), ``rounds`` (8), ``render_mode``."""
    return Cue(**options)
