"""Dash: two runners race down a track, a PettingZoo parallel game whose observations are a nested Dict with a Tuple
inside and an action mask.

Both runners start at cell 0 of a track of ``length`` cells (8). Each step a runner waits (action 0), steps one cell
(1) or dashes two (2); a runner has ``dashes`` dashes (1) and a dash it no longer has is forbidden by its
``action_mask``. The first runner to reach the last cell wins (reward +1, the other -1, at that step); both reaching
it at once is a draw (0), and so is a race still running after ``max_cycles`` steps (12: truncated). Which cell each
runner starts from is drawn from the seed (0 or 1), so a runner must read the track to know how far it has to go.

Observation (per runner), a Dict of every kind of space marl flattens::

    {"action_mask": MultiBinary(3),
     "me": Dict({"cell": Discrete(length), "dash": MultiBinary(1)}),
     "rival": Tuple((Discrete(length), MultiBinary(1))),
     "clock": Box(0, 1, (1,), float32)}          # the share of the race still to run

``render_mode="rgb_array"`` draws the track and both runners (64 x 64).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

SIZE = 64
COLOURS = ((220, 40, 40), (40, 40, 220))


class Dash(ParallelEnv):
    metadata = {"name": "dash_v0", "render_modes": ["rgb_array"], "render_fps": 4, "is_parallelizable": True,
                "marl_description": "race down a track, nested Dict/Tuple observations with a mask (tests/games)"}

    def __init__(self, length: int = 8, dashes: int = 1, max_cycles: int = 12, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"dash renders only 'rgb_array', not {render_mode!r}")
        if int(length) != length or length < 3 or int(dashes) != dashes or dashes < 0:
            raise ValueError("length must be a whole number >= 3 and dashes a whole number >= 0")
        if int(max_cycles) != max_cycles or max_cycles < 1:
            raise ValueError("max_cycles must be a whole number >= 1")
        self.length, self.dashes, self.max_cycles = int(length), int(dashes), int(max_cycles)
        self.render_mode = render_mode
        self.possible_agents = ["red", "blue"]
        self.agents: list[str] = []
        self._obs_space = spaces.Dict({
            "action_mask": spaces.MultiBinary(3),
            "me": spaces.Dict({"cell": spaces.Discrete(self.length), "dash": spaces.MultiBinary(1)}),
            "rival": spaces.Tuple((spaces.Discrete(self.length), spaces.MultiBinary(1))),
            "clock": spaces.Box(0.0, 1.0, (1,), dtype=np.float32),
        })
        self._act_space = spaces.Discrete(3)
        self._rng = np.random.default_rng()
        self.cell = np.zeros(2, dtype=np.int64)
        self.left = np.zeros(2, dtype=np.int64)  # dashes left
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def _observations(self) -> dict[str, dict]:
        clock = np.array([1.0 - self.t / self.max_cycles], dtype=np.float32)
        out = {}
        for i, agent in enumerate(self.possible_agents):
            j = 1 - i
            out[agent] = {
                "action_mask": np.array([1, 1, self.left[i] > 0], dtype=np.int8),
                "me": {"cell": int(self.cell[i]), "dash": np.array([self.left[i] > 0], dtype=np.int8)},
                "rival": (int(self.cell[j]), np.array([self.left[j] > 0], dtype=np.int8)),
                "clock": clock,
            }
        return out

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.cell = self._rng.integers(0, 2, 2)
        self.left[:] = self.dashes
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        for i, agent in enumerate(self.possible_agents):
            a = int(actions[agent])
            if a == 2 and self.left[i] <= 0:
                raise ValueError(f"{agent} dashed without a dash left (its action mask forbids it)")
            self.left[i] -= a == 2
            self.cell[i] = min(self.length - 1, self.cell[i] + a)
        self.t += 1
        home = self.cell >= self.length - 1
        agents = self.agents
        rewards = dict.fromkeys(agents, 0.0)
        if home.any() and not home.all():
            winner = int(np.argmax(home))
            rewards = {a: (1.0 if i == winner else -1.0) for i, a in enumerate(agents)}
        over, cut = bool(home.any()), self.t >= self.max_cycles and not home.any()
        out = (self._observations(), rewards, dict.fromkeys(agents, over), dict.fromkeys(agents, cut),
               {a: {} for a in agents})
        if over or cut:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((SIZE, SIZE, 3), 240, dtype=np.uint8)
        width = SIZE // self.length
        img[:, (self.length - 1) * width:] = (200, 200, 200)  # the finish
        for i, colour in enumerate(COLOURS):
            top = 12 + i * 28
            x = int(self.cell[i]) * width
            img[top:top + 12, x:x + width - 1] = colour
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Dash:
    """A new game; options: ``length`` (8), ``dashes`` (1), ``max_cycles`` (12), ``render_mode``."""
    return Dash(**options)
