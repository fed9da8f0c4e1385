"""Endless: a two-sides PettingZoo parallel game that never ends by itself, for the game loop's length rules.

Two agents each pick 0 or 1 every step; an agent scores +1 (the other -1) when the two picks differ and it picked 1.
No agent is ever terminated or truncated. ``env`` declares ``metadata["marl_max_steps"]`` (``limit``, 30 by
default), which the game loop must enforce; ``undeclared`` declares no maximum at all (the loop's own cap applies).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

AGENTS = ("a", "b")


class Endless(ParallelEnv):
    metadata = {"name": "endless_v0", "marl_kind": "two-sides",
                "marl_description": "two agents that pick 0 or 1 for ever (tests/games)"}

    def __init__(self, limit: int | None = 30) -> None:
        self.metadata = dict(self.metadata)
        if limit is not None:
            self.metadata["marl_max_steps"] = limit
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return spaces.Box(0.0, 1.0, (1,), dtype=np.float32)

    def action_space(self, agent: str) -> spaces.Space:
        return spaces.Discrete(2)

    def _obs(self) -> dict[str, np.ndarray]:
        return {a: np.array([self.t % 2], dtype=np.float32) for a in self.agents}

    def reset(self, seed: int | None = None, options: dict | None = None):
        self.agents, self.t = list(AGENTS), 0
        return self._obs(), {a: {} for a in self.agents}

    def step(self, actions):
        self.t += 1
        a, b = int(actions["a"]), int(actions["b"])
        reward = float(a - b)
        rewards = {"a": reward, "b": -reward}
        never = {x: False for x in self.agents}
        return self._obs(), rewards, never, dict(never), {x: {} for x in self.agents}


def env(limit: int = 30) -> Endless:
    """The game declaring ``marl_max_steps = limit``."""
    return Endless(limit)


def undeclared() -> Endless:
    """The game declaring no maximum length."""
    return Endless(None)
