"""Snapshot files and network policies: round trips, refusals of bad files, atomic saves, acting."""

from __future__ import annotations

import json
import os
import pickle
import struct

import numpy as np
import pytest
import torch
from safetensors.torch import save_file

from selfplay_cli.policies.network import Arch, MLPNet, NetworkPolicy, SnapshotError, build_network, resolve_device
from selfplay_cli.policies.snapshot_format import FORMAT, FORMAT_VERSION, SnapshotMeta, file_sha256, save_snapshot
from selfplay_cli.policies.snapshot_policy import load_policy
from selfplay_cli.policies.snapshot_reader import export_snapshot, import_check, load_snapshot, read_meta

OBS_SHAPE = (8, 6)


def make_meta(**kw) -> SnapshotMeta:
    base = dict(
        env="pong",
        env_options={},
        obs_shape=OBS_SHAPE,
        n_actions=3,
        arch=Arch(hidden=(32, 32)),
        algo="ppo",
        step=12_345,
        episode=90,
        run="r1",
        name="ep90",
        parent="r1/ep80",
        created="2024-01-02T03:04:05+00:00",
        seat=None,
        extra={"lr": 0.00025, "gamma": 0.99},
    )
    base.update(kw)
    return SnapshotMeta(**base)


def make_net(seed: int = 1, arch: Arch | None = None) -> MLPNet:
    net = build_network(OBS_SHAPE, 3, arch or Arch(hidden=(32, 32)), seed=seed)
    with torch.no_grad():  # a non-trivial policy head so actions differ between observations
        net.action_head.weight.mul_(300.0)
    return net


def obs_batch(n: int = 64, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, size=(n, *OBS_SHAPE)).astype(np.float32)


@pytest.fixture
def saved(tmp_path):
    path = tmp_path / "league" / "snapshots" / "r1" / "ep90.safetensors"
    net = make_net()
    meta = save_snapshot(path, net, make_meta())
    return path, net, meta


def data_start(path) -> int:
    with open(path, "rb") as f:
        (n,) = struct.unpack("<Q", f.read(8))
    return 8 + n


# ---------------------------------------------------------------------------------------------------------------
# Round trip


def test_round_trip_tensors_meta_and_actions(saved):
    path, net, meta = saved
    assert len(meta.weights_sha256) == 64
    tensors, loaded = load_snapshot(path, expect_env="pong")
    assert loaded == meta
    assert read_meta(path) == meta
    original = net.state_dict()
    assert set(tensors) == set(original)
    for k, v in original.items():
        assert torch.equal(tensors[k], v)
    policy = load_policy(path)
    assert policy.id == "r1/ep90" and policy.env == "pong" and policy.kind == "snapshot"
    assert policy.meta == meta
    obs = obs_batch()
    before = NetworkPolicy(net, "x", "pong").act(obs)
    after = policy.act(obs)
    np.testing.assert_array_equal(before, after)
    assert len(set(after.tolist())) > 1  # the check means something
    assert load_policy(path, id="custom").id == "custom"


def test_meta_dict_round_trip_and_runless_id(tmp_path):
    meta = make_meta(run=None, seat="left")
    assert SnapshotMeta.from_dict(json.loads(json.dumps(meta.to_dict()))) == meta
    path = tmp_path / "solo.safetensors"
    save_snapshot(path, make_net(), meta)
    assert load_policy(path).id == "ep90"
    assert read_meta(path).seat == "left"


def test_arch_validation():
    assert Arch.from_dict(Arch(hidden=[16], activation="relu").to_dict()) == Arch(hidden=(16,), activation="relu")
    with pytest.raises(SnapshotError, match="activation"):
        Arch.from_dict({"activation": "gelu"})
    with pytest.raises(SnapshotError, match="kind"):
        Arch.from_dict({"kind": "transformer"})
    with pytest.raises(SnapshotError, match="unknown network arch field"):
        Arch.from_dict({"widths": [3]})


def test_build_network_is_reproducible_and_shaped():
    state = torch.get_rng_state()
    a, b = build_network(OBS_SHAPE, 3, Arch(), seed=7), build_network(OBS_SHAPE, 3, Arch(), seed=7)
    assert torch.equal(torch.get_rng_state(), state)  # a seeded build leaves the global RNG alone
    for (ka, va), (kb, vb) in zip(a.state_dict().items(), b.state_dict().items(), strict=True):
        assert ka == kb and torch.equal(va, vb)
    c = build_network(OBS_SHAPE, 3, Arch(), seed=8)
    assert not torch.equal(a.action_head.weight, c.action_head.weight)
    out, value = a(torch.zeros(5, *OBS_SHAPE))
    assert out.shape == (5, 3) and value.shape == (5,)
    # CleanRL init: orthogonal hidden layers with gain sqrt(2), zero biases
    w = a.trunk[2].weight
    torch.testing.assert_close(w @ w.T, 2.0 * torch.eye(64), atol=1e-4, rtol=0)
    assert not a.trunk[0].bias.any()
    q, none = build_network(OBS_SHAPE, 3, Arch(value_head=False, dueling=True), seed=0)(torch.zeros(2, 48))
    assert q.shape == (2, 3) and none is None


