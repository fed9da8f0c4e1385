"""MAPPO (``--algo mappo``): PPO whose critic reads the whole team, trained through `marl train`.

On the suite's duet (tests/games/duet.py) a round pays only when both singers name their own targets, and each
sees luck of its own that moves the team's reward: PPO FuPS, whose critic reads one seat, carries the other's luck
as noise in its advantages, and MAPPO, whose critic reads the team, does not. Measured (10,000 steps, 32 games,
16-step rollouts), the chance both are right: PPO FuPS 0.32, 0.26, 0.29, 0.43, 0.19 over seeds 0-4; MAPPO FuPS
0.999, 0.998, 0.998, 0.999, 0.999; MAPPO NoPS 0.997, 0.998, 0.996 over seeds 0-2. Also: the team's view the trainer
hands a centralised learner, the snapshot (the actor alone, played by `marl match` like PPO's), a killed run's
resume restoring the critic, and the refusals (a game that is not cooperative, one agent over the team).
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_helpers import run, run_json
from team_helpers import DUET, RELAY, duet_together, train_team

from selfplay_cli.algos import MAPPOConfig, MAPPOLearner, POCAConfig, get_learner
from selfplay_cli.envs import get_env
from selfplay_cli.envs.team import team_spec
from selfplay_cli.league.store import League
from selfplay_cli.play.team_view import TeamViews
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies.snapshot_reader import read_snapshot

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))
KILL_POINTS = Path(__file__).with_name("kill_points.py")


@pytest.mark.slow
def test_mappo_learns_the_duet_that_ppo_fups_does_not_at_equal_steps(home, capsys):
    ppo = duet_together(train_team(capsys, home, DUET, "ppo", "fups", seed=0, run="ppo"))
    fups = duet_together(train_team(capsys, home, DUET, "mappo", "fups", seed=0, run="mappo-fups"))
    nops = duet_together(train_team(capsys, home, DUET, "mappo", "nops", seed=0, run="mappo-nops"))
    assert ppo < 0.6 and fups > 0.9 and nops > 0.9, (ppo, fups, nops)


def test_the_team_view_is_every_seat_of_the_slots_game_and_who_is_in_it():
    spec = get_env(RELAY)  # the scout answers and leaves; the runner is paid 1 at step 4 if the answer was right
    layout = np.zeros((2, 3), dtype=np.int64)  # one learner (FuPS) on both seats of 3 games
    games = SelfPlayGames(spec, 3, layout, ["team"])
    games.team = views = TeamViews(games)
    before = views.view()
    assert before.present.all() and before.obs.shape == (3, 2, 4) and before.state.shape == (3, 4)
    np.testing.assert_array_equal(before.obs[:, 0, -2], 1.0)  # seat 0 is the scout
    signal = before.obs[:, 0, :2].argmax(axis=1)
    games.step([np.concatenate((signal, np.zeros(3, np.int64)))])  # every scout right
    step = views.steps(before, after := views.view())[0]
    assert step.actions.shape == (6, 2, 2) and step.reward.tolist() == [0.0] * 6 and not step.done.any()
    np.testing.assert_array_equal(step.actions[:3, 0].argmax(axis=1), signal)  # slots 0-2 the scouts, 3-5 runners
    np.testing.assert_array_equal(step.actions[3:], step.actions[:3])  # both seats' slots see the same team
    assert not after.present[:, 0].any() and after.present[:, 1].all()  # the scouts left
    np.testing.assert_array_equal(after.state[:, -2], 1.0)  # the state says they were right
    for _ in range(3):
        before = after
        games.step([np.zeros(6, np.int64)])
        step = views.steps(before, after := views.view())[0]
        assert not step.actions[:, 0].any()  # an absent seat's action is no information
    assert step.done.all() and step.reward.tolist() == [1.0] * 6  # the team's reward: the runner's 1
    assert after.present.all()  # the next games


def test_team_specs_give_each_learner_its_slots_seats():
    spec = get_env(DUET)
    seats = spec.seat_spaces(spec.config())
    fups = team_spec(spec, spec.config(), seats, np.zeros((2, 4), dtype=np.int64), 0)
    assert fups.seats.tolist() == [0, 0, 0, 0, 1, 1, 1, 1] and fups.state_width == 8 and fups.act_width == 3
    nops = [team_spec(spec, spec.config(), seats, np.array([[0] * 4, [1] * 4]), i).seats.tolist() for i in (0, 1)]
    assert nops == [[0] * 4, [1] * 4]
    with pytest.raises(ValueError, match="reads the whole team"):
        MAPPOLearner(seats[0], 4, MAPPOConfig())


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["mappo", "poca"])
def test_a_snapshot_is_the_actor_alone_and_plays_in_marl_match(home, capsys, algo):
    paths = train_team(capsys, home, DUET, algo, "nops", seed=1, run="r", steps=1_500)
    snap = read_snapshot(paths[0])
    assert snap.meta.algo == algo and not snap.meta.arch.value_head
    assert sorted(snap.tensors) == sorted(k for k in snap.tensors if "critic" not in k and "value" not in k)
    name = paths[0].stem.rsplit("-", 1)[0]  # the team of the final moment: s1.54k (its members s1.54k-singer_0, ...)
    report = run_json(capsys, "match", f"r/{name}", "random", "--games", "4")
    assert report["results"] >= 1, report


@pytest.mark.parametrize("algo", ["mappo", "poca"])
def test_the_learner_state_round_trips_the_critic(algo):
    spec = get_env(DUET)
    seats = spec.seat_spaces(spec.config())
    team = team_spec(spec, spec.config(), seats, np.zeros((2, 4), dtype=np.int64), 0)
    cls, cfg = get_learner(algo), (MAPPOConfig if algo == "mappo" else POCAConfig)(rollout_steps=4)
    a, b = cls(seats[0], 8, cfg, seed=0, team=team), cls(seats[0], 8, cfg, seed=5, team=team)
    games = SelfPlayGames(spec, 4, np.zeros((2, 4), dtype=np.int64), ["team"])
    games.team = views = TeamViews(games)
    before = views.view()
    for _ in range(4):
        (obs,) = games.observe()
        rewards, dones, _ = games.step([a.act(obs)])
        a.see_team(views.steps(before, before := views.view())[0])
        a.record(rewards[0], dones[0])
    a.update(games.observe()[0])
    buf = io.BytesIO()  # as the run state file is written and read (torch.load with weights_only=True)
    torch.save(a.state_dict(), buf)
    buf.seek(0)
    b.load_state_dict(torch.load(buf, weights_only=True))
    for (name, p), q in zip(a.critic.state_dict().items(), b.critic.state_dict().values(), strict=True):
        assert torch.equal(p, q), name
    assert torch.equal(a.opt.m, b.opt.m) and a.updates == b.updates == 1


@pytest.mark.slow
def test_a_killed_mappo_run_resumes_with_its_trained_critic(tmp_path, capsys, monkeypatch):
    home = tmp_path / "h"
    monkeypatch.delenv("MARL_DB", raising=False)
    args = ["train", DUET, "--algo", "mappo", "--agents", "2", "--sharing", "nops", "--games", "16", "--steps", "6000",
            "--snapshot-steps", "2048", "--eval-games", "0", "--run", "r"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join((str(ROOT), os.environ.get("PYTHONPATH", "")))}  # this
    # checkout's package and its suite's games
    child = subprocess.run([sys.executable, str(KILL_POINTS), "after-rows", str(home), *args], capture_output=True,
                           text=True, timeout=300, env=env)
    assert child.returncode == -9, child.stderr[-2000:]  # killed (SIGKILL) with its second moment's rows committed
    pending = torch.load(home / "runs" / "r" / "state.pt.pending", weights_only=True)
    first = torch.load(home / "runs" / "r" / "state.pt", weights_only=True)
    critic = pending["learners"][0]["critic"]
    assert any(not torch.equal(v, first["learners"][0]["critic"][k]) for k, v in critic.items())  # it trained
    loaded = []
    real = MAPPOLearner.load_state_dict
    monkeypatch.setattr(MAPPOLearner, "load_state_dict", lambda self, state: (
        real(self, state), loaded.append({k: v.clone() for k, v in self.critic.state_dict().items()}))[0])
    code, _, err = run(capsys, "train", "--resume", "r", "--home", str(home), "--json")
    assert code == 0, err
    assert loaded and all(torch.equal(v, loaded[0][k]) for k, v in critic.items())
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"


@pytest.mark.parametrize("algo", ["mappo", "poca"])
@pytest.mark.parametrize(("game", "sharing", "says"), [
    ("pong", "nops", "pong is two-sides: use --algo ppo"),
    (DUET, "sa", "--sharing sa makes the team one agent"),
])
def test_a_team_critic_refuses_a_game_that_is_not_cooperative_and_one_agent_over_the_team(home, capsys, algo, game,
                                                                                           sharing, says):
    code, out, err = run(capsys, "train", game, "--algo", algo, "--agents", "2", "--sharing", sharing, "--steps", "100")
    assert code == 2 and out == "" and err.count("\n") == 1 and says in err and "Traceback" not in err, err
    assert not (home / "runs").exists() or not any((home / "runs").iterdir())  # before a run was created
