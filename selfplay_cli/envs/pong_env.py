"""The PettingZoo ``ParallelEnv`` view of Pong: one game, played by :class:`~selfplay_cli.envs.pong_scalar.ScalarPong`
(the batched core's rules in plain Python floats, bit for bit the same game: ~10x faster than a batch of one)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .pong import HEIGHT, N_FEATURES, WIDTH, PongConfig, PongCore, make_config
from .pong_scalar import ScalarPong

AGENTS = ("left", "right")


def observation_space(config: PongConfig) -> spaces.Box:
    if config.obs_mode == "rgb":
        return spaces.Box(0, 255, shape=(HEIGHT, WIDTH, 3), dtype=np.uint8)
    return spaces.Box(-1.0, 1.0, shape=(config.frame_stack, N_FEATURES), dtype=np.float32)


def action_space(config: PongConfig) -> spaces.Discrete:
    return spaces.Discrete(3)


class PongParallelEnv(ParallelEnv):
    """Two-player Pong with agents ``left`` and ``right``; see :mod:`selfplay_cli.envs.pong` for the rules.

    ``reset(seed=s)`` makes the game reproducible; later resets without a seed draw fresh game seeds from a
    generator seeded by ``s``. Rewards are +1/-1 per point (plus ``r_for_hit`` per touch). Infos carry the
    score, the seat's touches and the game's seed. The game is the batched core's game ``game_seed``, step for step.
    """

    metadata = {"name": "marl_pong_v0", "render_modes": ["rgb_array"], "render_fps": 60,
                "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"pong renders only 'rgb_array' (offscreen), not {render_mode!r}")
        self.config = make_config(**options)
        self.render_mode = render_mode
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self.game = ScalarPong(self.config)
        self._rgb = self.config.obs_mode == "rgb"
        self._obs_space = observation_space(self.config)
        self._act_space = action_space(self.config)
        self._seeds = np.random.default_rng()
        self._renderer = None
        self.game_seed: int | None = None

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._seeds = np.random.default_rng(seed)
            self.game_seed = int(seed)
        else:
            self.game_seed = int(self._seeds.integers(2**62))
        self.game.reset(self.game_seed)
        self.agents = ["left", "right"]
        return self._observations(), self._infos()

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        a0, a1 = int(actions.get("left", 0)), int(actions.get("right", 0))
        if not (0 <= a0 < 3 and 0 <= a1 < 3):
            raise ValueError(f"pong actions are 0 (stay), 1 (up), 2 (down); got {actions}")
        game = self.game
        r0, r1 = game.step(a0, a1)
        if self._rgb:
            obs = self._observations()
        else:
            both = game.observe()
            obs = {"left": both[0], "right": both[1]}
        done, cut = game.terminated, game.truncated
        seed = self.game_seed
        out = (
            obs,
            {"left": r0, "right": r1},
            {"left": done, "right": done},
            {"left": cut, "right": cut},
            {"left": {"score": (int(game.s0), int(game.s1)), "touches": game.hits0, "seed": seed},
             "right": {"score": (int(game.s1), int(game.s0)), "touches": game.hits1, "seed": seed}},
        )
        if done or cut:
            self.agents = []
        return out

    def _observations(self) -> dict[str, np.ndarray]:
        if self._rgb:
            frame = self.render_frame()
            return {"left": frame, "right": np.ascontiguousarray(frame[:, ::-1])}
        both = self.game.observe()
        return {"left": both[0], "right": both[1]}

    def _infos(self) -> dict[str, dict]:
        g = self.game
        return {"left": {"score": (int(g.s0), int(g.s1)), "touches": g.hits0, "seed": self.game_seed},
                "right": {"score": (int(g.s1), int(g.s0)), "touches": g.hits1, "seed": self.game_seed}}

    @property
    def core(self) -> PongCore:
        """A one-game batched core holding this game's exact state (a copy: stepping it does not move this game)."""
        core = PongCore(1, self.config)
        core.set_state(self.game.get_state())
        return core

    def _scene(self) -> SimpleNamespace:
        """What the renderer reads of a core, for this one game."""
        g = self.game
        return SimpleNamespace(paddle=np.array([[g.p0], [g.p1]]), bx=np.array([g.bx]), by=np.array([g.by]),
                               score=np.array([[g.s0], [g.s1]]))

    def render_frame(self) -> np.ndarray:
        if self._renderer is None:
            from .pong_render import PongRenderer

            self._renderer = PongRenderer()
        return self._renderer.draw(self._scene(), 0)

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self.render_frame()
        return None

    def state(self) -> np.ndarray:
        """The global state: the left seat's latest observation frame (world-complete)."""
        return self.game.latest()

    def get_state(self) -> dict[str, Any]:
        """Exact state of the game (physics, score, RNG counters and observation history)."""
        return {"core": self.game.get_state(), "agents": list(self.agents), "game_seed": self.game_seed}

    def set_state(self, state: dict[str, Any]) -> None:
        self.game.set_state(state["core"])
        self.agents = list(state["agents"])
        self.game_seed = state["game_seed"]

    def close(self) -> None:
        self._renderer = None
