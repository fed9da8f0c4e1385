"""The lander game's PettingZoo views: a ``ParallelEnv`` (all landers act at every physics step, the game marl
trains and rates) and an ``AECEnv`` (the sequential version: one lander acts, the world steps, the next lander acts).
Both play one game of :class:`~selfplay_cli.envs.lander.core.LanderCore`.

In the AEC view a lander acts once every N physics steps (N landers), so with gymnasium's engines gravity wins
from 3 landers on: the game cannot be solved. The view therefore sets ``engine_scale`` to N unless told otherwise:
one turn's impulse (and fuel) is N frames' worth. Its time limit ``max_steps`` counts physics steps, as in the
parallel game.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from pettingzoo import AECEnv

from ..view import CoreGame, OneGameView
from .config import FLYING, FPS, RESULT_NAMES, LanderConfig, action_space, agents, make_config, observation_space
from .core import LanderCore
from .render import LanderRenderer


class _LanderGame(CoreGame):
    """What both views share: one game of the core, the landers' actions and infos."""

    game_name = "lander"
    renderer = LanderRenderer

    def _setup_lander(self, render_mode: str | None, config: LanderConfig) -> None:
        self._check_render_mode(render_mode)
        self._setup(render_mode, config, agents(config.landers), observation_space(config), action_space(config))
        self._setup_core(LanderCore(1, config),
                         np.zeros((config.landers, 1, 2), dtype=np.float32) if config.continuous
                         else np.zeros((config.landers, 1), dtype=np.int64))

    def _action(self, agent: str, action: Any) -> Any:
        if self.config.continuous:
            a = np.asarray(action, dtype=np.float32).reshape(-1)
            if a.shape != (2,) or not np.isfinite(a).all():
                raise ValueError(f"{agent}: a continuous lander action is 2 finite numbers, not {action!r}")
            return a
        a = int(action)
        if not 0 <= a < 4:
            raise ValueError(f"{agent}: lander actions are 0 no-op, 1 left, 2 main, 3 right; not {action!r}")
        return a

    def _ended(self, seat: int) -> bool:
        return bool(self.core.result[seat, 0] != FLYING)

    def _info(self, seat: int) -> dict[str, Any]:
        return {"result": RESULT_NAMES[int(self.core.result[seat, 0])], "seed": self.game_seed}

    def __reduce__(self) -> tuple[Any, ...]:
        """A copy (``copy.deepcopy``, pickle: SuperSuit's and RLlib's vector wrappers copy the env they are given,
        or send it to their worker processes) is the same game made afresh, from its options and render mode: Box2D's
        world cannot be copied, so a view copied with a game under way is refused (copy it before ``reset``)."""
        if self.agents:
            raise TypeError(f"a {self.game_name} view with a game under way cannot be copied (Box2D's world cannot "
                            "be): copy it before reset(), or make a new one")
        options = {f.name: getattr(self.config, f.name) for f in dataclasses.fields(self.config)}
        return (_remade, (type(self), self.render_mode, options))


def _remade(cls: type, render_mode: str | None, options: dict[str, Any]) -> Any:
    """A lander view made afresh (a copy's :meth:`_LanderGame.__reduce__`)."""
    return cls(render_mode=render_mode, **options)


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

    def state(self) -> np.ndarray:
        """The global state: every lander's observation, concatenated (seat order)."""
        return self.core.observe()[:, 0].reshape(-1)


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
        return self.core.observe()[self._index[agent], 0]

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        buf = self._noop.copy()
        buf[self._index[agent], 0] = self._action(agent, action)
        rewards = self.core.step(buf)
        self._cumulative_rewards[agent] = 0.0
        cut = self._cut()
        for a in self.agents:
            i = self._index[a]
            self.rewards[a] = float(rewards[i, 0])
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