def test_dueling_snapshot_round_trip(tmp_path):
    arch = Arch(hidden=(16,), activation="relu", value_head=False, dueling=True)
    net = build_network(OBS_SHAPE, 3, arch, seed=3)
    path = tmp_path / "dqn.safetensors"
    save_snapshot(path, net, make_meta(arch=arch, algo="dqn"))
    obs = obs_batch(16)
    np.testing.assert_array_equal(load_policy(path).act(obs), NetworkPolicy(net, "x", "pong").act(obs))


# ---------------------------------------------------------------------------------------------------------------
# Never unpickle


def test_loading_never_unpickles(saved, monkeypatch):
    path, _, meta = saved

    def refuse(*a, **k):
        raise AssertionError("unpickling during snapshot load")

    monkeypatch.setattr(torch, "load", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "Unpickler", refuse)
    policy = load_policy(path)
    assert policy.meta == meta
    assert import_check(path, env="pong") == meta


# ---------------------------------------------------------------------------------------------------------------
# Refusals


def test_flipped_weight_byte_fails_checksum(saved):
    path, _, _ = saved
    raw = bytearray(path.read_bytes())
    pos = data_start(path) + 100
    raw[pos] ^= 0x01
    path.write_bytes(bytes(raw))
    read_meta(path)  # the header alone is still fine
    for load in (load_snapshot, load_policy, import_check):
        with pytest.raises(SnapshotError) as e:
            load(path)
        assert str(path) in str(e.value) and "checksum" in str(e.value)


@pytest.mark.parametrize("keep", [0.5, 0.95, 0.02, 4 / 10_000])
def test_truncated_file_refused(saved, keep):
    path, _, _ = saved
    raw = path.read_bytes()
    path.write_bytes(raw[: max(1, int(len(raw) * keep))])
    with pytest.raises(SnapshotError) as e:
        load_snapshot(path)
    assert str(path) in str(e.value)
    with pytest.raises(SnapshotError):
        read_meta(path)


@pytest.mark.parametrize("size", [0, 5, 64, 5000])
def test_garbage_refused(tmp_path, size):
    path = tmp_path / "junk.safetensors"
    path.write_bytes(np.random.default_rng(size).integers(0, 256, size=size, dtype=np.uint8).tobytes())
    with pytest.raises(SnapshotError) as e:
        load_policy(path)
    assert str(path) in str(e.value) and "not a marl snapshot" in str(e.value)


def test_text_header_garbage_refused(tmp_path):
    path = tmp_path / "fake.safetensors"
    body = b"[1, 2, 3]"
    path.write_bytes(struct.pack("<Q", len(body)) + body)
    with pytest.raises(SnapshotError, match="bad header") as e:
        load_snapshot(path)
    assert str(path) in str(e.value)


def test_missing_file_refused(tmp_path):
    path = tmp_path / "nope.safetensors"
    with pytest.raises(SnapshotError, match="no such") as e:
        load_policy(path)
    assert str(path) in str(e.value)
    with pytest.raises(SnapshotError, match="no such"):
        file_sha256(path)


def test_plain_safetensors_without_marl_metadata_refused(tmp_path):
    path = tmp_path / "plain.safetensors"
    save_file(make_net().state_dict(), str(path))
    with pytest.raises(SnapshotError, match="not a marl snapshot") as e:
        load_policy(path)
    assert str(path) in str(e.value)
    path2 = tmp_path / "other.safetensors"
    save_file({"w": torch.zeros(2)}, str(path2), metadata={"format": "pt"})
    with pytest.raises(SnapshotError, match="not a marl snapshot") as e:
        read_meta(path2)
    assert str(path2) in str(e.value)


def _rewrite_header(path, tensors, **md):
    save_file(tensors, str(path), metadata=md)


def test_newer_format_version_refused(saved):
    path, _, _ = saved
    tensors, meta = load_snapshot(path)
    _rewrite_header(path, tensors, format=FORMAT, format_version=str(FORMAT_VERSION + 1),
                    marl=json.dumps(meta.to_dict()))
    with pytest.raises(SnapshotError, match="newer") as e:
        load_snapshot(path)
    assert str(path) in str(e.value)


