"""Scripted players: what one is (:class:`BotSpec`, a rule from a batch of one seat's observations to actions) and
the ``random`` player any game can have (:func:`random_rule`, :func:`random_bot`), for every action space `marl`
plays. A game lists its scripted players in its declaration (``EnvSpec.bots``); the built-in games' own rules are in
their ``bots`` modules.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from .seat_spaces import check_action, describe_space

BotRule = Callable[..., np.ndarray]


@dataclass(frozen=True)
class BotSpec:
    """A scripted player: a rule from a batch of one seat's observations (and a generator) to actions.

    With ``uses_mask`` the rule also takes the seat's action masks (``rule(obs, rng, mask)``, mask None when the
    seat has none); without, ``rule(obs, rng)``. ``make_rule(cfg)``, where given, is the rule for a config whose
    options change how the player must act (the lander's ``continuous=true``); ``rule`` is the default config's."""

    name: str
    description: str
    rule: BotRule
    uses_mask: bool = False
    make_rule: Callable[[Any], BotRule] | None = None

    def rule_for(self, cfg: Any) -> BotRule:
        return self.rule if self.make_rule is None else self.make_rule(cfg)


def random_rule(action_space: spaces.Space) -> BotRule:
    """Uniformly random actions for any supported action space: Discrete (uniform over the actions the mask
    allows, when given one), MultiDiscrete (each dimension uniform) and Box (uniform within its bounds).

    The rule is ``rule(obs, rng, mask=None)``; without a mask a Discrete rule draws ``rng.integers(0, n)``."""
    if isinstance(action_space, spaces.Discrete):
        n = int(action_space.n)

        def discrete(obs: np.ndarray, rng: np.random.Generator, mask: np.ndarray | None = None) -> np.ndarray:
            if mask is None:
                return rng.integers(0, n, size=len(obs))
            allowed = np.asarray(mask, dtype=bool).reshape(len(obs), n)
            counts = allowed.sum(axis=1)
            if (counts == 0).any():
                raise ValueError("the random player was given a mask that allows no action")
            # The k-th allowed action, k uniform in [0, count): one draw per row.
            k = np.floor(rng.random(len(obs)) * counts).astype(np.int64)
            return (np.cumsum(allowed, axis=1) > k[:, None]).argmax(axis=1).astype(np.int64)

        return discrete
    if isinstance(action_space, spaces.MultiDiscrete):
        nvec = action_space.nvec.astype(np.int64)

        def multi(obs: np.ndarray, rng: np.random.Generator, mask: np.ndarray | None = None) -> np.ndarray:
            return rng.integers(0, nvec, size=(len(obs), len(nvec)))

        return multi
    if isinstance(action_space, spaces.Box):
        check_action(action_space)
        low, high = action_space.low.astype(np.float32), action_space.high.astype(np.float32)

        def box(obs: np.ndarray, rng: np.random.Generator, mask: np.ndarray | None = None) -> np.ndarray:
            u = rng.random((len(obs), *low.shape), dtype=np.float32)
            return np.clip(low + u * (high - low), low, high)

        return box
    raise TypeError(f"the random player has no rule for action space {describe_space(action_space)}")


def random_bot(action_space: spaces.Space, description: str = "uniformly random legal actions") -> BotSpec:
    """The ``random`` scripted player of a game with this action space (mask-aware)."""
    return BotSpec("random", description, random_rule(action_space), uses_mask=True)
