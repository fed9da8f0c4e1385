"""Learners behind one interface: the registry, construction from a seat's spaces, masks, truncation bootstraps,
turn-based games (steps where the seat does not act), Gaussian and MultiDiscrete PPO, and DQN's masks and limits."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces

from selfplay_cli.algos import (
    LEARNERS,
    DQNConfig,
    DQNLearner,
    Learner,
    MAPPOLearner,
    POCALearner,
    PPOConfig,
    PPOLearner,
    SACLearner,
    get_learner,
)
from selfplay_cli.envs import SeatSpace
from selfplay_cli.errors import MarlError
from selfplay_cli.policies.network import Arch
from selfplay_cli.policies.spaces import box_of_shape

BOX2 = spaces.Box(-1.0, 1.0, (2,), np.float32)



def discrete_seat(shape: tuple[int, ...], n: int) -> SeatSpace:
    """A seat that reads an unbounded float32 Box of ``shape`` and plays ``Discrete(n)``."""
    return SeatSpace(box_of_shape(shape), spaces.Discrete(n))


def constant_value(learner: PPOLearner, value: float) -> None:
    with torch.no_grad():
        learner.net.value_head.weight.zero_()
        learner.net.value_head.bias.fill_(value)


# ---------------------------------------------------------------------------------------------------------------
# The registry and construction


def test_registry_names_the_learners_and_refuses_unknown_ones():
    assert {"ppo": PPOLearner, "dqn": DQNLearner, "sac": SACLearner, "mappo": MAPPOLearner,
            "poca": POCALearner} == LEARNERS
    assert get_learner("ppo") is PPOLearner and PPOLearner.name == "ppo" and PPOLearner.config_class is PPOConfig
    assert DQNLearner.config_class is DQNConfig
    with pytest.raises(MarlError, match="unknown algorithm 'td3'; known: dqn, mappo, poca, ppo, sac"):
        get_learner("td3")


@pytest.mark.parametrize("cls", [PPOLearner, DQNLearner])
def test_built_from_a_seat_space_alone(cls):
    seat = SeatSpace(spaces.Box(0.0, 1.0, (3, 2), np.float32), spaces.Discrete(4), True)
    a = cls(seat, 5, cls.config_class(), seed=3)
    b = cls(discrete_seat((3, 2), 4), 5, cls.config_class(), seed=3)  # unbounded observations, no masks
    assert isinstance(a, Learner)
    assert a.n_slots == b.n_slots == 5 and a.obs_shape == b.obs_shape == (3, 2) and a.n_actions == 4
    for (ka, va), (kb, vb) in zip(a.net.state_dict().items(), b.net.state_dict().items(), strict=True):
        assert ka == kb and torch.equal(va, vb)  # the same network from the same seed
    assert a.policy("p", "g").act_space == spaces.Discrete(4)
    assert a.net.obs_space == seat.observation
    with pytest.raises(TypeError, match="(?i)config"):
        cls(seat, 5, "not a config")
    with pytest.raises(TypeError, match="built from a SeatSpace, not tuple"):  # (obs_shape, n_actions, ...): gone
        cls((3, 2), 4, cls.config_class())


def test_dqn_refuses_other_action_spaces_in_one_line():
    for space, shown in ((BOX2, "Box(-1, 1, (2,), float32)"), (spaces.MultiDiscrete([3, 2]), "MultiDiscrete([3, 2])")):
        with pytest.raises(MarlError) as e:
            DQNLearner(SeatSpace(BOX2, space), 4)
        msg = str(e.value)
        assert msg.startswith("DQN learns Discrete actions only") and shown in msg and "--algo ppo" in msg, msg
        assert "\n" not in msg
    with pytest.raises(MarlError, match="PPO cannot learn this seat's actions: .*finite bounds"):
        PPOLearner(SeatSpace(BOX2, spaces.Box(-np.inf, np.inf, (1,), np.float32)), 2)


# ---------------------------------------------------------------------------------------------------------------
# PPO: truncation bootstrap


@pytest.mark.parametrize("bootstrap", [True, False])
def test_ppo_truncated_game_bootstraps_from_its_final_observation(bootstrap):
    cfg = PPOConfig(rollout_steps=3, gamma=0.9, gae_lambda=0.5, bootstrap_truncated=bootstrap)
    learner = PPOLearner(SeatSpace(BOX2, spaces.Discrete(2)), 1, cfg, seed=0)
    obs = np.zeros((1, 2), np.float32)
    rewards, dones, truncated = [0.0, 1.0, -1.0], [0.0, 1.0, 0.0], [False, True, False]
    for t in range(3):
        learner.act(obs)
        constant_value(learner, 5.0)  # V(final obs of step 1) = 5, valued when it is recorded
        learner.record(np.array([rewards[t]]), np.array([dones[t]]), truncated=np.array([truncated[t]]),
                       final_obs=np.full((1, 2), 0.5, np.float32))
    learner.values[:, 0] = torch.tensor([1.0, 2.0, 3.0])
    constant_value(learner, 4.0)  # V(next obs) = 4
    adv, ret = learner._advantages(np.zeros((1, 2), dtype=np.float32))
    d2 = -1 + 0.9 * 4 - 3
    d1 = 1 + (0.9 * 5 if bootstrap else 0.0) - 2  # truncated: r + gamma V(final obs) - V(s); terminated: r - V(s)
    d0 = 0 + 0.9 * 2 - 1
    a2, a1 = d2, d1  # the chain is cut at the truncation all the same
    a0 = d0 + 0.9 * 0.5 * a1
    assert adv[:, 0].tolist() == pytest.approx([a0, a1, a2])
    assert ret[:, 0].tolist() == pytest.approx([a0 + 1, a1 + 2, a2 + 3])


def test_ppo_final_observations_may_come_with_the_update_and_are_required():
    learner = PPOLearner(SeatSpace(BOX2, spaces.Discrete(2)), 2, PPOConfig(rollout_steps=1), seed=0)
    obs = np.zeros((2, 2), np.float32)
    learner.act(obs)
    learner.record(np.zeros(2), np.array([1.0, 0.0]), truncated=np.array([True, False]))
    with pytest.raises(ValueError, match="final_obs"):
        learner.update(obs)
    learner.update(obs, final_obs=np.ones((2, 2), np.float32))  # the truncated game's final observation
    learner.act(obs)
    with pytest.raises(ValueError, match="must also be done"):
        learner.record(np.zeros(2), np.zeros(2), truncated=np.array([True, False]), final_obs=obs)


# ---------------------------------------------------------------------------------------------------------------
# PPO: turn-based games


def test_turn_gae_skips_steps_where_the_seat_did_not_act():
    """Slot 0 decides at steps 0, 2 and 4; the opponent's moves (steps 1, 3, 5) bring rewards and, at step 3, the
    game's end. Slot 1 always acts (the ordinary GAE)."""
    cfg = PPOConfig(rollout_steps=6, gamma=0.9, gae_lambda=0.5)
    learner = PPOLearner(SeatSpace(BOX2, spaces.Discrete(2)), 2, cfg, seed=0)
    g, lam = 0.9, 0.5
    acting = np.array([[1, 0, 1, 0, 1, 0], [1, 1, 1, 1, 1, 1]], bool).T
    rewards = np.array([[0.0, 0.5, 0.0, -1.0, 0.0, 0.25], [1.0, 0.0, 0.0, 2.0, 0.0, 1.0]], np.float32).T
    dones = np.array([[0, 0, 0, 1, 0, 0], [0, 0, 1, 0, 0, 0]], bool).T
    values = np.array([[1, 2, 3, 4, 5, 6], [1, 1, 2, 2, 3, 3]], np.float32).T
    k = len(acting)
    adv, learn, carried, carry_reward = learner._turn_advantages(rewards, dones, np.zeros((k, 2), np.float32),
                                                                 acting, values)
    # slot 0: decision 2 ends with the game at step 3 (reward 0 + -1); decision 0 earns 0 + 0.5 and bootstraps
    # from decision 2; decision 4 (game still running, no next decision) is carried, with 0 + 0.25 so far.
    a2 = -1.0 - 3.0
    a0 = 0.5 + g * 3.0 - 1.0 + g * lam * a2
    assert learn[:, 0].tolist() == [True, False, True, False, False, False]
    assert carried[:, 0].tolist() == [False, False, False, False, True, False]
    assert adv[[0, 2], 0].tolist() == pytest.approx([a0, a2])
    assert carry_reward[0] == pytest.approx(0.25)
    # slot 1: every step a decision; the last one is carried (its continuation comes with the next rollout)
    d = [1 + g * 1 - 1, 0 + g * 2 - 1, 0 - 2, 2 + g * 3 - 2, 0 + g * 3 - 3]
    a = [0.0] * 5
    a[4] = d[4] - 0.0 * 0 + 0.0  # bootstraps from the carried decision: A = delta, V(carried) = 3
    a[3] = d[3] + g * lam * a[4]
    a[2] = d[2]  # its game ended at this step
    a[1] = d[1] + g * lam * a[2]
    a[0] = d[0] + g * lam * a[1]
    assert learn[:, 1].tolist() == [True] * 5 + [False] and carried[5, 1]
    assert adv[:5, 1].tolist() == pytest.approx(a)


