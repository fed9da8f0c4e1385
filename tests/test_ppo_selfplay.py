"""Self-play rollouts over the batched core, and PPO learning through them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces

from selfplay_cli.algos.ppo import PPOConfig, PPOLearner
from selfplay_cli.envs import SeatSpace, get_env
from selfplay_cli.errors import MarlError
from selfplay_cli.play.seat_plan import OPPONENT, plan_layout, plan_seats
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.policies.spaces import box_of_shape


def discrete_seat(shape: tuple[int, ...], n: int) -> SeatSpace:
    """A seat that reads an unbounded float32 Box of ``shape`` and plays ``Discrete(n)``."""
    return SeatSpace(box_of_shape(shape), spaces.Discrete(n))


def seat_layout(n_games: int, agents: int, sharing: str, league_games: float = 0.0) -> np.ndarray:
    return plan_layout(plan_seats(get_env("pong"), agents, sharing), n_games, agents, league_games)


def test_seat_layouts_for_agents_and_sharing():
    assert seat_layout(4, 2, "nops").tolist() == [[0, 0, 0, 0], [1, 1, 1, 1]]
    assert seat_layout(4, 2, "fups").tolist() == [[0, 0, 0, 0], [0, 0, 0, 0]]
    assert seat_layout(4, 1, "nops").tolist() == [[0, OPPONENT, 0, OPPONENT], [OPPONENT, 0, OPPONENT, 0]]
    assert seat_layout(6, 2, "nops", league_games=0.5).tolist() == [[0, OPPONENT, 0, 0, 0, 0],
                                                                       [OPPONENT, 1, OPPONENT, 1, 1, 1]]
    assert seat_layout(4, 2, "fups", league_games=0.5).tolist() == [[0, OPPONENT, 0, 0], [OPPONENT, 0, 0, 0]]
    with pytest.raises(MarlError, match="pong has 2 seats"):
        seat_layout(4, 3, "nops")
    with pytest.raises(MarlError, match="--sharing must be one of"):
        seat_layout(4, 2, "shared")


def test_selfplay_games_restart_with_fresh_seeds_and_report_results():
    cpu, rnd = ScriptedPolicy("pong", "cpu"), ScriptedPolicy("pong", "random", seed=3)
    n = 8
    games = SelfPlayGames("pong", n, seat_layout(n, 1, "nops"), ["me"],
                          choose_opponents=lambda slots: [rnd] * len(slots),
                          env_options={"points_to_win": 2}, first_seed=100)
    finished = []
    for _ in range(3000):
        (obs,) = games.observe()
        assert obs.shape == (n, 8, 6)
        rewards, dones, fin = games.step([cpu.act(obs)])
        finished += fin
        for r in fin:  # the learner's reward on the final step is its side of the last point
            slot = int(np.flatnonzero(games.slots[0] % n == r.index)[0])
            assert dones[0][slot]
    assert len(finished) >= 8
    seeds = sorted(r.seed for r in finished)
    assert len(set(seeds)) == len(seeds) and min(seeds) >= 100
    assert all(set(r.players) == {"me", "random"} for r in finished)
    assert sum(r.points_of("me") for r in finished) / len(finished) > 0.9  # the tracker beats random
    assert games.games_started == n + len(finished)
    lefts = sum(r.players[0] == "me" for r in finished)
    assert 0 < lefts < len(finished), "the learner plays both sides"


def test_gae_matches_hand_computed_advantages():
    cfg = PPOConfig(rollout_steps=3, gamma=0.9, gae_lambda=0.5)
    learner = PPOLearner(discrete_seat((2,), 2), 1, cfg, seed=0)
    learner.values[:, 0] = torch.tensor([1.0, 2.0, 3.0])
    learner.rewards[:, 0] = torch.tensor([0.0, 1.0, -1.0])
    learner.dones[:, 0] = torch.tensor([0.0, 1.0, 0.0])  # the game ends after step 1; step 2 starts a new one
    with torch.no_grad():
        learner.net.value_head.weight.zero_()
        learner.net.value_head.bias.fill_(4.0)  # V(next obs) = 4
    adv, ret = learner._advantages(np.zeros((1, 2), dtype=np.float32))
    d2 = -1 + 0.9 * 4 - 3  # = -0.4
    d1 = 1 - 2  # done: no bootstrap
    d0 = 0 + 0.9 * 2 - 1  # = 0.8
    a2 = d2
    a1 = d1
    a0 = d0 + 0.9 * 0.5 * a1
    assert adv[:, 0].tolist() == pytest.approx([a0, a1, a2])
    assert ret[:, 0].tolist() == pytest.approx([a0 + 1, a1 + 2, a2 + 3])


def test_learner_state_round_trip_resumes_identically():
    rng = np.random.default_rng(0)
    obs = rng.standard_normal((4, 8, 6)).astype(np.float32)
    a = PPOLearner(discrete_seat((8, 6), 3), 4, PPOConfig(rollout_steps=2), seed=1)
    for _ in range(2):
        a.act(obs)
        a.record(np.ones(4), np.zeros(4))
    a.update(obs)
    state = a.state_dict()
    b = PPOLearner(discrete_seat((8, 6), 3), 4, PPOConfig(rollout_steps=2), seed=99)
    b.load_state_dict(state)
    assert np.array_equal(a.act(obs), b.act(obs)), "same weights and same sampling stream"
    assert b.updates == 1


@pytest.mark.slow
def test_ppo_learns_to_beat_random_at_pong(learn_against_random, one_thread):
    """A real learning assertion: from an even game to a clear win against the random player.

    The bars, measured on seeds 0-19 (one torch thread): the first 300 games 0.39-0.55 (mean 0.49, sd 0.035), the
    last 300 0.84-0.95 (mean 0.92, sd 0.03). 0.7 is 7 sd below the learned rate and 6 sd above what a learner that
    never updates keeps (its first games' rate); 0.65 is 4.5 sd above the first games' mean. The budget is where
    every seed has learned: at 200k steps the last 300 games are 0.46-0.87, at 150k 0.42-0.64."""
    torch.manual_seed(0)
    learner = PPOLearner(discrete_seat((8, 6), 3), 128, PPOConfig(rollout_steps=64, lr=2e-3), seed=0)
    first, last, _ = learn_against_random(learner, n_games=128, budget=400_000)
    print(f"win rate vs random: first 300 games {first:.2f}, last 300 {last:.2f}")
    assert first < 0.65, first
    assert last > 0.7, (first, last)
