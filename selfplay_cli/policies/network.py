"""Neural policies: the network itself and the policy that plays with it (its shape, :class:`Arch`, is
:mod:`.arch`'s).

Image observations (:func:`~selfplay_cli.envs.obs_spaces.image_layout`: uint8 HxWxC or CxHxW) are read by a
convolutional encoder in front of the MLP trunk (``Arch.conv``), by default (:func:`~.arch.default_conv`) the
Nature-CNN's ``32x8s4, 64x4s2, 64x3s1`` where the image's smaller side has 64 pixels or more, else ``16x3s1, 32x3s2``
(sides of 7 to 63 pixels; ``16x3s1`` alone below); no padding, ReLU after each convolution, the pixels scaled to
[0, 1] inside the network (frames stay uint8 everywhere before it).

The MLP serves every learner: its action head gives PPO's logits or DQN's Q-values, and an optional value head gives
PPO's critic. The action head is the one its seat's action space calls for (:class:`ActionHead`): ``n`` logits for
``Discrete(n)``, ``sum(nvec)`` logits (one block per dimension) for ``MultiDiscrete(nvec)``, and for a ``Box`` the
means of a Gaussian with a learned state-independent ``log_std`` parameter, or, with ``Arch.squash`` (SAC's actor),
the means and a second head of state-dependent log-stds of a tanh-squashed Gaussian. Everything here is plain torch;
nothing is set globally (threads, seeds, default dtype): callers that care about throughput may call
``torch.set_num_threads`` themselves.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from torch import nn
from torch.nn import functional as F

from .arch import Arch, SnapshotError, conv_shapes
from .base import Policy
from .heads import HeadMath, squashed_log_std, to_numpy_actions
from .spaces import ActionHead, SpaceError, box_of_shape

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}
ACTIVATION_FNS = {"tanh": torch.tanh_, "relu": torch.relu_}  # in place, on each layer's fresh output


def _layer(in_dim: int, out_dim: int, gain: float, generator: torch.Generator | None) -> nn.Linear:
    """A Linear layer with CleanRL's init: orthogonal weights with ``gain``, zero bias.

    torch's default init runs on a fork of the global RNG, so a seeded build never moves the global RNG
    (``nn.utils.skip_init`` would too, but its meta-device round trip took ~0.2 s a network).
    """
    with torch.random.fork_rng(devices=[]):
        layer = nn.Linear(in_dim, out_dim)
    with torch.no_grad():
        nn.init.orthogonal_(layer.weight, gain, generator=generator)
        layer.bias.zero_()
    return layer


class MLPNet(nn.Module):
    """Flattened observation (or, for a cnn arch, the image through the conv encoder) -> trunk (Linear + activation
    per hidden width) -> heads.

    ``forward(x)`` takes ``(batch, *obs_shape)`` (or already flat ``(batch, obs_dim)``) and returns
    ``(action_out, value)``: ``action_out`` is ``(batch, head.outputs)``: logits (PPO; per dimension, side by side,
    for MultiDiscrete), Q-values (DQN) or Gaussian means (Box); ``value`` is ``(batch,)`` or ``None`` without a
    value head. ``obs_space`` and ``act_space`` are the seat's spaces (gymnasium).

    Parameter names (the snapshot's tensor names): ``encoder.{2i}.weight/bias`` (a cnn's conv layers),
    ``trunk.{2i}.weight/bias``, ``action_head.*``, ``log_std``
    (Box actions), ``value_head.*`` and, for a dueling arch, ``state_value.*``. A squashed arch (SAC's actor) has
    ``log_std_head.*`` (the state-dependent log-std, see :meth:`gaussian`) instead of ``log_std``; its
    ``forward`` gives the Gaussian's means (before the tanh).
    """

    def __init__(self, obs_dim: int, action: int | spaces.Space | ActionHead, arch: Arch,
                 generator: torch.Generator | None = None, obs_space: spaces.Box | None = None) -> None:
        super().__init__()
        try:
            head = action if isinstance(action, ActionHead) else ActionHead.of(action)
        except SpaceError as e:
            raise SnapshotError(str(e)) from None
        if int(obs_dim) < 1:
            raise SnapshotError(f"a network needs obs_dim >= 1 and n_actions >= 1, got {obs_dim} and {head.outputs}")
        if arch.dueling and head.kind != "discrete":
            raise SnapshotError(f"a dueling head is for Discrete actions (Q-values), not {head.describe()}")
        if arch.squash and head.kind != "box":
            raise SnapshotError(f"a squashed Gaussian head is for Box actions, not {head.describe()}")
        self.obs_dim = int(obs_dim)
        self.head = head
        self.n_actions = head.outputs  # the action head's width (the action count of a Discrete space)
        self.obs_space = obs_space if obs_space is not None else box_of_shape((self.obs_dim,))
        self.act_space = action if isinstance(action, spaces.Space) else _space_of(head)
        self.arch = arch
        self.obs_shape = tuple(int(d) for d in self.obs_space.shape)
        hidden_gain = math.sqrt(2.0)
        width = self.obs_dim
        self.encoder: nn.Sequential | None = None
        self._convs: list[nn.Conv2d] = []
        if arch.kind == "cnn":
            weights, width = conv_shapes(self.obs_shape, arch)
            convs: list[nn.Module] = []
            for (out, cin, k, _), (_, _, stride) in zip(weights, arch.conv or (), strict=True):
                convs += [_conv(cin, out, k, stride, hidden_gain, generator), nn.ReLU()]
            self.encoder = nn.Sequential(*convs)
            self._convs = [m for m in convs if isinstance(m, nn.Conv2d)]
        layers: list[nn.Module] = []
        for h in arch.hidden:
            layers.append(_layer(width, h, hidden_gain, generator))
            layers.append(ACTIVATIONS[arch.activation]())
            width = h
        self.trunk = nn.Sequential(*layers)
        self._linears = [m for m in layers if isinstance(m, nn.Linear)]
        self._activation = ACTIVATION_FNS[arch.activation]
        self.action_head = _layer(width, self.n_actions, 0.01, generator)
        self.squash = arch.squash
        self.log_std = nn.Parameter(torch.zeros(self.n_actions)) if head.kind == "box" and not self.squash else None
        self.value_head = _layer(width, 1, 1.0, generator) if arch.value_head else None
        self.state_value = _layer(width, 1, 1.0, generator) if arch.dueling else None
        self.log_std_head = _layer(width, self.n_actions, 0.01, generator) if self.squash else None

    def _inputs(self, x: torch.Tensor) -> torch.Tensor:
        """Observations ``(batch, *obs_shape)`` or flat ``(batch, obs_dim)``, of any dtype, as the trunk's float
        input: a cnn's images scaled to [0, 1] (here, not before: frames travel as uint8) and encoded."""
        if x.dim() == 1:
            x = x.unsqueeze(0)
        x = x.flatten(1)  # (0 rows keep their width: reshape(0, -1) cannot tell it)
        if x.shape[1] != self.obs_dim:
            raise ValueError(f"observations have {x.shape[1]} features per row; this network takes {self.obs_dim}")
        if self.encoder is None:
            return x if x.dtype == torch.float32 else x.float()
        z = x.reshape(x.shape[0], *self.obs_shape).float().mul_(1.0 / 255.0)
        if self.arch.layout == "hwc":
            z = z.permute(0, 3, 1, 2)
        for conv in self._convs:
            z = torch.relu_(conv(z))
        return z.flatten(1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        x = self._inputs(x)
        # Layers without nn.Module call overhead (it dominates small batches), each activation in place on its layer's
        # output (autograd saves tanh's and relu's output, not their input, so this is the same computation with one
        # activation-sized tensor less per layer to allocate and fill).
        z = self._features(x)
        head = self.action_head
        out = F.linear(z, head.weight, head.bias)
        if self.state_value is not None:
            out = F.linear(z, self.state_value.weight, self.state_value.bias) + out - out.mean(dim=1, keepdim=True)
        value = None
        if self.value_head is not None:
            value = F.linear(z, self.value_head.weight, self.value_head.bias).squeeze(-1)
        return out, value

    def _features(self, x: torch.Tensor) -> torch.Tensor:
        z = x
        for layer in self._linears:
            z = self._activation(F.linear(z, layer.weight, layer.bias))
        return z

    def gaussian(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A squashed arch's Gaussian before the tanh: ``(mean, log_std)``, both ``(batch, outputs)``, the log-std
        state-dependent (:func:`~selfplay_cli.policies.heads.squashed_log_std` of its head's output)."""
        if self.log_std_head is None:
            raise ValueError("gaussian() is for a squashed arch (SAC's actor)")
        z = self._features(self._inputs(x))
        mean = F.linear(z, self.action_head.weight, self.action_head.bias)
        return mean, squashed_log_std(F.linear(z, self.log_std_head.weight, self.log_std_head.bias))


def _conv(cin: int, out: int, k: int, stride: int, gain: float, generator: torch.Generator | None) -> nn.Conv2d:
    """A Conv2d layer (no padding) with the same init as :func:`_layer`: orthogonal weights, zero bias."""
    with torch.random.fork_rng(devices=[]):
        layer = nn.Conv2d(cin, out, k, stride)
    with torch.no_grad():
        nn.init.orthogonal_(layer.weight, gain, generator=generator)
        layer.bias.zero_()
    return layer


def _space_of(head: ActionHead) -> spaces.Space:
    if head.kind == "discrete":
        return spaces.Discrete(head.nvec[0])
    if head.kind == "multidiscrete":
        return spaces.MultiDiscrete(np.array(head.nvec, dtype=np.int64))
    return spaces.Box(np.array(head.low, np.float32).reshape(head.shape),
                      np.array(head.high, np.float32).reshape(head.shape), dtype=np.float32)


def build_network(obs: tuple[int, ...] | spaces.Box, action: int | spaces.Space | ActionHead, arch: Arch,
                  seed: int | None = None) -> MLPNet:
    """A freshly initialised network for a seat's observations (a Box, or just its shape) and actions (a space, or
    an int ``n`` for ``Discrete(n)``); ``arch`` as :meth:`Arch.for_obs` makes it for the observation (an image seat
    gets a cnn; the network's ``arch`` is the resolved one, what a snapshot records).

    With ``seed`` the init is reproducible and the global torch RNG is left alone; without it the global RNG
    is used. The network is built on the CPU (move it with ``.to(device)``).
    """
    obs_space = obs if isinstance(obs, spaces.Box) else None
    raw = obs.shape if isinstance(obs, spaces.Box) else obs
    try:
        shape = tuple(int(d) for d in raw)
    except (TypeError, ValueError):
        raise SnapshotError(f"bad observation shape {raw!r}") from None
    if not shape or any(d < 1 for d in shape):
        raise SnapshotError(f"bad observation shape {raw!r}")
    if obs_space is None:
        obs_space = box_of_shape(shape)
    arch = arch.for_obs(obs_space)
    generator = torch.Generator().manual_seed(int(seed)) if seed is not None else None
    if isinstance(action, (int, np.integer)) and not isinstance(action, bool):
        action = int(action)
    return MLPNet(math.prod(shape), action, arch, generator=generator, obs_space=obs_space)


def resolve_device(name: str | torch.device = "cpu") -> torch.device:
    """``cpu``, ``cuda`` (or ``cuda:N``) or ``auto`` (cuda if available, else cpu) as a ``torch.device``."""
    if isinstance(name, torch.device):
        name = str(name)
    key = str(name).strip().lower()
    if key == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if key == "cpu":
        return torch.device("cpu")
    if key == "cuda" or (key.startswith("cuda:") and key[5:].isdigit()):
        if not torch.cuda.is_available():
            raise SnapshotError(f"cuda requested but not available (device {name!r}); use --device cpu or auto")
        index = int(key[5:]) if ":" in key else 0
        if index >= torch.cuda.device_count():
            raise SnapshotError(f"cuda device {index} requested but only {torch.cuda.device_count()} available")
        return torch.device(key)
    raise SnapshotError(f"unknown device {name!r}; use cpu, cuda, cuda:N or auto")


class NetworkPolicy(Policy):
    """A network playing one seat: greedy (the best action: argmax of the logits or Q-values, a Gaussian's mean
    clipped to the bounds) or sampling from its distribution (softmax of the logits, per dimension for
    MultiDiscrete; ``clip(mean + std * eps)`` for Box actions). A squashed arch (SAC's actor) plays ``tanh(mean)``
    greedily and ``tanh(mean + std(s) * eps)`` sampling, mapped onto the Box bounds. Masked actions are never chosen.

    ``act`` runs under ``torch.inference_mode`` and converts observations with ``torch.from_numpy`` (a copy is
    made only when the array is not already a writable array of the observation's dtype: float32, or an image's
    uint8, which the network scales itself). Sampling uses the policy's own
    ``torch.Generator`` seeded with ``seed``, so a seeded policy replays the same actions for the same
    observations. For large batches on the CPU, callers may tune ``torch.set_num_threads``; nothing global
    is set here. ``meta`` is the :class:`~selfplay_cli.policies.snapshot_format.SnapshotMeta` it was loaded from,
    if any; ``obs_space`` and ``act_space`` are the network's.
    """

    kind = "snapshot"

    def __init__(
        self,
        net: MLPNet,
        id: str,
        env: str,
        device: str | torch.device = "cpu",
        greedy: bool = True,
        seed: int = 0,
        meta: Any = None,
    ) -> None:
        super().__init__(id, env, obs_space=net.obs_space, act_space=net.act_space)
        self.device = resolve_device(device)
        self.net = net.to(self.device).eval()
        self.head = net.head
        self.greedy = bool(greedy)
        self.meta = meta
        self.obs_dtype = np.dtype(net.obs_space.dtype)  # what act() hands the network: uint8 frames stay uint8
        self.generator = torch.Generator(device=self.device)
        self._math: HeadMath | None = None
        self.reseed(seed)

    @property
    def n_actions(self) -> int:
        return self.net.n_actions

    def reseed(self, seed: int) -> None:
        """Restart the sampling generator (only used when ``greedy`` is false)."""
        self.seed = int(seed)
        self.generator.manual_seed(self.seed)

    def _tensor(self, array: np.ndarray, dtype: np.dtype) -> torch.Tensor:
        a = np.asarray(array, dtype=dtype)
        if not (a.flags.writeable and a.flags.c_contiguous):
            a = np.array(a, dtype=dtype, order="C")  # from_numpy warns on read-only arrays
        t = torch.from_numpy(a)
        return t if self.device.type == "cpu" else t.to(self.device, non_blocking=True)

    def _mask(self, mask: np.ndarray | None, rows: int) -> torch.Tensor | None:
        m = self.head.check_mask(mask, rows)
        if m is None:
            return None
        if self.head.kind == "discrete":
            if not bool(m.any(axis=1).all()):
                raise ValueError("the action mask allows no action in some rows")
        else:
            index, valid = self.math.index.cpu().numpy(), self.math.valid.cpu().numpy()
            if not bool((m[:, index] & valid).any(axis=2).all()):
                raise ValueError("the action mask allows no action in some rows")
        return self._tensor(m, np.bool_)

    @property
    def math(self) -> HeadMath:
        if self._math is None:
            self._math = HeadMath(self.head, self.device)
        return self._math

    @torch.inference_mode()
    def action_scores(self, obs: np.ndarray, mask: np.ndarray | None = None) -> torch.Tensor:
        """The action head's ``(batch, outputs)`` output, with disallowed actions set to ``-inf`` (Discrete and
        MultiDiscrete heads; a Box head's outputs are its means)."""
        scores, _ = self.net(self._tensor(obs, self.obs_dtype))
        m = self._mask(mask, scores.shape[0])
        if m is not None:
            scores = scores.masked_fill(~m, float("-inf"))
        return scores

    @torch.inference_mode()
    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        if self.net.squash:  # SAC's actor: tanh(mean) or tanh(mean + std * eps), on the bounds
            mean, log_std = self.net.gaussian(self._tensor(obs, self.obs_dtype))
            self._mask(mask, mean.shape[0])  # a Box head takes no mask: refused as for any Box head
            return to_numpy_actions(self.head, self.math.sample_squashed(mean, log_std, self.generator, self.greedy))
        if self.head.kind != "discrete":
            out, _ = self.net(self._tensor(obs, self.obs_dtype))
            _, played = self.math.sample(out, self._mask(mask, out.shape[0]), self.generator, self.greedy,
                                         log_std=self.net.log_std)
            return to_numpy_actions(self.head, played)
        scores = self.action_scores(obs, mask)
        if self.greedy:
            actions = scores.argmax(dim=1)
        else:
            probs = torch.softmax(scores, dim=1)
            actions = torch.multinomial(probs, 1, generator=self.generator).squeeze(1)
        return actions.to("cpu").numpy().astype(np.int64, copy=False)