def test_turn_rollout_learns_only_decisions_and_carries_the_last_one():
    cfg = PPOConfig(rollout_steps=4, minibatches=1, update_epochs=1)
    learner = PPOLearner(SeatSpace(spaces.Box(-10, 10, (1,), np.float32), spaces.Discrete(3)), 1, cfg, seed=0)
    acting = [True, False, True, False]
    for t in range(4):
        learner.act(np.array([[float(t)]], np.float32), mask=np.array([[True, True, acting[t]]]))
        learner.record(np.array([1.0 * t]), np.array([0.0]), acting=np.array([acting[t]]))
    batch = learner._turn_batch()
    assert batch["obs"][:, 0].tolist() == [0.0]  # decision 0 (decision 2 is the last: carried, not learned)
    assert batch["masks"].tolist() == [[True, True, True]]
    learner.update(np.zeros((1, 1), np.float32))
    carry = learner.carry
    assert carry is not None and carry["valid"].tolist() == [True] and carry["obs"][0, 0, 0] == 2.0
    assert carry["reward"].tolist() == [2.0 + 3.0]  # its own reward and the opponent's move's after it
    # next rollout: the carried decision is row 0, learned now that the seat's next decision is known
    for t in range(4):
        learner.act(np.array([[10.0 + t]], np.float32))
        learner.record(np.array([0.0]), np.array([0.0]), acting=np.array([t % 2 == 1]))
    batch = learner._turn_batch()
    assert batch["obs"][:, 0].tolist() == [2.0, 11.0]
    stats = learner.update(np.zeros((1, 1), np.float32))
    assert stats["decisions"] == 2.0 and np.isfinite(stats["policy_loss"])


