"""NaN never enters the league (issue 30, item 5).

Training stops at the first observation, reward, loss or gradient that is NaN or infinite, in one line naming where
it appeared (exit 2: the user's game or settings produced it), the run marked failed and no snapshot saved after
it; a snapshot is never saved nor read (``marl checkpoint import``, ``marl match``) with weights that are not finite,
a Gaussian log-std out of its bounds, a joint (SA) record its network contradicts, or NaN in its metadata."""

from __future__ import annotations

import json
import re
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_helpers import run
from gymnasium import spaces
from safetensors.torch import save_file

from selfplay_cli.algos.dqn import DQNConfig, DQNLearner
from selfplay_cli.algos.ppo import PPOConfig, PPOLearner
from selfplay_cli.algos.sac import SACConfig, SACLearner
from selfplay_cli.envs import SeatSpace, get_env
from selfplay_cli.errors import NonFiniteError
from selfplay_cli.league.store import League
from selfplay_cli.play.seat_plan import plan_layout, plan_seats
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies.joint import joint_spaces
from selfplay_cli.policies.network import Arch, SnapshotError, build_network
from selfplay_cli.policies.snapshot_format import (
    FORMAT,
    MAX_LOG_STD,
    SnapshotMeta,
    check_values,
    save_snapshot,
    weights_sha256,
)
from selfplay_cli.policies.snapshot_reader import load_snapshot, read_snapshot

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

TUG = "tests.games.tug:parallel_env"
TRAIN = ("train", TUG, "--steps", "20000", "--games", "16", "--snapshot-steps", "2000", "--eval-games", "0",
         "--run", "r", "-q")


def _one_line(err: str) -> str:
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.strip()


def _run_state(home: Path) -> tuple[str, list[str]]:
    """The run's status and its snapshots, each checked to load (finite weights) from the file its row names."""
    with League.open(home, readonly=True) as league:
        status = league.roster.get_run("r").status
        snaps = league.roster.players(kind="snapshot")
        for s in snaps:
            tensors, _ = load_snapshot(home / s.path)
            assert all(bool(torch.isfinite(t).all()) for t in tensors.values())
    files = sorted(p.name for p in (home / "snapshots" / "r").iterdir())
    assert files == sorted(Path(s.path).name for s in snaps)  # no file without its row
    return status, sorted(s.name for s in snaps)


# ---------------------------------------------------------------------------------------------------------------
# Training


@pytest.mark.slow
@pytest.mark.parametrize("where", ["observation", "reward"])
def test_a_game_that_turns_nan_stops_training_in_one_line_and_nothing_after_it_is_saved(home, capsys, where):
    # each of the 16 game objects breaks after 300 of its steps: at step 16 x 300 = 4,800 of the run
    code, _, err = run(capsys, *TRAIN, "--env-option", f"nan_in={where}")
    line = _one_line(err)
    assert code == 2, err
    assert f"{where} of seat 1 (player_1) in game " in line and "is NaN at that game's step" in line, line
    assert line.endswith("training stopped at step 4,800"), line
    status, names = _run_state(home)
    assert status == "failed"
    assert names == ["s0-player_0", "s0-player_1", "s2k-player_0", "s2k-player_1", "s4k-player_0",
                     "s4k-player_1"], names  # the moments before step 4,800, and none after

    # resumed, it breaks again (the game does): failed again, never left running
    code, _, err = run(capsys, "train", "--resume", "r", "-q")
    assert code == 2 and f"{where} of seat 1 (player_1)" in err.splitlines()[-1], err
    assert _run_state(home)[0] == "failed"


