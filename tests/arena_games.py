"""Small batched games of every shape, written for the arena's and the league's tests (not PettingZoo envs: cores
that keep the game contract directly, so every result can be worked out by hand).

- ``arena-ffa3``: free-for-all, 3 seats acting together, MultiDiscrete([3, 2]) actions. 4 steps; each step a seat
  scores ``(a0 + 3 a1) * w`` with ``w`` 1 or 2 by the seed and step (``w`` sums to 6 over a game, whatever the seed),
  so a policy that always plays ``(k, j)`` ends with ``6 (k + 3 j)``.
- ``arena-coop2``: cooperative, 2 seats acting together, Box(-1, 1, (2,)) actions, tie tolerance 0.5. 5 steps, then
  the game is cut by its time limit (truncated); each step a seat scores ``a0 + a1``, so a policy that always plays
  ``(x, y)`` flies a team return of ``10 (x + y)``.
- ``arena-seq2``: two-sides, 2 seats in turns (seat 0 on even steps, seat 1 on odd ones), Discrete(4) with masks:
  each move takes one of the numbers 0..3 not taken yet, and scores it for the mover; 4 moves. Observations: which
  numbers are taken, and whether it is the seat's turn. Taking a taken number raises ``IllegalActionError``.
- ``arena-sides4``: two-sides, 4 seats, sides (0, 1) against (2, 3), Discrete(3) actions; 3 steps, each seat scores
  its action.

- ``arena-rps``: two-sides, 2 seats acting together, Discrete(3): rock-paper-scissors, one throw a game (0 rock, 1
  paper, 2 scissors; paper beats rock, scissors paper, rock scissors): the winner scores +1, the loser -1.

Each game has scripted players: ``high`` and ``low`` (and ``mid`` for arena-coop2), constant or, in arena-seq2, the
highest / lowest number still free; arena-rps has ``rock``, which always throws rock (its counter: paper, every
time).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from types import SimpleNamespace
from typing import Any

import numpy as np
from gymnasium import spaces

from selfplay_cli.envs import BotSpec, EnvSpec, IllegalActionError, SeatSpace, UnknownEnvError, get_env, register
from selfplay_cli.envs.loading import _REGISTRY
from selfplay_cli.policies import Policy


class _Core:
    """What every test core shares: N games, seats on the leading axis, a fixed length."""

    obs_dim = 2

    def __init__(self, n: int, n_seats: int, length: int) -> None:
        self.n, self.n_seats, self.length = n, n_seats, length
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        self.score = np.zeros((n_seats, n))
        self.steps = np.zeros(n, dtype=np.int64)
        self.seed = np.zeros(n, dtype=np.int64)

    def reset(self, games: Any, seeds: Any) -> None:
        g = np.asarray(games, dtype=np.int64)
        self.score[:, g] = 0.0
        self.steps[g] = 0
        self.terminated[g] = self.truncated[g] = False
        self.seed[g] = np.asarray(seeds, dtype=np.int64)

    @property
    def running(self) -> np.ndarray:
        return ~(self.terminated | self.truncated)

    def observe(self) -> np.ndarray:
        obs = np.zeros((self.n_seats, self.n, self.obs_dim), dtype=np.float32)
        obs[:, :, 0] = self.steps / self.length
        obs[:, :, 1] = np.arange(self.n_seats)[:, None]
        return obs

    def action_masks(self) -> list[np.ndarray | None]:
        return [None] * self.n_seats

    def to_act(self) -> np.ndarray:
        return np.broadcast_to(self.running, (self.n_seats, self.n)).copy()

    def _advance(self, live: np.ndarray, gained: np.ndarray) -> np.ndarray:
        rewards = np.zeros((self.n_seats, self.n), dtype=np.float32)
        rewards[:, live] = gained[:, live]
        self.score[:, live] += gained[:, live]
        self.steps[live] += 1
        return rewards


class FFACore(_Core):
    def __init__(self, n: int, cfg: Any) -> None:
        super().__init__(n, 3, 4)

    def step(self, actions: Any) -> np.ndarray:
        a = np.stack([np.asarray(actions[s]) for s in range(3)]).astype(np.float64)  # (3, n, 2)
        live = self.running
        w = 1.0 + (self.seed + self.steps) % 2
        rewards = self._advance(live, (a[..., 0] + 3 * a[..., 1]) * w)
        self.terminated |= live & (self.steps >= self.length)
        return rewards


class CoopCore(_Core):
    def __init__(self, n: int, cfg: Any) -> None:
        super().__init__(n, 2, 5)

    def step(self, actions: Any) -> np.ndarray:
        a = np.stack([np.asarray(actions[s]) for s in range(2)])
        assert a.dtype == np.float32, a.dtype
        live = self.running
        rewards = self._advance(live, a.astype(np.float64).sum(axis=2))
        self.truncated |= live & (self.steps >= self.length)
        return rewards


class SeqCore(_Core):
    obs_dim = 5

    def __init__(self, n: int, cfg: Any) -> None:
        super().__init__(n, 2, 4)
        self.taken = np.zeros((n, 4), dtype=bool)

    def reset(self, games: Any, seeds: Any) -> None:
        super().reset(games, seeds)
        self.taken[np.asarray(games, dtype=np.int64)] = False

    def observe(self) -> np.ndarray:
        obs = np.zeros((2, self.n, 5), dtype=np.float32)
        obs[:, :, :4] = self.taken
        obs[:, :, 4] = self.to_act()
        return obs

    def action_masks(self) -> list[np.ndarray | None]:
        return [~self.taken, ~self.taken]

    def to_act(self) -> np.ndarray:
        acting = np.zeros((2, self.n), dtype=bool)
        g = np.flatnonzero(self.running)
        acting[self.steps[g] % 2, g] = True
        return acting

    def step(self, actions: Any) -> np.ndarray:
        live = np.flatnonzero(self.running)
        seat = self.steps[live] % 2
        chosen = np.asarray(actions)[seat, live]
        for g, s, a in zip(live.tolist(), seat.tolist(), chosen.tolist(), strict=True):
            if not 0 <= a < 4 or self.taken[g, a]:
                raise IllegalActionError(s, g, a)
        gained = np.zeros((2, self.n))
        gained[seat, live] = chosen
        self.taken[live, chosen] = True
        rewards = self._advance(self.running, gained)
        self.terminated |= self.running & (self.steps >= self.length)
        return rewards


class SidesCore(_Core):
    def __init__(self, n: int, cfg: Any) -> None:
        super().__init__(n, 4, 3)

    def step(self, actions: Any) -> np.ndarray:
        a = np.stack([np.asarray(actions[s]) for s in range(4)]).astype(np.float64)
        live = self.running
        rewards = self._advance(live, a)
        self.terminated |= live & (self.steps >= self.length)
        return rewards


class RPSCore(_Core):
    def __init__(self, n: int, cfg: Any) -> None:
        super().__init__(n, 2, 1)

    def step(self, actions: Any) -> np.ndarray:
        a = np.stack([np.asarray(actions[s]) for s in range(2)]).astype(np.int64)
        live = self.running
        first = ((a[0] - a[1]) % 3 == 1).astype(np.float64) - ((a[1] - a[0]) % 3 == 1)
        rewards = self._advance(live, np.stack([first, -first]))
        self.terminated |= live & (self.steps >= self.length)
        return rewards


def _const(action: Any) -> Any:
    return lambda obs, rng: np.repeat(np.asarray(action)[None], len(obs), axis=0)


def _free(highest: bool) -> Any:
    def rule(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        free = obs[:, :4] < 0.5
        order = np.arange(4)[::-1] if highest else np.arange(4)
        return order[np.argmax(free[:, order], axis=1)]

    return rule


def _spec(name: str, core: Any, n_seats: int, obs_dim: int, action: spaces.Space, bots: dict[str, Any],
          **declared: Any) -> EnvSpec:
    obs = spaces.Box(-1.0, 1.0, (obs_dim,), np.float32)
    masked = declared.pop("masked", False)
    return EnvSpec(
        name=name, description=f"{name}: a test game", agents=tuple(f"p{i}" for i in range(n_seats)),
        make_config=lambda **options: SimpleNamespace(**options), make_core=core,
        make_parallel=lambda **options: None, observation_space=lambda cfg: obs, action_space=lambda cfg: action,
        bots={b: BotSpec(b, b, rule) for b, rule in bots.items()},
        make_seat_spaces=lambda cfg: tuple(SeatSpace(obs, action, masked) for _ in range(n_seats)), **declared)


SPECS = {
    "arena-ffa3": lambda: _spec("arena-ffa3", FFACore, 3, 2, spaces.MultiDiscrete([3, 2]),
                                {"high": _const((2, 1)), "low": _const((0, 0))}, kind="free-for-all"),
    "arena-coop2": lambda: _spec("arena-coop2", CoopCore, 2, 2, spaces.Box(-1.0, 1.0, (2,), np.float32),
                                 {"high": _const((1.0, 1.0)), "mid": _const((1.0, 0.0)), "low": _const((-1.0, 0.0))},
                                 kind="cooperative", tie_tolerance=0.5),
    "arena-seq2": lambda: _spec("arena-seq2", SeqCore, 2, 5, spaces.Discrete(4),
                                {"high": _free(True), "low": _free(False)}, turns="sequential", masked=True),
    "arena-sides4": lambda: _spec("arena-sides4", SidesCore, 4, 2, spaces.Discrete(3),
                                  {"high": _const(2), "low": _const(0)}, sides=((0, 1), (2, 3))),
    "arena-rps": lambda: _spec("arena-rps", RPSCore, 2, 2, spaces.Discrete(3), {"rock": _const(0)}),
}


@contextmanager
def registered() -> Iterator[None]:
    """The test games registered for the duration of the block (then removed, so no other test sees them:
    the conformance test and the lists of known games are for real games)."""
    added = []
    for name, make in SPECS.items():
        try:
            get_env(name)
        except UnknownEnvError:
            register(make())
            added.append(name)
    try:
        yield
    finally:
        for name in added:
            _REGISTRY.pop(name, None)


class Const(Policy):
    """Always the same action (a scalar for Discrete seats, a vector for MultiDiscrete and Box seats)."""

    def __init__(self, id: str, env: str, action: Any) -> None:
        super().__init__(id, env)
        self.action = np.asarray(action)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        return np.repeat(self.action[None], len(obs), axis=0)


class Spy(Policy):
    """Plays arena-seq2's highest (or lowest) free number and keeps every batch it was asked to act on."""

    def __init__(self, id: str, env: str, highest: bool = True) -> None:
        super().__init__(id, env)
        self.rule = _free(highest)
        self.calls: list[tuple[np.ndarray, np.ndarray | None]] = []

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        self.calls.append((obs.copy(), None if mask is None else mask.copy()))
        return self.rule(obs, None)


class Random(Policy):
    """Uniform random actions of any Discrete, MultiDiscrete or Box space (under the mask, for Discrete ones)."""

    def __init__(self, id: str, env: str, space: spaces.Space, seed: int) -> None:
        super().__init__(id, env)
        self.space, self.rng = space, np.random.default_rng(seed)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        b = len(obs)
        if isinstance(self.space, spaces.Box):
            return self.rng.uniform(self.space.low, self.space.high, (b, *self.space.shape)).astype(np.float32)
        if isinstance(self.space, spaces.MultiDiscrete):
            return self.rng.integers(0, self.space.nvec, (b, len(self.space.nvec)))
        if mask is None:
            return self.rng.integers(0, int(self.space.n), b)
        return np.array([self.rng.choice(np.flatnonzero(m)) for m in mask], dtype=np.int64)