# ---------------------------------------------------------------------------------------------------------------
# PPO: masks, MultiDiscrete, Box


def test_ppo_never_samples_a_masked_action_and_learns_under_masks():
    rng = np.random.default_rng(0)
    for space, width in ((spaces.Discrete(5), 5), (spaces.MultiDiscrete([3, 4]), 7)):
        learner = PPOLearner(SeatSpace(BOX2, space), 64, PPOConfig(rollout_steps=8), seed=1)
        for _ in range(8):
            mask = rng.random((64, width)) < 0.4
            mask[np.arange(64), rng.integers(0, width, 64)] = True
            if width == 7:  # each dimension keeps an allowed action
                mask[:, 0] |= ~mask[:, :3].any(axis=1)
                mask[:, 3] |= ~mask[:, 3:].any(axis=1)
            a = learner.act(rng.standard_normal((64, 2)).astype(np.float32), mask)
            if width == 5:
                assert a.shape == (64,) and mask[np.arange(64), a].all()
            else:
                rows = np.arange(64)
                assert a.shape == (64, 2) and mask[rows, a[:, 0]].all() and mask[rows, 3 + a[:, 1]].all()
            learner.record(np.zeros(64), np.zeros(64))
        stats = learner.update(np.zeros((64, 2), np.float32))
        assert all(np.isfinite(v) for v in stats.values()), stats