def test_bad_marl_json_refused(saved):
    path, _, _ = saved
    tensors, meta = load_snapshot(path)
    _rewrite_header(path, tensors, format=FORMAT, format_version="1", marl="{not json")
    with pytest.raises(SnapshotError, match="metadata") as e:
        read_meta(path)
    assert str(path) in str(e.value)
    d = meta.to_dict()
    del d["act_space"]
    _rewrite_header(path, tensors, format=FORMAT, format_version="2", marl=json.dumps(d))
    with pytest.raises(SnapshotError, match="act_space"):
        read_meta(path)
    legacy = {k: v for k, v in d.items() if k != "obs_space"} | {"obs_shape": [8, 6]}  # version 1 without n_actions
    _rewrite_header(path, tensors, format=FORMAT, format_version="1", marl=json.dumps(legacy))
    with pytest.raises(SnapshotError, match="n_actions"):
        read_meta(path)


def test_wrong_env_refused(saved):
    path, _, _ = saved
    with pytest.raises(SnapshotError) as e:
        load_policy(path, expect_env="soccer")
    assert str(path) in str(e.value) and "soccer" in str(e.value)


def test_unknown_env_refused(tmp_path):
    path = tmp_path / "mystery.safetensors"
    save_snapshot(path, make_net(), make_meta(env="no-such-game"))
    with pytest.raises(SnapshotError, match="unknown env") as e:
        load_snapshot(path)
    assert str(path) in str(e.value)


def test_shape_mismatch_with_env_refused(tmp_path):
    path = tmp_path / "small.safetensors"
    net = build_network((4, 6), 3, Arch(hidden=(8,)), seed=0)
    save_snapshot(path, net, make_meta(obs_shape=(4, 6), arch=Arch(hidden=(8,))))
    with pytest.raises(SnapshotError, match="observ") as e:
        load_policy(path)
    assert str(path) in str(e.value)
    # ...but fine for a pong configured with 4 stacked frames
    save_snapshot(path, net, make_meta(obs_shape=(4, 6), arch=Arch(hidden=(8,)), env_options={"frame_stack": 4}))
    assert load_policy(path).act(np.zeros((2, 4, 6), np.float32)).shape == (2,)


def test_action_count_mismatch_refused(tmp_path):
    path = tmp_path / "five.safetensors"
    net = build_network(OBS_SHAPE, 5, Arch(hidden=(8,)), seed=0)
    save_snapshot(path, net, make_meta(n_actions=5, arch=Arch(hidden=(8,))))
    with pytest.raises(SnapshotError, match="actions") as e:
        load_snapshot(path)
    assert str(path) in str(e.value)


def test_weights_not_fitting_arch_refused(saved, tmp_path):
    path, net, meta = saved
    # save refuses weights that do not fit the arch the meta describes
    with pytest.raises(SnapshotError, match="do not fit"):
        save_snapshot(tmp_path / "bad.safetensors", net, make_meta(arch=Arch(hidden=(64, 64))))
    # a file whose header lies about the arch (consistent checksum) is refused at load, naming the file
    tensors, _ = load_snapshot(path)
    tensors["extra.weight"] = torch.zeros(2)
    from selfplay_cli.policies.snapshot_format import weights_sha256

    lying = meta.to_dict() | {"weights_sha256": weights_sha256(tensors)}
    _rewrite_header(path, tensors, format=FORMAT, format_version="1", marl=json.dumps(lying))
    for load in (load_snapshot, load_policy, import_check):  # checksum fine, but the layout is checked first
        with pytest.raises(SnapshotError, match="unexpected extra.weight") as e:
            load(path)
        assert str(path) in str(e.value)


# ---------------------------------------------------------------------------------------------------------------
# Atomic save, export, import


def test_atomic_save_leaves_no_temp_and_replaces_whole(saved):
    path, _, first = saved
    assert not list(path.parent.glob("*.tmp-*"))
    other = make_net(seed=99)
    second = save_snapshot(path, other, make_meta(name="ep90", step=1))
    assert not list(path.parent.glob("*.tmp-*"))
    assert second.weights_sha256 != first.weights_sha256
    tensors, meta = load_snapshot(path)
    assert meta == second and meta.step == 1
    for k, v in other.state_dict().items():
        assert torch.equal(tensors[k], v)


def test_failed_save_keeps_old_file(saved, monkeypatch):
    path, _, first = saved
    before = path.read_bytes()

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(SnapshotError, match="cannot write") as e:
        save_snapshot(path, make_net(seed=5), make_meta())
    assert str(path) in str(e.value)
    assert e.value.exit_code == 4  # a full disk is an I/O error, not a mistake in the snapshot (issue 49: it was 2)
    assert path.read_bytes() == before
    assert not list(path.parent.glob("*.tmp-*"))