def test_reward_scale_float32_cannot_hold_is_refused_before_the_run_exists(home, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[ppo]\nreward_scale = 1e308\n")
    code, _, err = run(capsys, "train", TUG, "--config", str(cfg), "--steps", "4096", "--eval-games", "0", "-q")
    assert code == 2 and "[ppo] reward_scale must be more than 0 and at most 1e+06, not 1e+308" in _one_line(err), err
    if (home / "league.db").exists():
        with League.open(home, readonly=True) as league:
            assert league.roster.list_runs() == []


def test_a_loss_that_overflows_stops_training_naming_the_learner_and_the_loss(home, tmp_path, capsys):
    # a game whose rewards are 1e30 from the start: finite in float32, their squares (the value loss) are not
    code, _, err = run(capsys, *TRAIN, "--env-option", "nan_after=0", "--env-option", "nan_in=reward",
                       "--env-option", "nan_value=1e30")
    line = _one_line(err)
    assert code == 2
    assert "learner player_1: the value loss is inf in update 1 (epoch 1, minibatch 1); training stopped at step " \
           "2,048" in line, line
    status, names = _run_state(home)
    assert status == "failed" and names == ["s0-player_0", "s0-player_1"]


@pytest.mark.parametrize("nan_in, said", [("observation", "observation of seat 1 (player_1) in the game of seed "),
                                           ("reward", "the score of seat 1 (player_1) in the game of seed ")])
def test_a_rated_game_that_turns_nan_stores_nothing(home, capsys, nan_in, said):
    """`marl match` of a game whose observations (or rewards) turn NaN: one line naming the seat and the game's
    seed, exit 2, and no game of it in the ledger (a NaN score would have been stored as a result)."""
    code, _, err = run(capsys, "train", TUG, "--env-option", "nan_after=-1", "--steps", "2048", "--games", "16",
                       "--eval-games", "0", "--run", "r", "-q")
    assert code == 0, err
    with League.open(home, readonly=True) as league:
        before = len(league.ledger.games())
    code, _, err = run(capsys, "match", "r/s0-player_0", "random", "--games", "20", "--env-option", "nan_after=5",
                       "--env-option", f"nan_in={nan_in}")
    line = _one_line(err)
    assert code == 2 and said in line and ("is NaN at its step 5" in line if nan_in == "observation"
                                           else line.endswith(" is NaN")), line
    with League.open(home, readonly=True) as league:
        assert len(league.ledger.games()) == before


def _games(env: str, n: int = 4) -> SelfPlayGames:
    spec = get_env(env)
    return SelfPlayGames(spec, n, plan_layout(plan_seats(spec, spec.n_seats), n, spec.n_seats),
                         [f"me{i}" for i in range(spec.n_seats)])


def test_games_name_the_first_seat_and_game_whose_observation_is_not_finite():
    games = _games("tests.games.chase:parallel_env")  # seats unlike each other: observations per seat
    obs = games.core.observe()
    obs[1][2, 4] = -np.inf
    obs[1][3, 0] = np.nan
    games.core.observe = lambda: obs
    with pytest.raises(NonFiniteError, match=r"^observation of seat 1 \(runner\) in game 2 \(seed 2\) is -inf at "
                                             r"that game's step 0$"):
        games.observe()


def _ppo(**cfg) -> tuple[PPOLearner, np.ndarray]:
    seat = SeatSpace(spaces.Box(-1, 1, (4,), np.float32), spaces.Discrete(3))
    obs = np.random.default_rng(0).uniform(-1, 1, (8, 4))
    return PPOLearner(seat, 8, PPOConfig(rollout_steps=8, **cfg), seed=0), obs


def _ppo_update(learner: PPOLearner, obs: np.ndarray, reward: float = 1.0) -> dict:
    for _ in range(8):
        learner.act(obs)
        learner.record(np.full(8, reward, np.float32), np.zeros(8))
    return learner.update(obs)


def test_ppo_names_the_first_minibatch_and_loss_that_broke():
    learner, obs = _ppo(lr=1e30, anneal_lr=False)  # the first step throws the weights to +-1e30
    with pytest.raises(NonFiniteError, match=r"^the policy loss is NaN in update 1 \(epoch 1, minibatch 2\)$"):
        _ppo_update(learner, obs)
    learner, obs = _ppo()
    assert np.isfinite(list(_ppo_update(learner, obs).values())).all()  # a sane one passes


def test_ppo_rewards_the_scale_overflows_are_named():
    learner, obs = _ppo(reward_scale=1e38)
    learner.act(obs)
    with pytest.raises(NonFiniteError, match=r"^a reward of 10 times reward_scale 1e\+38 is beyond float32"):
        learner.record(np.full(8, 10.0, np.float32), np.zeros(8))


def test_dqn_and_sac_name_the_first_gradient_step_that_broke():
    rng = np.random.default_rng(0)
    dqn = DQNLearner(SeatSpace(spaces.Box(-1, 1, (4,), np.float32), spaces.Discrete(3)), 8,
                     DQNConfig(lr=1e30, learning_starts=16, batch_size=8, replay_ratio=1.0, loss="mse"), seed=0)
    sac = SACLearner(SeatSpace(spaces.Box(-1, 1, (4,), np.float32), spaces.Box(-1, 1, (2,), np.float32)), 8,
                     SACConfig(lr=1e30, learning_starts=16, batch_size=8, replay_ratio=1.0), seed=0)
    for learner in (dqn, sac):
        with pytest.raises(NonFiniteError, match=r"^the [a-zA-Z' -]+ is (NaN|inf|-inf) in gradient step \d+$"):
            for _ in range(20):
                obs = rng.uniform(-1, 1, (8, 4)).astype(np.float32)
                learner.act(obs)
                if learner.record(rng.uniform(-1, 1, 8).astype(np.float32), np.zeros(8)):
                    learner.update(obs)


# ---------------------------------------------------------------------------------------------------------------
# Snapshot files


def _craft(path: Path, env: str, obs: spaces.Box, act: spaces.Space, arch: Arch, change=None, **meta) -> Path:
    """A snapshot file as marl writes it (checksum consistent), its weights changed by ``change(tensors)``."""
    tensors = {k: v.detach().clone() for k, v in build_network(obs, act, arch, seed=0).state_dict().items()}
    if change is not None:
        change(tensors)
    data = SnapshotMeta(env=env, obs_space=obs, act_space=act, arch=arch, algo="x", run="contrib", name="c",
                        **meta).to_dict() | {"weights_sha256": weights_sha256(tensors)}
    save_file(tensors, str(path), metadata={"format": FORMAT, "format_version": "2", "marl": json.dumps(data)})
    return path


def _tennis(path: Path, arch: Arch, change=None, **meta) -> Path:
    seat = get_env("tennis").seat_spaces(get_env("tennis").config())[0]
    return _craft(path, "tennis", seat.observation, seat.action, arch, change, **meta)


SAC_ARCH = Arch(hidden=(32, 32), activation="relu", value_head=False, squash=True)
PPO_BOX = Arch(hidden=(32, 32), activation="tanh", value_head=True)


def _set(name: str, index: int, value: float):
    def change(tensors):
        tensors[name].view(-1)[index] = value

    return change


def _lander_joint(path: Path, base: int) -> Path:
    seat = get_env("lander").seat_spaces(get_env("lander").config())[0]
    obs, act = joint_spaces(seat.observation, seat.action, 2)
    return _craft(path, "lander", obs, act, Arch(hidden=(32,), activation="relu", value_head=False),
                  extra={"joint": {"seats": 2, "base": base}})


def _metadata_nan(path: Path, value: str) -> Path:
    file = _tennis(path, PPO_BOX)
    raw = file.read_bytes()
    n = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8:8 + n])
    marl = header["__metadata__"]["marl"]
    header["__metadata__"]["marl"] = marl.replace('"extra": {}', '"extra": {"x": ' + value + "}")
    body = json.dumps(header).encode()
    file.write_bytes(len(body).to_bytes(8, "little") + body + raw[8 + n:])
    return file


