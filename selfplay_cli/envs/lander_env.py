"""The lander game's PettingZoo views: a ``ParallelEnv`` (all landers act at every physics step, the game marl
trains and rates) and an ``AECEnv`` (seed 001's sequential version: one lander acts, the world steps, the next
lander acts). Both play one game of :class:`~selfplay_cli.envs.lander_core.LanderCore`.

In the AEC view a lander acts once every N physics steps (N landers), so with gymnasium's engines gravity wins
from 3 landers on (seed 001: "the AEC environment becomes unsolvable with 3 or more landers"). The view therefore
sets ``engine_scale`` to N unless told otherwise: one turn's impulse (and fuel) is N frames' worth. Its time limit
``max_steps`` counts physics steps, as in the parallel game.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv

from .lander import (
    AGENTS,
    FLYING,
    FPS,
    RESULT_NAMES,
    LanderConfig,
    action_space,
    agents,
    heuristic_continuous_rule,
    heuristic_rule,
    make_config,
    observation_space,
)
from .lander_core import LanderCore
from .registry import BotSpec, EnvSpec


class _OneGame:
    """What both views share: the config, one game of the core, seeding, spaces, rendering."""

    def _setup(self, render_mode: str | None, config: LanderConfig) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"lander renders only 'rgb_array' (offscreen), not {render_mode!r}")
        self.render_mode = render_mode
        self.config = config
        self.core = LanderCore(1, config)
        self.possible_agents = list(agents(config.landers))
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self._obs_space = observation_space(config)
        self._act_space = action_space(config)
        self._noop = (np.zeros((config.landers, 1, 2), dtype=np.float32) if config.continuous
                      else np.zeros((config.landers, 1), dtype=np.int64))
        self._seeds = np.random.default_rng()
        self._renderer: Any = None
        self.game_seed: int | None = None

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def _new_game(self, seed: int | None) -> None:
        if seed is not None:
            self._seeds = np.random.default_rng(seed)
            self.game_seed = int(seed)
        else:
            self.game_seed = int(self._seeds.integers(2**62))
        self.core.reset([0], [self.game_seed])

    def _put(self, buf: np.ndarray, agent: str, action: Any) -> None:
        i = self._index[agent]
        if self.config.continuous:
            a = np.asarray(action, dtype=np.float32).reshape(-1)
            if a.shape != (2,) or not np.isfinite(a).all():
                raise ValueError(f"{agent}: a continuous lander action is 2 finite numbers, not {action!r}")
            buf[i, 0] = a
        else:
            a = int(action)
            if not 0 <= a < 4:
                raise ValueError(f"{agent}: lander actions are 0 no-op, 1 left, 2 main, 3 right; not {action!r}")
            buf[i, 0] = a

    def _info(self, i: int) -> dict[str, Any]:
        return {"result": RESULT_NAMES[int(self.core.result[i, 0])], "seed": self.game_seed}

    def render_frame(self) -> np.ndarray:
        if self._renderer is None:
            from .lander_render import LanderRenderer

            self._renderer = LanderRenderer()
        return self._renderer.draw(self.core, 0)

    def render(self) -> np.ndarray | None:
        return self.render_frame() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self._renderer = None


class LanderParallelEnv(_OneGame, ParallelEnv):
    """N landers acting together (agents ``lander_0`` ..); see :mod:`selfplay_cli.envs.lander` for the rules.

    A lander leaves ``agents`` on the step it ends (crash, out of bounds, at rest); every lander still flying is
    truncated at ``max_steps``. Rewards are each lander's own; the team's return is their sum. ``reset(seed=s)``
    makes the game reproducible (it is the batched core's game with seed ``s``); later resets without a seed draw
    game seeds from a generator seeded by ``s``. Infos carry how each lander ended and the game's seed.
    """

    metadata = {"name": "marl_lander_v0", "render_modes": ["rgb_array"], "render_fps": FPS,
                "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self._setup(render_mode, make_config(**options))
        self.agents: list[str] = []

    def reset(self, seed: int | None = None, options: dict | None = None):
        self._new_game(seed)
        self.agents = self.possible_agents[:]
        obs = self.core.observe()
        return ({a: obs[i, 0] for i, a in enumerate(self.agents)},
                {a: self._info(i) for i, a in enumerate(self.agents)})

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        buf = self._noop.copy()
        for agent in self.agents:
            if agent in actions:
                self._put(buf, agent, actions[agent])
        core = self.core
        rewards = core.step(buf)
        obs = core.observe()
        out_obs, out_rew, term, trunc, infos = {}, {}, {}, {}, {}
        for agent in self.agents:
            i = self._index[agent]
            out_obs[agent] = obs[i, 0]
            out_rew[agent] = float(rewards[i, 0])
            ended = bool(core.result[i, 0] != FLYING)
            term[agent] = ended
            trunc[agent] = bool(core.truncated[0]) and not ended
            infos[agent] = self._info(i)
        self.agents = [a for a in self.agents if not (term[a] or trunc[a])]
        return out_obs, out_rew, term, trunc, infos

    def state(self) -> np.ndarray:
        """The global state: every lander's observation, concatenated (seat order)."""
        return self.core.observe()[:, 0].reshape(-1)


class LanderAECEnv(_OneGame, AECEnv):
    """Seed 001's sequential lander game: landers take turns; each turn fires that lander's engines (scaled by
    ``engine_scale``, N by default) and steps the world once. Rewards of every lander are given at every step
    (PettingZoo's AEC accumulates them until the lander's turn). A lander that ends is stepped once more with
    ``None`` (PettingZoo's dead step) and leaves."""

    metadata = {"name": "marl_lander_aec_v0", "render_modes": ["rgb_array"], "render_fps": FPS,
                "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        opts = dict(options)
        if "engine_scale" not in opts:
            opts["engine_scale"] = float(make_config(**opts).landers)
        AECEnv.__init__(self)
        self._setup(render_mode, make_config(**opts))
        self.agents = []
        self.agent_selection = self.possible_agents[0]

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        self._new_game(seed)
        self.agents = self.possible_agents[:]
        self.rewards = dict.fromkeys(self.agents, 0.0)
        self._cumulative_rewards = dict.fromkeys(self.agents, 0.0)
        self.terminations = dict.fromkeys(self.agents, False)
        self.truncations = dict.fromkeys(self.agents, False)
        self.infos = {a: self._info(i) for i, a in enumerate(self.agents)}
        self.agent_selection = self.agents[0]
        self._skip_agent_selection = None

    def observe(self, agent: str) -> np.ndarray:
        return self.core.observe()[self._index[agent], 0]

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        buf = self._noop.copy()
        self._put(buf, agent, action)
        core = self.core
        rewards = core.step(buf)
        self._cumulative_rewards[agent] = 0.0
        for a in self.agents:
            i = self._index[a]
            self.rewards[a] = float(rewards[i, 0])
            ended = bool(core.result[i, 0] != FLYING)
            self.terminations[a] = ended
            self.truncations[a] = bool(core.truncated[0]) and not ended
            self.infos[a] = self._info(i)
        flying = [a for a in self.agents if not (self.terminations[a] or self.truncations[a])]
        if flying:  # the next lander still flying after this one, in seat order
            after = [a for a in flying if self._index[a] > self._index[agent]]
            self.agent_selection = (after or flying)[0]
        self._accumulate_rewards()
        self._deads_step_first()


def _renderer():
    from .lander_render import LanderRenderer

    return LanderRenderer()


LANDER = EnvSpec(
    name="lander",
    description="Multi-agent Lunar Lander (seed 001): gymnasium's lander for 1-8 landers in one Box2D world, one team",
    agents=AGENTS,
    make_config=make_config,
    make_core=LanderCore,
    make_parallel=LanderParallelEnv,
    observation_space=observation_space,
    action_space=action_space,
    make_renderer=_renderer,
    bots={
        "heuristic": BotSpec("heuristic", "gymnasium's heuristic lander controller, each lander on its own "
                             "observation (its continuous form with continuous=true)", heuristic_rule,
                             make_rule=lambda cfg: heuristic_continuous_rule if cfg.continuous else heuristic_rule),
    },  # random: marl's own, uniform over the config's action space (discrete or continuous)
    turns="simultaneous",
    kind="cooperative",
    render_fps=FPS,
    make_agents=lambda cfg: agents(cfg.landers),  # landers=M: M seats (a team trained with N flies M)
    anchor="heuristic",  # the ratings' zero point: seed 001's heuristic
    # No neutral options: each changes the flight, the score (the summed rewards) or how the heuristic flies.
    # PPO for the lander (benchmarks/lander_modes.py; FuPS, 2 landers, mean return per lander of the most likely
    # action over 100 games): rewards of +-100 scaled to order 1 (unscaled, the value loss swamps the policy's
    # gradient in the shared trunk: 25 after 6M steps; scaled, 197), 10 epochs of 8 minibatches (189 after 4M
    # steps, 165 with 4 of 4), the long horizon gymnasium's lander wants (gamma 0.999), a constant step; 64 games.
    train_defaults={"games": 64, "ppo": {"lr": 5e-4, "anneal_lr": False, "gamma": 0.999, "rollout_steps": 256,
                                         "update_epochs": 10, "minibatches": 8, "reward_scale": 0.01}},
)
"""The lander game's declaration (registered as ``lander``)."""
