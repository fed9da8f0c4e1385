"""Scripted players as policies: fixed anchors of the league.

A scripted player is the game's registered rule (given the seat's action masks when it declares ``uses_mask``).
``random`` is defined for every game and every action space, whether or not the game registers it: a game that
does not is played by :class:`RandomPolicy`: uniform over the allowed actions of a Discrete space (under the mask),
per dimension for MultiDiscrete, uniform in a bounded Box.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from ..envs import get_env
from ..errors import MarlError
from .base import Policy
from .spaces import ActionHead, SpaceError, describe_space, uniform_allowed

RANDOM = "random"


def league_bots(spec: Any) -> list[str]:
    """The scripted players a league holds for a game, in the game's order, ``random`` last if it does not
    register its own."""
    return list(dict.fromkeys([*spec.bots, RANDOM]))


def bot_names(spec: Any) -> list[str]:
    """The scripted players of a game: the ones it registers, and ``random``, which every game has."""
    return sorted(set(spec.bots) | {RANDOM})


class RandomPolicy(Policy):
    """Uniformly random actions in ``act_space`` (see the module docstring); mask-aware for categorical actions.

    Without a mask a Discrete seat draws ``rng.integers(0, n, size=batch)``, exactly as the registered ``random``
    rule of pong always has, so games against it replay unchanged."""

    kind = "bot"

    def __init__(self, act_space: spaces.Space, id: str = RANDOM, env: str = "", seed: int = 0,
                 obs_space: spaces.Space | None = None) -> None:
        super().__init__(id, env, obs_space=obs_space, act_space=act_space)
        try:
            self.head = ActionHead.of(act_space)
        except SpaceError as e:
            raise MarlError(f"the random player cannot play {env or 'this game'}: {e}") from None
        self.rng = np.random.default_rng(seed)
        if self.head.kind == "box":
            self.low = np.asarray(act_space.low, dtype=np.float64)
            self.high = np.asarray(act_space.high, dtype=np.float64)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        b = len(obs)
        head = self.head
        m = head.check_mask(mask, b)
        if head.kind == "discrete":
            if m is None:
                return np.asarray(self.rng.integers(0, head.nvec[0], size=b), dtype=np.int64)
            return uniform_allowed(m, self.rng.random(b))
        if head.kind == "multidiscrete":
            nvec = np.asarray(head.nvec)
            if m is None:
                return self.rng.integers(0, nvec, size=(b, len(nvec))).astype(np.int64)
            out = np.empty((b, len(nvec)), dtype=np.int64)
            u = self.rng.random((b, len(nvec)))
            offset = 0
            for j, n in enumerate(head.nvec):
                out[:, j] = uniform_allowed(m[:, offset:offset + n], u[:, j])
                offset += n
            return out
        a = self.rng.uniform(self.low, self.high, size=(b, *head.shape))
        return np.clip(a, self.low, self.high).astype(np.float32)


class ScriptedPolicy(Policy):
    """A game's scripted player ``name`` (``random`` for any game: :class:`RandomPolicy` unless the game registers
    its own).

    ``env_options`` configure the game (the seat's spaces depend on them); ``seat`` picks the seat whose spaces it
    plays (default the first). A scripted player plays any seat: the runner asks :meth:`for_seat` for the player
    of each seat, which is this one where that seat's spaces are its own, else a copy bound to that seat (``random``
    where the seats act differently: a hunter's 3 actions, a runner's 5). A rule that returns an action its mask
    forbids is a clear error naming the player."""

    kind = "bot"

    def __init__(self, env: str, name: str, seed: int = 0, env_options: dict[str, Any] | None = None,
                 seat: int | None = None) -> None:
        spec = get_env(env)
        if name not in spec.bots and name != RANDOM:
            known = ", ".join(bot_names(spec))
            raise KeyError(f"{env} has no scripted player '{name}'; it has: {known}")
        super().__init__(name, env)
        self._name, self._seat, self._seed, self._options = name, seat, seed, dict(env_options or {})
        self._by_seat: dict[int, ScriptedPolicy] = {}
        self._setup(spec, name, seed, self._options, seat)

    def for_seat(self, seat: int) -> ScriptedPolicy:
        """The player of seat ``seat``: itself where that seat reads and acts as its own, else a copy bound to the
        seat, drawing from the same generator (so a game's draws do not depend on how its seats are grouped)."""
        player = self._by_seat.get(seat)
        if player is None:
            spec = get_env(self.env).for_options(**self._options)
            space = spec.seat_spaces(spec.config(**self._options))[seat]
            same = (tuple(space.observation.shape) == tuple(self.obs_space.shape)
                    and describe_space(space.action) == describe_space(self.act_space))
            player = self if same else ScriptedPolicy(self.env, self._name, self._seed, self._options, seat=seat)
            self._by_seat[seat] = player
        if player is not self:
            player.rng = self.rng
            if player._random is not None:
                player._random.rng = self.rng
        return player

    def configure(self, env_options: dict[str, Any] | None) -> None:
        """Play the game as ``env_options`` make it (the runner tells every player the options of the games it
        plays): a rule or action space that depends on them follows. The random generator carries on."""
        options = dict(env_options or {})
        if options != self._options:
            rng = self.rng
            self._options = options
            self._by_seat = {}
            self._setup(get_env(self.env), self._name, self._seed, options, self._seat)
            self.rng = rng
            if self._random is not None:
                self._random.rng = rng

    def _setup(self, spec: Any, name: str, seed: int, env_options: dict[str, Any], seat: int | None) -> None:
        env = spec.name
        cfg = spec.config(**env_options)
        space = spec.for_options(**env_options).seat_spaces(cfg)[seat if seat is not None else 0]
        self.obs_space, self.act_space = space.observation, space.action
        self.rng = np.random.default_rng(seed)
        self.bot = spec.bots.get(name)
        self._random = None
        if self.bot is None:  # random, which the game does not register
            self._random = RandomPolicy(space.action, name, env, seed=seed, obs_space=space.observation)
            self._random.rng = self.rng
        self._uses_mask = bool(getattr(self.bot, "uses_mask", False))
        self._rule = self.bot.rule_for(cfg) if self.bot is not None else None

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        if self._random is not None:
            return self._random.act(obs, mask)
        if self._uses_mask:
            actions = self._rule(obs, self.rng, mask)  # type: ignore[misc]
        else:
            actions = self._rule(obs, self.rng)  # type: ignore[misc]
        if isinstance(self.act_space, spaces.Box):
            return np.asarray(actions, dtype=np.float32)
        actions = np.asarray(actions, dtype=np.int64)
        if mask is not None and isinstance(self.act_space, spaces.Discrete):
            m = np.asarray(mask, dtype=bool)
            if not m[np.arange(len(actions)), actions].all():
                raise MarlError(f"scripted player {self.id} of {self.env} chose an action its mask forbids")
        return actions
