"""Training games on Ray actors (``marl train --executor ray``): the split that makes a sharded run the local run,
and, with Ray on this machine, PPO equal to the local run, a PettingZoo game through actors, an actor killed
mid-run, SAC learning through actors, and the one-line refusals."""

from __future__ import annotations

import hashlib
import os
import signal
import sys

import numpy as np
import procs
import pytest
import torch
from cli_helpers import ctrl_c_enabled
from cli_helpers import run as run_cli
from gymnasium import spaces

from selfplay_cli.algos import DQNConfig, PPOConfig, SACConfig
from selfplay_cli.algos.dqn import DQNLearner
from selfplay_cli.algos.ppo import PPOLearner
from selfplay_cli.algos.sac import SACLearner
from selfplay_cli.envs import SeatSpace
from selfplay_cli.league.store import League
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies.network import Arch
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.loop import Trainer
from selfplay_cli.train.opponents import PolicyCache
from selfplay_cli.train.shards import plan_shards

REACH = "tests.games.reach:parallel_env"
TICTACTOE = "tests.games.tictactoe:env"


# ---------------------------------------------------------------------------------------------------------------
# The split (no Ray needed)


def test_shards_are_contiguous_game_ranges_placed_in_each_learners_slot_order():
    layout = np.zeros((2, 5), dtype=np.int64)  # one network on both seats of 5 games: slots 0-4 seat 0, 5-9 seat 1
    plan = plan_shards(layout, 2)
    assert [g.tolist() for g in plan.games] == [[0, 1, 2], [3, 4]]
    assert [p[0].tolist() for p in plan.positions] == [[0, 1, 2, 5, 6, 7], [3, 4, 8, 9]]
    assert plan.totals == [10]
    two = np.array([[0, 0, -1, 0], [1, -1, 1, 1]])  # two learners and some opponent seats
    plan = plan_shards(two, 2)
    assert [[p.tolist() for p in ps] for ps in plan.positions] == [[[0, 1], [0]], [[2], [1, 2]]]
    with pytest.raises(ValueError):
        plan_shards(layout, 6)


def _split_decide(learner_cls, seat, config, obs, mask=None, rows=((0, 1, 2), (3, 4))):
    """Actions and what is kept for ``obs`` decided by one learner for the whole batch, and by copies of it each
    deciding its share of the rows (the same generator state to start from), plus the generator states after."""
    whole = learner_cls(seat, len(obs), config, seed=3)
    played, taken = whole.decide(obs, mask)
    parts = []
    for r in rows:
        copy = learner_cls(seat, len(r), config, seed=3)
        copy.share = (np.asarray(r), len(obs))
        idx = list(r)
        parts.append(copy.decide(obs[idx], None if mask is None else mask[idx]) + (copy,))
    return (played, taken, whole), parts


def _as_np(x):
    return None if x is None else (x.numpy() if isinstance(x, torch.Tensor) else np.asarray(x))


@pytest.mark.parametrize("kind", ["discrete", "masked", "box"])
def test_ppo_decides_the_same_rows_however_the_batch_is_split(kind):
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(5, 3)).astype(np.float32)
    act = spaces.Box(-1.0, 1.0, (2,), np.float32) if kind == "box" else spaces.Discrete(4)
    seat = SeatSpace(spaces.Box(-5, 5, (3,), np.float32), act, kind == "masked")
    mask = np.array([[1, 0, 1, 0], [0, 1, 0, 0], [1, 1, 1, 1], [0, 0, 1, 1], [1, 0, 0, 1]], bool) \
        if kind == "masked" else None
    (played, taken, whole), parts = _split_decide(PPOLearner, seat, PPOConfig(), obs, mask)
    joined = np.concatenate([p[0] for p in parts])
    assert np.array_equal(joined, played)
    for key in ("actions", "logprobs", "values"):
        assert np.array_equal(np.concatenate([_as_np(p[1][key]) for p in parts]), _as_np(taken[key]))
    if mask is not None:
        assert mask[np.arange(5), played].all()  # never a masked action
    for _, _, copy in parts:  # every share drew the whole batch's noise: the generators stand where the whole's does
        assert torch.equal(copy.gen.get_state(), whole.gen.get_state())


