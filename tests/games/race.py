"""Race: a free-for-all PettingZoo parallel game whose agents leave when they finish and one of which joins late.

Two runners (``runner_0``, ``runner_1``) start at 0 on a track of ``goal`` (4) steps; a third, the ``latecomer``, is
not in the game at its start and joins it (appears in ``agents``) at step ``join_at`` (2), from 0. Each step every
runner in the race moves back, stays or moves forward (Discrete(3): 0, 1, 2), within [0, goal]; a forward move
stumbles (stays) with probability 0.1, drawn from the seed. A runner that reaches the goal at step t finishes: it is
rewarded ``1 + (max_cycles - t) / max_cycles`` (more the sooner, its only reward: a learner that lost it would learn
nothing) and leaves the race (terminated, removed from ``agents``) while the others run on. Runners still running
after ``max_cycles`` (12) steps are truncated with nothing; the game ends when nobody is left. Each runner sees
(3,) float32: its own position and the leader's among the others (as shares of the goal) and the share of the game
played; the game's global state (``state()``, ``state_space``) is every runner's position as a share of the goal
(0 for one not in the race) and the share played. ``render_mode="rgb_array"`` draws the three lanes (24 x 48).

``env()`` is the same race as an AEC game (PettingZoo's ``parallel_to_aec``), whose agents leave and join the same
way.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

AGENTS = ("runner_0", "runner_1", "latecomer")
STUMBLE = 0.1


class Race(ParallelEnv):
    metadata = {"name": "race_v0", "render_modes": ["rgb_array"], "render_fps": 5, "is_parallelizable": True,
                "marl_kind": "free-for-all",
                "marl_description": "a race whose runners leave as they finish and one joins late (tests/games)"}

    def __init__(self, goal: int = 4, join_at: int = 2, max_cycles: int = 12, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"race renders only 'rgb_array', not {render_mode!r}")
        if not (1 <= join_at < max_cycles and goal >= 1):
            raise ValueError("need goal >= 1 and 1 <= join_at < max_cycles")
        self.goal, self.join_at, self.max_cycles = int(goal), int(join_at), int(max_cycles)
        self.render_mode = render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self._obs = spaces.Box(0.0, 1.0, (3,), dtype=np.float32)
        self._act = spaces.Discrete(3)
        self.state_space = spaces.Box(0.0, 1.0, (len(AGENTS) + 1,), dtype=np.float32)
        self._rng = np.random.default_rng()
        self.pos = dict.fromkeys(AGENTS, 0)
        self.t = 0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs

    def action_space(self, agent: str) -> spaces.Space:
        return self._act

    def _observe(self, agent: str) -> np.ndarray:
        others = [self.pos[a] for a in self.agents if a != agent]
        return np.array([self.pos[agent] / self.goal, max(others, default=0) / self.goal, self.t / self.max_cycles],
                        dtype=np.float32)

    def state(self) -> np.ndarray:
        return np.array([*(self.pos[a] / self.goal if a in self.agents else 0.0 for a in AGENTS),
                         self.t / self.max_cycles], dtype=np.float32)

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.t = 0
        self.pos = dict.fromkeys(AGENTS, 0)
        self.agents = ["runner_0", "runner_1"]
        return {a: self._observe(a) for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        self.t += 1
        running = list(self.agents)
        stumbles = self._rng.random(len(running)) < STUMBLE
        for a, stumble in zip(running, stumbles, strict=True):
            move = int(actions.get(a, 1)) - 1
            if move > 0 and stumble:
                move = 0
            self.pos[a] = min(max(self.pos[a] + move, 0), self.goal)
        finished = {a: self.pos[a] >= self.goal for a in running}
        late = self.t >= self.max_cycles
        rewards = {a: (1.0 + (self.max_cycles - self.t) / self.max_cycles if finished[a] else 0.0) for a in running}
        truncated = {a: late and not finished[a] for a in running}
        self.agents = [a for a in running if not (finished[a] or truncated[a])]
        if self.t == self.join_at and not late:  # the latecomer joins the race
            self.agents.append("latecomer")
        for a in self.agents:
            if a not in running:  # the latecomer, on the step it joins
                rewards[a], finished[a], truncated[a] = 0.0, False, False
        obs = {a: self._observe(a) for a in rewards}
        return obs, rewards, finished, truncated, {a: {} for a in obs}

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((24, 48, 3), 240, dtype=np.uint8)
        img[:, 44] = 60  # the finish line
        for lane, (a, colour) in enumerate(zip(AGENTS, ((220, 40, 40), (40, 40, 220), (40, 160, 40)), strict=True)):
            x = 2 + int(round(self.pos[a] / self.goal * 40))
            shade = colour if a in self.agents else tuple(c // 2 + 100 for c in colour)
            img[2 + 8 * lane:6 + 8 * lane, x:x + 4] = shade
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def parallel_env(**options) -> Race:
    """A new race; options: ``goal`` (4), ``join_at`` (2), ``max_cycles`` (12), ``render_mode``."""
    return Race(**options)


def env(**options):
    """The race as an AEC game (its runners take turns within each step of the race)."""
    return parallel_to_aec(Race(**options))
