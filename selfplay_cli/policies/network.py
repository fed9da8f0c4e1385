"""Neural policies: the network architecture record, the MLP itself and the policy that plays with it.

The MLP serves both learners: its action head gives PPO's logits or DQN's Q-values (same shape), and an
optional value head gives PPO's critic. Everything here is plain torch; nothing is set globally (threads,
seeds, default dtype): callers that care about throughput may call ``torch.set_num_threads`` themselves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ..errors import MarlError
from .base import Policy

KINDS = ("mlp",)
ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}
ACTIVATION_FNS = {"tanh": torch.tanh_, "relu": torch.relu_}  # in place, on each layer's fresh output


class SnapshotError(MarlError):
    """A snapshot file (or the network it describes) that cannot be saved, read or played.

    Messages about a file always start with the file's path. Defined here (the lowest module of the two)
    and re-exported by :mod:`selfplay_cli.policies.snapshot`, which is where callers should import it from.
    """

    __module__ = "selfplay_cli.policies.snapshot"


@dataclass(frozen=True)
class Arch:
    """The shape of a policy network: everything needed (with the env's spaces) to rebuild it from weights.

    ``kind`` is ``mlp`` (the only kind so far); ``hidden`` the widths of the trunk's layers; ``activation``
    ``tanh`` or ``relu``; ``value_head`` adds a state-value output (PPO's critic); ``dueling`` makes the action
    head a dueling Q head (``V(s) + A(s, a) - mean_a A(s, a)``, for DQN). Invalid values raise
    :class:`SnapshotError` (a user-facing error).
    """

    kind: str = "mlp"
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    value_head: bool = True
    dueling: bool = False

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
        for name in ("value_head", "dueling"):
            if not isinstance(getattr(self, name), bool):
                raise SnapshotError(f"arch field {name!r} must be true or false, not {getattr(self, name)!r}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "hidden": list(self.hidden),
            "activation": self.activation,
            "value_head": self.value_head,
            "dueling": self.dueling,
        }

    @classmethod
    def from_dict(cls, data: Any) -> Arch:
        """Inverse of :meth:`to_dict`; missing fields take their defaults, unknown fields are refused."""
        if not isinstance(data, dict):
            raise SnapshotError(f"network arch must be an object, not {type(data).__name__}")
        known = {"kind", "hidden", "activation", "value_head", "dueling"}
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
    ``(action_out, value)``: ``action_out`` is ``(batch, n_actions)`` logits (PPO) or Q-values (DQN);
    ``value`` is ``(batch,)`` or ``None`` without a value head.

    Parameter names (the snapshot's tensor names): ``trunk.{2i}.weight/bias``, ``action_head.*``,
    ``value_head.*`` and, for a dueling arch, ``state_value.*``.
    """

    def __init__(self, obs_dim: int, n_actions: int, arch: Arch, generator: torch.Generator | None = None) -> None:
        super().__init__()
        if int(obs_dim) < 1 or int(n_actions) < 1:
            raise SnapshotError(f"a network needs obs_dim >= 1 and n_actions >= 1, got {obs_dim} and {n_actions}")
        self.obs_dim = int(obs_dim)
        self.n_actions = int(n_actions)
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
        self.value_head = _layer(width, 1, 1.0, generator) if arch.value_head else None
        self.state_value = _layer(width, 1, 1.0, generator) if arch.dueling else None

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        if x.dim() == 1:
            x = x.unsqueeze(0)
        x = x.reshape(x.shape[0], -1)
        if x.shape[1] != self.obs_dim:
            raise ValueError(f"observations have {x.shape[1]} features per row; this network takes {self.obs_dim}")
        # Layers without nn.Module call overhead (it dominates small batches), each activation in place on its layer's
        # output (autograd saves tanh's and relu's output, not their input, so this is the same computation with one
        # activation-sized tensor less per layer to allocate and fill).
        z = x
        for layer in self._linears:
            z = self._activation(F.linear(z, layer.weight, layer.bias))
        head = self.action_head
        out = F.linear(z, head.weight, head.bias)
        if self.state_value is not None:
            out = F.linear(z, self.state_value.weight, self.state_value.bias) + out - out.mean(dim=1, keepdim=True)
        value = None
        if self.value_head is not None:
            value = F.linear(z, self.value_head.weight, self.value_head.bias).squeeze(-1)
        return out, value


def build_network(obs_shape: tuple[int, ...], n_actions: int, arch: Arch, seed: int | None = None) -> MLPNet:
    """A freshly initialised network for an env's observation shape and action count.

    With ``seed`` the init is reproducible and the global torch RNG is left alone; without it the global RNG
    is used. The network is built on the CPU (move it with ``.to(device)``).
    """
    shape = tuple(int(d) for d in obs_shape)
    if not shape or any(d < 1 for d in shape):
        raise SnapshotError(f"bad observation shape {obs_shape!r}")
    generator = torch.Generator().manual_seed(int(seed)) if seed is not None else None
    return MLPNet(math.prod(shape), int(n_actions), arch, generator=generator)


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
    """A network playing one seat: greedy (argmax of the action head) or sampling from ``softmax(logits)``.

    ``act`` runs under ``torch.inference_mode`` and converts observations with ``torch.from_numpy`` (a copy is
    made only when the array is not already a writable float32 array). Sampling uses the policy's own
    ``torch.Generator`` seeded with ``seed``, so a seeded policy replays the same actions for the same
    observations. For large batches on the CPU, callers may tune ``torch.set_num_threads``; nothing global
    is set here. ``meta`` is the :class:`~selfplay_cli.policies.snapshot.SnapshotMeta` it was loaded from,
    if any.
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
        super().__init__(id, env)
        self.device = resolve_device(device)
        self.net = net.to(self.device).eval()
        self.greedy = bool(greedy)
        self.meta = meta
        self.generator = torch.Generator(device=self.device)
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

    @torch.inference_mode()
    def action_scores(self, obs: np.ndarray, mask: np.ndarray | None = None) -> torch.Tensor:
        """The action head's ``(batch, n_actions)`` output, with disallowed actions set to ``-inf``."""
        scores, _ = self.net(self._tensor(obs, np.float32))
        if mask is not None:
            m = self._tensor(mask, np.bool_)
            if m.shape != scores.shape:
                raise ValueError(f"mask has shape {tuple(m.shape)}; expected {tuple(scores.shape)}")
            if not bool(m.any(dim=1).all()):
                raise ValueError("the action mask allows no action in some rows")
            scores = scores.masked_fill(~m, float("-inf"))
        return scores

    @torch.inference_mode()
    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        scores = self.action_scores(obs, mask)
        if self.greedy:
            actions = scores.argmax(dim=1)
        else:
            probs = torch.softmax(scores, dim=1)
            actions = torch.multinomial(probs, 1, generator=self.generator).squeeze(1)
        return actions.to("cpu").numpy().astype(np.int64, copy=False)
