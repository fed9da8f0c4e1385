"""Several network policies acting as one: their weights stacked, one batched forward per step for all of them.

A gauntlet seats a dozen snapshots in one batch of games; acting one network after the other costs a dozen rounds
of torch's per-call overhead every step (tens of microseconds each, more than the arithmetic of a 64x64 MLP on a
few dozen rows). A :class:`NetworkBank` stacks the networks' layers into ``(P, in, out)`` tensors and runs each
layer once for all of them with ``torch.baddbmm``, on a ``(P, M, in)`` batch padded to the largest player's rows.

Sampling draws one uniform per row (and dimension) from the bank's own stream (inverse CDF of the softmax);
greedy players take the argmax. Masked actions are never chosen (their logits are -inf, so their share of the CDF is
empty). A MultiDiscrete head is handled as its dimensions' logits laid out side by side in one padded tensor; a Box
head gives each member's Gaussian means, played as they are (greedy) or as ``mean + std * eps`` with one standard
normal per row and dimension, clipped to the bounds; a squashed one (SAC's actor) also its state-dependent log-stds,
played as ``tanh(mean)`` or ``tanh(mean + std * eps)`` on the bounds. A match between the same players with the same
schedule therefore replays the same actions. A bank computes tanh as ``2 sigmoid(2x) - 1`` (faster here): its scores
equal a network's own to float rounding, not bit for bit.

A bank of a Discrete head on the CPU acting on few rows (at most :data:`NUMPY_ROWS` with its padding, and few
enough a member that numpy's BLAS stays on one thread: :data:`SINGLE_THREAD_MNK`; a gauntlet's or a match's last
games) runs its forward and its sampling in numpy instead: there torch's fixed
cost per call (some 25 calls a step) is most of the step, and numpy's is a fraction of it (measured by
``benchmarks/match_speed.py``). The two paths compute the same functions, to float rounding; the uniforms come from
the bank's one stream either way, so a match still replays the same actions for the same schedule.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from .heads import HeadMath, squashed_log_std, to_numpy_actions
from .network import MLPNet, NetworkPolicy


def _tanh(x: torch.Tensor) -> torch.Tensor:
    """tanh(x) = 2 sigmoid(2x) - 1: the same function (to float rounding), ~2.5x faster than this torch build's
    tanh on these CPUs (measured: 130 vs 345 us for 2 x 1000 x 64)."""
    return torch.sigmoid(x.mul_(2.0)).mul_(2.0).sub_(1.0)


_FAST = {"tanh": _tanh, "relu": torch.relu_}


def _np_relu(x: np.ndarray) -> np.ndarray:
    return np.maximum(x, 0.0, out=x)


def _np_tanh(x: np.ndarray) -> np.ndarray:
    return np.tanh(x, out=x)


_NUMPY = {"tanh": _np_tanh, "relu": _np_relu}
NUMPY_ROWS = 256
"""The most rows (members x the largest member's rows) a CPU bank of a Discrete head acts on in numpy (more go
through torch, whose batched matmul wins on many rows)."""
SINGLE_THREAD_MNK = 262_144
"""numpy's OpenBLAS multiplies on one thread while rows x in x out of a product is at most this (its
``GEMM_MULTITHREAD_THRESHOLD`` of 4 x 65,536); above it, it starts a thread per core, which beside training takes the
trainer's core. A member's rows in numpy stay under it."""


def bank_key(policy: object) -> tuple | None:
    """Policies with the same key can act in one bank: network policies of one MLP architecture and one action
    head (kind, sizes and bounds) on one device (a cnn has no key: its convolutions are not batched here)."""
    if not isinstance(policy, NetworkPolicy) or policy.net.encoder is not None:  # a cnn acts on its own
        return None
    net = policy.net
    return (str(policy.device), net.obs_dim, net.head, net.arch.hidden, net.arch.activation, net.arch.dueling,
            net.arch.squash)


def bank_groups(policies: Sequence[object]) -> list[list[int]]:
    """The policies' indices grouped by :func:`bank_key`; policies without a key (bots) stay alone."""
    groups: dict[object, list[int]] = {}
    for i, p in enumerate(policies):
        key = bank_key(p)
        groups.setdefault(("alone", i) if key is None else key, []).append(i)
    return list(groups.values())


