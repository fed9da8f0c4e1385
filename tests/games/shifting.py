"""Shifting: a two-sides PettingZoo parallel game whose agents change mid-game without being done.

Two agents ``a`` and ``b`` pick 0 or 1 each step, rewarded what they pick. In ``parallel_env`` agent ``b`` vanishes
from ``agents`` at step ``at`` (3 by default) without being terminated or truncated (it left: it keeps its score and
acts no more); in ``joining`` only ``a`` plays at first and ``b`` joins at step ``at``; in ``stranger`` an agent
``c``, not one of ``possible_agents``, appears at step ``at``, which the adapter refuses in one line. No agent is
ever done; the game declares ``marl_max_steps = 20``.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

AGENTS = ("a", "b")


class Shifting(ParallelEnv):
    metadata = {"name": "shifting_v0", "marl_kind": "two-sides", "marl_max_steps": 20}

    def __init__(self, at: int = 3, rejoin: bool = False, stranger: bool = False) -> None:
        self.at, self.rejoin, self.stranger = at, rejoin, stranger
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return spaces.Box(0.0, 1.0, (1,), dtype=np.float32)

    def action_space(self, agent: str) -> spaces.Space:
        return spaces.Discrete(2)

    def reset(self, seed: int | None = None, options: dict | None = None):
        self.agents, self.t = ["a"] if self.rejoin else list(AGENTS), 0
        return {x: np.zeros(1, np.float32) for x in self.agents}, {x: {} for x in self.agents}

    def step(self, actions):
        self.t += 1
        if self.t == self.at:  # b joins late, c (a stranger) appears, or b vanishes without being done
            self.agents = list(AGENTS) if self.rejoin else [*AGENTS, "c"] if self.stranger else ["a"]
        obs = {x: np.full(1, self.t % 2, np.float32) for x in self.agents}
        rewards = {x: float(actions.get(x, 0)) for x in self.agents}
        never = {x: False for x in self.agents}
        return obs, rewards, never, dict(never), {x: {} for x in self.agents}


def parallel_env(at: int = 3) -> Shifting:
    """``b`` vanishes at step ``at`` without being done."""
    return Shifting(at)


def joining(at: int = 3) -> Shifting:
    """``b`` is missing at the start and joins at step ``at``."""
    return Shifting(at, rejoin=True)


def stranger(at: int = 3) -> Shifting:
    """An agent ``c`` that is not one of ``possible_agents`` appears at step ``at``."""
    return Shifting(at, stranger=True)