def test_sac_and_dqn_decide_the_same_rows_however_the_batch_is_split():
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(5, 4)).astype(np.float32)
    box = SeatSpace(spaces.Box(-3, 3, (4,), np.float32), spaces.Box(-1.0, 1.0, (2,), np.float32), False)
    for starts in (0, 10**9):  # the random warm-up, then the actor's samples
        (played, _, _), parts = _split_decide(SACLearner, box, SACConfig(learning_starts=starts), obs)
        assert np.array_equal(np.concatenate([p[0] for p in parts]), played)
    seat = SeatSpace(spaces.Box(-3, 3, (4,), np.float32), spaces.Discrete(3), False)
    (played, _, _), parts = _split_decide(DQNLearner, seat, DQNConfig(eps_start=0.5, eps_end=0.5), obs)
    assert np.array_equal(np.concatenate([p[0] for p in parts]), played)


def test_a_games_seed_is_its_slots_and_count_so_shards_play_the_runs_games():
    layout = np.array([[0] * 4, [1] * 4])
    whole = SelfPlayGames("pong", 4, layout, ["a", "b"], env_options={"points_to_win": 1}, first_seed=50)
    shards = [SelfPlayGames("pong", 2, layout[:, ids], ["a", "b"], env_options={"points_to_win": 1}, first_seed=50,
                            game_ids=ids, total_games=4) for ids in (np.array([0, 1]), np.array([2, 3]))]
    assert whole.seeds.tolist() == [50, 51, 52, 53] == [*shards[0].seeds.tolist(), *shards[1].seeds.tolist()]
    rng = np.random.default_rng(0)
    seen_whole, seen_split = [], []
    for _ in range(3000):
        acts = [rng.integers(0, 3, 4), rng.integers(0, 3, 4)]
        _, _, done = whole.step(acts)
        seen_whole += [(g.index, g.seed, g.scores) for g in done]
        for k, sh in enumerate(shards):
            _, _, done = sh.step([a[2 * k:2 * k + 2] for a in acts])
            seen_split += [(g.index, g.seed, g.scores) for g in done]
    assert len(seen_whole) > 8
    assert sorted(seen_whole) == sorted(seen_split)
    assert {seed for _, seed, _ in seen_whole} >= {54, 55}  # each slot's second game: 50 + 1 * 4 + slot


def test_opponent_policies_are_kept_in_a_bounded_cache():
    loads = []
    cache = PolicyCache(lambda pid: loads.append(pid) or object(), size=3)
    first = cache.get(1)
    for pid in (2, 3, 1, 4, 5):
        cache.get(pid)
    assert len(cache) == 3 and loads == [1, 2, 3, 4, 5]  # 1 was used again, so 2 went first
    assert cache.get(1) is first and cache.get(2) is not None and loads[-1] == 2


def test_training_games_let_go_of_opponents_no_game_plays():
    made = []

    def fresh(slots):
        made.extend(object() for _ in slots)
        from selfplay_cli.policies import ScriptedPolicy

        return [ScriptedPolicy("pong", "random", seed=len(made) + i) for i in range(len(slots))]

    layout = np.array([[0] * 4, [-1] * 4])
    games = SelfPlayGames("pong", 4, layout, ["a"], choose_opponents=fresh, env_options={"points_to_win": 1})
    rng = np.random.default_rng(0)
    for _ in range(4000):
        games.step([rng.integers(0, 3, 4)])
    assert len(made) > 40  # a new policy object for every game
    assert len(games.policies) <= 16 and len({id(p) for p in games.policies}) == len(games.policies)


# ---------------------------------------------------------------------------------------------------------------
# With Ray on this machine


def _digest(learners) -> list[str]:
    return [hashlib.sha256(b"".join(v.numpy().tobytes() for v in learner.net.state_dict().values())).hexdigest()
            for learner in learners]


def _weights(path) -> str:
    """A snapshot file's tensors, hashed (its metadata names the run's settings, the executor among them)."""
    from safetensors.numpy import load_file

    tensors = load_file(str(path))
    return hashlib.sha256(b"".join(k.encode() + tensors[k].tobytes() for k in sorted(tensors))).hexdigest()