def test_ppo_multidiscrete_learns_a_bandit(one_thread):
    """Reward 1 for choosing (2, 0): the learner samples that pair far more often in its last rollout than in its
    first, and its greedy action is that pair.

    The bar, measured on seeds 0-19: the first rollout's 512 draws hit (2, 0) 0.14-0.19 of the time (chance: 1/6),
    the last rollout's 0.77-0.82 (sd 0.014); 0.4 is 15 sd from either. A learner that does not update keeps its
    first rate (and its greedy pair is (2, 0) for one network in six: hence the rates, not the greedy pair alone)."""
    learner = PPOLearner(SeatSpace(BOX2, spaces.MultiDiscrete([3, 2])), 32, PPOConfig(rollout_steps=16, lr=1e-2),
                         seed=0)
    obs = np.zeros((32, 2), np.float32)
    rates = []
    for u in range(15):
        hits = 0.0
        for _ in range(16):
            a = learner.act(obs)
            r = ((a[:, 0] == 2) & (a[:, 1] == 0)).astype(np.float32)
            hits += r.mean()
            learner.record(r, np.ones(32))
        rates.append(hits / 16)
        learner.update(obs, progress=u / 15)
    assert rates[0] < 0.4 < rates[-1], rates
    assert learner.policy("p", "bandit", greedy=True).act(obs[:1]).tolist() == [[2, 0]]


class Reach:
    """``b`` games of a 1-D task: move a point (from 0) toward a random target in [-1, 1] by 0.25 x the action per
    step; reward -|target - position| each step; a game is cut short (truncated) after 10 steps."""

    def __init__(self, b: int, seed: int) -> None:
        self.b, self.rng = b, np.random.default_rng(seed)
        self.pos, self.target, self.t = np.zeros(b), self.rng.uniform(-1, 1, b), np.zeros(b, int)

    def obs(self) -> np.ndarray:
        return np.stack([self.pos, self.target - self.pos], 1).astype(np.float32)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        self.pos = np.clip(self.pos + 0.25 * action[:, 0], -1, 1)
        reward = -np.abs(self.target - self.pos)
        self.t += 1
        cut = self.t >= 10
        final = self.obs()
        self.pos[cut], self.target[cut], self.t[cut] = 0.0, self.rng.uniform(-1, 1, int(cut.sum())), 0
        return reward.astype(np.float32), cut, final


def greedy_return(policy, b: int = 256) -> float:
    env, total = Reach(b, seed=123), np.zeros(b)
    for _ in range(10):
        r, _, _ = env.step(policy.act(env.obs()))
        total += r
    return float(total.mean())


