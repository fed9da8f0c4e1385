"""Image observations: uint8 frames kept from the game to the network, the convolutional encoder an image seat gets,
its snapshots (saved, loaded, refused when crafted), frame stacking, and PPO learning to read the suite's image game
(tests/games/spot.py) well enough to beat `random`."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch
from cli_helpers import run, run_json
from gymnasium import spaces

from selfplay_cli.algos.ppo import PPOConfig, PPOLearner
from selfplay_cli.envs import get_env
from selfplay_cli.envs.seat_spaces import seat_space_of
from selfplay_cli.play.matches import Game, play
from selfplay_cli.play.seat_plan import plan_layout, plan_seats
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies import Policy, ScriptedPolicy
from selfplay_cli.policies.arch import NATURE_CNN, SMALL_CNN, Arch, SnapshotError
from selfplay_cli.policies.network import build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot
from selfplay_cli.policies.snapshot_policy import load_policy

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))
from tests.games.spot import Spot  # noqa: E402

SPOT = "tests.games.spot:parallel_env"
FRAME = spaces.Box(0, 255, (16, 16, 3), np.uint8)


def test_an_image_seat_keeps_its_frames_and_gets_a_cnn():
    """A uint8 HxWxC Box stays itself (not flattened, not float32); the network built for it is the small CNN for a
    16x16 image (the Nature-CNN for an 84x84 CxHxW one), and gives one row of logits and a value per image."""
    seat = seat_space_of(FRAME, spaces.Discrete(4))
    assert seat.observation.shape == (16, 16, 3) and seat.observation.dtype == np.uint8
    net = build_network(seat.observation, seat.action, Arch(hidden=(64,), activation="relu"), seed=0)
    assert (net.arch.kind, net.arch.conv, net.arch.layout) == ("cnn", SMALL_CNN, "hwc")
    # 16 -> 14 (3x3, stride 1) -> 6 (3x3, stride 2): 32 channels of 6x6 into the trunk
    assert net.trunk[0].weight.shape == (64, 32 * 6 * 6)
    logits, value = net(torch.zeros((5, 16, 16, 3), dtype=torch.uint8))
    assert logits.shape == (5, 4) and value.shape == (5,)
    big = build_network(spaces.Box(0, 255, (3, 84, 84), np.uint8), 6, Arch(), seed=0)
    assert (big.arch.conv, big.arch.layout) == (NATURE_CNN, "chw")
    # a float vector is no image: the MLP as before, and conv layers asked for it are refused in one line
    assert build_network(spaces.Box(-1, 1, (8,), np.float32), 3, Arch(), seed=0).arch.kind == "mlp"
    with pytest.raises(SnapshotError, match="conv layers .* read images"):
        build_network(spaces.Box(-1, 1, (8,), np.float32), 3, Arch(conv="16x3s1"), seed=0)


def test_ppo_keeps_uint8_frames_in_its_rollout():
    """PPO's rollout buffer holds an image seat's observations as uint8 (a quarter of float32's memory), exactly as
    the game gave them, and learns from them."""
    seat = seat_space_of(FRAME, spaces.Discrete(4))
    ppo = PPOLearner(seat, 4, PPOConfig(rollout_steps=2, minibatches=1, update_epochs=1), seed=0)
    assert ppo.obs.dtype == torch.uint8
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (4, 16, 16, 3), dtype=np.uint8) for _ in range(3)]
    for t in range(2):
        ppo.act(frames[t])
        ppo.record(np.ones(4, np.float32), np.zeros(4, bool))
    assert np.array_equal(ppo.obs[1].numpy(), frames[1].reshape(4, -1))
    before = ppo.net.encoder[0].weight.detach().clone()
    ppo.update(frames[2])
    assert not torch.equal(before, ppo.net.encoder[0].weight)  # the gradient reached the convolutions


def _spot_net(seed: int = 0):
    return build_network(FRAME, spaces.Discrete(4), Arch(hidden=(32,), activation="relu"), seed=seed)


def test_a_cnn_snapshot_saves_loads_and_acts_the_same(tmp_path):
    """A CNN's snapshot records its layers; loaded back (the hostile reader, safetensors), it plays exactly as the
    network it was saved from."""
    net = _spot_net()
    meta = SnapshotMeta(env=SPOT, obs_space=FRAME, act_space=spaces.Discrete(4), arch=net.arch, name="cnn")
    path = tmp_path / "cnn.safetensors"
    save_snapshot(path, net, meta)
    policy = load_policy(path, expect_env=SPOT)
    assert policy.net.arch == net.arch and policy.meta.arch.to_dict()["conv"] == [[16, 3, 1], [32, 3, 2]]
    frames = np.random.default_rng(1).integers(0, 256, (64, 16, 16, 3), dtype=np.uint8)
    with torch.no_grad():
        want = net(torch.from_numpy(frames))[0].argmax(dim=1).numpy()
    assert np.array_equal(policy.act(frames), want)
    assert len(set(want.tolist())) > 1  # the images decide the actions (not one action for all)


def test_a_snapshot_whose_conv_layers_do_not_fit_is_refused_in_one_line(tmp_path, capsys):
    """A crafted file whose metadata says one conv stack and whose weights are another's: `marl checkpoint import`
    refuses it in one line naming the file and the tensor, before anything is built."""
    net = _spot_net()
    meta = SnapshotMeta(env=SPOT, obs_space=FRAME, act_space=spaces.Discrete(4), arch=net.arch, name="cnn")
    path = tmp_path / "evil.safetensors"
    save_snapshot(path, net, meta)
    raw = path.read_bytes()
    n = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8:8 + n])
    marl = json.loads(header["__metadata__"]["marl"])
    marl["arch"]["conv"] = [[16, 5, 1], [32, 3, 2]]  # 5x5 kernels: encoder.0.weight would be [16, 3, 5, 5]
    header["__metadata__"]["marl"] = json.dumps(marl)
    body = json.dumps(header).encode()
    path.write_bytes(len(body).to_bytes(8, "little") + body + raw[8 + n:])
    code, _, err = run(capsys, "checkpoint", "import", str(path), "--env", SPOT, "--home", str(tmp_path / "league"))
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"marl: error: {path}: weights do not fit the cnn 16x5s1,32x3s2"), err
    assert "encoder.0.weight is [16, 3, 3, 3], expected [16, 3, 5, 5]" in err, err


class _Watcher(Policy):
    """Reads its seat's last 2 observations (frame_stack 2) and keeps what it was given, step by step."""

    kind = "snapshot"
    frame_stack = 2

    def __init__(self) -> None:
        super().__init__("watcher", SPOT, obs_space=spaces.Box(0, 255, (16, 16, 6), np.uint8),
                         act_space=spaces.Discrete(4))
        self.seen: list[np.ndarray] = []

    def act(self, obs, mask=None):
        self.seen.append(np.array(obs))
        return np.zeros(len(obs), dtype=np.int64)


def test_frame_stacking_gives_the_first_frame_twice_then_the_last_two():
    """A policy with frame_stack 2 gets, at a game's start, its first image twice on the channel axis; after each
    step, the previous image and the new one (the game's own images, seed for seed); a scripted player beside it
    reads the single image."""
    watcher = _Watcher()
    play(SPOT, [watcher, ScriptedPolicy(SPOT, "random", seed=0)], [Game(seed=7, seats=(0, 1))], parallel=1)
    env = Spot()
    images = [env.reset(seed=7)[0]["p0"]]
    while env.agents:
        images.append(env.step({"p0": 0, "p1": 0})[0]["p0"])
    assert len(watcher.seen) == 8 and all(s.shape == (1, 16, 16, 6) for s in watcher.seen)
    first = watcher.seen[0][0]
    assert np.array_equal(first[..., :3], images[0]) and np.array_equal(first[..., 3:], images[0])
    for k in range(1, 8):
        assert np.array_equal(watcher.seen[k][0][..., :3], images[k - 1])
        assert np.array_equal(watcher.seen[k][0][..., 3:], images[k])


@pytest.mark.slow
def test_ppo_learns_to_read_the_image_and_beats_random(tmp_path, capsys):
    """The suite's image game: PPO with the default CNN, 10,000 game steps (a few seconds), then `marl match` shows
    the final snapshot beating `random` clearly; the snapshot is rated on the ladder and recorded (the mp4 decodes)."""
    home = ["--home", str(tmp_path / "league")]
    report = run_json(capsys, "train", SPOT, "--agents", "1", "--steps", "10000", "--games", "16", "--seed", "0",
                      "--eval-games", "2", "--eval", "inline", "--eval-playoff", "0", "--run", "spot", "--quiet", *home)
    (final,) = report["final"]
    m = run_json(capsys, "match", final["snapshot"], "random", "--games", "100", "--seed", "1000", *home)
    assert m["score"] >= 0.8 and m["elo_low"] > 100, m  # random names the quadrant a quarter of the time
    ladder = run_json(capsys, "league", "ladder", "--run", "spot", *home)
    assert final["snapshot"] in json.dumps(ladder)
    code, out, err = run(capsys, "record", "--ckpt", final["snapshot"], "--vs", "random", "--seconds", "0",
                         "--out", str(tmp_path / "spot.mp4"), *home)
    assert code == 0, err
    frames = iio.imread(tmp_path / "spot.mp4")
    assert frames.shape[0] >= 9 and frames.shape[-1] == 3  # the first frame and one a round (8 rounds)


def test_training_games_stack_vector_observations_side_by_side():
    """In training's games a learner with frame_stack 3 reads its seat's last 3 vector observations one after the
    other: the first observation three times at the start, then one older frame dropped a step (the suite's reach
    game, (4,) float32 a seat)."""
    reach = "tests.games.reach:parallel_env"
    spec = get_env(reach)
    games = SelfPlayGames(reach, 2, plan_layout(plan_seats(spec, 1), 2, 1), ["me"], frame_stack=3)
    assert games.spaces[0].observation.shape == (12,)
    raw = [games.core.observe().reshape(4, 4).copy()]
    seen = [games.observe()[0]]
    for _ in range(3):
        games.step([np.ones((4, 2), np.float32)])
        raw.append(games.core.observe().reshape(4, 4).copy())
        seen.append(games.observe()[0])
    assert np.array_equal(seen[0], np.concatenate([raw[0]] * 3, axis=1))
    assert np.array_equal(seen[1], np.concatenate([raw[0], raw[0], raw[1]], axis=1))
    assert np.array_equal(seen[3], np.concatenate([raw[1], raw[2], raw[3]], axis=1))
    assert not np.array_equal(raw[1], raw[3])  # the points moved: the frames differ
