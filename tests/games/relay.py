"""Relay: a scout answers once and leaves; whether it answered right is the team's reward, paid later to the runner
who stays; a cooperative PettingZoo parallel game whose agents come and go.

At the game's start the ``scout`` is shown a signal among ``choices`` (2), drawn from the seed, and answers with
one of the choices (Discrete); then it leaves the game (terminated, removed from ``agents``) with no reward of its
own. The ``runner`` sees nothing of the signal nor of the answer: it runs ``length`` (4) steps (its action, of the
same Discrete, changes nothing) and at the last one is rewarded 1 if the scout's answer was the signal (0
otherwise); then the game ends (terminated). So the scout's one action decides the team's reward, which comes after
it left: a learner that stops at its own end (PPO) never sees it and answers at random, one credited with the team's
later reward (MA-POCA) learns to answer right. Observation (per agent, (choices + 2,) float32): the signal one-hot
(the scout's; zeros for the runner), whether it is the scout, and the share of the game played. The game's global
state (``state()``, ``state_space``): the signal one-hot, whether the scout's answer was right (once it answered)
and the share played. ``render_mode="rgb_array"`` draws the signal, the answer and the runner's progress (8 x 24).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

AGENTS = ("scout", "runner")


class Relay(ParallelEnv):
    metadata = {"name": "relay_v0", "render_modes": ["rgb_array"], "render_fps": 4, "is_parallelizable": True,
                "marl_kind": "cooperative",
                "marl_description": "a scout answers and leaves, the runner is paid for its answer later: credit "
                                    "after leaving (tests/games)"}

    def __init__(self, choices: int = 2, length: int = 4, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"relay renders only 'rgb_array', not {render_mode!r}")
        if not (int(choices) == choices >= 2 and int(length) == length >= 2):
            raise ValueError("need choices >= 2 and length >= 2 (whole numbers)")
        self.choices, self.length, self.render_mode = int(choices), int(length), render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self._obs = spaces.Box(0.0, 1.0, (self.choices + 2,), dtype=np.float32)
        self._act = spaces.Discrete(self.choices)
        self.state_space = spaces.Box(0.0, 1.0, (self.choices + 2,), dtype=np.float32)
        self._rng = np.random.default_rng()
        self.signal, self.answer, self.t = 0, -1, 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs

    def action_space(self, agent: str) -> spaces.Space:
        return self._act

    def _observe(self, agent: str) -> np.ndarray:
        out = np.zeros(self.choices + 2, dtype=np.float32)
        if agent == "scout":
            out[self.signal] = 1.0
            out[-2] = 1.0
        out[-1] = self.t / self.length
        return out

    def state(self) -> np.ndarray:
        out = np.zeros(self.choices + 2, dtype=np.float32)
        out[self.signal] = 1.0
        out[-2] = float(self.answer == self.signal)
        out[-1] = self.t / self.length
        return out

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.signal, self.answer, self.t = int(self._rng.integers(self.choices)), -1, 0
        self.agents = list(AGENTS)
        return {a: self._observe(a) for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        acting = list(self.agents)
        if self.t == 0:
            self.answer = int(actions.get("scout", -1))
        self.t += 1
        over = self.t >= self.length
        rewards = dict.fromkeys(acting, 0.0)
        done = dict.fromkeys(acting, over)
        if "scout" in acting:
            done["scout"] = True  # it answered: it leaves
        if over:
            rewards["runner"] = float(self.answer == self.signal)
        self.agents = [a for a in acting if not done[a]]
        obs = {a: self._observe(a) for a in acting}
        return obs, rewards, done, dict.fromkeys(acting, False), {a: {} for a in acting}

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((8, 24, 3), 240, dtype=np.uint8)
        img[2:6, 1:5] = (40, 40, 220) if self.signal == 0 else (220, 140, 40)
        if self.answer >= 0:
            img[2:6, 6:10] = (40, 160, 40) if self.answer == self.signal else (220, 40, 40)
        x = 11 + int(round(self.t / self.length * 8))
        img[2:6, x:x + 4] = (60, 60, 60)
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Relay:
    """A new game; options: ``choices`` (2), ``length`` (4), ``render_mode``."""
    return Relay(**options)
