"""Kickstarting (a teacher the learners imitate, its weight fading): the imitation losses by hand, the ring of
labelled states, learners that come to play as their teacher, and the run's settings and errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from cli_helpers import run, run_json
from gymnasium import spaces

from selfplay_cli.algos import PPOLearner, SACLearner
from selfplay_cli.algos.kickstart import SQUASH_EDGE, Imitation
from selfplay_cli.envs import SeatSpace, get_env
from selfplay_cli.errors import MarlError
from selfplay_cli.league.store import League
from selfplay_cli.players.load import load_player
from selfplay_cli.policies.spaces import ActionHead
from selfplay_cli.ratings.names import resolve
from selfplay_cli.train.config import TeacherConfig, TrainConfig


class Fixed(torch.nn.Module):
    """A 'network' whose outputs are parameters (the same row for every observation)."""

    def __init__(self, out, log_std=None):
        super().__init__()
        self.out = torch.nn.Parameter(torch.tensor([out], dtype=torch.float32))
        self.log_std = None if log_std is None else torch.nn.Parameter(torch.tensor(log_std, dtype=torch.float32))

    def forward(self, x):
        return self.out.expand(len(x), -1), None

    def gaussian(self, x):
        return self.out.expand(len(x), -1), self.log_std.expand(len(x), -1)


def test_gaussian_imitation_is_the_teachers_likelihood_on_the_unit_scale():
    """PPO's Gaussian: -log N(teacher; mean, std) on the [-1, 1] scale, less its constant, by hand."""
    head = ActionHead.of(spaces.Box(np.array([-2.0, 0.0], np.float32), np.array([2.0, 10.0], np.float32)))
    im = Imitation(head, obs_dim=3, capacity=10)
    im.add(np.zeros((4, 3)), np.array([[1.0, 5.0]] * 4))  # on the unit scale: (0.5, 0.0)
    net = Fixed([0.0, 7.5], log_std=[math.log(2.0), math.log(5.0)])  # mean (0, 0.5), std 1 on the unit scale
    loss = im.loss(net, 8, np.random.default_rng(0))
    assert loss.item() == pytest.approx(0.5 * (0.5 ** 2 + 0.5 ** 2))  # z = (-0.5, 0.5), log std 0
    loss.backward()
    # d/dm 0.5 (m/2 - 0.5)^2 at m = 0: -0.25; d/dm 0.5 ((m - 5)/5)^2 at m = 7.5: 0.1
    assert net.out.grad.tolist() == [[pytest.approx(-0.25), pytest.approx(0.1)]]
    # d/du (0.5 z^2 e^(-2u) + u) at u = 0: 1 - z^2 = 0.75: the spread shrinks toward what separates the actions
    assert net.log_std.grad.tolist() == [pytest.approx(0.75), pytest.approx(0.75)]


def test_squashed_imitation_compares_the_tanh_of_the_mean_and_holds_targets_inside():
    head = ActionHead.of(spaces.Box(-1.0, 1.0, (1,), np.float32))
    im = Imitation(head, obs_dim=2, capacity=10, squashed=True)
    im.add(np.zeros((2, 2)), np.array([[1.0], [-1.0]]))  # the bounds themselves: tanh reaches them only at infinity
    assert im.actions[:2, 0].tolist() == [pytest.approx(SQUASH_EDGE), pytest.approx(-SQUASH_EDGE)]
    net = Fixed([math.atanh(0.5)], log_std=[0.0])  # (the squashed loss reads the mean alone)
    loss = im.loss(net, 1000, np.random.default_rng(1)).item()
    # half the draws are each row: (0.5 - 0.999)^2 and (0.5 + 0.999)^2, averaged
    expect = 0.5 * ((0.5 - SQUASH_EDGE) ** 2 + (0.5 + SQUASH_EDGE) ** 2)
    assert loss == pytest.approx(expect, rel=0.1)


def test_discrete_imitation_is_the_cross_entropy_among_allowed_actions():
    head = ActionHead.of(spaces.Discrete(3))
    im = Imitation(head, obs_dim=1, capacity=5)
    im.add(np.zeros((1, 1)), np.array([1]), mask=np.array([[True, True, False]]))
    net = Fixed([0.0, math.log(2.0), 5.0])  # action 2 masked: p(1) = 2 / 3
    assert im.loss(net, 4, np.random.default_rng(0)).item() == pytest.approx(-math.log(2 / 3))


def test_multidiscrete_imitation_sums_the_dimensions_cross_entropies():
    head = ActionHead.of(spaces.MultiDiscrete([2, 3]))
    im = Imitation(head, obs_dim=1, capacity=5)
    im.add(np.zeros((1, 1)), np.array([[0, 2]]))
    net = Fixed([0.0, 0.0, 0.0, 0.0, math.log(2.0)])  # p(0) = 1/2; p(2) = 2/4
    assert im.loss(net, 3, np.random.default_rng(0)).item() == pytest.approx(2 * math.log(2.0))


