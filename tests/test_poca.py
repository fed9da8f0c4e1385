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
from cli_helpers import run_json
from team_helpers import DUET, RELAY, duet_together, relay_scout_right, train_team

from selfplay_cli.algos.poca import TeamCritic

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
