"""n-step returns for the replay learners: each slot's chain of its last decisions, turned into n-step transitions.

A learner hands over one-step transitions ``(s, a, r)`` of some slots as their s' becomes known; the chain of each
slot keeps its last ``n - 1`` of them. Once a slot's chain holds ``n`` decisions, its oldest one becomes the
transition ``(s_t, a_t, R, s_{t+n})`` with ``R = r_t + gamma r_{t+1} + ... + gamma^(n-1) r_{t+n-1}`` and the
bootstrap discount ``gamma^n``; when the slot's game ends (won, lost or cut short), every decision in its chain
becomes a transition to that end, ``R`` its rewards up to it and the discount ``gamma^k`` (k the decisions from it to
the end), and the chain starts afresh. The caller attaches s' and done (the end's: its final observation and 0
where a game was cut short) to what :meth:`NStepChains.push` returns. ``n = 1`` gives every transition back at once
with the discount gamma.
"""

from __future__ import annotations

import numpy as np


class NStepChains:
    """The chains of ``n_slots`` slots (see the module docstring); ``act_shape`` and ``act_dtype`` are one action's."""

    def __init__(self, n: int, gamma: float, n_slots: int, obs_dim: int, act_shape: tuple[int, ...] = (),
                 act_dtype: type = np.float32) -> None:
        if n < 1:
            raise ValueError(f"n-step returns need n >= 1, not {n}")
        self.n, self.gamma = int(n), float(gamma)
        k = self.n - 1
        self.obs = np.zeros((k, n_slots, obs_dim), np.float32)
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
        seq_obs = np.empty((k + 1, m, obs.shape[1]), np.float32)
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
            return (np.zeros(0, np.int64), np.zeros((0, obs.shape[1]), np.float32),
                    np.zeros((0, *act.shape[1:]), self.act.dtype), np.zeros(0, np.float32), np.zeros(0, np.float32))
        return tuple(np.concatenate(x) for x in zip(*parts, strict=True))
