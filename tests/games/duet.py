"""Duet: every agent must pick its own target at once, while luck it alone sees moves the team's reward; a
cooperative PettingZoo parallel game.

Each of ``agents`` (2) agents is shown, privately, a target among ``choices`` (3) and its luck, -1 or +1 (both drawn
from the seed, afresh every round); it answers with one of the choices (Discrete). Every agent gets the team's
reward for the round: 1 if every agent named its own target (0 if any missed: the reward needs them all to act
together) plus ``luck`` (2.0) times the sum of the agents' lucks. The luck does not depend on what anyone does, but
an agent sees only its own: a critic of its own observation cannot tell how lucky the others were, so its advantages
carry their luck as noise (an independent learner learns slowly), while a critic of the team (MAPPO, MA-POCA) sees
every agent's luck and takes it out. Observation (per agent, (choices + 1,) float32): its target one-hot, then its
luck. The game's global state (``state()``, ``state_space``): every agent's observation side by side. A game is
``rounds`` (1) rounds, all agents terminated after the last. ``render_mode="rgb_array"`` draws one row per agent:
its target, its answer (green: right) and its luck (16 x 8 per agent).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv


class Duet(ParallelEnv):
    metadata = {"name": "duet_v0", "render_modes": ["rgb_array"], "render_fps": 2, "is_parallelizable": True,
                "marl_kind": "cooperative",
                "marl_description": "every agent must name its target at once, each sees only its own luck: a "
                                    "team critic's game (tests/games)"}

    def __init__(self, agents: int = 2, choices: int = 3, luck: float = 2.0, rounds: int = 1,
                 render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"duet renders only 'rgb_array', not {render_mode!r}")
        if not (int(agents) == agents >= 2 and int(choices) == choices >= 2 and int(rounds) == rounds >= 1
                and 0 <= luck <= 100):
            raise ValueError("need agents >= 2, choices >= 2, rounds >= 1 (whole numbers) and luck in [0, 100]")
        self.n, self.choices, self.luck, self.rounds = int(agents), int(choices), float(luck), int(rounds)
        self.render_mode = render_mode
        self.possible_agents = [f"singer_{i}" for i in range(self.n)]
        self.agents: list[str] = []
        self._obs = spaces.Box(-1.0, 1.0, (self.choices + 1,), dtype=np.float32)
        self._act = spaces.Discrete(self.choices)
        self.state_space = spaces.Box(-1.0, 1.0, (self.n * (self.choices + 1),), dtype=np.float32)
        self._rng = np.random.default_rng()
        self.targets = np.zeros(self.n, dtype=np.int64)
        self.lucks = np.zeros(self.n)
        self.answers = np.full(self.n, -1)
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs

    def action_space(self, agent: str) -> spaces.Space:
        return self._act

    def _draw(self) -> None:
        self.targets = self._rng.integers(self.choices, size=self.n)
        self.lucks = self._rng.choice((-1.0, 1.0), size=self.n)

    def _observe(self, i: int) -> np.ndarray:
        out = np.zeros(self.choices + 1, dtype=np.float32)
        out[self.targets[i]] = 1.0
        out[-1] = self.lucks[i]
        return out

    def state(self) -> np.ndarray:
        return np.concatenate([self._observe(i) for i in range(self.n)])

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.t = 0
        self.answers = np.full(self.n, -1)
        self._draw()
        self.agents = self.possible_agents[:]
        return {a: self._observe(i) for i, a in enumerate(self.agents)}, {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        self.answers = np.array([int(actions.get(a, -1)) for a in self.possible_agents])
        together = float(np.all(self.answers == self.targets))
        reward = together + self.luck * float(self.lucks.sum())
        self.t += 1
        over = self.t >= self.rounds
        if not over:
            self._draw()
        agents = self.agents
        out = ({a: self._observe(i) for i, a in enumerate(agents)}, dict.fromkeys(agents, reward),
               dict.fromkeys(agents, over), dict.fromkeys(agents, False), {a: {} for a in agents})
        if over:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((8 * self.n, 16, 3), 240, dtype=np.uint8)
        for i in range(self.n):
            row = slice(8 * i + 1, 8 * i + 7)
            img[row, 1:5] = (40, 40, 220) if self.targets[i] == 0 else (40, 40, 40 + 60 * int(self.targets[i]))
            if self.answers[i] >= 0:
                img[row, 6:10] = (40, 160, 40) if self.answers[i] == self.targets[i] else (220, 40, 40)
            img[row, 11:15] = (230, 200, 40) if self.lucks[i] > 0 else (90, 90, 90)
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Duet:
    """A new game; options: ``agents`` (2), ``choices`` (3), ``luck`` (2.0), ``rounds`` (1), ``render_mode``."""
    return Duet(**options)
