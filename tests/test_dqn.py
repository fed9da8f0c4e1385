"""DQN: epsilon schedules, the replay buffer, n-step transitions, TD targets, resume, and learning at Pong."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest
import torch
from gymnasium import spaces

from selfplay_cli.algos.dqn import DQNConfig, DQNLearner, epsilon_at, seed000_config
from selfplay_cli.envs import SeatSpace
from selfplay_cli.policies.network import Arch
from selfplay_cli.policies.spaces import box_of_shape


def discrete_seat(shape: tuple[int, ...], n: int) -> SeatSpace:
    """A seat that reads an unbounded float32 Box of ``shape`` and plays ``Discrete(n)``."""
    return SeatSpace(box_of_shape(shape), spaces.Discrete(n))


def test_linear_epsilon_schedule_by_transitions():
    cfg = DQNConfig(eps_start=1.0, eps_end=0.05, eps_decay_steps=1000)
    assert epsilon_at(cfg, 0) == pytest.approx(1.0)
    assert epsilon_at(cfg, 500) == pytest.approx(0.525)
    assert epsilon_at(cfg, 250) == pytest.approx(0.7625)
    assert epsilon_at(cfg, 1000) == pytest.approx(0.05)
    assert epsilon_at(cfg, 10**6) == pytest.approx(0.05)
    # The learner counts transitions: 4 slots x 25 steps = 100 transitions.
    learner = DQNLearner(discrete_seat((3,), 2), 4, cfg, seed=0)
    obs = np.zeros((4, 3), dtype=np.float32)
    for _ in range(25):
        learner.act(obs)
        learner.record(np.zeros(4), np.zeros(4))
    assert learner.transitions == 100
    assert learner.epsilon == pytest.approx(1.0 - 0.95 * 0.1)


def test_seed_exponential_epsilon_schedule():
    cfg = seed000_config()  # x0.995 per step down to 0.25
    assert epsilon_at(cfg, 0) == pytest.approx(1.0)
    assert epsilon_at(cfg, 1) == pytest.approx(0.995)
    assert epsilon_at(cfg, 100) == pytest.approx(0.6057704364907278)
    assert epsilon_at(cfg, 276) == pytest.approx(0.995**276) and 0.995**276 > 0.25
    assert epsilon_at(cfg, 277) == pytest.approx(0.25)  # 0.995 ** 277 < 0.25: the floor
    assert epsilon_at(cfg, 2000) == pytest.approx(0.25)


def test_seed000_config_is_the_seeds_setup():
    """The preset against the seed's set-up as the docs record it (docs/history/learners.md, from seed 000's own
    document), read from that text: the code is not its own oracle."""
    import re
    from pathlib import Path

    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "history" / "learners.md").read_text().split())
    said = text[text.index("Seed 000 trained plain DQN"):text.index("marl's own defaults are")]

    def number(pattern: str) -> float:
        return float(re.search(pattern, said).group(1).replace(",", ""))

    cfg = seed000_config()
    hidden = tuple(int(w) for w in re.search(r"a ([\d-]+) ReLU MLP", said).group(1).split("-"))
    assert cfg.arch.hidden == hidden and cfg.arch.activation == "relu"
    assert not cfg.arch.value_head and not cfg.arch.dueling
    assert cfg.lr == number(r"Adam at ([\d.e-]+),") and cfg.batch_size == number(r"batches of (\d+)")
    assert cfg.buffer_size == number(r"a ([\d,]+)-transition buffer") and cfg.n_step == number(r"n_step = (\d+)")
    assert cfg.target_period == number(r"copied every (\d+) steps") and cfg.tau == 1.0  # copied: not averaged
    assert cfg.learning_starts == number(r"learning from step (\d+)")
    assert cfg.replay_ratio == number(r"replay ratio (\d+)")
    assert cfg.eps_schedule == "exponential" and "`exponential` schedule" in said
    assert (cfg.eps_start, cfg.eps_decay, cfg.eps_end) == (1.0, number(r"decayed by x([\d.]+)"),
                                                           number(r"floor of ([\d.]+)"))
    assert not cfg.double_dqn and "plain (not double) DQN target" in said
    assert cfg.loss == "mse" and "MSE loss" in said and cfg.max_grad_norm == 0 and "no gradient clipping" in said
    assert cfg.gamma == 0.99  # (the seed's discount; the docs' set-up leaves it at DQN's usual)
    learner = DQNLearner(discrete_seat((8, 6), 3), 1, cfg, seed=0)
    widths = [m.out_features for m in learner.net.modules() if isinstance(m, torch.nn.Linear)]
    assert widths == [*hidden, 3]


def test_config_rejects_bad_values():
    with pytest.raises(ValueError):
        DQNConfig(eps_schedule="cosine")
    with pytest.raises(ValueError):
        DQNConfig(loss="l1")
    with pytest.raises(ValueError):
        DQNConfig(tau=0.0)
    with pytest.raises(ValueError):
        DQNConfig(n_step=0)
    with pytest.raises(ValueError):
        DQNConfig(arch=Arch(value_head=True))
    assert DQNConfig(arch=DQNConfig().arch.to_dict()).arch == DQNConfig().arch


def test_learner_stores_transitions_with_next_obs_and_dones():
    """One step's obs is the next obs of the step before; a done's next obs (the new game's) is stored too."""
    learner = DQNLearner(discrete_seat((1,), 2), 2, DQNConfig(n_step=1, learning_starts=10**6), seed=0)
    observations = [np.array([[0.0], [10.0]]), np.array([[1.0], [11.0]]), np.array([[2.0], [12.0]])]
    learner.act(observations[0])
    assert not learner.record(np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    learner.act(observations[1])  # completes step 0
    assert len(learner.buffer) == 2
    learner.record(np.array([-1.0, 0.0]), np.array([1.0, 0.0]))
    learner.update(observations[2])  # update() completes step 1 as well (no gradient step: not started)
    assert learner.grad_steps == 0 and len(learner.buffer) == 4
    b = learner.buffer
    assert b.obs[:4, 0].tolist() == [0.0, 10.0, 1.0, 11.0]
    assert b.next_obs[:4, 0].tolist() == [1.0, 11.0, 2.0, 12.0]
    assert b.rewards[:4].tolist() == [0.0, 1.0, -1.0, 0.0]
    assert b.dones[:4].tolist() == [0.0, 1.0, 1.0, 0.0]
    learner.act(observations[2])  # nothing left to push twice
    assert len(learner.buffer) == 4


def test_n_step_returns_stop_at_the_end_of_a_game():
    gamma = 0.5
    learner = DQNLearner(discrete_seat((1,), 2), 2, DQNConfig(n_step=3, gamma=gamma, learning_starts=10**6), seed=0)
    rewards = [[1.0, 1.0], [2.0, 2.0], [4.0, 4.0], [8.0, 8.0]]
    dones = [[0, 0], [0, 1], [0, 0], [0, 0]]  # slot 1's game ends after step 1
    for t in range(4):
        learner.act(np.array([[float(t)], [10.0 + t]]))
        learner.record(np.array(rewards[t]), np.array(dones[t], dtype=float))
    learner.update(np.array([[4.0], [14.0]]))
    b = learner.buffer
    # slot 1's game ended at step 1: both its decisions were written then (s' never read: done); slot 0's steps 0
    # and 1 as its chain grew to 3 decisions; steps 2 and 3 of both slots still wait for later rewards
    assert len(b) == 4
    assert b.obs[:4, 0].tolist() == [10.0, 11.0, 0.0, 1.0]
    assert b.next_obs[:4, 0].tolist() == [12.0, 12.0, 3.0, 4.0]  # s_{t+3} for slot 0
    r0 = 1 + gamma * 2 + gamma**2 * 4
    r1 = 2 + gamma * 4 + gamma**2 * 8
    assert b.rewards[:4].tolist() == pytest.approx([1 + gamma * 2, 2.0, r0, r1])
    assert b.dones[:4].tolist() == [1.0, 1.0, 0.0, 0.0]
    assert b.discounts[:4].tolist() == pytest.approx([gamma**2, gamma, gamma**3, gamma**3])


def _constant_q(net: torch.nn.Module, values: list[float]) -> None:
    with torch.no_grad():
        net.action_head.weight.zero_()
        net.action_head.bias.copy_(torch.tensor(values))


@pytest.mark.parametrize("double", [True, False])
def test_td_target_double_and_plain(double):
    gamma = 0.9
    learner = DQNLearner(discrete_seat((2,), 3), 1, DQNConfig(gamma=gamma, double_dqn=double, n_step=1), seed=0)
    _constant_q(learner.net, [1.0, 3.0, 2.0])  # the online net prefers action 1
    _constant_q(learner.target, [10.0, 20.0, 30.0])  # the target values action 1 at 20, its own best at 30
    r = torch.tensor([1.0, -1.0, 0.5])
    d = torch.tensor([0.0, 1.0, 0.0])
    s2 = torch.randn(3, 2)
    y = learner.td_target(r, d, s2)
    q_next = 20.0 if double else 30.0  # Q_target(s', argmax_a Q(s', a)) vs max_a Q_target(s', a)
    assert y.tolist() == pytest.approx([1 + gamma * q_next, -1.0, 0.5 + gamma * q_next])
    # n-step: the bootstrap is discounted by gamma^n.
    learner3 = DQNLearner(discrete_seat((2,), 3), 1, DQNConfig(gamma=gamma, double_dqn=double, n_step=3), seed=0)
    _constant_q(learner3.net, [1.0, 3.0, 2.0])
    _constant_q(learner3.target, [10.0, 20.0, 30.0])
    assert learner3.td_target(r, d, s2).tolist() == pytest.approx([1 + gamma**3 * q_next, -1.0,
                                                                    0.5 + gamma**3 * q_next])


def _fill(learner: DQNLearner, steps: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = learner.n_slots
    obs = rng.standard_normal((n, *learner.obs_shape)).astype(np.float32)
    for _ in range(steps):
        learner.act(obs)
        obs = rng.standard_normal((n, *learner.obs_shape)).astype(np.float32)
        if learner.record(rng.choice([-1.0, 0.0, 1.0], n), rng.random(n) < 0.1):
            learner.update(obs)
    return obs


def test_updates_follow_the_replay_ratio_and_sync_the_target():
    cfg = DQNConfig(replay_ratio=0.25, learning_starts=40, batch_size=8, target_period=5, n_step=1)
    learner = DQNLearner(discrete_seat((3,), 3), 4, cfg, seed=0)
    obs = _fill(learner, 9)  # 36 transitions: not started
    assert learner.grad_steps == 0
    # 21 steps more; from the step that brings the buffer to 40 on (steps 10 to 30), each step's 4 transitions
    # earn 0.25 updates each: 21 * 4 * 0.25 = 21.
    _fill(learner, 21)
    assert learner.grad_steps == 21
    learner.act(obs)
    learner.record(np.zeros(4), np.zeros(4))
    stats = learner.update(obs)
    assert stats["grad_steps"] == 1.0 and np.isfinite(stats["loss"]) and stats["buffer_size"] == 124
    # target_period 5: synced at update 20, two updates since, so they differ; after 3 more they agree again.
    pairs = list(zip(learner.net.parameters(), learner.target.parameters(), strict=True))
    assert any(not torch.equal(a, b) for a, b in pairs)
    _fill(learner, 3)
    assert learner.grad_steps == 25
    assert all(torch.equal(a, b) for a, b in pairs)


def test_polyak_target_update():
    learner = DQNLearner(discrete_seat((3,), 3), 1, DQNConfig(tau=0.1), seed=0)
    with torch.no_grad():
        for p in learner.net.parameters():
            p.add_(1.0)
    old = [t.clone() for t in learner.target.parameters()]
    learner._sync_target()
    for t, o, p in zip(learner.target.parameters(), old, learner.net.parameters(), strict=True):
        assert torch.allclose(t, 0.9 * o + 0.1 * p)


def test_state_round_trip_resumes_identically():
    cfg = DQNConfig(learning_starts=64, batch_size=16, eps_decay_steps=400)
    a = DQNLearner(discrete_seat((8, 6), 3), 8, cfg, seed=1)
    _fill(a, 30)
    assert a.grad_steps > 0
    buf = io.BytesIO()
    torch.save(a.state_dict(), buf)  # a checkpoint goes through torch.save / torch.load (weights_only)
    buf.seek(0)
    b = DQNLearner(discrete_seat((8, 6), 3), 8, cfg, seed=99)
    b.load_state_dict(torch.load(buf))
    obs = np.random.default_rng(5).standard_normal((8, 8, 6)).astype(np.float32)
    assert b.epsilon == a.epsilon and b.transitions == a.transitions == 240
    pa, pb = a.policy("a", "pong", greedy=True), b.policy("b", "pong", greedy=True)
    assert np.array_equal(pa.act(obs), pb.act(obs))
    assert np.array_equal(pa.act(obs), a.net(torch.from_numpy(obs))[0].argmax(1).numpy())  # greedy = argmax Q
    assert np.array_equal(a.act(obs), b.act(obs)), "same weights and same exploration stream"
    for x, y in zip(a.target.parameters(), b.target.parameters(), strict=True):
        assert torch.equal(x, y)
    assert len(b.buffer) == 0  # the replay buffer is not saved: it refills
    assert not b.record(np.zeros(8), np.zeros(8))  # and updates wait until it holds learning_starts again


@pytest.mark.slow
def test_dqn_learns_to_beat_random_at_pong(one_thread, learn_against_random):
    """A real learning assertion: from an even game to a clear win against the random player.

    The bar, measured on seeds 0-19: the first 300 games 0.51-0.61 (mean 0.56, sd 0.023: they end by ~60k steps,
    so updates from 20k on count in them), the last 300 0.89-0.98 (mean 0.93, sd 0.026). 0.7 is 6 sd above the
    first and 8.7 sd below the last; a learner that never updates stays near its first games' rate."""
    cfg = DQNConfig(lr=1e-3, batch_size=128, replay_ratio=0.0625, target_period=100, n_step=5,
                    learning_starts=20_000, eps_decay_steps=50_000)
    learner = DQNLearner(discrete_seat((8, 6), 3), 64, cfg, seed=0)
    start = time.perf_counter()
    first, last, n_games = learn_against_random(learner, n_games=64, budget=160_000)
    print(f"DQN win rate vs random: first 300 games {first:.2f}, last 300 {last:.2f} ({n_games} games, "
          f"{learner.grad_steps} updates, {time.perf_counter() - start:.1f} s)")
    assert first < 0.7 < last, (first, last)
