"""The replay every off-policy learner (DQN, SAC) keeps: one ring buffer of transitions, and the n-step chains that
turn each slot's one-step decisions into the n-step transitions the buffer holds.

:class:`ReplayBuffer` is a ring of preallocated arrays (the oldest transitions overwritten once full) sampled
uniformly with the learner's generator. :class:`NStepChains` keeps each slot's chain of its last decisions: a
learner hands over one-step transitions ``(s, a, r)`` of some slots as their s' becomes known, and the chain of each
slot keeps its last ``n - 1`` of them. Once a slot's chain holds ``n`` decisions, its oldest one becomes the
transition ``(s_t, a_t, R, s_{t+n})`` with ``R = r_t + gamma r_{t+1} + ... + gamma^(n-1) r_{t+n-1}`` and the
bootstrap discount ``gamma^n``; when the slot's game ends (won, lost or cut short), every decision in its chain
becomes a transition to that end, ``R`` its rewards up to it and the discount ``gamma^k`` (k the decisions from it to
the end), and the chain starts afresh. ``n = 1`` gives every transition back at once with the discount gamma.
:func:`store_decisions` is the one path from decisions to the buffer: the chains, then s', done and the mask of s'
(the end's where a game ended: its final observation and done 0 where it was cut short) attached to each
transition.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class ReplayBuffer:
    """A ring of preallocated numpy arrays: obs and next_obs (flattened, of ``obs_dtype``: float32, or an image's
    uint8, a quarter of the memory), actions (``act_shape`` of
    ``act_dtype`` each: a Discrete action's int64, a Box's float32 numbers), rewards, dones, each transition's
    bootstrap discount (gamma^k for a return over k decisions) and, once a transition comes with one, the action
    mask of its s' (True everywhere for transitions without).

    ``add`` writes a batch of transitions at once (the oldest overwritten once full, so the buffer always holds the
    newest ``capacity``); ``sample`` draws uniformly, with replacement, from the filled entries with the caller's
    generator; ``(k, batch)`` draws k batches at once.
    """

    def __init__(self, capacity: int, obs_dim: int, act_shape: tuple[int, ...] = (),
                 act_dtype: type = np.int64, obs_dtype: Any = np.float32) -> None:
        self.capacity = int(capacity)
        self.obs = np.zeros((capacity, obs_dim), dtype=obs_dtype)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=obs_dtype)
        self.actions = np.zeros((capacity, *act_shape), dtype=act_dtype)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.dones = np.zeros(capacity, dtype=np.float32)
        self.discounts = np.ones(capacity, dtype=np.float32)
        self.next_masks: np.ndarray | None = None  # (capacity, n_actions) bool, made by the first masked add
        self.pos = 0  # next entry to write
        self.size = 0  # filled entries

    def __len__(self) -> int:
        return self.size

    def add(self, obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray, next_obs: np.ndarray,
            dones: np.ndarray, discounts: np.ndarray | float = 1.0, next_masks: np.ndarray | None = None) -> None:
        n = len(actions)
        if n == 0:
            return
        discounts = np.broadcast_to(np.asarray(discounts, dtype=np.float32), (n,))
        if next_masks is not None and self.next_masks is None:
            self.next_masks = np.ones((self.capacity, next_masks.shape[1]), dtype=bool)
        if n > self.capacity:  # only the newest fit
            obs, actions, rewards, next_obs, dones, discounts = (x[n - self.capacity:] for x in
                                                                 (obs, actions, rewards, next_obs, dones, discounts))
            next_masks = None if next_masks is None else next_masks[n - self.capacity:]
            n = self.capacity
        end = self.pos + n
        if end <= self.capacity:  # one contiguous write (the common case)
            at: slice | np.ndarray = slice(self.pos, end)
        else:
            at = np.arange(self.pos, end) % self.capacity
        self.obs[at] = obs
        self.next_obs[at] = next_obs
        self.actions[at] = actions
        self.rewards[at] = rewards
        self.dones[at] = dones
        self.discounts[at] = discounts
        if self.next_masks is not None:
            self.next_masks[at] = True if next_masks is None else next_masks
        self.pos = end % self.capacity
        self.size = min(self.size + n, self.capacity)

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> dict[str, np.ndarray]:
        """``size`` transitions drawn uniformly from the filled entries; ``(k, batch)`` draws k batches at once."""
        if self.size == 0:
            raise RuntimeError("cannot sample from an empty replay buffer")
        idx = rng.integers(0, self.size, size=size)
        out = {"obs": self.obs[idx], "actions": self.actions[idx], "rewards": self.rewards[idx],
               "next_obs": self.next_obs[idx], "dones": self.dones[idx], "discounts": self.discounts[idx]}
        if self.next_masks is not None:
            out["next_masks"] = self.next_masks[idx]
        return out


class NStepChains:
    """The chains of ``n_slots`` slots (see the module docstring); ``act_shape`` and ``act_dtype`` are one action's,
    ``obs_dtype`` an observation's."""

    def __init__(self, n: int, gamma: float, n_slots: int, obs_dim: int, act_shape: tuple[int, ...] = (),
                 act_dtype: type = np.float32, obs_dtype: Any = np.float32) -> None:
        if n < 1:
            raise ValueError(f"n-step returns need n >= 1, not {n}")
        self.n, self.gamma = int(n), float(gamma)
        k = self.n - 1
        self.obs = np.zeros((k, n_slots, obs_dim), obs_dtype)
        self.act = np.zeros((k, n_slots, *act_shape), act_dtype)
        self.rew = np.zeros((k, n_slots), np.float32)
        self.count = np.zeros(n_slots, np.int64)  # decisions waiting in each slot's chain (< n)

    def clear(self) -> None:
        """Forget every chain (after a resume: the decisions in flight are gone)."""
        self.count[:] = 0

    def push(self, rows: np.ndarray, obs: np.ndarray, act: np.ndarray, rew: np.ndarray,
             ended: np.ndarray) -> tuple[np.ndarray, ...]:
        """The one-step decisions ``(obs, act, rew)`` of slots ``rows`` (each slot at most once), whose s' is now
        known; ``ended``: the row's game ended with it. Returns the transitions completed, ``(src, obs, act, ret,
        discount)``: ``src`` the index (into ``rows``) of the decision whose s' and done each one takes."""
        rows = np.asarray(rows, dtype=np.int64)
        g, k = self.gamma, self.n - 1
        m = rows.size
        if not k:  # one step: every decision is its own transition, as it came
            return np.arange(m), obs, act, np.asarray(rew, np.float32), np.full(m, g, np.float32)
        ended = np.asarray(ended, dtype=bool)
        count = self.count[rows]
        cols = np.arange(m)
        # Each row's chain: entries 0 .. count-1 from the ring, then this decision at position count
        seq_obs = np.empty((k + 1, m, obs.shape[1]), self.obs.dtype)
        seq_act = np.empty((k + 1, *act.shape), self.act.dtype)
        seq_rew = np.zeros((k + 1, m), np.float32)
        seq_obs[:k], seq_act[:k], seq_rew[:k] = self.obs[:, rows], self.act[:, rows], self.rew[:, rows]
        seq_obs[count, cols], seq_act[count, cols], seq_rew[count, cols] = obs, act, rew
        ret = np.zeros((k + 2, m), np.float32)  # ret[j]: the discounted rewards from position j to the chain's end
        for j in reversed(range(k + 1)):
            ret[j] = np.where(j <= count, seq_rew[j] + np.float32(g) * ret[j + 1], 0.0)
        full = count == k
        parts = []
        for j in range(k + 1):  # a full chain gives its oldest decision; an ended one gives all of them
            take = np.flatnonzero(np.where(ended, j <= count, full & (j == 0)))
            if take.size:
                disc = (g ** (count[take] - j + 1)).astype(np.float32)
                parts.append((take, seq_obs[j, take], seq_act[j, take], ret[j, take], disc))
        # The chains move on: an ended one starts afresh, a full one drops its oldest, a shorter one grows
        self.count[rows[ended]] = 0
        shift = np.flatnonzero(~ended & full)
        if shift.size:
            r = rows[shift]
            self.obs[:, r], self.act[:, r], self.rew[:, r] = seq_obs[1:, shift], seq_act[1:, shift], seq_rew[1:, shift]
        grow = np.flatnonzero(~ended & ~full)
        if grow.size:
            r, c = rows[grow], count[grow]
            self.obs[c, r], self.act[c, r], self.rew[c, r] = obs[grow], act[grow], rew[grow]
            self.count[r] = c + 1
        if not parts:
            return (np.zeros(0, np.int64), np.zeros((0, obs.shape[1]), self.obs.dtype),
                    np.zeros((0, *act.shape[1:]), self.act.dtype), np.zeros(0, np.float32), np.zeros(0, np.float32))
        return tuple(np.concatenate(x) for x in zip(*parts, strict=True))


def store_decisions(buffer: ReplayBuffer, chains: NStepChains, rows: np.ndarray, obs: np.ndarray, act: np.ndarray,
                    rew: np.ndarray, next_obs: np.ndarray, dones: np.ndarray, ended: np.ndarray | bool,
                    next_masks: np.ndarray | None = None) -> None:
    """The one-step decisions ``(obs, act, rew)`` of slots ``rows`` whose s' is ``next_obs`` (with ``dones`` and,
    for masked actions, ``next_masks``, one row each), into ``buffer`` as the n-step transitions they complete in
    ``chains``; ``ended``: the row's game ended with it (one flag for all rows, or one a row)."""
    src, o, a, r, discount = chains.push(rows, obs, act, rew, np.broadcast_to(np.asarray(ended, bool), len(rows)))
    buffer.add(o, a, r, next_obs[src], np.asarray(dones, np.float32)[src], discount,
               None if next_masks is None else next_masks[src])
