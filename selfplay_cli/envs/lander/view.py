"""The lander game's PettingZoo views: a ``ParallelEnv`` (all landers act at every physics step, the game marl
trains and rates) and an ``AECEnv`` (the sequential version: one lander acts, the world steps, the next lander acts).
Both play one game with :class:`~selfplay_cli.envs.lander.scalar.ScalarLander` (the batched core's rules in plain
Python floats around the same Box2D world: the core's game for the same seed, step for step and bit for bit; 3 to 6
times faster than a batch of one, fewer landers gaining more: benchmarks/lander_env_speed.py).

In the AEC view a lander acts once every N physics steps (N landers), so with gymnasium's engines gravity wins
from 3 landers on: the game cannot be solved. The view therefore sets ``engine_scale`` to N unless told otherwise:
one turn's impulse (and fuel) is N frames' worth. Its time limit ``max_steps`` counts physics steps, as in the
parallel game.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
from pettingzoo import AECEnv

from ..view import OneGame, OneGameView
from .config import FLYING, FPS, RESULT_NAMES, LanderConfig, action_space, agents, make_config, observation_space
from .render import LanderRenderer
from .scalar import ScalarLander


class _LanderGame(OneGame):
    """What both views share: one game (``self.game``), the landers' actions and infos."""

    game_name = "lander"
    renderer = LanderRenderer

    def _setup_lander(self, render_mode: str | None, config: LanderConfig) -> None:
        self._check_render_mode(render_mode)
        self._setup(render_mode, config, agents(config.landers), observation_space(config), action_space(config))
        self.game = ScalarLander(config)
        self._noop: Any = (0.0, 0.0) if config.continuous else 0  # a lander given no action fires no engine

    def _action(self, agent: str, action: Any) -> Any:
        if self.config.continuous:
            a = np.asarray(action, dtype=np.float32).reshape(-1)
            if a.shape != (2,) or not np.isfinite(a).all():
                raise ValueError(f"{agent}: a continuous lander action is 2 finite numbers, not {action!r}")
            return a.tolist()
        a = int(action)
        if not 0 <= a < 4:
            raise ValueError(f"{agent}: lander actions are 0 no-op, 1 left, 2 main, 3 right; not {action!r}")
        return a

    def _start(self, seed: int) -> None:
        self.game.reset(seed)

    def _ended(self, seat: int) -> bool:
        return self.game.result[seat] != FLYING

    def _cut(self) -> bool:
        return self.game.truncated

    def _observe(self) -> np.ndarray:
        return self.game.observe()

    def _info(self, seat: int) -> dict[str, Any]:
        return {"result": RESULT_NAMES[self.game.result[seat]], "seed": self.game_seed}

    @property
    def core(self) -> SimpleNamespace:
        """This game as a one-game :class:`~.core.LanderCore` shows it: the core's attributes, its arrays
        ``(n_seats, 1)`` (``result``, ``alive``, ``score``, ``state``, the engines' powers) and ``(1,)`` (``steps``,
        ``terminated``, ``truncated``, ``over``), and ``worlds`` (this game's world). A snapshot (what the renderer
        draws), not a core: Box2D's world cannot be copied into one."""
        g = self.game

        def col(values: list, dtype: Any = np.float64) -> np.ndarray:
            return np.array(values, dtype=dtype)[:, None]

        return SimpleNamespace(
            config=g.config, n=1, n_seats=g.n_seats, continuous=g.continuous, worlds=[g.world],
            result=col(g.result, np.int8), alive=col(g.alive, bool), score=col(g.score), state=col(g.state),
            main_power=col(g.main_power), side_power=col(g.side_power), side_dir=col(g.side_dir),
            steps=np.array([g.steps]), terminated=np.array([g.terminated]), truncated=np.array([g.truncated]),
            over=np.array([g.over]))

    def _scene(self) -> SimpleNamespace:
        return self.core

    def _at_start(self) -> bool:
        return self.game.steps == 0  # (Box2D's world cannot be copied: a copy is rebuilt from the game's seed)


class LanderParallelEnv(_LanderGame, OneGameView):
    """N landers acting together (agents ``lander_0`` ..); see :mod:`selfplay_cli.envs.lander` for the rules.

    A lander leaves ``agents`` on the step it ends (crash, out of bounds, at rest); every lander still flying is
    truncated at ``max_steps``. Rewards are each lander's own; the team's return is their sum. ``reset(seed=s)``
    makes the game reproducible (it is the batched core's game with seed ``s``); later resets without a seed draw
    game seeds from a generator seeded by ``s``. Infos carry how each lander ended and the game's seed.
    """

    metadata = {"name": "marl_lander_v0", "render_modes": ["rgb_array"], "render_fps": FPS,
                "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self._setup_lander(render_mode, make_config(**options))

    def _play(self, actions: dict[str, Any]) -> tuple[float, ...]:
        acts = [self._noop] * self.game.n_seats
        index = self._index
        for agent in self.agents:
            if agent in actions:
                acts[index[agent]] = self._action(agent, actions[agent])
        return self.game.step(acts)

    def state(self) -> np.ndarray:
        """The global state: every lander's observation, concatenated (seat order)."""
        return self.game.observe().reshape(-1)


class LanderAECEnv(_LanderGame, AECEnv):
    """The sequential lander game: landers take turns; each turn fires that lander's engines (scaled by
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
        self._setup_lander(render_mode, make_config(**opts))
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
        return self.game.observe()[self._index[agent]]

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        acts = [self._noop] * self.game.n_seats
        acts[self._index[agent]] = self._action(agent, action)
        rewards = self.game.step(acts)
        self._cumulative_rewards[agent] = 0.0
        cut = self._cut()
        for a in self.agents:
            i = self._index[a]
            self.rewards[a] = rewards[i]
            ended = self._ended(i)
            self.terminations[a] = ended
            self.truncations[a] = cut and not ended
            self.infos[a] = self._info(i)
        flying = [a for a in self.agents if not (self.terminations[a] or self.truncations[a])]
        if flying:  # the next lander still flying after this one, in seat order
            after = [a for a in flying if self._index[a] > self._index[agent]]
            self.agent_selection = (after or flying)[0]
        self._accumulate_rewards()
        self._deads_step_first()
