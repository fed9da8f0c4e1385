"""Chase: a hunter and a runner on a line, a two-sides PettingZoo parallel game whose two seats differ.

The hunter starts in [0.1, 0.3], the runner in [0.6, 0.9] (drawn from the seed). Each step the hunter moves by
0.1 times its action minus 1 (Discrete(3): back, stay, forward) and the runner by 0.05 times its action minus 2
(Discrete(5), slower but finer), both inside [0, 1]. The hunter wins (+1, the runner -1) once it is within 0.08
of the runner; the runner wins (+1, the hunter -1) when ``max_cycles`` (12) steps pass without a catch: a game
always has a winner. The seats see different things: the hunter (3,) float32: its position, the runner's and the
share of the game left; the runner (5,) float32: its position, the hunter's, the gap, whether the hunter is
closing in and the share left. So the two seats are two roles: a network learned on one cannot play the other.
``render_mode="rgb_array"`` draws the line and the two (16 x 64).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

AGENTS = ("hunter", "runner")
CATCH = 0.08


class Chase(ParallelEnv):
    metadata = {"name": "chase_v0", "render_modes": ["rgb_array"], "render_fps": 10, "is_parallelizable": True,
                "marl_kind": "two-sides",
                "marl_description": "a hunter against a runner on a line: two seats that see and act differently "
                                    "(tests/games)"}

    def __init__(self, max_cycles: int = 12, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"chase renders only 'rgb_array', not {render_mode!r}")
        if int(max_cycles) != max_cycles or max_cycles < 1:
            raise ValueError("max_cycles must be a whole number >= 1")
        self.max_cycles, self.render_mode = int(max_cycles), render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self._obs = {"hunter": spaces.Box(0.0, 1.0, (3,), dtype=np.float32),
                     "runner": spaces.Box(np.array([0, 0, -1, 0, 0], dtype=np.float32),
                                          np.array([1, 1, 1, 1, 1], dtype=np.float32), dtype=np.float32)}
        self._act = {"hunter": spaces.Discrete(3), "runner": spaces.Discrete(5)}
        self._rng = np.random.default_rng()
        self.pos = np.zeros(2)
        self.closing = 0.0
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self._act[agent]

    def _observations(self) -> dict[str, np.ndarray]:
        h, r = self.pos
        left = 1.0 - self.t / self.max_cycles
        return {"hunter": np.array([h, r, left], dtype=np.float32),
                "runner": np.array([r, h, r - h, self.closing, left], dtype=np.float32)}

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.pos = np.array([self._rng.uniform(0.1, 0.3), self._rng.uniform(0.6, 0.9)])
        self.closing = 0.0
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        gap = abs(self.pos[1] - self.pos[0])
        self.pos[0] = np.clip(self.pos[0] + 0.1 * (int(actions.get("hunter", 1)) - 1), 0.0, 1.0)
        self.pos[1] = np.clip(self.pos[1] + 0.05 * (int(actions.get("runner", 2)) - 2), 0.0, 1.0)
        self.closing = float(abs(self.pos[1] - self.pos[0]) < gap)
        self.t += 1
        caught = abs(self.pos[1] - self.pos[0]) <= CATCH
        over = self.t >= self.max_cycles
        rewards = {"hunter": 0.0, "runner": 0.0}
        if caught or over:
            rewards = {"hunter": 1.0, "runner": -1.0} if caught else {"hunter": -1.0, "runner": 1.0}
        agents = self.agents
        out = (self._observations(), rewards, dict.fromkeys(agents, bool(caught)),
               dict.fromkeys(agents, bool(over and not caught)), {a: {} for a in agents})
        if caught or over:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((16, 64, 3), 240, dtype=np.uint8)
        img[8, :] = 160
        for x, colour in zip(self.pos, ((220, 40, 40), (40, 40, 220)), strict=True):
            c = int(round(x * 63))
            img[4:12, max(c - 1, 0):c + 2] = colour
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Chase:
    """A new game; options: ``max_cycles`` (12), ``render_mode``."""
    return Chase(**options)


def cooperative_env(**options) -> Chase:
    """The same game declared one team (``marl_kind`` cooperative; its team return is always 0): a crew whose two
    members read and act differently, each of which must fly its own seat."""
    env = Chase(**options)
    env.metadata = {**env.metadata, "marl_kind": "cooperative"}
    return env