CRAFTED = {
    "SAC actor with a NaN weight": (
        lambda p: _tennis(p, SAC_ARCH, _set("trunk.2.weight", 7, float("nan"))),
        r"weights are not finite \(trunk\.2\.weight holds NaN\)"),
    "SAC actor with an inf log-std head": (
        lambda p: _tennis(p, SAC_ARCH, _set("log_std_head.bias", 0, float("inf"))),
        r"weights are not finite \(log_std_head\.bias holds inf\)"),
    "Gaussian head with log_std -inf": (
        lambda p: _tennis(p, PPO_BOX, _set("log_std", 1, float("-inf"))),
        r"weights are not finite \(log_std holds -inf\)"),
    "Gaussian head with log_std 100": (
        lambda p: _tennis(p, PPO_BOX, _set("log_std", 2, 100.0)),
        r"log_std holds 100, outside the -80 to 80 a Gaussian head's log-std may take"),
    "joint record of base 2 for lander's 4 actions": (
        lambda p: _lander_joint(p, 2),
        r"bad joint record in the snapshot's metadata: 2 seats of 2 actions make 4 joint actions, but its network "
        r"plays Discrete\(16\)"),
    "NaN in the metadata": (lambda p: _metadata_nan(p, "NaN"),
                            r"bad snapshot metadata \(a number that is not finite\)"),
    "1e999 in the metadata": (lambda p: _metadata_nan(p, "1e999"),
                              r"bad snapshot metadata \(a number that is not finite\)"),
    "step 2**70 in the metadata": (lambda p: _tennis(p, PPO_BOX, step=2**70),
                                   r"bad snapshot metadata \(field 'step' must lie between 0 and 9,223,372"),
    "episode -1 in the metadata": (lambda p: _tennis(p, PPO_BOX, episode=-1),
                                   r"bad snapshot metadata \(field 'episode' must lie between 0 and 9,223,372"),
}
SOUND = {  # the same files without the fault: imported
    "SAC actor": lambda p: _tennis(p, SAC_ARCH),
    "Gaussian head with log_std 79": lambda p: _tennis(p, PPO_BOX, _set("log_std", 2, 79.0)),
    "joint record of base 4 for lander's 4 actions": lambda p: _lander_joint(p, 4),
    "metadata with 1e300": lambda p: _metadata_nan(p, "1e300"),
    "step 2**63 - 1": lambda p: _tennis(p, PPO_BOX, step=2**63 - 1),
}


