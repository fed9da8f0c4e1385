"""The one-game PettingZoo view every built-in game is offered through (its ``EnvSpec.make_parallel``).

:class:`OneGame` holds what any view of one game needs, whatever PettingZoo API it speaks: the config, the seats and
their spaces, the game seeds (``reset(seed=s)`` plays game ``s``; later resets without a seed draw game seeds from a
generator seeded by ``s``), the offscreen renderer. :class:`OneGameView` is the ``ParallelEnv``: every seat acts at
each step, a seat leaves ``agents`` on the step it ends, and every seat still playing is truncated when the game is.
Each game's view plays its one game with a scalar copy of its batched core's rules (faster for one game: the same
game, step for step, which its tests hold against the core) and gives the hooks below.

A game's view sets ``game_name`` (in messages), ``metadata`` and ``renderer`` (a class whose ``draw(scene, 0)``
returns an RGB array), calls :meth:`OneGame._setup` from its ``__init__`` and provides the hooks: ``_start(seed)``
(begin a game), ``_info(seat)``, ``_scene()`` (what the renderer draws), and for :class:`OneGameView`
``_play(actions)`` (one step: each seat's reward), ``_observe()`` (each seat's observation), ``_ended(seat)`` and
``_cut()`` (the game was truncated on this step).

A view is copied (``copy.deepcopy``, ``pickle``, ``cloudpickle``: SuperSuit's vector envs copy the env they are given
once per game and send it to their worker processes; RLlib's env runners do the like) as what made it and where its
game stands (:meth:`OneGame.__reduce__`): a view never reset is the same game made afresh from its options and render
mode, with randomness of its own (copies of it play different games, as views made alike do); a reset view's copy
also holds its game seed and its seed generator, and the game itself: exactly (:class:`SavedState`, a game that gives
and takes its state) or, for a game that cannot (Box2D's world), rebuilt from its seed while it has not been stepped
since ``reset``, and refused with one clear error once it has.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv


class OneGame(ABC):
    """The config, seats, spaces, seeds and renderer of one game (mixed into a ParallelEnv or an AECEnv)."""

    game_name: ClassVar[str]
    renderer: ClassVar[Any]

    def _setup(self, render_mode: str | None, config: Any, agents: Sequence[str], observation_space: spaces.Space,
               action_space: spaces.Space) -> None:
        self.render_mode = render_mode
        self.config = config
        self.possible_agents = list(agents)
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self._obs_space = observation_space
        self._act_space = action_space
        self._seeds = np.random.default_rng()
        self._renderer: Any = None
        self.game_seed: int | None = None

    def _check_render_mode(self, render_mode: str | None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"{self.game_name} renders only 'rgb_array' (offscreen), not {render_mode!r}")

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
        self._start(self.game_seed)

    @abstractmethod
    def _start(self, seed: int) -> None:
        """A game's hook (see the module docstring)."""

    @abstractmethod
    def _info(self, seat: int) -> dict[str, Any]:
        """A game's hook (see the module docstring)."""

    @abstractmethod
    def _scene(self) -> Any:
        """A game's hook (see the module docstring)."""

    def render_frame(self) -> np.ndarray:
        if self._renderer is None:
            self._renderer = self.renderer()
        return self._renderer.draw(self._scene(), 0)

    def render(self) -> np.ndarray | None:
        return self.render_frame() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self._renderer = None

    def __reduce__(self) -> tuple[Any, ...]:
        """A copy: the view made afresh from its options and render mode, then put where this one's game stands (see
        the module docstring). Raises ``TypeError`` for a game under way that cannot give its state."""
        options = {f.name: getattr(self.config, f.name) for f in dataclasses.fields(self.config) if f.init}
        return (_remade, (type(self), self.render_mode, options, self._copied_state()))

    def _copied_state(self) -> dict[str, Any] | None:
        if self.game_seed is None:  # never reset: the copy draws its games from randomness of its own
            return None
        return {"game_seed": self.game_seed, "seeds": self._seeds.bit_generator.state, "agents": list(self.agents),
                "game": self._game_state()}

    def _game_state(self) -> Any:
        """The game's state for a copy (``None``: rebuilt from its seed). A game that cannot give its state is copied
        at its start (:meth:`_at_start`) or once over (the copy is ready for ``reset``), never under way."""
        if self.agents and not self._at_start():
            raise TypeError(f"a {self.game_name} view cannot be copied (pickled) with a game under way: its game "
                            "cannot give its state. Copy it before reset() or right after one, or make a new view")
        return None

    def _at_start(self) -> bool:
        """Whether the game has not been stepped since ``reset`` (a game without a saved state overrides it)."""
        return False

    def _restore(self, state: dict[str, Any]) -> None:
        """Put a copy where the original's game stood (:meth:`__reduce__`)."""
        self.reset(seed=state["game_seed"])
        if state["game"] is not None:
            self.game.set_state(state["game"])
        self.agents = list(state["agents"])
        self._seeds.bit_generator.state = state["seeds"]


def _remade(cls: type, render_mode: str | None, options: dict[str, Any], state: dict[str, Any] | None) -> OneGame:
    """A view's copy (:meth:`OneGame.__reduce__`)."""
    view = cls(render_mode=render_mode, **options)
    if state is not None:
        view._restore(state)
    return view


class OneGameView(OneGame, ParallelEnv):
    """One game as a PettingZoo ``ParallelEnv`` (see the module docstring for what a game provides)."""

    def reset(self, seed: int | None = None, options: dict | None = None):
        self._new_game(seed)
        self.agents = self.possible_agents[:]
        obs = self._observe()
        return ({a: obs[i] for i, a in enumerate(self.agents)},
                {a: self._info(i) for i, a in enumerate(self.agents)})

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        rewards = self._play(actions)
        obs = self._observe()
        cut = self._cut()
        out_obs, out_rew, term, trunc, infos = {}, {}, {}, {}, {}
        index, ended_of, info_of = self._index, self._ended, self._info
        playing = []
        for agent in self.agents:
            i = index[agent]
            out_obs[agent] = obs[i]
            out_rew[agent] = float(rewards[i])
            ended = ended_of(i)
            term[agent] = ended
            trunc[agent] = cut and not ended
            infos[agent] = info_of(i)
            if not (ended or cut):
                playing.append(agent)
        self.agents = playing
        return out_obs, out_rew, term, trunc, infos

    @abstractmethod
    def _play(self, actions: dict[str, Any]) -> Sequence[float]:
        """A game's hook (see the module docstring)."""

    @abstractmethod
    def _observe(self) -> Sequence[np.ndarray]:
        """A game's hook (see the module docstring)."""

    @abstractmethod
    def _ended(self, seat: int) -> bool:
        """A game's hook (see the module docstring)."""

    @abstractmethod
    def _cut(self) -> bool:
        """A game's hook (see the module docstring)."""


class SavedState:
    """``get_state`` / ``set_state`` for a view whose one game (``self.game``) can give and take its exact state
    (pong's and tennis's scalar games): the game's state, the seats still playing and the game's seed. Such a view
    is copied with its game exactly where it stands, under way or not."""

    game: Any
    agents: list[str]
    game_seed: int | None

    def get_state(self) -> dict[str, Any]:
        """Exact state of the game (its own format), the seats still playing and the game's seed."""
        return {"core": self.game.get_state(), "agents": list(self.agents), "game_seed": self.game_seed}

    def set_state(self, state: dict[str, Any]) -> None:
        self.game.set_state(state["core"])
        self.agents = list(state["agents"])
        self.game_seed = state["game_seed"]

    def _game_state(self) -> Any:
        return self.game.get_state()