def test_the_ring_keeps_the_newest_states():
    head = ActionHead.of(spaces.Discrete(4))
    im = Imitation(head, obs_dim=1, capacity=4)
    im.add(np.array([[0.0], [1.0], [2.0]]), np.array([0, 1, 2]))
    im.add(np.array([[3.0], [4.0], [5.0]]), np.array([3, 0, 1]))
    assert len(im) == 4
    assert sorted(im.obs[:, 0].tolist()) == [2.0, 3.0, 4.0, 5.0]
    assert {int(o): int(a) for o, a in zip(im.obs[:, 0], im.actions, strict=True)} == {2: 2, 3: 3, 4: 0, 5: 1}
    im.add(np.arange(9.0)[:, None], np.arange(9) % 4)  # more than it holds at once: the last four
    assert sorted(im.obs[:, 0].tolist()) == [5.0, 6.0, 7.0, 8.0]


@pytest.mark.slow
@pytest.mark.parametrize("learner_cls", [SACLearner, PPOLearner])
def test_a_learner_taught_comes_to_act_as_its_teacher(learner_cls, one_thread):
    """A teacher's rule a = clip(2 s0 - s1) on random states: with the imitation term weighted and no reward, the
    learner's deterministic action follows the rule on states it never saw (its untaught error is ~25x larger).

    The bar, measured on seeds 0-9: untaught errors 0.65-0.69; taught, SAC 0.0229-0.0252 (sd 0.0008: the bar 0.04 is
    19 sd above) and PPO 0.0001-0.0014; two torch threads instead of one move them by less than 0.0012. Without the
    imitation term nothing draws the action toward the rule (there is no reward): the error stays near its start."""
    rng = np.random.default_rng(0)
    seat = SeatSpace(spaces.Box(-1.0, 1.0, (2,), np.float32), spaces.Box(-1.0, 1.0, (1,), np.float32))
    n = 64
    if learner_cls is SACLearner:
        from selfplay_cli.algos.sac import SACConfig

        learner = SACLearner(seat, n, SACConfig(learning_starts=64, replay_ratio=1 / 16, batch_size=128,
                                                 critic_hidden=(32, 32)), seed=0)
    else:
        from selfplay_cli.algos.ppo import PPOConfig

        learner = PPOLearner(seat, n, PPOConfig(rollout_steps=8, lr=3e-3), seed=0)

    def rule(s):
        return np.clip(2 * s[:, :1] - s[:, 1:], -1, 1).astype(np.float32)

    def error():
        test = rng.uniform(-1, 1, (500, 2)).astype(np.float32)
        with torch.no_grad():
            policy = learner.policy("p", "toy", greedy=True)
            return float(np.mean((policy.act(test) - rule(test)) ** 2))

    before = error()
    learner.teacher_weight = 1.0
    for _ in range(400):
        obs = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
        learner.act(obs)
        learner.teach(obs, rule(obs))
        if learner.record(np.zeros(n), np.zeros(n)):
            stats = learner.update(obs, 0.0)
    assert stats["teacher_weight"] == 1.0 and math.isfinite(stats["imitation_loss"])
    after = error()
    assert after < 0.04 and after < before / 15, (before, after)


def test_without_weight_a_learner_keeps_no_term(one_thread):
    seat = SeatSpace(spaces.Box(-1.0, 1.0, (2,), np.float32), spaces.Discrete(3))
    learner = PPOLearner(seat, 4, seed=0)
    learner.teach(np.zeros((4, 2)), np.zeros(4, dtype=np.int64))
    for _ in range(learner.cfg.rollout_steps):
        learner.act(np.zeros((4, 2), np.float32))
        learner.record(np.zeros(4), np.zeros(4))
    stats = learner.update(np.zeros((4, 2), np.float32))
    assert "imitation_loss" not in stats and "teacher_weight" not in stats


# -- the run's settings ---------------------------------------------------------------------------------------
def test_teacher_settings_and_their_errors():
    t = TeacherConfig(player="cpu")
    assert [t.schedule().value(p) for p in (0.0, 0.25, 0.5, 1.0)] == [1.0, 0.5, 0.0, 0.0]  # the default fade
    assert TeacherConfig(player="None").player == ""  # "none" switches a game's default teacher off
    with pytest.raises(MarlError, match=r"\[teacher\] weight must not be negative"):
        TeacherConfig(player="cpu", weight=-1.0)
    with pytest.raises(MarlError, match=r"\[teacher\] weight: a ramp takes start, end"):
        TeacherConfig(player="cpu", weight={"start": 1.0})
    with pytest.raises(MarlError, match=r"\[teacher\] states must be at least 1"):
        TeacherConfig(player="cpu", states=0)
    cfg = TrainConfig.from_dict({"env": "pong", "teacher": {"player": "cpu", "weight": 0.5}})
    assert cfg.teacher.schedule().value(0.9) == 0.5
    assert TrainConfig.from_dict(cfg.to_dict()).teacher == cfg.teacher  # saved with the run, resumed as it was
    with pytest.raises(MarlError, match="dqn learners cannot imitate a teacher"):
        TrainConfig.from_dict({"env": "pong", "algo": "dqn", "teacher": {"player": "cpu"}})
    with pytest.raises(MarlError, match=r"unknown \[teacher\] setting\(s\) strength"):
        TrainConfig.from_dict({"env": "pong", "teacher": {"player": "cpu", "strength": 1.0}})


