"""Several network policies acting as one: their weights stacked, one batched forward per step for all of them.

A gauntlet seats a dozen snapshots in one batch of games; acting one network after the other costs a dozen rounds
of torch's per-call overhead every step (tens of microseconds each, more than the arithmetic of a 64x64 MLP on a
few dozen rows). A :class:`NetworkBank` stacks the networks' layers into ``(V, in, out)`` tensors and runs each
layer once for all of them with ``torch.baddbmm``, on a ``(V, M, in)`` batch of ``V`` slots of ``M`` rows each
(:class:`Layout`): a member with many rows (a gauntlet's new snapshot, which plays every matchup) fills several
slots, so the members with few are not padded to its rows, and a member without rows this step takes none.

Sampling draws one uniform per row (and dimension) from the bank's own stream, for the members' rows end to end
whatever the layout (inverse CDF of the softmax); greedy players take the argmax. Masked actions are never chosen
(their logits are -inf, so their share of the CDF is empty). A MultiDiscrete head is handled as its dimensions'
logits laid out side by side in one padded tensor; a Box head gives each member's Gaussian means, played as they are
(greedy) or as ``mean + std * eps`` with one standard normal per row and dimension, clipped to the bounds; a
squashed one (SAC's actor) also its state-dependent log-stds, played as ``tanh(mean)`` or ``tanh(mean + std * eps)``
on the bounds. A match between the same players with the same schedule therefore replays the same actions. A bank
applies the networks' own activation (``torch.tanh_`` in place): its scores equal a network's own to the rounding of
the batched matmuls. (An earlier ``2 sigmoid(2x) - 1``, measured faster on an AMD EPYC, took three more calls a layer:
on an Intel Xeon with AVX-512 it was 23% slower: 645 against 499 us a step for two 64x64 networks on 1,000 rows each.)

A bank of a Discrete head on the CPU acting on few rows (at most :data:`NUMPY_ROWS` with its padding, and few
enough a slot that numpy's BLAS stays on one thread: :data:`SINGLE_THREAD_MNK`; a gauntlet, a match's last games)
runs its forward and its sampling in numpy instead: there torch's fixed cost per call (some 25 calls a step) is most
of the step, and numpy's is a fraction of it (measured by ``benchmarks/match_speed.py``). The two paths compute the
same functions, to float rounding, on the same uniforms, so a match replays the same actions for the same schedule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from .heads import HeadMath, squashed_log_std, to_numpy_actions
from .network import MLPNet, NetworkPolicy


def _np_relu(x: np.ndarray) -> np.ndarray:
    return np.maximum(x, 0.0, out=x)


def _np_tanh(x: np.ndarray) -> np.ndarray:
    return np.tanh(x, out=x)


_NUMPY = {"tanh": _np_tanh, "relu": _np_relu}
NUMPY_ROWS = 384
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


def bank_groups(policies: Sequence[object]) -> list[tuple[object | None, list[int]]]:
    """The policies' indices grouped by :func:`bank_key`, each group with its key; policies without a key (bots) stay
    alone, under None."""
    groups: dict[object, tuple[object | None, list[int]]] = {}
    for i, p in enumerate(policies):
        key = bank_key(p)
        groups.setdefault(("alone", i) if key is None else key, (key, []))[1].append(i)
    return list(groups.values())


SLOT_ROWS = 16
"""What one more slot of a layout costs, in rows of arithmetic (a batched matmul's per-member overhead, measured on
pong's 64x64 networks): :meth:`NetworkBank.layout` splits members into slots only where that saves padding."""


@dataclass(frozen=True)
class _Stack:
    """The members' weights in the order of a layout's slots: ``(V, in, out)`` layers, the action head as ``(V, A, H)``
    (the log-std head and the dueling state value alike), Box stds ``(V, d, 1)``, who plays greedy ``(V, 1)``; and
    their numpy copies where the bank has a numpy path (layers as in torch, heads as ``(V, H, A)``)."""

    layers: list[tuple[torch.Tensor, torch.Tensor]]
    out: tuple[torch.Tensor, torch.Tensor]
    state_value: tuple[torch.Tensor, torch.Tensor] | None
    log_std_head: tuple[torch.Tensor, torch.Tensor] | None
    std: torch.Tensor | None
    greedy: torch.Tensor
    np_layers: list[tuple[np.ndarray, np.ndarray]] | None = None
    np_out: tuple[np.ndarray, np.ndarray] | None = None
    np_value: tuple[np.ndarray, np.ndarray] | None = None
    np_greedy: np.ndarray | None = None
    any_greedy: bool = field(init=False)
    any_sampling: bool = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "any_greedy", bool(self.greedy.any()))
        object.__setattr__(self, "any_sampling", not bool(self.greedy.all()))

    def take(self, slots: Sequence[int], numpy: bool) -> _Stack:
        """This stack's members in the order ``slots`` (repeats allowed)."""
        idx = torch.tensor(slots, device=self.greedy.device)

        def pick(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else t.index_select(0, idx).contiguous()

        def pair(t: tuple[torch.Tensor, torch.Tensor] | None) -> tuple[torch.Tensor, torch.Tensor] | None:
            return None if t is None else (pick(t[0]), pick(t[1]))  # type: ignore[return-value]

        stack = _Stack([pair(wb) for wb in self.layers], pair(self.out), pair(self.state_value),  # type: ignore[misc]
                       pair(self.log_std_head), pick(self.std), pick(self.greedy))  # type: ignore[arg-type]
        return stack.with_numpy() if numpy else stack

    def with_numpy(self) -> _Stack:
        """The same stack with its numpy copies (CPU only)."""
        def heads(t: tuple[torch.Tensor, torch.Tensor] | None) -> tuple[np.ndarray, np.ndarray] | None:
            return None if t is None else (np.ascontiguousarray(t[0].numpy().transpose(0, 2, 1)),
                                           np.ascontiguousarray(t[1].numpy().transpose(0, 2, 1)))

        return _Stack(self.layers, self.out, self.state_value, self.log_std_head, self.std, self.greedy,
                      [(w.numpy().copy(), b.numpy().copy()) for w, b in self.layers], heads(self.out),
                      heads(self.state_value), self.greedy.numpy())


@dataclass(frozen=True)
class Layout:
    """How one step's rows sit in a bank's batch: ``slots`` (the member each of ``V`` slots of ``width`` rows holds;
    a member with many rows fills several slots, one after the other, one without rows none) and ``starts``, where
    each member's rows begin in the batch's ``V * width`` rows (they run on from there, the padding after them)."""

    slots: tuple[int, ...]
    width: int
    starts: tuple[int, ...]
    bounds: tuple[int, ...]  # where each member's rows begin, the rows end to end (and where they end)
    dense: bool  # no padding: the rows end to end are the batch's rows
    stack: _Stack  # the members' weights, slot by slot
    numpy: bool  # acted on in numpy (see the module docstring)


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
        self.activation = nets[0]._activation  # (in place, on each layer's fresh output)
        with torch.no_grad():
            def stacked(mods: list[torch.nn.Linear]) -> tuple[torch.Tensor, torch.Tensor]:
                return (torch.stack([m.weight for m in mods]).contiguous(),
                        torch.stack([m.bias for m in mods]).unsqueeze(2).contiguous())

            layers = [(torch.stack([n._linears[k].weight.T for n in nets]).contiguous(),
                       torch.stack([n._linears[k].bias for n in nets]).unsqueeze(1).contiguous())
                      for k in range(len(nets[0]._linears))]
            # The heads are applied as (P, A, H) @ (P, H, M): with A = 3 outputs, the (M, H) @ (H, A) way round is
            # ~6x slower in torch's batched matmul. The action scores come out as (P, A, M).
            std = None
            log_std_head = None
            if nets[0].squash:  # (P, d, H) and (P, d, 1): each member's log-std head, applied as the action head
                log_std_head = stacked([n.log_std_head for n in nets])  # type: ignore[misc]
            elif self.head.kind == "box":  # (P, d, 1): each member's standard deviations
                std = torch.stack([n.log_std for n in nets]).exp().unsqueeze(2).contiguous()  # type: ignore[misc]
            state_value = None if nets[0].state_value is None else stacked([n.state_value for n in nets])  # type: ignore[misc]
            greedy = torch.tensor([p.greedy for p in members], device=self.device)[:, None]
            self.stack = _Stack(layers, stacked([n.action_head for n in nets]), state_value, log_std_head, std, greedy)
        self.members = len(members)
        # the uniforms a row draws (a categorical head where a member samples): their shape
        self.draws = (self.head.action_shape if self.head.kind in ("discrete", "multidiscrete")
                      and self.stack.any_sampling else None)
        bank_seed = int(seed) ^ (sum(int(p.seed) * 1_000_003 ** k for k, p in enumerate(members)) & 0x7FFF_FFFF_FFFF)
        self.generator = torch.Generator(device=self.device)  # a Box head's normals
        self.generator.manual_seed(bank_seed)
        self.uniforms = np.random.Generator(np.random.PCG64(bank_seed))  # a categorical head's uniforms
        self.obs_dim = nets[0].obs_dim
        # The numpy copies of the weights for few rows (see the module docstring).
        self.numpy = False
        act = _NUMPY.get(nets[0].arch.activation)
        if self.device.type == "cpu" and self.head.kind == "discrete" and act is not None:
            self.numpy = True
            self.np_activation = act
            self.stack = self.stack.with_numpy()
            widest = max(w.shape[1] * w.shape[2] for w, _ in layers)
            out_w = self.stack.out[0]
            self.np_rows = SINGLE_THREAD_MNK // max(widest, out_w.shape[1] * out_w.shape[2])
        self._layouts: dict[tuple[int, ...], Layout] = {}
        self._stacks: dict[tuple[int, ...], _Stack] = {tuple(range(len(members))): self.stack}

    def layout(self, rows: Sequence[int]) -> Layout:
        """Where the members' ``rows`` sit this step: slots of one width, the width that costs least (padded rows,
        plus :data:`SLOT_ROWS` a slot), so a gauntlet's new snapshot with many rows beside opponents with few fills
        several slots of their size instead of padding every opponent to its rows; a member without rows takes no
        slot. Worked out once per distinct ``rows`` (they change when games end)."""
        key = tuple(rows)
        got = self._layouts.get(key)
        if got is not None:
            return got
        counts = np.array(key, dtype=np.int64)
        best: tuple[int, int] | None = None
        for width in sorted({int(r) for r in key if r}, reverse=True):  # (ties: the widest, fewest slots)
            n_slots = int(np.sum(-(-counts // width)))
            cost = n_slots * (width + SLOT_ROWS)
            if best is None or cost < best[0]:
                best = (cost, width)
        width = best[1]  # type: ignore[index]
        slots: list[int] = []
        starts: list[int] = []
        for k, r in enumerate(key):
            starts.append(len(slots) * width)
            slots += [k] * -(-r // width)
        bounds = tuple(int(b) for b in np.cumsum([0, *key]))
        if len(self._layouts) >= 256:  # (a long gauntlet passes through many; the recent ones recur)
            self._layouts.clear()
        numpy = self.numpy and len(slots) * width <= NUMPY_ROWS and width <= self.np_rows
        got = self._layouts[key] = Layout(tuple(slots), width, tuple(starts), bounds, bounds[-1] == len(slots) * width,
                                          self._stack_for(tuple(slots)), numpy)
        return got

    def _stack_for(self, slots: tuple[int, ...]) -> _Stack:
        """The weights of the members in the order ``slots`` (gathered once per distinct order)."""
        got = self._stacks.get(slots)
        if got is None:
            if len(self._stacks) >= 64:
                self._stacks = {tuple(range(self.members)): self.stack}
            got = self._stacks[slots] = self.stack.take(slots, self.numpy)
        return got

    @staticmethod
    def _spread(parts: Sequence[np.ndarray | None], rows: list[int], lay: Layout, fill: bool, dtype: type,
                shape: tuple[int, ...]) -> np.ndarray:
        """Each member's per-row values (``parts[k]``: ``(rows[k], *shape)``; None: ``fill``) in the layout's slots
        ``(V, width, *shape)`` (padding: ``fill``, zeros or ones)."""
        if lay.dense and all(p is not None for p in parts):  # the rows end to end, as they are
            flat = np.concatenate([p.reshape(r, *shape) for p, r in zip(parts, rows, strict=True) if r])
            return flat.astype(dtype, copy=False).reshape(len(lay.slots), lay.width, *shape)
        out = (np.zeros if not fill else np.ones)((len(lay.slots) * lay.width, *shape), dtype=dtype)
        for k, (part, r) in enumerate(zip(parts, rows, strict=True)):
            if r and part is not None:
                out[lay.starts[k] : lay.starts[k] + r] = part.reshape(r, *shape)
        return out.reshape(len(lay.slots), lay.width, *shape)

    def _masks(self, masks: Sequence[np.ndarray | None] | None, rows: list[int], lay: Layout) -> np.ndarray | None:
        """The members' masks as one ``(V, width, A)`` bool array in the layout (padding and members without a
        mask: all allowed)."""
        if masks is None or all(m is None for m in masks):
            return None
        if self.head.kind == "box":
            raise ValueError("Box actions take no action mask")
        checked = [None if m is None or not r else self.head.check_mask(m, r) for m, r in zip(masks, rows, strict=True)]
        out = self._spread(checked, rows, lay, True, bool, (self.head.mask_width,))
        if self.head.kind == "discrete" and not out.any(axis=2).all():
            raise ValueError("the action mask allows no action in some rows")
        return out

    def act(self, obs: Sequence[np.ndarray], masks: Sequence[np.ndarray | None] | None = None) -> list[np.ndarray]:
        """Actions of every member for its own observations (``obs[k]``: member k's rows, any count, maybe 0) and,
        optionally, its action masks (``masks[k]``: ``(rows, n_actions)`` bool, or None)."""
        rows = [len(o) for o in obs]
        n = sum(rows)
        if n == 0:
            shape = self.head.action_shape
            dtype = np.float32 if self.head.kind == "box" else np.int64
            return [np.zeros((0, *shape), dtype=dtype) for _ in obs]
        lay = self._layouts.get(tuple(rows)) or self.layout(rows)
        # padding is zeros (never garbage: no NaN or denormal slows the arithmetic down)
        x = self._spread(obs, rows, lay, False, np.float32, (self.obs_dim,))
        mask = self._masks(masks, rows, lay)
        u = None  # a categorical head's uniforms: one per row (and dimension), drawn for the rows end to end, so the
        # draws do not depend on the layout or the path
        if self.draws is not None:
            drawn = self.uniforms.random((n, *self.draws), dtype=np.float32)
            if lay.dense:
                u = drawn.reshape(len(lay.slots), lay.width, *self.draws)
            else:
                b = lay.bounds
                u = self._spread([drawn[b[k] : b[k + 1]] for k in range(len(rows))], rows, lay, False, np.float32,
                                 self.draws)
        every = (self._numpy_categorical if lay.numpy else self._torch_act)(x, mask, u, lay.stack)
        flat = every.reshape(len(lay.slots) * lay.width, *every.shape[2:])
        return [flat[lay.starts[k] : lay.starts[k] + r] for k, r in enumerate(rows)]

    @torch.inference_mode()
    def _torch_act(self, x: np.ndarray, mask_np: np.ndarray | None, u_np: np.ndarray | None,
                   stack: _Stack) -> np.ndarray:
        """The slots' actions ``(V, M, ...)`` for the padded observations ``x`` ``(V, M, in)``, masks ``(V, M, A)``
        and uniforms ``(V, M, ...)`` (padding: zeros; a mask's: all allowed), through torch."""
        p, most = x.shape[0], x.shape[1]
        mask = None
        if mask_np is not None:
            mask = torch.from_numpy(mask_np)
            if self.device.type != "cpu":
                mask = mask.to(self.device)
            mask = mask.transpose(1, 2)
        u = None
        if u_np is not None:
            u = torch.from_numpy(u_np.reshape(p, 1, -1))  # (V, 1, M) or (V, 1, M * k)
            if self.device.type != "cpu":
                u = u.to(self.device)
        z = torch.from_numpy(x)
        if self.device.type != "cpu":
            z = z.to(self.device)
        for w, b in stack.layers:
            z = self.activation(torch.baddbmm(b, z, w))
        zt = z.transpose(1, 2)
        out = torch.baddbmm(stack.out[1], stack.out[0], zt)  # (V, A, M)
        if stack.state_value is not None:
            out = torch.baddbmm(stack.state_value[1], stack.state_value[0], zt) + out - out.mean(dim=1, keepdim=True)
        if stack.log_std_head is not None:  # (its log-stds only where a member samples: SAC plays its mean)
            log_std = (squashed_log_std(torch.baddbmm(stack.log_std_head[1], stack.log_std_head[0], zt))
                       if stack.any_sampling else None)
            a = self._squashed(out, log_std, stack)
        elif self.head.kind == "discrete":
            a = self._categorical(out if mask is None else out.masked_fill(~mask, float("-inf")), u, stack)
        elif self.head.kind == "multidiscrete":
            a = self._multi(out, mask, u, p, most, stack)
        else:
            a = self._gaussian(out, p, most, stack)
        every = to_numpy_actions(self.head, a.reshape(p * most, *a.shape[2:]))  # one copy off the tensor
        return every.reshape(p, most, *every.shape[1:])

    def _numpy_categorical(self, x: np.ndarray, mask: np.ndarray | None, u: np.ndarray | None,
                           stack: _Stack) -> np.ndarray:
        """A Discrete head's actions ``(V, M)`` int64 for the padded observations ``x`` ``(V, M, in)``, masks
        ``(V, M, A)`` and uniforms ``(V, M)``, in numpy: the torch path's functions (tanh itself, not through the
        sigmoid)."""
        z = x
        for w, b in stack.np_layers:  # type: ignore[union-attr]
            z = np.matmul(z, w)
            z += b
            z = self.np_activation(z)
        out = np.matmul(z, stack.np_out[0])  # type: ignore[index]
        out += stack.np_out[1]  # type: ignore[index]  # (V, M, A)
        if stack.np_value is not None:
            value = np.matmul(z, stack.np_value[0]) + stack.np_value[1]
            out += value - out.mean(axis=2, keepdims=True)
        if mask is not None:
            out[~mask] = -np.inf
        actions = out.argmax(axis=2) if stack.any_greedy else None
        if stack.any_sampling:  # as _categorical: a = #{k : cumsum(e)_k <= u * sum(e)}
            e = np.exp(out - out.max(axis=2, keepdims=True))
            np.cumsum(e, axis=2, out=e)
            sampled = (e <= u[:, :, None] * e[:, :, -1:]).sum(axis=2)  # type: ignore[index]
            np.minimum(sampled, self.n_actions - 1, out=sampled)
            actions = sampled if actions is None else np.where(stack.np_greedy, actions, sampled)
        return actions.astype(np.int64, copy=False)  # type: ignore[union-attr]

    def _categorical(self, out: torch.Tensor, u: torch.Tensor | None, stack: _Stack) -> torch.Tensor:
        """Discrete: ``out`` (V, A, M) and uniforms ``u`` (V, 1, M) -> actions (V, M)."""
        actions = out.max(dim=1).indices if stack.any_greedy else None  # (argmax over dim 1: ~10x slower)
        if stack.any_sampling:  # inverse CDF of the softmax, unnormalised: a = #{k : cumsum(e)_k <= u * sum(e)}
            e = (out - out.amax(dim=1, keepdim=True)).exp_().cumsum_(dim=1)
            sampled = (e <= u * e[:, -1:, :]).sum(dim=1).clamp_(max=self.n_actions - 1)
            actions = sampled if actions is None else torch.where(stack.greedy, actions, sampled)
        return actions  # type: ignore[return-value]

    def _multi(self, out: torch.Tensor, mask: torch.Tensor | None, u: torch.Tensor | None, p: int, most: int,
               stack: _Stack) -> torch.Tensor:
        """MultiDiscrete: ``out`` (V, A, M) and uniforms ``u`` (V, 1, M * k) -> actions (V, M, k), each dimension as
        a Discrete head."""
        flat = out.transpose(1, 2).reshape(p * most, -1)
        m = None if mask is None else mask.transpose(1, 2).reshape(p * most, -1)
        logits = self.math.padded(flat, m, float("-inf"))  # (P*M, k, W)
        if not bool(torch.isfinite(logits.amax(dim=2)).all()):
            raise ValueError("the action mask allows no action in some rows")
        k, w = logits.shape[1], logits.shape[2]
        cat = logits.reshape(p, most * k, w).transpose(1, 2)  # (P, W, M*k): the Discrete layout
        greedy = stack.greedy
        actions = cat.max(dim=1).indices if stack.any_greedy else None
        if stack.any_sampling:
            e = (cat - cat.amax(dim=1, keepdim=True)).exp_().cumsum_(dim=1)
            sampled = (e <= u * e[:, -1:, :]).sum(dim=1).clamp_(max=w - 1)
            actions = sampled if actions is None else torch.where(greedy, actions, sampled)
        return actions.reshape(p, most, k)  # type: ignore[union-attr]

    def _gaussian(self, out: torch.Tensor, p: int, most: int, stack: _Stack) -> torch.Tensor:
        """Box: the means ``out`` (V, d, M) -> clipped actions (V, M, d)."""
        a = out
        if stack.any_sampling:
            eps = torch.randn(out.shape, generator=self.generator, device=self.device)
            sampled = out + stack.std * eps
            a = sampled if not stack.any_greedy else torch.where(stack.greedy[:, :, None], out, sampled)
        a = a.transpose(1, 2)
        return torch.maximum(torch.minimum(a, self.math.high), self.math.low)

    def _squashed(self, out: torch.Tensor, log_std: torch.Tensor | None, stack: _Stack) -> torch.Tensor:
        """Box, squashed: the means and log-stds ``(V, d, M)`` -> ``tanh(u)`` on the bounds ``(V, M, d)``."""
        u = out
        if stack.any_sampling:
            sampled = out + log_std.exp() * torch.randn(out.shape, generator=self.generator,  # type: ignore[union-attr]
                                                          device=self.device)
            u = sampled if not stack.any_greedy else torch.where(stack.greedy[:, :, None], out, sampled)
        y = torch.tanh(u).transpose(1, 2)
        a = self.math.low + (y + 1.0) * (0.5 * (self.math.high - self.math.low))
        return torch.maximum(torch.minimum(a, self.math.high), self.math.low)
