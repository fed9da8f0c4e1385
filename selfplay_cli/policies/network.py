"""Neural policies: the network architecture record, the MLP itself and the policy that plays with it.

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
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from torch import nn
from torch.nn import functional as F

from ..errors import MarlError
from .base import Policy
from .heads import HeadMath, squashed_log_std, to_numpy_actions
from .spaces import ActionHead, SpaceError, box_of_shape

KINDS = ("mlp",)
ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}
ACTIVATION_FNS = {"tanh": torch.tanh_, "relu": torch.relu_}  # in place, on each layer's fresh output


class SnapshotError(MarlError):
    """A snapshot file (or the network it describes) that cannot be saved, read or played.

    Messages about a file always start with the file's path. Defined here, the lowest of the modules that raise it
    (a network's arch; the snapshot format, reader and policy building).
    """


@dataclass(frozen=True)
class Arch:
    """The shape of a policy network: everything needed (with the env's spaces) to rebuild it from weights.

    ``kind`` is ``mlp`` (the only kind so far); ``hidden`` the widths of the trunk's layers; ``activation``
    ``tanh`` or ``relu``; ``value_head`` adds a state-value output (PPO's critic); ``dueling`` makes the action
    head a dueling Q head (``V(s) + A(s, a) - mean_a A(s, a)``, for DQN); ``squash`` makes a Box action head a
    tanh-squashed Gaussian with a state-dependent std (SAC's actor: a second head gives the log-std). Invalid values
    raise :class:`SnapshotError` (a user-facing error). ``squash`` is written out only when true, so every network
    without it (PPO's, DQN's) is described exactly as before it existed.
    """

    kind: str = "mlp"
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    value_head: bool = True
    dueling: bool = False
    squash: bool = False

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise SnapshotError(f"unknown network kind {self.kind!r}; known: {', '.join(KINDS)}")
        if self.activation not in ACTIVATIONS:
            raise SnapshotError(f"unknown activation {self.activation!r}; known: {', '.join(ACTIVATIONS)}")
        try:
            hidden = tuple(self.hidden)
        except TypeError:
            raise SnapshotError(f"hidden layer sizes must be a list of integers, not {self.hidden!r}") from None
        if not all(isinstance(h, (int, np.integer)) and not isinstance(h, bool) and h > 0 for h in hidden):
            raise SnapshotError(f"hidden layer sizes must be positive integers, not {list(hidden)!r}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in hidden))
        for name in ("value_head", "dueling", "squash"):
            if not isinstance(getattr(self, name), bool):
                raise SnapshotError(f"arch field {name!r} must be true or false, not {getattr(self, name)!r}")

    def to_dict(self) -> dict[str, Any]:
        d = {
            "kind": self.kind,
            "hidden": list(self.hidden),
            "activation": self.activation,
            "value_head": self.value_head,
            "dueling": self.dueling,
        }
        if self.squash:
            d["squash"] = True
        return d

    @classmethod
    def from_dict(cls, data: Any) -> Arch:
        """Inverse of :meth:`to_dict`; missing fields take their defaults, unknown fields are refused."""
        if not isinstance(data, dict):
            raise SnapshotError(f"network arch must be an object, not {type(data).__name__}")
        known = {"kind", "hidden", "activation", "value_head", "dueling", "squash"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise SnapshotError(f"unknown network arch field(s) {', '.join(map(str, unknown))}")
        return cls(**data)

    def describe(self) -> str:
        """Short human form, e.g. ``mlp 64x64 tanh +value``."""
        parts = [self.kind, "x".join(map(str, self.hidden)) or "linear", self.activation]
        if self.value_head:
            parts.append("+value")
        if self.dueling:
            parts.append("dueling")
        if self.squash:
            parts.append("tanh-gaussian")
        return " ".join(parts)


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
    """Flattened observation -> trunk (Linear + activation per hidden width) -> heads.

    ``forward(x)`` takes ``(batch, *obs_shape)`` (or already flat ``(batch, obs_dim)``) and returns
    ``(action_out, value)``: ``action_out`` is ``(batch, head.outputs)``: logits (PPO; per dimension, side by side,
    for MultiDiscrete), Q-values (DQN) or Gaussian means (Box); ``value`` is ``(batch,)`` or ``None`` without a
    value head. ``obs_space`` and ``act_space`` are the seat's spaces (gymnasium).

    Parameter names (the snapshot's tensor names): ``trunk.{2i}.weight/bias``, ``action_head.*``, ``log_std``
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
        hidden_gain = math.sqrt(2.0)
        layers: list[nn.Module] = []
        width = self.obs_dim
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

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        if x.dim() == 1:
            x = x.unsqueeze(0)
        x = x.reshape(x.shape[0], -1)
        if x.shape[1] != self.obs_dim:
            raise ValueError(f"observations have {x.shape[1]} features per row; this network takes {self.obs_dim}")
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
        if x.dim() == 1:
            x = x.unsqueeze(0)
        x = x.reshape(x.shape[0], -1)
        if x.shape[1] != self.obs_dim:
            raise ValueError(f"observations have {x.shape[1]} features per row; this network takes {self.obs_dim}")
        z = self._features(x)
        mean = F.linear(z, self.action_head.weight, self.action_head.bias)
        return mean, squashed_log_std(F.linear(z, self.log_std_head.weight, self.log_std_head.bias))


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
    an int ``n`` for ``Discrete(n)``).

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
    made only when the array is not already a writable float32 array). Sampling uses the policy's own
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
        scores, _ = self.net(self._tensor(obs, np.float32))
        m = self._mask(mask, scores.shape[0])
        if m is not None:
            scores = scores.masked_fill(~m, float("-inf"))
        return scores

    @torch.inference_mode()
    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        if self.net.squash:  # SAC's actor: tanh(mean) or tanh(mean + std * eps), on the bounds
            mean, log_std = self.net.gaussian(self._tensor(obs, np.float32))
            self._mask(mask, mean.shape[0])  # a Box head takes no mask: refused as for any Box head
            return to_numpy_actions(self.head, self.math.sample_squashed(mean, log_std, self.generator, self.greedy))
        if self.head.kind != "discrete":
            out, _ = self.net(self._tensor(obs, np.float32))
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
