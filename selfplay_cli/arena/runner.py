"""The batched game runner: plays N games between policies in one batched core.

Training rollouts, evaluation matches and recordings all go through here, so a match, a training episode and a
video of it are the same game.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..policies import Policy


@dataclass(frozen=True)
class Game:
    """One game to play: its seed and, for each seat, the index of the policy that plays it."""

    seed: int
    seats: tuple[int, ...]


@dataclass(frozen=True)
class GameResult:
    """What a finished game leaves in the ledger. ``outcome`` is points per seat: 1 win, 0.5 draw, 0 loss."""

    env: str
    players: tuple[str, ...]
    seed: int
    scores: tuple[int, ...]
    outcome: tuple[float, ...]
    length: int
    truncated: bool
    index: int  # position of the game in the schedule

    def points_of(self, player: str) -> float:
        return sum(o for p, o in zip(self.players, self.outcome, strict=True) if p == player)


def paired_schedule(n_games: int, first_seed: int = 0, n_policies: int = 2) -> list[Game]:
    """Game pairs: each seed is played once with policy 0 on seat 0 and once with the seats swapped."""
    if n_policies != 2:
        raise ValueError("paired schedules are for two policies")
    games = []
    for i in range(n_games):
        seed = first_seed + i // 2
        games.append(Game(seed, (0, 1) if i % 2 == 0 else (1, 0)))
    return games


def play(
    env: str | EnvSpec,
    policies: Sequence[Policy],
    games: Sequence[Game],
    parallel: int = 1024,
    env_options: dict[str, Any] | None = None,
    on_result: Callable[[GameResult], None] | None = None,
    on_step: Callable[[int], None] | None = None,
) -> list[GameResult]:
    """Play ``games`` with up to ``parallel`` of them at once; returns results in schedule order.

    Each step, every policy acts once on the batch of all (game, seat) positions it holds. ``on_result`` is
    called as each game ends (e.g. to store it at once); ``on_step`` with the number of game steps just played.
    """
    spec = get_env(env) if isinstance(env, str) else env
    if not games:
        return []
    for g in games:
        if len(g.seats) != len(spec.agents) or not all(0 <= s < len(policies) for s in g.seats):
            raise ValueError(f"game {g} does not seat {len(spec.agents)} of the {len(policies)} policies")
    n = min(parallel, len(games))
    core = spec.core(n, **(env_options or {}))
    seats = np.zeros((len(spec.agents), n), dtype=np.int64)  # policy index per (seat, slot)
    game_of = np.full(n, -1, dtype=np.int64)  # schedule index per slot, -1 when idle
    next_game = 0

    def start(slots: np.ndarray) -> None:
        nonlocal next_game
        take = slots[: max(0, len(games) - next_game)]
        game_of[slots] = -1
        if take.size:
            chosen = games[next_game : next_game + take.size]
            game_of[take] = np.arange(next_game, next_game + take.size)
            seats[:, take] = np.array([g.seats for g in chosen]).T
            core.reset(take, [g.seed for g in chosen])
            next_game += take.size

    start(np.arange(n))
    results: list[GameResult | None] = [None] * len(games)
    actions = np.zeros((len(spec.agents), n), dtype=np.int64)
    while (game_of >= 0).any():
        obs = core.observe()
        active = game_of >= 0
        actions.fill(0)
        for p, policy in enumerate(policies):
            where = (seats == p) & active
            if where.any():
                actions[where] = policy.act(obs[where])
        core.step(actions)
        if on_step is not None:
            on_step(int(active.sum()))
        ended = np.flatnonzero((core.terminated | core.truncated) & active)
        if ended.size:
            outcome = core.outcome()
            for slot in ended:
                gi = int(game_of[slot])
                g = games[gi]
                r = GameResult(
                    env=spec.name,
                    players=tuple(policies[s].id for s in g.seats),
                    seed=g.seed,
                    scores=tuple(int(x) for x in core.score[:, slot]),
                    outcome=tuple(float(x) for x in outcome[:, slot]),
                    length=int(core.steps[slot]),
                    truncated=bool(core.truncated[slot]),
                    index=gi,
                )
                results[gi] = r
                if on_result is not None:
                    on_result(r)
            start(ended)
    return [r for r in results if r is not None]
