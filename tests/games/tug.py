"""Tug: a tug of war whose numbers break after a while, a two-sides PettingZoo parallel game (a user's buggy game).

A marker starts at 0 on [-1, 1]; each step both players pull (Discrete(3): left, none, right) and it moves by 0.1
times the sum of the pulls. ``player_0`` wins (+1, ``player_1`` -1) if it reaches -1, ``player_1`` if it reaches +1;
after ``max_cycles`` (20) steps the game is cut short, a draw. Each player observes (3,) float32: the marker, its
own last pull and the share of the game left.

The bug, on purpose: once one game object has played ``nan_after`` steps (counted over all its games), seat
``nan_seat``'s ``nan_in`` (``"observation"`` or ``"reward"``) is NaN (``nan_value``: another value such as inf),
as a user's physics that divides by zero after a while would. ``nan_after=-1`` never breaks.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

AGENTS = ("player_0", "player_1")


class Tug(ParallelEnv):
    metadata = {"name": "tug_v0", "render_modes": [], "is_parallelizable": True, "marl_kind": "two-sides",
                "marl_description": "a tug of war whose observations or rewards turn NaN after a while (tests/games)"}

    def __init__(self, max_cycles: int = 20, nan_after: int = 300, nan_seat: int = 1, nan_in: str = "observation",
                 nan_value: float = float("nan"), render_mode: str | None = None) -> None:
        if nan_in not in ("observation", "reward") or nan_seat not in (0, 1) or max_cycles < 1:
            raise ValueError("nan_in must be observation or reward, nan_seat 0 or 1, max_cycles >= 1")
        self.max_cycles, self.nan_after, self.nan_seat = int(max_cycles), int(nan_after), int(nan_seat)
        self.nan_in, self.nan_value, self.render_mode = nan_in, float(nan_value), render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self._obs = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
        self._act = spaces.Discrete(3)
        self.x = 0.0
        self.pulls = [0, 0]
        self.t = 0
        self.lifetime = 0  # steps of this game object, over all its games

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs

    def action_space(self, agent: str) -> spaces.Space:
        return self._act

    @property
    def broken(self) -> bool:
        return 0 <= self.nan_after <= self.lifetime

    def _observations(self) -> dict[str, np.ndarray]:
        left = 1.0 - self.t / self.max_cycles
        out = {a: np.array([self.x, self.pulls[i], left], dtype=np.float32) for i, a in enumerate(AGENTS)}
        if self.broken and self.nan_in == "observation":
            out[AGENTS[self.nan_seat]][0] = self.nan_value
        return out

    def reset(self, seed: int | None = None, options: dict | None = None):
        self.x, self.pulls, self.t = 0.0, [0, 0], 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        self.pulls = [int(actions.get(a, 1)) - 1 for a in AGENTS]
        self.x = float(np.clip(self.x + 0.1 * sum(self.pulls), -1.0, 1.0))
        self.t += 1
        self.lifetime += 1
        won = abs(self.x) >= 1.0
        over = self.t >= self.max_cycles
        rewards = {a: 0.0 for a in AGENTS}
        if won:
            rewards = {"player_0": -self.x, "player_1": self.x}
        if self.broken and self.nan_in == "reward":
            rewards[AGENTS[self.nan_seat]] = self.nan_value
        agents = self.agents
        out = (self._observations(), rewards, dict.fromkeys(agents, won), dict.fromkeys(agents, over and not won),
               {a: {} for a in agents})
        if won or over:
            self.agents = []
        return out

    def close(self) -> None:
        """Nothing to release."""


def parallel_env(**options) -> Tug:
    """A new game; options: ``max_cycles`` (20), ``nan_after`` (300), ``nan_seat`` (1), ``nan_in``, ``nan_value``."""
    return Tug(**options)
