"""A bank of networks acts as each network alone would, on the torch path and on the numpy path it takes for few
rows (``NUMPY_ROWS``), and both paths draw the same uniforms from the bank's generator."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces

from selfplay_cli.policies import bank as bank_module
from selfplay_cli.policies.bank import NetworkBank
from selfplay_cli.policies.network import Arch, NetworkPolicy, build_network


def _members(arch: Arch, greedy: list[bool], n_actions: int = 5, obs: int = 7) -> list[NetworkPolicy]:
    return [NetworkPolicy(build_network((obs,), spaces.Discrete(n_actions), arch, seed=10 + k), f"p{k}", "g",
                          greedy=g, seed=k) for k, g in enumerate(greedy)]


def _both_paths(members: list[NetworkPolicy], obs: list[np.ndarray], masks=None, monkeypatch=None, seed: int = 3):
    """The bank's actions on the numpy path and on the torch path, from two banks of one seed."""
    numpy_bank, torch_bank = NetworkBank(members, seed=seed), NetworkBank(members, seed=seed)
    assert numpy_bank.numpy
    a = numpy_bank.act(obs, masks)
    monkeypatch.setattr(bank_module, "NUMPY_ROWS", 0)  # every batch through torch
    b = torch_bank.act(obs, masks)
    monkeypatch.undo()
    return a, b


@pytest.mark.parametrize("arch", [Arch(hidden=(16, 16)), Arch(hidden=(16,), activation="relu"),
                                  Arch(hidden=(16, 16), value_head=False, dueling=True)],
                         ids=["tanh", "relu", "dueling"])
def test_the_numpy_path_plays_what_the_networks_and_the_torch_path_play(arch, monkeypatch):
    rng = np.random.default_rng(0)
    obs = [rng.normal(size=(r, 7)).astype(np.float32) for r in (9, 0, 4)]
    greedy = _members(arch, [True, True, True])
    a, b = _both_paths(greedy, obs, monkeypatch=monkeypatch)
    for k, m in enumerate(greedy):  # greedy: each network's own argmax, on either path
        assert a[k].dtype == np.int64 and a[k].shape == b[k].shape == (len(obs[k]),)
        if len(obs[k]):  # (a member without rows this step gets none)
            assert np.array_equal(a[k], m.act(obs[k])) and np.array_equal(b[k], m.act(obs[k]))
    sampling = _members(arch, [False, False, True])
    a, b = _both_paths(sampling, obs, monkeypatch=monkeypatch)
    for x, y in zip(a, b, strict=True):  # the same uniforms, the same inverse CDF: the same draws
        assert np.array_equal(x, y)
    assert np.array_equal(a[2], sampling[2].act(obs[2]))  # a greedy member among sampling ones


def test_the_numpy_path_keeps_to_masks_and_samples_by_the_softmax(monkeypatch):
    members = _members(Arch(hidden=(8,)), [False, False], n_actions=4, obs=3)
    rng = np.random.default_rng(1)
    obs = [rng.normal(size=(100, 3)).astype(np.float32), rng.normal(size=(50, 3)).astype(np.float32)]
    masks = [np.tile([True, False, True, False], (100, 1)), None]
    bank = NetworkBank(members, seed=5)
    counts = np.zeros(4)
    for _ in range(20):  # 2,000 draws of the first member on one row's logits
        a = bank.act([np.repeat(obs[0][:1], 100, axis=0), obs[1]], masks)
        assert set(np.unique(a[0])) <= {0, 2}  # never a masked action
        counts += np.bincount(a[0], minlength=4)
    logits = members[0].net(torch.from_numpy(obs[0][:1]))[0].detach().numpy()[0]
    p = np.exp(logits[[0, 2]] - logits[[0, 2]].max())
    p /= p.sum()
    share = counts[0] / counts.sum()
    assert abs(share - p[0]) < 4 * np.sqrt(p[0] * p[1] / counts.sum()) + 1e-9  # the softmax's share, within 4 sigma
    a, b = _both_paths(members, obs, masks, monkeypatch=monkeypatch)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def test_many_rows_go_through_torch():
    """More rows than NUMPY_ROWS, or more a member than numpy's BLAS multiplies on one thread (it would start a
    thread per core and take the trainer's), go through torch."""
    def refuse(*args, **kwargs):
        raise AssertionError("numpy path taken")

    bank = NetworkBank(_members(Arch(hidden=(8,)), [True, True]))
    bank._numpy_categorical = refuse  # type: ignore[method-assign]
    assert [len(x) for x in bank.act([np.zeros((200, 7), dtype=np.float32)] * 2)] == [200, 200]  # 400 > 384
    wide = NetworkBank(_members(Arch(hidden=(256, 256)), [True]))
    assert wide.np_rows == 262_144 // (256 * 256) == 4
    wide._numpy_categorical = refuse  # type: ignore[method-assign]
    assert len(wide.act([np.zeros((5, 7), dtype=np.float32)])[0]) == 5  # 5 x 256 x 256 > 262,144