def _train(where, **kw):
    league = League.open(where)
    base = dict(env="pong", steps=4096, games=16, snapshot_steps=2048, snapshot_every=0, eval_games=0, run="t",
                env_options={"points_to_win": 1}, ppo=PPOConfig(rollout_steps=32, minibatches=2, update_epochs=1))
    cfg = TrainConfig(**{**base, **kw})
    league.roster.create_run("t", cfg.env, cfg.to_dict(), algo=cfg.algo)
    trainer = Trainer(league, cfg)
    report = trainer.train()
    snaps = sorted((p.name, _weights(league.snapshot_file(p))) for p in league.roster.players(cfg.game().name,
                                                                                         kind="snapshot"))
    games = league.ledger.games(cfg.game().name)
    played = sorted(zip(games.seed.tolist(), games.game_id.tolist(), strict=True))
    return trainer, report, snaps, len(played), league


@pytest.mark.slow
def test_ppo_with_two_actors_is_the_local_run(ray_local, tmp_path):
    local, rep_l, snaps_l, games_l, _ = _train(tmp_path / "local", agents=2)
    ray, rep_r, snaps_r, games_r, _ = _train(tmp_path / "ray", agents=2, executor="ray", actors=2)
    assert _digest(local.learners) == _digest(ray.learners)
    assert snaps_l == snaps_r and len(snaps_l) == 6  # s0, s2k, s4k of each side: the same weights
    assert (rep_l.steps, rep_l.episodes) == (rep_r.steps, rep_r.episodes) and rep_l.episodes > 0
    assert games_l == games_r


@pytest.mark.slow
def test_a_pettingzoo_game_with_turns_and_masks_through_actors_is_the_local_run(ray_local, tmp_path):
    local, rep_l, snaps_l, _, _ = _train(tmp_path / "local", env=TICTACTOE, env_options={}, steps=3000,
                                         snapshot_steps=1500, agents=2)
    ray, rep_r, snaps_r, _, league = _train(tmp_path / "ray", env=TICTACTOE, env_options={}, steps=3000,
                                            snapshot_steps=1500, agents=2, executor="ray", actors=2)
    assert rep_l.episodes == rep_r.episodes > 300
    assert _digest(local.learners) == _digest(ray.learners) and snaps_l == snaps_r


@pytest.mark.slow
def test_one_agent_for_the_whole_team_on_the_lander_through_actors_is_the_local_run(ray_local, tmp_path):
    kw = dict(env="lander", env_options={}, agents=2, sharing="sa", steps=4096, snapshot_steps=2048,
              ppo=PPOConfig(rollout_steps=64, minibatches=2, update_epochs=1))
    local, rep_l, snaps_l, _, _ = _train(tmp_path / "local", **kw)
    ray, rep_r, snaps_r, _, _ = _train(tmp_path / "ray", executor="ray", actors=2, **kw)
    assert rep_l.episodes == rep_r.episodes > 0  # (SA: one decision a game, placed by game, not by seat)
    assert _digest(local.learners) == _digest(ray.learners) and snaps_l == snaps_r


@pytest.mark.slow
def test_an_actor_killed_mid_run_is_restarted_and_the_run_loses_nothing(ray_local, tmp_path):
    league = League.open(tmp_path / "league")
    cfg = TrainConfig(env="pong", steps=24_576, games=16, snapshot_steps=8192, snapshot_every=0, eval_games=0,
                      run="k", env_options={"points_to_win": 1}, executor="ray", actors=2,
                      ppo=PPOConfig(rollout_steps=32, minibatches=2, update_epochs=1))
    league.roster.create_run("k", "pong", cfg.to_dict(), algo="ppo")
    notes, killed = [], []

    def watch(event):
        if event["event"] == "note":
            notes.append(event["line"])
        elif event["event"] == "training" and event["standing"].steps > 8192 and not killed:
            killed.append(trainer.rollouts.actor_pids()[1])
            os.kill(killed[0], signal.SIGKILL)

    trainer = Trainer(league, cfg, on_progress=watch)
    report = trainer.train()
    assert killed and len(notes) == 1 and "rollout actor 2 of 2 died" in notes[0], notes
    assert report.steps == 24_576
    rows = league.roster.players("pong", kind="snapshot")
    moments = {p.name.rsplit("-", 1)[0] for p in rows}  # every 8,192 steps (at an update), from s0 to the final one
    assert len(rows) == 8 and len(moments) == 4 and "s0" in moments, sorted(moments)
    assert [p.step for p in rows if p.name.endswith("-left")] == [0, 8192, 16384, 24576]
    for p in rows:
        assert league.snapshot_file(p).is_file()