def test_a_teacher_the_run_cannot_have_is_one_line_and_no_run(tmp_path, capsys):
    home = str(tmp_path / "league")
    code, out, err = run(capsys, "train", "pong", "--teacher", "nobody", "--steps", "2000", "--home", home)
    assert code != 0 and err.count("\n") == 1 and "--teacher: no policy named 'nobody'" in err, err
    code, out, err = run(capsys, "train", "pong", "--algo", "dqn", "--teacher", "cpu", "--steps", "2000",
                         "--home", home)
    assert code != 0 and err.count("\n") == 1 and "dqn learners cannot imitate" in err, err
    league = League.open(home=tmp_path / "league")
    assert league.roster.list_runs() == []  # refused before the run was created
    league.close()


def agreement_with_cpu(league, snapshot: str) -> float:
    """The share of states in which ``snapshot`` (greedy, on the left) chooses the scripted cpu player's move, over
    9,600 states of 32 pong games between the cpu player and the random player (the same games for every call)."""
    spec = get_env("pong")
    core = spec.make_core(32, spec.config())
    cpu = spec.bots["cpu"].rule_for(spec.config())
    rng = np.random.default_rng(3)
    player = load_player(league, resolve(league, snapshot, "pong"), greedy=True)
    same = total = 0
    core.reset(np.arange(32), np.arange(32))
    for _ in range(300):
        obs = core.observe()
        teacher = cpu(obs[0], rng)
        same += int((player.act(obs[0]) == teacher).sum())
        total += len(teacher)
        core.step([teacher, rng.integers(0, 3, 32)])
        done = np.flatnonzero(core.terminated | core.truncated)
        core.reset(done, 1000 + done)
    return same / total


@pytest.mark.slow
def test_pong_learners_kickstarted_by_the_cpu_player_choose_its_moves(tmp_path, capsys):
    """PPO on pong taught by the scripted cpu player (its weight held at 2), on three seeds: the imitation loss falls
    and the final snapshot chooses the cpu player's move in most states of games between cpu and random players.

    The bar, measured on seeds 0-9 at this budget (50k steps: six PPO updates, 96 minibatches, each with its
    imitation term): taught snapshots agree 0.731-0.745 (mean 0.740, sd 0.005; the imitation is supervised
    learning, whose outcome hardly depends on the run's trajectory); untaught runs of the same budget agree
    0.30-0.53 (mean 0.46, sd 0.07: a constant move agrees about half the time, since the cpu player never stays).
    The bar 0.70 is 8 sd below the taught mean and 3.4 sd above the untaught one. The median of three seeds falls
    below it only if two seeds do: even at three times the measured spread (p = 0.004 a seed), 3 p^2 < 1e-4. With
    the imitation term broken the three runs are untaught ones, and the median clears 0.70 with p < 1e-6.

    Not compared with an untaught run: one that learns pong learns to follow the ball, as the cpu player does
    (seed 0: 0.52 at 200k steps; seed 6: 0.67 at 100k), so the gap between the two measured how far the untaught
    run had got, which varies from machine to machine (this test once asked taught > untaught + 0.3 at 200k steps:
    0.83 and 0.53 on torch 2.13)."""
    home = tmp_path / "league"
    config = tmp_path / "teach.toml"
    config.write_text('[teacher]\nplayer = "cpu"\nweight = 2.0\n')
    agree = []
    for seed in (0, 1, 2):
        taught = run_json(capsys, "train", "pong", "--config", str(config), "--run", f"taught{seed}", "--seed",
                          str(seed), "--agents", "2", "--steps", "50000", "--games", "64", "--eval-games", "0",
                          "--quiet", "--home", str(home))
        lines = (home / "runs" / f"taught{seed}" / "metrics.jsonl").read_text().splitlines()
        losses = [m["left/imitation_loss"] for m in map(json.loads, lines) if "left/imitation_loss" in m]
        # the cross-entropy to the cpu player's moves: 0.90-0.92 after the first update, 0.22-0.24 at the end
        assert losses[-1] < 0.5 * losses[0], (seed, losses)
        league = League.open(home=home, readonly=True)
        agree.append(agreement_with_cpu(league, taught["final"][0]["snapshot"]))
        league.close()
    assert sorted(agree)[1] > 0.70, agree
