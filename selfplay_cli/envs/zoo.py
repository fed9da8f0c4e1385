"""marl's built-in games offered the way PettingZoo offers its own: a module per game and version
(``selfplay_cli.envs.pong_v0``, ``lander_v0``, ``tennis_v0``), each with ``parallel_env(render_mode=None,
**options)`` (the game's PettingZoo ``ParallelEnv``: its view), ``raw_env`` (the same game through PettingZoo's
``parallel_to_aec``: the AEC API, every seat acting in turn and the game stepping once all have) and ``env``
(``raw_env`` behind PettingZoo's ``OrderEnforcingWrapper``, as PettingZoo's ``env()`` factories give), and ``metadata``.

The options are the game's own (``marl envs GAME`` lists them; the docs' games page says what each does), checked as the
game checks them: an unknown option or a bad value is one ``ValueError`` naming it. A game's version changes when its
rules change so that the same options and seed no longer play the same game.

:class:`black_death` keeps every seat of a game in play until the game ends (an ended seat sees zeros and earns
nothing), as vector wrappers of a fixed number of agents need (SuperSuit's ``pettingzoo_env_to_vec_env_v1``): the
lander's landers end one by one. It is SuperSuit's ``black_death_v3`` with the end of a game that SuperSuit 3.11 misses
(it ends a game only when every seat is both terminated and truncated, so a game whose landers all land or crash was
stepped past its end; mended in SuperSuit's pull request 265, not yet released).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec
from pettingzoo.utils.wrappers import BaseParallelWrapper, OrderEnforcingWrapper


def factories(view: type, module: str) -> tuple[dict[str, Any], Any, Any, Any]:
    """A game module's ``metadata`` (its view's: name, render modes, frames a second, ``is_parallelizable``) and its
    three factories, ``parallel_env``, ``raw_env`` and ``env``, for the one-game view class ``view``, named as the
    module ``module``'s own functions (so that pickle finds them by name, as it finds PettingZoo's)."""

    def parallel_env(render_mode: str | None = None, **options: Any) -> ParallelEnv:
        """The game's PettingZoo ``ParallelEnv`` (render mode ``None`` or ``"rgb_array"``)."""
        return view(render_mode=render_mode, **options)

    def raw_env(render_mode: str | None = None, **options: Any) -> AECEnv:
        """The same game through PettingZoo's AEC API (``parallel_to_aec``: one seat acting at a time)."""
        return parallel_to_aec(parallel_env(render_mode, **options))

    def env(render_mode: str | None = None, **options: Any) -> AECEnv:
        """``raw_env`` behind PettingZoo's order check (reset before step, and so on), as PettingZoo's own ``env()``
        factories give."""
        return OrderEnforcingWrapper(raw_env(render_mode, **options))

    for f in (parallel_env, raw_env, env):
        f.__module__, f.__qualname__ = module, f.__name__
    return dict(view.metadata), parallel_env, raw_env, env


class black_death(BaseParallelWrapper):  # (named as SuperSuit names its wrapper)
    """A ``ParallelEnv`` whose seats all stay in ``agents`` until the game ends: a seat that has ended observes
    zeros, earns 0 and its actions are ignored; on the step the game ends every seat is terminated (a seat the game
    cut, truncated) and ``agents`` empties. Observation spaces must be ``Box`` (the zeros are of their shape)."""

    def __init__(self, env: ParallelEnv) -> None:
        super().__init__(env)
        self._zeros = {}
        for agent in env.possible_agents:
            space = env.observation_space(agent)
            if not isinstance(space, spaces.Box):
                raise TypeError(f"black_death needs Box observations (an ended seat sees zeros); {agent} has {space}")
            self._zeros[agent] = np.zeros(space.shape, space.dtype)
        self.agents: list = []
        self._cut: set = set()

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        self.agents = list(self.env.possible_agents)
        self._cut = set()
        return ({a: obs.get(a, self._zeros[a]) for a in self.agents}, {a: infos.get(a, {}) for a in self.agents})

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        playing = list(self.env.agents)
        obs, rewards, terms, truncs, infos = self.env.step({a: actions[a] for a in playing if a in actions})
        self._cut |= {a for a in playing if truncs.get(a, False)}
        over = not self.env.agents
        agents = self.agents
        out = ({a: obs.get(a, self._zeros[a]) for a in agents}, {a: float(rewards.get(a, 0.0)) for a in agents},
               {a: over and a not in self._cut for a in agents}, {a: over and a in self._cut for a in agents},
               {a: infos.get(a, {}) for a in agents})
        if over:
            self.agents = []
        return out
