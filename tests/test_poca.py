"""MA-POCA (``--algo poca``): an attention critic over the agents present, a counterfactual baseline per agent, and
credit for an agent's decisions after it left; trained through `marl train`.

Measured at 10,000 steps (32 games, 16-step rollouts). The duet (tests/games/duet.py; see tests/test_mappo.py), the
chance both singers are right: PPO FuPS 0.32, 0.26, 0.29, 0.43, 0.19 over seeds 0-4, POCA FuPS 0.999, 0.999, 0.998,
0.998, 0.998, POCA NoPS 0.997, 0.998, 0.996 over seeds 0-2. The relay (tests/games/relay.py): the scout answers once
and leaves, and whether it was right is the runner's reward at the game's end; the scout's chance of answering
right: PPO FuPS 0.47, 0.44, 0.46 and MAPPO FuPS 0.44, 0.49, 0.44 over seeds 0-2, PPO NoPS 0.58, 0.48 over seeds 3-4
(they stop at the scout's own end, where its reward is always 0: it answers at random); POCA FuPS 0.999 over seeds
0-2, POCA NoPS 0.998, 0.998, 0.998, 0.999 over seeds 0, 1, 3, 4.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from cli_helpers import run_json
from team_helpers import DUET, RELAY, duet_together, relay_scout_right, train_team
from torch import nn

from selfplay_cli.algos import POCAConfig, POCALearner
from selfplay_cli.algos.mappo import mlp
from selfplay_cli.algos.poca import FewTokenAttention, PairAttention, TeamCritic
from selfplay_cli.envs import get_env
from selfplay_cli.envs.team import team_spec
from selfplay_cli.play.team_view import TeamViews
from selfplay_cli.play.training_games import SelfPlayGames

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))


@pytest.mark.slow
def test_poca_learns_the_duet_that_ppo_fups_does_not_at_equal_steps(home, capsys):
    ppo = duet_together(train_team(capsys, home, DUET, "ppo", "fups", seed=1, run="ppo"))
    poca = duet_together(train_team(capsys, home, DUET, "poca", "fups", seed=1, run="poca"))
    assert ppo < 0.6 and poca > 0.9, (ppo, poca)


@pytest.mark.slow
@pytest.mark.parametrize("sharing", ["fups", "nops"])
def test_an_agent_that_leaves_keeps_its_credit_for_the_teams_later_reward(home, capsys, sharing):
    ppo = relay_scout_right(train_team(capsys, home, RELAY, "ppo", sharing, seed=2, run="ppo"))
    poca = relay_scout_right(train_team(capsys, home, RELAY, "poca", sharing, seed=2, run="poca"))
    assert 0.3 < ppo < 0.7 and poca > 0.9, (ppo, poca)  # PPO never sees the reward: it answers at random


def test_the_baseline_reads_the_others_actions_and_not_its_own():
    torch.manual_seed(0)
    critic = TeamCritic(3, 4, 2, None, (16, 16), 4, "relu")
    obs, present = torch.randn(5, 3, 4), torch.tensor([[True, True, False]] * 5)
    acts = torch.nn.functional.one_hot(torch.randint(2, (5, 3)), 2).float()
    seat = torch.zeros(5, dtype=torch.long)
    base = critic.baseline(obs, acts, present, seat, None)
    own = acts.clone()
    own[:, 0] = 1 - own[:, 0]  # agent 0's own action changed: its baseline is the same
    torch.testing.assert_close(critic.baseline(obs, own, present, seat, None), base)
    other = acts.clone()
    other[:, 1] = 1 - other[:, 1]  # another agent's: it moves
    assert not torch.allclose(critic.baseline(obs, other, present, seat, None), base)
    absent = acts.clone()
    absent[:, 2] = 1 - absent[:, 2]  # an absent agent's: nothing
    torch.testing.assert_close(critic.baseline(obs, absent, present, seat, None), base)
    values = critic.value(obs, torch.zeros(5, 3, dtype=torch.bool), None)  # nobody in the game: still defined
    assert torch.isfinite(values).all() and np.isfinite(base.detach().numpy()).all()


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["mappo", "poca"])
def test_three_agents_with_box_actions_no_state_and_a_time_limit_train(home, capsys, algo):
    report = run_json(capsys, "train", "tests.games.rendezvous:parallel_env", "--algo", algo, "--agents", "3",
                      "--sharing", "fups", "--steps", "1200", "--games", "8", "--eval-games", "0", "--run", "r",
                      "--config", str(_rollout(home)))
    assert report["steps"] >= 1200 and len(report["final"]) == 1, report  # games cut at 50 steps bootstrapped


def _rollout(home: Path) -> Path:
    path = home.parent / "short.toml"
    path.write_text("[mappo]\nrollout_steps = 16\n[poca]\nrollout_steps = 16\n")
    return path


class OracleCritic(nn.Module):
    """The critic as it was first written (one nn.MultiheadAttention pass for V and another for each baseline, once
    per seat's row): the oracle the computed-once critic must equal, on the same weights."""

    def __init__(self, n_seats: int, obs_width: int, act_width: int, state_width: int | None,
                 hidden: tuple[int, ...], heads: int, activation: str) -> None:
        super().__init__()
        h = hidden[0]
        self.n_seats = n_seats
        self.obs_token = mlp(obs_width + n_seats, (), h, activation)
        self.obs_action_token = mlp(obs_width + act_width + n_seats, (), h, activation)
        self.state_token = None if state_width is None else mlp(state_width, (), h, activation)
        self.attention = nn.MultiheadAttention(h, heads, batch_first=True)
        self.norm = nn.LayerNorm(h)
        self.head = mlp(h, hidden[1:], 1, activation)
        self.register_buffer("eye", torch.eye(n_seats), persistent=False)

    def _seated(self, x):
        return torch.cat((x, self.eye.expand(x.shape[0], -1, -1)), dim=-1)

    def _pool(self, tokens, mask, state):
        tokens = F.relu(tokens)
        if self.state_token is not None and state is not None:
            tokens = torch.cat((tokens, F.relu(self.state_token(state))[:, None]), dim=1)
            mask = torch.cat((mask, torch.ones_like(mask[:, :1])), dim=1)
        mask = mask | ~mask.any(dim=1, keepdim=True)
        attended, _ = self.attention(tokens, tokens, tokens, key_padding_mask=~mask, need_weights=False)
        z = self.norm(tokens + attended)
        m = mask.unsqueeze(-1).to(z.dtype)
        return self.head((z * m).sum(dim=1) / m.sum(dim=1)).squeeze(-1)

    def value(self, obs, present, state):
        return self._pool(self.obs_token(self._seated(obs)), present, state)

    def baseline(self, obs, actions, present, seat, state):
        own = self.obs_token(self._seated(obs))
        others = self.obs_action_token(self._seated(torch.cat((obs, actions), dim=-1)))
        is_self = F.one_hot(seat, self.n_seats).bool()
        return self._pool(torch.where(is_self.unsqueeze(-1), own, others), present | is_self, state)


@pytest.mark.parametrize(("seats", "state"), [(2, None), (2, 3), (3, 5), (6, 4)])  # 2 tokens, 3-4, 7 (matmul)
def test_the_critic_computed_once_equals_the_critic_as_first_written(seats, state):
    torch.manual_seed(seats)
    args = (seats, 7, 3, state, (32, 16), 4, "tanh" if seats == 3 else "relu")
    new, old = TeamCritic(*args), OracleCritic(*args)
    old.load_state_dict(new.state_dict())
    rows = 257
    obs, acts = torch.randn(rows, seats, 7), torch.randn(rows, seats, 3)
    present = torch.rand(rows, seats) < 0.7
    present[:4] = False  # nobody in the game: defined all the same
    s = None if state is None else torch.randn(rows, state)
    seat = torch.randint(0, seats, (rows,))
    v, q = new.values_and_baselines(obs, acts, present, s)  # V and every seat's baseline of every step
    v_old = old.value(obs, present, s)
    q_old = torch.stack([old.baseline(obs, acts, present, torch.full((rows,), i), s) for i in range(seats)], dim=1)
    torch.testing.assert_close(v, v_old, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(q, q_old, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(new.baseline(obs, acts, present, seat, s), old.baseline(obs, acts, present, seat, s),
                               rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(new.value(obs, present, s), v_old, rtol=1e-5, atol=1e-5)
    (v.square().sum() + q.square().sum()).backward()
    (v_old.square().sum() + q_old.square().sum()).backward()
    for (name, a), b in zip(new.named_parameters(), old.parameters(), strict=True):
        torch.testing.assert_close(a.grad, b.grad, rtol=1e-4, atol=1e-4, msg=name)


@pytest.mark.parametrize("attention", [FewTokenAttention, PairAttention])
def test_the_written_out_attentions_backward_is_its_gradient(attention):
    tokens = 2 if attention is PairAttention else 3
    q, k, v = (torch.randn(tokens, 6, 2, 4, dtype=torch.double, requires_grad=True) for _ in range(3))
    mask = torch.rand(tokens, 6) < 0.6
    mask[0, :3] = True
    mask[1, 3:] = True  # (each set has a key; some have one only, masked on either side)
    if attention is PairAttention:  # each token's q, k, v a tensor of its own
        def attend(q, k, v):
            return attention.apply(q[0], q[1], k[0], k[1], v[0], v[1], mask)
    else:
        def attend(q, k, v):
            return attention.apply(q, k, v, mask)
    assert torch.autograd.gradcheck(attend, (q, k, v))


@pytest.mark.parametrize(("game", "n_games"), [(DUET, 3), (RELAY, 4)])  # the relay: state, agents leave
def test_returns_advantages_and_the_critics_loss_are_the_per_seat_ones(game, n_games):
    """One game step valued once for its seats gives every decision the return, value and advantage the per-seat
    computation gave, and over a whole rollout the critic's weighted loss is the per-decision loss."""
    spec = get_env(game)
    seats = spec.seat_spaces(spec.config())
    layout = np.zeros((2, n_games), dtype=np.int64)  # FuPS: both seats of every game are the learner's
    cfg = POCAConfig(rollout_steps=6, minibatches=1, gamma=0.9, gae_lambda=0.8)
    learner = POCALearner(seats[0], 2 * n_games, cfg, seed=3, team=team_spec(spec, spec.config(), seats, layout, 0))
    games = SelfPlayGames(spec, n_games, layout, ["team"])
    games.team = views = TeamViews(games)
    before = views.view()
    for _ in range(cfg.rollout_steps):
        (obs,) = games.observe()
        acting = before.present.T.reshape(-1).copy()
        rewards, dones, _ = games.step([learner.act(obs)])
        learner.see_team(step := views.steps(before, before := views.view())[0])
        learner.record(rewards[0], dones[0], acting=acting)
    batch = learner._batch(games.observe()[0])
    assert len(learner._critic["v_weight"]) <= cfg.rollout_steps * n_games  # a game step once, not once a seat
    # the oracle: every slot's row valued on its own, GAE over each slot's team rewards
    buf, t, b = learner.team_buf, cfg.rollout_steps, 2 * n_games
    flat = {k: buf[k].reshape(t * b, *buf[k].shape[2:]) for k in ("team_obs", "present", "team_actions", "team_state")
            if k in buf}
    critic = learner.critic
    with torch.no_grad():
        values = critic.value(flat["team_obs"], flat["present"], flat.get("team_state")).reshape(t, b)
        after = learner._tensors(step.after)
        next_value = critic.value(after["team_obs"], after["present"], after.get("team_state"))
        base = critic.baseline(flat["team_obs"], flat["team_actions"], flat["present"], learner.seats.repeat(t),
                               flat.get("team_state"))
    live = 1.0 - buf["team_done"]
    deltas = buf["team_reward"] + cfg.gamma * (torch.cat((values[1:], next_value[None])) * live + buf["team_boot"]) \
        - values
    adv, last = torch.zeros_like(deltas), torch.zeros(b)
    for k in reversed(range(t)):
        last = deltas[k] + cfg.gamma * cfg.gae_lambda * live[k] * last
        adv[k] = last
    returns = (adv + values).reshape(-1)
    idx = learner.acting.reshape(-1).nonzero().squeeze(-1) if learner.acting is not None else torch.arange(t * b)
    torch.testing.assert_close(batch["returns"], returns[idx], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(batch["values"], values.reshape(-1)[idx], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(batch["adv"], (returns - base)[idx], rtol=1e-5, atol=1e-6)
    loss = learner._value_loss(None, batch, idx)  # one minibatch a pass: the whole rollout
    with torch.no_grad():
        r = returns[idx]
        per_decision = 0.5 * ((values.reshape(-1)[idx] - r).square().mean() + (base[idx] - r).square().mean())
    torch.testing.assert_close(loss.detach(), per_decision, rtol=1e-5, atol=1e-6)