def test_ppo_learns_a_continuous_task(one_thread):
    """A Gaussian policy over Box(-1, 1, (1,)): from standing still (a return of about -5) to reaching the target
    (the best return is about -0.5) in 12 updates of 32 games x 32 steps.

    The bars, measured on seeds 0-19: before -4.91 to -5.00, after -0.52 to -0.64 (sd 0.025): -3.0 and -1.2 are each
    more than 20 sd away; a learner that does not update keeps its return of about -5."""
    seat = SeatSpace(spaces.Box(-2, 2, (2,), np.float32), spaces.Box(-1, 1, (1,), np.float32))
    cfg = PPOConfig(rollout_steps=32, lr=3e-3, ent_coef=0.0, gamma=0.9, arch=Arch(hidden=(32, 32), activation="tanh"))
    learner = PPOLearner(seat, 32, cfg, seed=0)
    before = greedy_return(learner.policy("p", "reach", greedy=True))
    env = Reach(32, seed=0)
    obs = env.obs()
    for u in range(12):
        for _ in range(32):
            a = learner.act(obs)
            assert a.shape == (32, 1) and a.dtype == np.float32 and (np.abs(a) <= 1).all()
            r, cut, final = env.step(a)
            obs = env.obs()
            learner.record(r, cut, truncated=cut, final_obs=final)
        stats = learner.update(obs, progress=u / 12)
    after = greedy_return(learner.policy("p", "reach", greedy=True))
    print(f"greedy return: before {before:.2f}, after {after:.2f} (std {stats['std']:.2f})")
    assert before < -3.0
    assert after > -1.2, after


def test_ppo_box_state_round_trip_resumes_identically():
    seat = SeatSpace(BOX2, spaces.Box(-1, 1, (3,), np.float32))
    obs = np.random.default_rng(0).standard_normal((4, 2)).astype(np.float32)
    a = PPOLearner(seat, 4, PPOConfig(rollout_steps=2), seed=1)
    for _ in range(2):
        a.act(obs)
        a.record(np.ones(4), np.zeros(4))
    a.update(obs)
    assert "log_std" in a.net.state_dict()
    b = PPOLearner(seat, 4, PPOConfig(rollout_steps=2), seed=9)
    b.load_state_dict(a.state_dict())
    assert np.array_equal(a.act(obs), b.act(obs))


# ---------------------------------------------------------------------------------------------------------------
# DQN: masks, truncation, turns


def test_dqn_masked_acting_and_targets():
    rng = np.random.default_rng(0)
    for eps in (1.0, 0.0):  # exploring, then greedy
        learner = DQNLearner(SeatSpace(BOX2, spaces.Discrete(6), True), 50,
                             DQNConfig(eps_start=eps, eps_end=eps, learning_starts=10**6), seed=0)
        for _ in range(20):
            mask = rng.random((50, 6)) < 0.3
            mask[np.arange(50), rng.integers(0, 6, 50)] = True
            a = learner.act(rng.standard_normal((50, 2)).astype(np.float32), mask)
            assert mask[np.arange(50), a].all()
            learner.record(np.zeros(50), np.zeros(50))
        assert learner.buffer.next_masks is not None and len(learner.buffer) == (20 - 3) * 50  # the last n_step wait
    learner = DQNLearner(SeatSpace(BOX2, spaces.Discrete(3), True), 1, DQNConfig(gamma=0.9, n_step=1), seed=0)
    for net, values in ((learner.net, [1.0, 3.0, 2.0]), (learner.target, [10.0, 20.0, 30.0])):
        with torch.no_grad():
            net.action_head.weight.zero_()
            net.action_head.bias.copy_(torch.tensor(values))
    r, d, s2 = torch.zeros(2), torch.zeros(2), torch.zeros(2, 2)
    masks = torch.tensor([[True, False, True], [True, True, True]])
    # double DQN: the online net's best allowed action (2, not 1) valued by the target
    assert learner.td_target(r, d, s2, next_masks=masks).tolist() == pytest.approx([0.9 * 30, 0.9 * 20])
    learner.cfg.double_dqn = False
    masks = torch.tensor([[True, True, False], [True, True, True]])
    assert learner.td_target(r, d, s2, next_masks=masks).tolist() == pytest.approx([0.9 * 20, 0.9 * 30])