@pytest.mark.parametrize("what", sorted(CRAFTED))
def test_crafted_files_are_refused_at_import_in_one_line_and_nothing_is_written(home, tmp_path, capsys, what):
    make, says = CRAFTED[what]
    file = make(tmp_path / "c.safetensors")
    code, _, err = run(capsys, "checkpoint", "import", str(file))
    line = _one_line(err)
    assert code == 2, err
    assert line.startswith(f"marl: error: {file}: "), line
    assert re.search(says, line), line
    assert not list(home.rglob("*.safetensors"))
    with pytest.raises(SnapshotError, match=says):
        read_snapshot(file)


@pytest.mark.parametrize("what", sorted(SOUND))
def test_the_same_files_without_the_fault_are_imported(home, tmp_path, capsys, what):
    file = SOUND[what](tmp_path / "c.safetensors")
    code, _, err = run(capsys, "checkpoint", "import", str(file))
    assert code == 0, err
    assert len(list(home.rglob("*.safetensors"))) == 1


def test_save_refuses_weights_that_are_not_finite_and_writes_nothing(tmp_path):
    seat = get_env("tennis").seat_spaces(get_env("tennis").config())[0]
    net = build_network(seat.observation, seat.action, PPO_BOX, seed=0)
    meta = SnapshotMeta(env="tennis", obs_space=seat.observation, act_space=seat.action, arch=PPO_BOX, name="s")
    with torch.no_grad():
        net.action_head.bias[1] = float("nan")
    with pytest.raises(SnapshotError, match=r"weights are not finite \(action_head\.bias holds NaN\)"):
        save_snapshot(tmp_path / "s.safetensors", net, meta)
    with torch.no_grad():
        net.action_head.bias[1] = 0.0
        net.log_std[0] = -MAX_LOG_STD - 1
    with pytest.raises(SnapshotError, match="log_std holds -81, outside"):
        save_snapshot(tmp_path / "s.safetensors", net, meta)
    assert list(tmp_path.iterdir()) == []


def test_a_joint_record_its_head_contradicts_is_never_saved(tmp_path):
    seat = get_env("lander").seat_spaces(get_env("lander").config())[0]
    obs, act = joint_spaces(seat.observation, seat.action, 2)
    arch = Arch(hidden=(32,), activation="relu", value_head=False)
    meta = SnapshotMeta(env="lander", obs_space=obs, act_space=act, arch=arch, name="s",
                        extra={"joint": {"seats": 2, "base": 2}})
    with pytest.raises(SnapshotError, match="2 seats of 2 actions make 4 joint actions"):
        save_snapshot(tmp_path / "s.safetensors", build_network(obs, act, arch, seed=0), meta)
    assert list(tmp_path.iterdir()) == []


def test_checking_the_values_allocates_nothing_beside_the_weights():
    big = np.zeros(4_000_000, np.float32)  # 16 MB
    big[-1] = np.nan
    tracemalloc.start()
    try:
        with pytest.raises(SnapshotError, match="big holds NaN"):
            check_values("f", {"big": big})
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 100_000, peak  # np.isfinite(big).all() would take 4 MB