def test_a_member_with_many_rows_fills_several_slots_and_plays_what_padding_plays(monkeypatch):
    """A gauntlet's new snapshot with many rows beside opponents with few: slots of the few's size (not every member
    padded to the most rows), a member without rows in none; the same actions as the padded batch, on either path
    (the uniforms are drawn per row, whatever the layout)."""
    arch = Arch(hidden=(16, 16))
    rows = (56, 16, 0, 5)
    rng = np.random.default_rng(2)
    obs = [rng.normal(size=(r, 7)).astype(np.float32) for r in rows]
    lay = NetworkBank(_members(arch, [False] * 4)).layout(rows)
    # widths 56, 16 and 5 cost 3 x (56 + 16), 6 x (16 + 16) and 17 x (5 + 16) rows (SLOT_ROWS = 16 a slot)
    assert (lay.width, lay.slots, lay.starts) == (16, (0, 0, 0, 0, 1, 3), (0, 64, 80, 80))
    for greedy in ([False, False, True, False], [True] * 4):
        members = _members(arch, greedy)
        slotted = NetworkBank(members, seed=4).act(obs)
        monkeypatch.setattr(bank_module, "SLOT_ROWS", 10**6)  # one slot a member, padded to 56 rows
        padded_bank = NetworkBank(members, seed=4)
        assert padded_bank.layout(rows).width == 56
        padded = padded_bank.act(obs)
        monkeypatch.setattr(bank_module, "NUMPY_ROWS", 0)
        through_torch = NetworkBank(members, seed=4).act(obs)
        monkeypatch.undo()
        for k, m in enumerate(members):
            assert slotted[k].shape == (rows[k],)
            assert np.array_equal(slotted[k], padded[k]) and np.array_equal(slotted[k], through_torch[k])
            if m.greedy and rows[k]:
                assert np.array_equal(slotted[k], m.act(obs[k]))


def test_a_lone_network_against_a_scripted_player_acts_through_a_bank_of_its_own():
    """A snapshot against a bot (``marl match A cpu``, a gate against the bots) gets the bank's numpy path: the
    played actions follow its softmax, and the same match replays them."""
    from selfplay_cli.play.matches import Game, _acting_groups, play
    from selfplay_cli.play.replay import decode_actions, seat_actions
    from selfplay_cli.policies.bots import ScriptedPolicy

    def fixed(seed: int) -> NetworkPolicy:  # logits [0, 1, -1] whatever it sees
        net = build_network((8, 6), 3, Arch(hidden=(4,)), seed=0)
        with torch.no_grad():
            net.action_head.weight.zero_()
            net.action_head.bias.copy_(torch.tensor([0.0, 1.0, -1.0]))
        return NetworkPolicy(net, "fixed", "pong", greedy=False, seed=seed)

    bot = ScriptedPolicy("pong", "cpu", seed=0)
    groups = _acting_groups([fixed(1), bot])
    assert isinstance(groups[0][1], NetworkBank) and groups[1][1] is None
    games = [Game(seed=s, seats=(0, 1) if s % 2 == 0 else (1, 0)) for s in range(4)]
    opts = {"max_steps": 500}
    first = play("pong", [fixed(1), bot], games, env_options=opts, record_actions=True)
    again = play("pong", [fixed(1), bot], games, env_options=opts, record_actions=True)
    assert [r.actions for r in first] == [r.actions for r in again]
    played = np.concatenate([seat_actions(decode_actions(r.actions, 2))[g.seats.index(0)]
                             for r, g in zip(first, games, strict=True)])
    share = np.bincount(played, minlength=3) / len(played)
    np.testing.assert_allclose(share, torch.softmax(torch.tensor([0.0, 1.0, -1.0]), 0).numpy(), atol=0.03)