class NetworkBank:
    """The policies ``members`` (one :func:`bank_key`) as one batched network."""

    def __init__(self, members: Sequence[NetworkPolicy], seed: int = 0) -> None:
        if len({bank_key(p) for p in members}) != 1:
            raise ValueError("a bank holds network policies of one architecture on one device")
        nets: list[MLPNet] = [p.net for p in members]
        self.device = members[0].device
        self.n_actions = nets[0].n_actions
        self.head = nets[0].head
        self.math = HeadMath(self.head, self.device)
        self.activation = _FAST.get(nets[0].arch.activation, nets[0]._activation)
        with torch.no_grad():
            self.layers = [(torch.stack([n._linears[k].weight.T for n in nets]).contiguous(),
                            torch.stack([n._linears[k].bias for n in nets]).unsqueeze(1).contiguous())
                           for k in range(len(nets[0]._linears))]
            # The heads are applied as (P, A, H) @ (P, H, M): with A = 3 outputs, the (M, H) @ (H, A) way round is
            # ~6x slower in torch's batched matmul. The action scores come out as (P, A, M).
            self.out_w = torch.stack([n.action_head.weight for n in nets]).contiguous()
            self.out_b = torch.stack([n.action_head.bias for n in nets]).unsqueeze(2).contiguous()
            self.std = None
            self.log_std_head = None
            if nets[0].squash:  # (P, d, H) and (P, d, 1): each member's log-std head, applied as the action head
                self.log_std_head = (torch.stack([n.log_std_head.weight for n in nets]).contiguous(),  # type: ignore[union-attr]
                                     torch.stack([n.log_std_head.bias for n in nets]).unsqueeze(2).contiguous())  # type: ignore[union-attr]
            elif self.head.kind == "box":  # (P, d, 1): each member's standard deviations
                self.std = torch.stack([n.log_std for n in nets]).exp().unsqueeze(2).contiguous()  # type: ignore[misc]
            self.state_value = None
            if nets[0].state_value is not None:
                self.state_value = (torch.stack([n.state_value.weight for n in nets]).contiguous(),  # type: ignore[union-attr]
                                    torch.stack([n.state_value.bias for n in nets]).unsqueeze(2).contiguous())  # type: ignore[union-attr]
        self.greedy = torch.tensor([p.greedy for p in members], device=self.device)[:, None]
        self.any_greedy = bool(self.greedy.any())
        self.any_sampling = not bool(self.greedy.all())
        bank_seed = int(seed) ^ (sum(int(p.seed) * 1_000_003 ** k for k, p in enumerate(members)) & 0x7FFF_FFFF_FFFF)
        self.generator = torch.Generator(device=self.device)  # a Box head's normals
        self.generator.manual_seed(bank_seed)
        self.uniforms = np.random.Generator(np.random.PCG64(bank_seed))  # a categorical head's uniforms
        self.obs_dim = nets[0].obs_dim
        # The numpy copies of the weights for few rows (see the module docstring): (P, in, out) layers, the action
        # head and the dueling state value as (P, H, A) and (P, 1, A).
        self.np_layers = None
        act = _NUMPY.get(nets[0].arch.activation)
        if self.device.type == "cpu" and self.head.kind == "discrete" and act is not None:
            self.np_activation = act
            self.np_layers = [(w.numpy().copy(), b.numpy().copy()) for w, b in self.layers]
            self.np_out = (np.ascontiguousarray(self.out_w.numpy().transpose(0, 2, 1)),
                           np.ascontiguousarray(self.out_b.numpy().transpose(0, 2, 1)))
            self.np_value = None if self.state_value is None else (
                np.ascontiguousarray(self.state_value[0].numpy().transpose(0, 2, 1)),
                np.ascontiguousarray(self.state_value[1].numpy().transpose(0, 2, 1)))
            self.np_greedy = self.greedy.numpy()  # (P, 1)
            widest = max(w.shape[1] * w.shape[2] for w, _ in self.np_layers)
            self.np_rows = SINGLE_THREAD_MNK // max(widest, self.np_out[0].shape[1] * self.np_out[0].shape[2])

    def _masks(self, masks: Sequence[np.ndarray | None] | None, rows: list[int], most: int) -> np.ndarray | None:
        """The members' masks as one ``(P, M, A)`` bool array (padding and members without a mask: all allowed)."""
        if masks is None or all(m is None for m in masks):
            return None
        if self.head.kind == "box":
            raise ValueError("Box actions take no action mask")
        width = self.head.mask_width
        out = np.ones((len(rows), most, width), dtype=bool)
        for k, m in enumerate(masks):
            if m is not None and rows[k]:
                m = self.head.check_mask(m, rows[k])
                out[k, : rows[k]] = m
        if self.head.kind == "discrete" and not out.any(axis=2).all():
            raise ValueError("the action mask allows no action in some rows")
        return out

    def act(self, obs: Sequence[np.ndarray], masks: Sequence[np.ndarray | None] | None = None) -> list[np.ndarray]:
        """Actions of every member for its own observations (``obs[k]``: member k's rows, any count, maybe 0) and,
        optionally, its action masks (``masks[k]``: ``(rows, n_actions)`` bool, or None)."""
        rows = [len(o) for o in obs]
        most = max(rows)
        if most == 0:
            shape = self.head.action_shape
            dtype = np.float32 if self.head.kind == "box" else np.int64
            return [np.zeros((0, *shape), dtype=dtype) for _ in obs]
        x = np.empty((len(obs), most, self.obs_dim), dtype=np.float32)
        for k, o in enumerate(obs):
            if rows[k]:
                x[k, : rows[k]] = o.reshape(rows[k], -1)
            x[k, rows[k]:] = 0.0  # padding (never garbage: no NaN or denormal slows the arithmetic down)
        mask_np = self._masks(masks, rows, most)
        if self.np_layers is not None and len(obs) * most <= NUMPY_ROWS and most <= self.np_rows:
            a = self._numpy_categorical(x, mask_np)
            return [a[k, : rows[k]] for k in range(len(obs))]
        every = self._torch_act(x, mask_np)
        return [every[k, : rows[k]] for k in range(len(obs))]

    @torch.inference_mode()
    def _torch_act(self, x: np.ndarray, mask_np: np.ndarray | None) -> np.ndarray:
        """The members' actions ``(P, M, ...)`` for the padded observations ``x`` ``(P, M, in)``, through torch."""
        p, most = x.shape[0], x.shape[1]
        mask = None
        if mask_np is not None:
            mask = torch.from_numpy(mask_np)
            if self.device.type != "cpu":
                mask = mask.to(self.device)
            mask = mask.transpose(1, 2)
        z = torch.from_numpy(x)
        if self.device.type != "cpu":
            z = z.to(self.device)
        for w, b in self.layers:
            z = self.activation(torch.baddbmm(b, z, w))
        zt = z.transpose(1, 2)
        out = torch.baddbmm(self.out_b, self.out_w, zt)  # (P, A, M)
        if self.state_value is not None:
            out = torch.baddbmm(self.state_value[1], self.state_value[0], zt) + out - out.mean(dim=1, keepdim=True)
        if self.log_std_head is not None:
            log_std = squashed_log_std(torch.baddbmm(self.log_std_head[1], self.log_std_head[0], zt))
            a = self._squashed(out, log_std)
        elif self.head.kind == "discrete":
            a = self._categorical(out if mask is None else out.masked_fill(~mask, float("-inf")), p, most)
        elif self.head.kind == "multidiscrete":
            a = self._multi(out, mask, p, most)
        else:
            a = self._gaussian(out, p, most)
        every = to_numpy_actions(self.head, a.reshape(p * most, *a.shape[2:]))  # one copy off the tensor
        return every.reshape(p, most, *every.shape[1:])

    def _numpy_categorical(self, x: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
        """A Discrete head's actions ``(P, M)`` int64 for the padded observations ``x`` ``(P, M, in)`` and masks
        ``(P, M, A)``, in numpy: the torch path's functions (tanh itself, not through the sigmoid), the bank's
        uniforms."""
        z = x
        for w, b in self.np_layers:  # type: ignore[union-attr]
            z = np.matmul(z, w)
            z += b
            z = self.np_activation(z)
        out = np.matmul(z, self.np_out[0])
        out += self.np_out[1]  # (P, M, A)
        if self.np_value is not None:
            value = np.matmul(z, self.np_value[0]) + self.np_value[1]
            out += value - out.mean(axis=2, keepdims=True)
        if mask is not None:
            out[~mask] = -np.inf
        p, most = x.shape[0], x.shape[1]
        actions = out.argmax(axis=2) if self.any_greedy else None
        if self.any_sampling:  # as _categorical: a = #{k : cumsum(e)_k <= u * sum(e)}
            e = np.exp(out - out.max(axis=2, keepdims=True))
            np.cumsum(e, axis=2, out=e)
            u = self.uniforms.random((p, most, 1), dtype=np.float32)  # (the torch path's draws, in the same order)
            sampled = (e <= u * e[:, :, -1:]).sum(axis=2)
            np.minimum(sampled, self.n_actions - 1, out=sampled)
            actions = sampled if actions is None else np.where(self.np_greedy, actions, sampled)
        return actions.astype(np.int64, copy=False)  # type: ignore[union-attr]

    def _uniforms(self, shape: tuple[int, ...]) -> torch.Tensor:
        """Uniforms [0, 1) of ``shape`` from the bank's stream, as a tensor on its device."""
        u = torch.from_numpy(self.uniforms.random(shape, dtype=np.float32))
        return u if self.device.type == "cpu" else u.to(self.device)

    def _categorical(self, out: torch.Tensor, p: int, most: int) -> torch.Tensor:
        """Discrete: ``out`` (P, A, M) -> actions (P, M)."""
        actions = out.argmax(dim=1) if self.any_greedy else None
        if self.any_sampling:  # inverse CDF of the softmax, unnormalised: a = #{k : cumsum(e)_k <= u * sum(e)}
            e = (out - out.amax(dim=1, keepdim=True)).exp_().cumsum_(dim=1)
            u = self._uniforms((p, 1, most))
            sampled = (e <= u * e[:, -1:, :]).sum(dim=1).clamp_(max=self.n_actions - 1)
            actions = sampled if actions is None else torch.where(self.greedy, actions, sampled)
        return actions  # type: ignore[return-value]

    def _multi(self, out: torch.Tensor, mask: torch.Tensor | None, p: int, most: int) -> torch.Tensor:
        """MultiDiscrete: ``out`` (P, A, M) -> actions (P, M, k), each dimension as a Discrete head."""
        flat = out.transpose(1, 2).reshape(p * most, -1)
        m = None if mask is None else mask.transpose(1, 2).reshape(p * most, -1)
        logits = self.math.padded(flat, m, float("-inf"))  # (P*M, k, W)
        if not bool(torch.isfinite(logits.amax(dim=2)).all()):
            raise ValueError("the action mask allows no action in some rows")
        k, w = logits.shape[1], logits.shape[2]
        cat = logits.reshape(p, most * k, w).transpose(1, 2)  # (P, W, M*k): the Discrete layout
        greedy = self.greedy
        actions = cat.argmax(dim=1) if self.any_greedy else None
        if self.any_sampling:
            e = (cat - cat.amax(dim=1, keepdim=True)).exp_().cumsum_(dim=1)
            u = self._uniforms((p, 1, most * k))
            sampled = (e <= u * e[:, -1:, :]).sum(dim=1).clamp_(max=w - 1)
            actions = sampled if actions is None else torch.where(greedy, actions, sampled)
        return actions.reshape(p, most, k)  # type: ignore[union-attr]

    def _gaussian(self, out: torch.Tensor, p: int, most: int) -> torch.Tensor:
        """Box: the means ``out`` (P, d, M) -> clipped actions (P, M, d)."""
        a = out
        if self.any_sampling:
            eps = torch.randn(out.shape, generator=self.generator, device=self.device)
            sampled = out + self.std * eps
            a = sampled if not self.any_greedy else torch.where(self.greedy[:, :, None], out, sampled)
        a = a.transpose(1, 2)
        return torch.maximum(torch.minimum(a, self.math.high), self.math.low)

    def _squashed(self, out: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
        """Box, squashed: the means and log-stds ``(P, d, M)`` -> ``tanh(u)`` on the bounds ``(P, M, d)``."""
        u = out
        if self.any_sampling:
            sampled = out + log_std.exp() * torch.randn(out.shape, generator=self.generator, device=self.device)
            u = sampled if not self.any_greedy else torch.where(self.greedy[:, :, None], out, sampled)
        y = torch.tanh(u).transpose(1, 2)
        a = self.math.low + (y + 1.0) * (0.5 * (self.math.high - self.math.low))
        return torch.maximum(torch.minimum(a, self.math.high), self.math.low)
