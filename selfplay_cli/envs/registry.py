"""The game registry: one :class:`EnvSpec` per game, everything the rest of `marl` needs to know about it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from gymnasium import spaces


class BatchedCore(Protocol):
    """What the arena and the learners use: N games stepped at once, seats on the leading axis."""

    n: int
    n_seats: int
    terminated: np.ndarray  # (n,) bool, set by the last step
    truncated: np.ndarray  # (n,) bool
    score: np.ndarray  # (n_seats, n)
    steps: np.ndarray  # (n,) steps played in each game

    def reset(self, games: Any, seeds: Any) -> None: ...
    def step(self, actions: np.ndarray) -> np.ndarray: ...
    def observe(self) -> np.ndarray: ...
    def outcome(self) -> np.ndarray: ...


BotRule = Callable[[np.ndarray, np.random.Generator], np.ndarray]


@dataclass(frozen=True)
class BotSpec:
    """A scripted player: a rule from a batch of one seat's observations (and a generator) to actions."""

    name: str
    description: str
    rule: BotRule


@dataclass(frozen=True)
class EnvSpec:
    name: str
    description: str
    agents: tuple[str, ...]
    make_config: Callable[..., Any]
    make_core: Callable[[int, Any], BatchedCore]
    make_parallel: Callable[..., Any]
    observation_space: Callable[[Any], spaces.Space]
    action_space: Callable[[Any], spaces.Space]
    make_renderer: Callable[[], Any] | None = None
    bots: dict[str, BotSpec] = field(default_factory=dict)

    def config(self, **options: Any) -> Any:
        return self.make_config(**options)

    def core(self, n_games: int, **options: Any) -> BatchedCore:
        return self.make_core(n_games, self.make_config(**options))


class UnknownEnvError(KeyError):
    def __init__(self, name: str, known: list[str]) -> None:
        super().__init__(name)
        self.name = name
        self.known = known

    def __str__(self) -> str:
        return f"unknown env '{self.name}'; registered: {', '.join(self.known)}"


_REGISTRY: dict[str, EnvSpec] = {}


def register(spec: EnvSpec) -> EnvSpec:
    if spec.name in _REGISTRY:
        raise ValueError(f"env {spec.name!r} is already registered")
    _REGISTRY[spec.name] = spec
    return spec


def get_env(name: str) -> EnvSpec:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownEnvError(name, sorted(_REGISTRY)) from None


def env_names() -> list[str]:
    return sorted(_REGISTRY)


def random_rule(action_space: spaces.Space) -> BotRule:
    """Uniformly random actions for a discrete action space."""
    if not isinstance(action_space, spaces.Discrete):
        raise TypeError("the random bot needs a Discrete action space")
    n = int(action_space.n)

    def rule(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rng.integers(0, n, size=len(obs))

    return rule
