"""Slow: a game whose every step takes ``seconds`` on a clock the test reads (:data:`CLOCK`), with no real waiting.

Two agents, simultaneous, cooperative; each sees a number drawn from the seed, (1,) float32, and is paid 1 for
naming its sign (Discrete(2)), 0 otherwise; the game is cut short after ``max_cycles`` (50) steps. Each step moves
:data:`CLOCK` on by ``seconds`` (default 0.25): a trainer given ``clock=CLOCK`` sees a game that is as slow as a
pistonball, while the test runs at the speed of a tiny game.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv


class Clock:
    """Seconds that pass only when the test (or a slow game's step) says so."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t

    def advance(self, seconds: float) -> None:
        self.t += seconds


CLOCK = Clock()


class Slow(ParallelEnv):
    metadata = {"name": "slow_v0", "render_modes": [], "is_parallelizable": True, "marl_kind": "cooperative",
                "marl_description": "name your number's sign; every step takes seconds on the test's clock "
                                    "(tests/games)"}

    def __init__(self, max_cycles: int = 50, seconds: float = 0.25) -> None:
        if int(max_cycles) != max_cycles or max_cycles < 1:
            raise ValueError("max_cycles must be a whole number >= 1")
        if seconds < 0:
            raise ValueError("seconds must be >= 0")
        self.max_cycles, self.seconds = int(max_cycles), float(seconds)
        self.possible_agents = ["a0", "a1"]
        self.agents: list[str] = []
        self._obs_space = spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)
        self._act_space = spaces.Discrete(2)
        self._rng = np.random.default_rng()
        self.x = np.zeros(2)
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def _observations(self) -> dict[str, np.ndarray]:
        return {a: self.x[i:i + 1].astype(np.float32) for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.x = self._rng.uniform(-1.0, 1.0, 2)
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        CLOCK.advance(self.seconds)
        rewards = {a: float(int(actions.get(a, 0)) == int(self.x[i] > 0))
                   for i, a in enumerate(self.possible_agents)}
        self.t += 1
        self.x = self._rng.uniform(-1.0, 1.0, 2)
        over = self.t >= self.max_cycles
        agents = self.agents
        out = (self._observations(), rewards, dict.fromkeys(agents, False), dict.fromkeys(agents, over),
               {a: {} for a in agents})
        if over:
            self.agents = []
        return out

    def render(self) -> None:
        return None

    def close(self) -> None:
        """Nothing to release."""


def parallel_env(**options) -> Slow:
    """A new game; options: ``max_cycles`` (50), ``seconds`` (0.25): the test clock's seconds a step takes."""
    return Slow(**options)