def test_dqn_n_step_return_bootstraps_a_truncated_game_from_its_final_observation():
    gamma = 0.5
    learner = DQNLearner(discrete_seat((1,), 2), 2, DQNConfig(n_step=3, gamma=gamma, learning_starts=10**6), seed=0)
    rewards = [[1.0, 1.0], [2.0, 2.0], [4.0, 4.0], [8.0, 8.0]]
    dones = [[0, 0], [0, 1], [0, 0], [0, 0]]  # slot 1's game is cut short after step 1
    for t in range(4):
        learner.act(np.array([[float(t)], [10.0 + t]]))
        learner.record(np.array(rewards[t]), np.array(dones[t], dtype=float), truncated=np.array([False, t == 1]),
                       final_obs=np.array([[-1.0], [99.0]]))
    learner.update(np.array([[4.0], [14.0]]))
    b = learner.buffer
    # slot 1's two decisions are written when its game is cut short, slot 0's as its chain grows to 3 decisions
    assert b.obs[:4, 0].tolist() == [10.0, 11.0, 0.0, 1.0]
    assert b.next_obs[:4, 0].tolist() == [99.0, 99.0, 3.0, 4.0]  # slot 1: the final observation of its game
    assert b.rewards[:4].tolist() == pytest.approx([1 + gamma * 2, 2.0, 1 + gamma * 2 + gamma**2 * 4,
                                                    2 + gamma * 4 + gamma**2 * 8])
    assert b.dones[:4].tolist() == [0.0, 0.0, 0.0, 0.0]  # bootstrapped, not ended
    assert b.discounts[:4].tolist() == pytest.approx([gamma**2, gamma, gamma**3, gamma**3])


def test_dqn_turn_based_transitions_run_from_decision_to_decision():
    """One slot deciding at steps 0, 2 and 4; the opponent's moves' rewards go to the decision before them; the
    game ends (lost) at step 3 and a new one starts with the seat's decision at step 4."""
    gamma = 0.5
    learner = DQNLearner(discrete_seat((1,), 2), 1, DQNConfig(n_step=2, gamma=gamma, learning_starts=10**6), seed=0)
    acting = [True, False, True, False, True, False, True]
    rewards = [0.5, 0.25, 0.0, -1.0, 0.0, 2.0, 0.0]
    dones = [0, 0, 0, 1, 0, 0, 0]
    for t in range(7):
        learner.act(np.array([[float(t)]]))
        learner.record(np.array([rewards[t]]), np.array([float(dones[t])]), acting=np.array([acting[t]]))
    b = learner.buffer
    n = len(b)
    rows = sorted(zip(b.obs[:n, 0].tolist(), b.rewards[:n].tolist(), b.next_obs[:n, 0].tolist(),
                      b.dones[:n].tolist(), b.discounts[:n].tolist(), strict=True))
    # the game's end flushes both decisions of its chain: decision 0 (0.5 + 0.25, then decision 2's -1) and
    # decision 2 (0 - 1); decision 4's chain of 2 completes only with a later decision
    # (s' of a transition that ends its game is never read: the chain's last decision's observation)
    expected = [(0.0, 0.75 + gamma * -1.0, 2.0, 1.0, gamma**2), (2.0, -1.0, 2.0, 1.0, gamma)]
    got, want = np.array(rows, dtype=float).ravel(), np.array(expected, dtype=float).ravel()
    assert got.tolist() == pytest.approx(want.tolist())
    learner.act(np.array([[7.0]]))
    learner.record(np.array([0.0]), np.array([0.0]), acting=np.array([True]))  # step 7 decides: 4's chain is 2 long
    assert len(b) == 3 and b.obs[2, 0] == 4.0 and b.next_obs[2, 0] == 7.0  # (4 -> 6 -> 7): s' two decisions on
    assert b.rewards[2] == pytest.approx(0.0 + 2.0 + gamma * 0.0) and b.dones[2] == 0.0
    assert b.discounts[2] == pytest.approx(gamma**2)
    assert learner.transitions == 5  # decisions, not steps