def test_export_and_import_check(saved, tmp_path):
    path, _, meta = saved
    out = tmp_path / "export" / "champ.safetensors"
    exported = export_snapshot(path, out, run="imported", name="champ")
    assert exported.run == "imported" and exported.name == "champ"
    assert exported.weights_sha256 == meta.weights_sha256  # same weights
    assert import_check(out, env="pong") == exported
    assert load_policy(out).id == "imported/champ"
    assert file_sha256(out) != file_sha256(path)
    with pytest.raises(SnapshotError, match="override"):
        export_snapshot(path, out, colour="red")
    with pytest.raises(SnapshotError, match="soccer"):
        import_check(out, env="soccer")


# ---------------------------------------------------------------------------------------------------------------
# Acting


def fixed_policy(logits: list[float], greedy: bool, seed: int = 0) -> NetworkPolicy:
    """A policy whose action logits are ``logits`` whatever the observation."""
    net = build_network(OBS_SHAPE, len(logits), Arch(hidden=(4,)), seed=0)
    with torch.no_grad():
        net.action_head.weight.zero_()
        net.action_head.bias.copy_(torch.tensor(logits))
    return NetworkPolicy(net, "fixed", "pong", greedy=greedy, seed=seed)


def test_greedy_is_argmax():
    net = make_net()
    obs = obs_batch(200)
    actions = NetworkPolicy(net, "x", "pong").act(obs)
    with torch.no_grad():
        logits, _ = net(torch.from_numpy(obs))
    np.testing.assert_array_equal(actions, logits.argmax(1).numpy())


def test_a_network_acts_on_no_rows():
    policy = NetworkPolicy(make_net(), "x", "pong")
    for rows in (0, 3):
        actions = policy.act(np.zeros((rows, *OBS_SHAPE), np.float32))
        assert actions.shape == (rows,) and actions.dtype == np.int64


def test_sampling_reproducible_and_follows_softmax():
    logits = [0.0, 1.0, -1.0]
    obs = np.zeros((20_000, *OBS_SHAPE), np.float32)
    a = fixed_policy(logits, greedy=False, seed=11).act(obs)
    b = fixed_policy(logits, greedy=False, seed=11).act(obs)
    c = fixed_policy(logits, greedy=False, seed=12).act(obs)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    expected = torch.softmax(torch.tensor(logits), 0).numpy()
    freq = np.bincount(a, minlength=3) / len(a)
    np.testing.assert_allclose(freq, expected, atol=0.015)  # ~5 standard errors


def test_masks_honoured():
    obs = np.zeros((2000, *OBS_SHAPE), np.float32)
    mask = np.ones((2000, 3), bool)
    mask[:1000, 1] = False  # the favourite is forbidden in the first half
    mask[1000:, [0, 1]] = False  # only action 2 allowed in the second half
    greedy = fixed_policy([0.0, 5.0, -1.0], greedy=True).act(obs, mask)
    assert (greedy[:1000] == 0).all() and (greedy[1000:] == 2).all()
    sampled = fixed_policy([0.0, 5.0, -1.0], greedy=False, seed=3).act(obs, mask)
    assert mask[np.arange(2000), sampled].all()
    assert set(sampled[:1000].tolist()) == {0, 2}
    with pytest.raises(ValueError, match="no action"):
        fixed_policy([0.0, 0.0, 0.0], greedy=True).act(obs[:2], np.zeros((2, 3), bool))


def test_act_output_shape_and_dtype():
    policy = NetworkPolicy(make_net(), "x", "pong")
    obs = obs_batch(1000)
    out = policy.act(obs)
    assert out.shape == (1000,) and out.dtype == np.int64
    assert ((out >= 0) & (out < 3)).all()
    ro = obs.copy()
    ro.flags.writeable = False  # read-only arrays (views of env buffers) work too
    np.testing.assert_array_equal(policy.act(ro), out)
    np.testing.assert_array_equal(policy.act(obs.astype(np.float64)), out)


# ---------------------------------------------------------------------------------------------------------------
# Devices


def test_resolve_device():
    if torch.cuda.is_available():
        pytest.skip("these checks are for a CPU-only machine")
    assert resolve_device("auto") == torch.device("cpu")
    assert resolve_device("cpu") == torch.device("cpu")
    with pytest.raises(SnapshotError, match="cuda requested but not available"):
        resolve_device("cuda")
    with pytest.raises(SnapshotError, match="unknown device"):
        resolve_device("tpu")
    with pytest.raises(SnapshotError, match="cuda requested"):
        NetworkPolicy(make_net(), "x", "pong", device="cuda")