@pytest.mark.slow
def test_sac_with_two_actors_learns_the_reaching_task(ray_local, tmp_path):
    sys.path.insert(0, os.path.dirname(__file__))
    from test_sac import final_distance

    sac = SACConfig(batch_size=128, learning_starts=500, replay_ratio=1 / 8, critic_hidden=(32, 32),
                    arch=Arch(hidden=(32, 32), activation="relu", value_head=False, squash=True))
    trainer, report, _, _, _ = _train(tmp_path / "sac", env=REACH, env_options={}, algo="sac", agents=1, steps=3200,
                                      games=8, snapshot_steps=3200, sac=sac, executor="ray", actors=2)
    learner = trainer.learners[0]
    assert report.steps == 3200 and learner.grad_steps > 500
    # measured with seeds 0 and 1: 0.287 and 0.289 through 2 actors (0.285, 0.294 local); the untrained actor and
    # random play stay above 0.8 (tests/test_sac.py)
    assert final_distance(learner.policy("sac", "reach", greedy=True).act) < 0.5


# ---------------------------------------------------------------------------------------------------------------
# One line, nothing written


def test_a_ray_cluster_out_of_reach_is_one_line_and_leaves_nothing(tmp_path, capsys):
    home = tmp_path / "h"
    code, out, err = run_cli(capsys, "train", "pong", "--executor", "ray", "--ray-address", "127.0.0.1:1",
                             "--steps", "1000", "--home", str(home))
    assert code == 4 and "cannot reach the Ray cluster at 127.0.0.1:1" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and not home.exists()


def test_ray_missing_and_bad_actor_counts_are_one_line(tmp_path, capsys, monkeypatch):
    home = tmp_path / "h"
    code, _, err = run_cli(capsys, "train", "pong", "--executor", "ray", "--actors", "300", "--games", "16",
                           "--home", str(home))
    assert code == 2 and "--actors must be between 1 and --games (16), not 300" in err and not home.exists()
    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    code, _, err = run_cli(capsys, "train", "pong", "--executor", "ray", "--home", str(home))
    assert code == 2 and 'pip install "selfplay-cli[ray]"' in err and not home.exists()
    assert len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_one_learner_meets_league_snapshots_loaded_by_the_actors_and_repeats(ray_local, tmp_path):
    kw = dict(env=TICTACTOE, env_options={}, steps=3000, snapshot_steps=512, agents=1, executor="ray", actors=2)
    first, report, _, _, league = _train(tmp_path / "a", **kw)
    again, _, _, _, _ = _train(tmp_path / "b", **kw)
    assert _digest(first.learners) == _digest(again.learners)  # the same seed and actors: the same run
    snapshots = {p.id for p in league.roster.players(first.spec.name, kind="snapshot")}
    games = league.ledger.games(first.spec.name, rated=False, variant=None, pooled=False)
    # the learner (filed as its latest snapshot) against a snapshot of the pool the actors loaded from the league
    against = np.isin(games.player_a, list(snapshots)) & np.isin(games.player_b, list(snapshots))
    assert report.episodes > 300 and int(against.sum()) > 20


@pytest.mark.slow
def test_a_trainer_killed_with_sigkill_resumes_on_actors(ray_local, tmp_path, capsys):
    import subprocess
    import time

    home = tmp_path / "h"
    args = ["train", "pong", "--agents", "2", "--games", "16", "--steps", "60000", "--snapshot-steps", "8192",
            "--eval-games", "0", "--env-option", "points_to_win=1", "--executor", "ray", "--actors", "2",
            "--run", "r", "--home", str(home), "--quiet"]
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=os.path.dirname(os.path.dirname(__file__)))
    folder = home / "snapshots" / "r"
    deadline = time.time() + 120
    while time.time() < deadline and len(list(folder.glob("*.safetensors"))) < 6:  # s0 and two moments after it
        time.sleep(0.1)
    proc.kill()
    proc.communicate(timeout=60)
    assert len(list(folder.glob("*.safetensors"))) >= 6
    code, out, err = run_cli(capsys, "train", "--resume", "r", "--home", str(home), "--actors", "1", "--json")
    assert code == 0, err
    report = __import__("json").loads(out)
    assert report["steps"] == 60_000 and report["sessions"] == 2
    assert (report["executor"], report["actors"]) == ("ray", 1)  # this session: moved to one actor
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"
        assert {"s0-left", "s60k-left"} <= {p.name for p in league.roster.players("pong", kind="snapshot")}


