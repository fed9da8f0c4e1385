"""Kickstarting: a learner also imitates a teacher on the states it visits, with a weight that fades as it trains.

Kickstarting (Schmitt et al., 2018) adds to a student's policy loss a distillation term toward a teacher's choices,
weighted by a schedule that decays to 0 so the student's own objective takes over; Unity ML-Agents offers the same
as ``behavioral_cloning`` (a ``strength`` annealed over ``steps``), from recorded demonstrations. Here the teacher
is a live player (a game's scripted player, or any snapshot), so it labels the states the *student* visits, its
own mistakes included (DAgger, Ross et al., 2011): the student learns to recover from where it actually goes, not
only from where the teacher would have gone.

Each step the trainer hands the learner the teacher's actions for the learner's observations
(``learner.teach(obs, actions, mask)``), which go into a ring of recent labelled states (:class:`Imitation`); each
gradient step of the learner's policy then adds ``weight * loss`` on a batch drawn from it, the loss by the action
head:

* Box, squashed (SAC): the squared difference between the policy's deterministic action (tanh of its mean) and the
  teacher's, both mapped from the bounds onto [-1, 1], summed over the action's numbers (SAC's temperature keeps
  its own spread about that action);
* Box, Gaussian (PPO): the negative log-likelihood of the teacher's action under the policy, on the same scale,
  ``(a - mean)^2 / (2 std^2) + log std`` summed over the action's numbers (dropping the constant): it pulls the mean
  onto the teacher's action and the state-independent spread down to what separates them (on tennis, imitating the
  mean alone let PPO's spread grow to 4 on actions in [-1, 1] in a 30-minute run: it sampled nearly at random);
* Discrete: the cross-entropy of the teacher's action under the policy (masked actions excluded);
* MultiDiscrete: the cross-entropies of the dimensions, summed.

The weight is the trainer's (``learner.teacher_weight``, from the run's ``[teacher] weight`` schedule); at 0 the
learner neither stores labels nor computes the term.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..policies.heads import MASKED, HeadMath
from ..policies.network import MLPNet
from ..policies.spaces import ActionHead

SQUASH_EDGE = 1.0 - 1e-3  # a squashed policy reaches +-1 only at infinity: teacher actions are held just inside


class Imitation:
    """The labelled states of one learner: a ring of ``capacity`` (observation, teacher action[, mask]) rows, and the
    imitation loss of a network on a batch of them (see the module docstring). The observations are kept in
    ``obs_dtype`` (an image's uint8, as the game gives it; float32 otherwise)."""

    def __init__(self, head: ActionHead, obs_dim: int, capacity: int, device: torch.device | str = "cpu",
                 squashed: bool = False, obs_dtype: Any = np.float32) -> None:
        if capacity < 1:
            raise ValueError(f"the imitation buffer needs room for at least one state, not {capacity}")
        self.head, self.squashed = head, squashed
        self.math = HeadMath(head, device)
        self.device = torch.device(device)
        self.capacity = int(capacity)
        self.obs = np.zeros((capacity, obs_dim), obs_dtype)
        if head.kind == "box":
            self.actions = np.zeros((capacity, head.outputs), np.float32)
            low, high = np.asarray(head.low, np.float32), np.asarray(head.high, np.float32)
            self._center, self._half = (high + low) / 2, np.maximum((high - low) / 2, 1e-12)
            # the same on the device, for the Gaussian's loss (made once, not per batch)
            self._center_t = torch.from_numpy(self._center).to(self.device)
            self._half_t = torch.from_numpy(self._half).to(self.device)
            self._log_half_t = torch.log(self._half_t)
        else:
            self.actions = np.zeros((capacity, *head.action_shape), np.int64)
        self.masks: np.ndarray | None = None  # made when a mask first comes (games with action masks)
        self.pos = self.size = 0

    def __len__(self) -> int:
        return self.size

    def unit(self, actions: np.ndarray) -> np.ndarray:
        """Box actions on their bounds mapped onto [-1, 1] (the scale the loss compares them on)."""
        y = (np.asarray(actions, np.float32).reshape(len(actions), -1) - self._center) / self._half
        edge = SQUASH_EDGE if self.squashed else 1.0
        return np.clip(y, -edge, edge)

    def add(self, obs: np.ndarray, actions: np.ndarray, mask: np.ndarray | None = None) -> None:
        """The teacher's ``actions`` for the observations ``obs`` (one row each; ``mask``: the actions allowed)."""
        n = len(obs)
        if n == 0:
            return
        x = np.asarray(obs, self.obs.dtype).reshape(n, -1)
        a = self.unit(actions) if self.head.kind == "box" else np.asarray(actions, np.int64).reshape(
            n, *self.head.action_shape)
        if mask is not None and self.masks is None:
            self.masks = np.ones((self.capacity, self.head.mask_width), bool)
        if n > self.capacity:
            x, a = x[-self.capacity:], a[-self.capacity:]
            mask = None if mask is None else np.asarray(mask)[-self.capacity:]
            n = self.capacity
        at = np.arange(self.pos, self.pos + n) % self.capacity
        self.obs[at], self.actions[at] = x, a
        if self.masks is not None:
            self.masks[at] = True if mask is None else np.asarray(mask, bool).reshape(n, -1)
        self.pos = (self.pos + n) % self.capacity
        self.size = min(self.size + n, self.capacity)

    def loss(self, net: MLPNet, batch_size: int, rng: np.random.Generator) -> torch.Tensor:
        """The imitation loss of ``net`` on ``batch_size`` labelled states drawn uniformly (a scalar tensor with
        gradients into ``net``)."""
        if self.size == 0:
            raise RuntimeError("no labelled states to imitate yet")
        idx = rng.integers(0, self.size, size=batch_size)
        obs = torch.from_numpy(self.obs[idx]).to(self.device)
        target = torch.from_numpy(self.actions[idx]).to(self.device)
        if self.head.kind == "box":
            if self.squashed:
                mean, _ = net.gaussian(obs)
                pred = torch.tanh(mean)
                return (pred - target).square().sum(-1).mean()
            out, _ = net(obs)
            assert net.log_std is not None, "a Gaussian policy's network has a log_std"
            log_std = net.log_std - self._log_half_t  # the spread on the [-1, 1] scale
            z = ((out - self._center_t) / self._half_t - target) * torch.exp(-log_std)
            return (0.5 * z.square() + log_std).sum(-1).mean()
        out, _ = net(obs)
        mask = None if self.masks is None else torch.from_numpy(self.masks[idx]).to(self.device)
        logp = torch.log_softmax(self.math.masked(out, mask, MASKED), dim=-1)
        if self.head.kind == "discrete":
            return -logp.gather(1, target[:, None]).mean()
        return -logp.gather(2, target[:, :, None]).squeeze(2).sum(1).mean()
