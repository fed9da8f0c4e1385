"""Shared fixtures."""

from __future__ import annotations

import numpy as np
import pytest

from selfplay_cli.arena.selfplay import SelfPlayGames, seat_layout
from selfplay_cli.policies import ScriptedPolicy


def _learn_against_random(learner, n_games: int, budget: int) -> tuple[float, float, int]:
    """Train ``learner`` (driving one seat of ``n_games`` games) for ``budget`` game steps against the random
    player; returns its win rate over the first and the last 300 games, and the number of games."""
    rnd = ScriptedPolicy("pong", "random", seed=1)
    games = SelfPlayGames("pong", n_games, seat_layout(2, n_games, 1, "nops"), ["me"],
                          choose_opponents=lambda slots: [rnd] * len(slots), env_options={"points_to_win": 1})
    results: list[float] = []
    steps = 0
    (obs,) = games.observe()
    while steps < budget:
        rewards, dones, finished = games.step([learner.act(obs)])
        results += [r.points_of("me") for r in finished]
        (obs,) = games.observe()
        if learner.record(rewards[0], dones[0]):
            learner.update(obs, progress=steps / budget)
        steps += n_games
    return float(np.mean(results[:300])), float(np.mean(results[-300:])), len(results)


@pytest.fixture
def learn_against_random():
    """The play-and-learn loop of the learners' learning tests (see ``_learn_against_random``)."""
    return _learn_against_random