# ---------------------------------------------------------------------------------------------------------------
# Issue 49: no more actors than cores on this machine; nothing of Ray left behind


def _marl(*args: str, env: dict | None = None, **kw):
    import subprocess

    return subprocess.Popen([sys.executable, "-m", "selfplay_cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})},
                            preexec_fn=ctrl_c_enabled, **kw)


@pytest.mark.slow
def test_more_actors_than_cores_is_refused_in_one_line_unless_a_cluster_is_given(tmp_path):
    """Issue 49: --actors 200 on 2 cores started Ray with 201 CPUs it did not have (5 GB in 25 s)."""
    from selfplay_cli.ray_support import machine_cores

    over = str(machine_cores() + 1)
    home = tmp_path / "h"
    env = {"RAY_ADDRESS": ""}
    for flags, needle in ((["--executor", "ray", "--actors", over], f"--actors {over} is more Ray actors than"),
                          (["--eval", "ray", "--eval-actors", over], f"--eval-actors {over} is more Ray actors than")):
        _, err = (p := _marl("train", "pong", "--games", "256", *flags, "--home", str(home), env=env)).communicate(
            timeout=300)
        assert p.returncode == 2 and needle in err and f"this machine has cores ({machine_cores()})" in err, err
        assert err.count("\n") == 1 and "--ray-address" in err and not home.exists()
    # a cluster is where more actors go: not refused for this machine's cores (this one cannot be reached)
    for flags, extra in ((["--ray-address", "127.0.0.1:1"], {}), ([], {"RAY_ADDRESS": "127.0.0.1:1"})):
        _, err = (p := _marl("train", "pong", "--games", "256", "--executor", "ray", "--actors", over, *flags,
                             "--home", str(home), env=env | extra)).communicate(timeout=300)
        assert p.returncode == 4 and "cannot reach the Ray cluster at 127.0.0.1:1" in err and not home.exists(), err


def _session(sid: int) -> list[tuple[int, str]]:
    """The live processes of session ``sid`` (a trainer started in a session of its own, and all it started: Ray's
    processes keep it), and the trainer's Ray keeper (in a session of its own), with their whole command lines."""
    return [(p.pid, p.cmdline) for p in procs.session(sid)]


def _wait_for(what, seconds: float):
    import time

    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not what():
        time.sleep(0.05)
    return what()


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig, when", [(signal.SIGTERM, "starting"), (signal.SIGINT, "starting"),
                                       (signal.SIGKILL, "training"), (None, "finished")])
def test_no_ray_process_outlives_its_run(tmp_path, sig, when):
    """Issue 49: a run on Ray actors leaves no Ray process behind, whichever way it ends: stopped while Ray starts
    (Ray's own SIGTERM handler made that exit 15, unsaid, and left Ray's agents running for a minute), killed
    outright while training (Ray's agents waited a minute for a dead GCS), or finished."""
    home = tmp_path / "h"
    proc = _marl("train", "pong", "--games", "16", "--steps", "40000" if sig else "2048", "--snapshot-steps", "1024",
                 "--eval-games", "0", "--env-option", "points_to_win=1", "--executor", "ray", "--actors", "2",
                 "--home", str(home), "--quiet", env={"RAY_ADDRESS": ""}, start_new_session=True)
    try:
        if when == "starting":  # Ray's core is up (its GCS started), the run not begun
            assert _wait_for(lambda: any("gcs_server" in c for _, c in _session(proc.pid)), 120)
        elif when == "training":
            assert _wait_for(lambda: len(list(home.glob("snapshots/*/*.safetensors"))) >= 4, 300)
            assert any(c.startswith("ray::RolloutShard") for _, c in _session(proc.pid))
        if sig is not None:
            proc.send_signal(sig)
        _, err = proc.communicate(timeout=300)
        left = _wait_for(lambda: not _session(proc.pid), 15) or _session(proc.pid)
    finally:
        for pid, _ in _session(proc.pid):  # (nothing, when it held)
            with __import__("contextlib").suppress(OSError):
                os.kill(pid, signal.SIGKILL)
    assert left is True, left
    if when == "starting":
        assert proc.returncode == (143 if sig == signal.SIGTERM else 130)
        assert err.count("\n") == 1 and "while starting: no training was under way" in err, err
    else:
        assert proc.returncode == (-signal.SIGKILL if sig else 0), err
