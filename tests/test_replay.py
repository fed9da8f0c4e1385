"""The replay every off-policy learner keeps (algos/replay.py): the ring buffer, the n-step chains and the one path
from decisions to the buffer."""

from __future__ import annotations

import numpy as np
import pytest

from selfplay_cli.algos.replay import NStepChains, ReplayBuffer, store_decisions


def _batch(ids: list[int], d: int = 2):
    ids_a = np.asarray(ids)
    obs = np.repeat(ids_a[:, None], d, axis=1).astype(np.float32)
    return obs, ids_a, ids_a.astype(np.float32), obs + 0.5, (ids_a % 2).astype(np.float32)


def test_replay_buffer_ring_keeps_the_newest_transitions():
    buf = ReplayBuffer(5, 2)
    buf.add(*_batch([0, 1, 2]))
    assert (len(buf), buf.pos) == (3, 3)
    buf.add(*_batch([3, 4, 5, 6]))  # wraps around: 0 and 1 are overwritten
    assert (len(buf), buf.pos) == (5, 2)
    assert sorted(buf.actions.tolist()) == [2, 3, 4, 5, 6]
    assert np.array_equal(buf.obs[:, 0], buf.actions.astype(np.float32))  # rows stay aligned
    assert np.array_equal(buf.next_obs[:, 1], buf.actions + 0.5)
    assert np.array_equal(buf.dones, buf.actions % 2)
    buf.add(*_batch(list(range(10, 17))))  # more than the capacity: only the newest 5 are kept
    assert sorted(buf.actions.tolist()) == [12, 13, 14, 15, 16] and len(buf) == 5


def test_replay_buffer_samples_only_filled_entries_with_the_right_shapes():
    buf = ReplayBuffer(100, 2)
    buf.add(*_batch(list(range(1, 11))))
    rng = np.random.default_rng(0)
    b = buf.sample(rng, 1000)
    assert b["obs"].shape == (1000, 2) and b["next_obs"].shape == (1000, 2)
    assert b["actions"].shape == b["rewards"].shape == b["dones"].shape == (1000,)
    assert b["obs"].dtype == np.float32 and b["actions"].dtype == np.int64
    assert set(b["actions"].tolist()) == set(range(1, 11))  # every filled entry, and nothing else
    assert np.array_equal(b["rewards"], b["actions"].astype(np.float32))
    k = buf.sample(rng, (3, 7))
    assert k["obs"].shape == (3, 7, 2) and k["actions"].shape == (3, 7)
    with pytest.raises(RuntimeError):
        ReplayBuffer(4, 2).sample(rng, 1)


def test_replay_buffer_holds_box_actions_as_float_vectors():
    buf = ReplayBuffer(4, 2, (3,), np.float32)
    acts = np.array([[0.5, -0.25, 1.0], [0.0, 0.125, -1.0]], np.float32)
    buf.add(np.zeros((2, 2), np.float32), acts, np.array([1.0, 2.0]), np.ones((2, 2), np.float32), np.zeros(2), 0.9)
    assert buf.actions.dtype == np.float32 and buf.actions.shape == (4, 3)
    assert np.array_equal(buf.actions[:2], acts) and buf.discounts[:2].tolist() == pytest.approx([0.9, 0.9])
    k = buf.sample(np.random.default_rng(0), (3, 5))
    assert k["actions"].shape == (3, 5, 3) and k["actions"].dtype == np.float32 and "next_masks" not in k


def test_store_decisions_attaches_the_end_of_each_completed_transition():
    """Two slots, 2-step returns: slot 0's chain fills and gives its oldest decision (s' the state two decisions on);
    slot 1's game ends and gives both its decisions at once, each with the s', done and mask of that end."""
    g = 0.5
    buf, chains = ReplayBuffer(10, 1), NStepChains(2, g, 2, 1, (), np.int64)
    rows = np.arange(2)
    store_decisions(buf, chains, rows, np.array([[0.0], [10.0]], np.float32), np.array([0, 1]),
                    np.array([1.0, 1.0], np.float32), np.array([[1.0], [11.0]], np.float32), np.zeros(2), False,
                    np.ones((2, 3), bool))
    assert len(buf) == 0  # both chains hold one decision of two
    ends = np.array([False, True])
    masks = np.array([[True, False, True], [False, True, True]])
    store_decisions(buf, chains, rows, np.array([[1.0], [11.0]], np.float32), np.array([2, 3]),
                    np.array([2.0, 4.0], np.float32), np.array([[2.0], [99.0]], np.float32), np.array([0.0, 1.0]),
                    ends, masks)
    n = len(buf)
    assert n == 3 and chains.count.tolist() == [1, 0]
    assert buf.obs[:n, 0].tolist() == [0.0, 10.0, 11.0]  # slot 0's oldest, then slot 1's chain oldest first
    assert buf.actions[:n].tolist() == [0, 1, 3]
    assert buf.rewards[:n].tolist() == pytest.approx([1 + g * 2, 1 + g * 4, 4.0])
    assert buf.next_obs[:n, 0].tolist() == [2.0, 99.0, 99.0] and buf.dones[:n].tolist() == [0.0, 1.0, 1.0]
    assert buf.discounts[:n].tolist() == pytest.approx([g**2, g**2, g])
    assert buf.next_masks is not None and buf.next_masks[:n].tolist() == [masks[0].tolist()] + [masks[1].tolist()] * 2
