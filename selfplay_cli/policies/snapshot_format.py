"""The snapshot file's format: what a ``*.safetensors`` snapshot holds, how it is checksummed and written, and the
limits every file marl writes or reads keeps.

A snapshot is a policy's weights plus everything needed to rebuild and identify it, in one file. Its header's
``__metadata__`` (a str -> str map) holds ``format = "marl-snapshot"``, ``format_version = "2"`` and ``marl``: the
JSON of :class:`SnapshotMeta` (env and its options, the seat's observation and action spaces, network arch,
algorithm, training counters, lineage). The weights are checksummed (:func:`weights_sha256`) on save and verified on
every load.

Format versions: 2 records the spaces (``obs_space``, ``act_space``: JSON of
:func:`~selfplay_cli.policies.spaces.space_to_dict`); 1 (files written before) recorded ``obs_shape`` and
``n_actions``, and still loads, as an unbounded float32 Box and ``Discrete(n_actions)``.

The rules a file's content must keep (its tensors exactly those of the network its metadata describes, within
:data:`LIMITS`, finite; a joint record that agrees with the action head) are here, checked by :func:`save_snapshot`
before a file is written and by :mod:`~selfplay_cli.policies.snapshot_reader` before one is built from. Every
problem is a :class:`~selfplay_cli.policies.network.SnapshotError` whose message starts with the path.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import struct
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import spaces

from .. import files
from ..envs.obs_spaces import stacked_space
from ..typecheck import MAX_INT
from .arch import MAX_FRAME_STACK, Arch, SnapshotError, SnapshotWriteError, conv_shapes
from .joint import MAX_JOINT_ACTIONS
from .spaces import ActionHead, SpaceError, canonical_space, space_from_dict

if TYPE_CHECKING:
    import torch

FORMAT = "marl-snapshot"
FORMAT_VERSION = 2
SUFFIX = ".safetensors"

# Limits of what marl reads (and writes): far above any network it trains (--preset seed000's 512-512-256-128-64 MLP has
# ~0.5 M parameters; an MLP over pong's RGB frames with 64 units ~61 M), far below what would hurt a machine.
MAX_HEADER = 4 * 1024 * 1024  # bytes of JSON header (marl's are a few kilobytes)
MAX_LAYERS = 64  # hidden layers
MAX_WIDTH = 65_536  # units in a hidden layer
MAX_OBS_DIMS = 8  # axes of an observation
MAX_OBS_SIZE = 1 << 24  # numbers in an observation
MAX_ACTIONS = 65_536  # outputs of an action head (actions of a Discrete space, sum(nvec), a Box's numbers)
MAX_PARAMS = 100_000_000  # parameters of a network (400 MB of float32)
MAX_FILE_BYTES = 8 + MAX_HEADER + 4 * MAX_PARAMS
# A Gaussian head's log_std (a Box head without squash) lies within +-MAX_LOG_STD: beyond it exp(log_std) leaves
# float32's normal range, and sampling (mean + std * eps) or a log-probability ((a - mean) / std) overflows. (A
# squashed head's log-std is bounded by construction: heads.LOG_STD_MIN to LOG_STD_MAX from finite weights.)
MAX_LOG_STD = 80.0
LIMITS = {"header_bytes": MAX_HEADER, "hidden_layers": MAX_LAYERS, "layer_width": MAX_WIDTH,
          "observation_axes": MAX_OBS_DIMS, "observation_size": MAX_OBS_SIZE, "actions": MAX_ACTIONS,
          "parameters": MAX_PARAMS, "file_bytes": MAX_FILE_BYTES, "log_std": MAX_LOG_STD}

def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def check_obs_shape(shape: tuple[int, ...]) -> None:
    if not 1 <= len(shape) <= MAX_OBS_DIMS or any(not 1 <= d <= MAX_OBS_SIZE for d in shape):
        raise SnapshotError(f"observation shape {list(shape)[:MAX_OBS_DIMS + 1]} is out of bounds (1 to "
                            f"{MAX_OBS_DIMS} sizes of 1 to {MAX_OBS_SIZE:,})")
    if math.prod(shape) > MAX_OBS_SIZE:
        raise SnapshotError(f"observations of {math.prod(shape):,} numbers are more than marl plays "
                            f"({MAX_OBS_SIZE:,})")


@dataclass(frozen=True, kw_only=True)
class SnapshotMeta:
    """What a snapshot is: the game it plays, the seat's spaces, the network's shape and where it came from.

    Keyword-only. ``obs_space`` and ``act_space`` are the seat's observation Box and action space (gymnasium spaces
    or their JSON; kept as the canonical JSON); code written before spaces were recorded may give ``obs_shape`` and
    ``n_actions`` instead (an unbounded float32 Box, ``Discrete(n_actions)``). Either way both are filled in:
    ``obs_shape`` is the observation's shape, ``n_actions`` the action count of a Discrete space (None for other
    action spaces). ``parent`` is the snapshot it was trained from (``"run/ep80"``); ``seat`` names the seat
    of a per-seat learner (``"left"``), ``None`` when one network plays every seat; ``role`` the role of the seats
    it learned in a game whose seats hold several (``"adversary"``; see :func:`snapshot_roles`), else None;
    ``created`` is ISO UTC; ``frame_stack`` how many of its seat's last observations it reads at once (its
    observation space is then the stacked one: :func:`~selfplay_cli.play.frames.stacked_space`; written only when
    more than 1);
    ``weights_sha256`` is filled by :func:`save_snapshot`; ``extra`` is free-form JSON (hyperparameters...).
    ``env_options`` and ``extra`` go through JSON, so tuples in them come back as lists.
    """

    env: str
    env_options: dict[str, Any] = field(default_factory=dict)
    obs_space: Any = None
    act_space: Any = None
    arch: Arch = field(default_factory=Arch)
    algo: str = ""
    step: int = 0
    episode: int = 0
    run: str | None = None
    name: str
    parent: str | None = None
    created: str = field(default_factory=utc_now)
    seat: str | None = None
    role: str | None = None
    weights_sha256: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    frame_stack: int = 1
    obs_shape: tuple[int, ...] | None = None
    n_actions: int | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.obs_space is None:
            if self.obs_shape is None:
                raise ValueError("a snapshot needs its observation space (obs_space, or obs_shape)")
            shape = tuple(int(d) for d in self.obs_shape)
            check_obs_shape(shape)
            set_(self, "obs_space", {"kind": "box", "shape": list(shape), "dtype": "float32", "low": None,
                                     "high": None})
        if self.act_space is None:
            if self.n_actions is None:
                raise ValueError("a snapshot needs its action space (act_space, or n_actions)")
            set_(self, "act_space", {"kind": "discrete", "n": int(self.n_actions)})
        try:
            obs = canonical_space(self.obs_space, limit=MAX_OBS_SIZE)
            act = canonical_space(self.act_space, limit=MAX_ACTIONS)
        except SpaceError as e:
            raise ValueError(str(e)) from None
        if obs["kind"] != "box":
            raise ValueError(f"the observation space must be a Box, not {obs['kind']}")
        shape = tuple(obs["shape"])
        check_obs_shape(shape)
        n = act["n"] if act["kind"] == "discrete" else None
        if self.obs_shape is not None and tuple(int(d) for d in self.obs_shape) != shape:
            raise ValueError(f"obs_shape {list(self.obs_shape)} is not the observation space's {list(shape)}")
        if self.n_actions is not None and self.n_actions != n:
            raise ValueError(f"n_actions {self.n_actions} does not match the action space ({act['kind']})")
        set_(self, "obs_space", obs)
        set_(self, "act_space", act)
        set_(self, "obs_shape", shape)
        set_(self, "n_actions", n)
        set_(self, "env_options", dict(self.env_options or {}))
        set_(self, "extra", dict(self.extra or {}))
        if isinstance(self.arch, dict):
            set_(self, "arch", Arch.from_dict(self.arch))

    @property
    def id(self) -> str:
        """The player id: ``run/name``, or ``name`` for a run-less snapshot."""
        return f"{self.run}/{self.name}" if self.run else self.name

    @property
    def head(self) -> ActionHead:
        """The action head the snapshot's action space calls for."""
        return ActionHead.of(space_from_dict(self.act_space, limit=MAX_ACTIONS))

    def spaces(self) -> tuple[spaces.Box, spaces.Space]:
        """The observation Box and the action space, as gymnasium spaces."""
        return space_from_dict(self.obs_space, limit=MAX_OBS_SIZE), space_from_dict(self.act_space, limit=MAX_ACTIONS)

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        del d["obs_shape"], d["n_actions"]  # derived from the spaces
        if self.frame_stack == 1:
            del d["frame_stack"]
        d["arch"] = self.arch.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Any) -> SnapshotMeta:
        """Inverse of :meth:`to_dict`, and reads the metadata of version 1 files (``obs_shape`` and ``n_actions``
        instead of the spaces). Unknown keys are ignored (informational additions); missing required keys or
        wrongly typed values raise ``ValueError`` (or :class:`SnapshotError` for a bad arch)."""
        if not isinstance(data, dict):
            raise ValueError(f"metadata must be an object, not {type(data).__name__}")
        spaced = "obs_space" in data or "act_space" in data
        required = ("env", "obs_space", "act_space", "name") if spaced else ("env", "obs_shape", "n_actions", "name")
        missing = [k for k in required if k not in data]
        if missing:
            raise ValueError(f"missing field(s) {', '.join(missing)}")
        names = {f.name for f in dataclasses.fields(cls)}
        kw = {k: v for k, v in data.items() if k in names}
        if spaced:  # obs_shape and n_actions beside the spaces (not written since) must agree with them
            for key in ("obs_space", "act_space"):
                if not isinstance(kw[key], dict):
                    raise ValueError(f"field {key!r} must be an object")
        for key in ("env", "name", "algo", "created", "weights_sha256"):
            if key in kw and not isinstance(kw[key], str):
                raise ValueError(f"field {key!r} must be a string")
        for key in ("run", "parent", "seat", "role"):
            if kw.get(key) is not None and not isinstance(kw[key], str):
                raise ValueError(f"field {key!r} must be a string or null")
        for key in ("env_options", "extra"):
            if key in kw and not isinstance(kw[key], dict):
                raise ValueError(f"field {key!r} must be an object")
        if "frame_stack" in kw and not (is_int(kw["frame_stack"]) and 1 <= kw["frame_stack"] <= MAX_FRAME_STACK):
            raise ValueError(f"field 'frame_stack' must be a whole number from 1 to {MAX_FRAME_STACK}")
        for key in ("n_actions", "step", "episode"):
            if key in kw and (not isinstance(kw[key], int) or isinstance(kw[key], bool)):
                raise ValueError(f"field {key!r} must be an integer")
            if key in kw and not 0 <= kw[key] <= MAX_INT:  # what the league's integer columns hold
                raise ValueError(f"field {key!r} must lie between 0 and {MAX_INT:,}, not {kw[key]:,}")
        if "obs_shape" in kw:
            shape = kw["obs_shape"]
            if not isinstance(shape, list) or not all(isinstance(d, int) and not isinstance(d, bool) for d in shape):
                raise ValueError("field 'obs_shape' must be a list of integers")
            if len(shape) > MAX_OBS_DIMS:
                raise ValueError(f"observations of {len(shape):,} axes are more than marl plays ({MAX_OBS_DIMS})")
        if "n_actions" in kw and not 1 <= kw["n_actions"] <= MAX_ACTIONS:
            raise ValueError(f"{kw['n_actions']} actions is out of bounds (1 to {MAX_ACTIONS:,})")
        kw["arch"] = Arch.from_dict(kw.get("arch", {}))
        return cls(**kw)


# --------------------------------------------------------------------------------------------------------------
# Checksums


def weights_sha256(tensors: dict[str, torch.Tensor]) -> str:
    """sha256 over the tensors in sorted-name order: for each, a length-prefixed JSON ``[name, dtype, shape]``
    then the length-prefixed raw (little-endian, C-order) bytes."""
    import torch  # (here: reading a snapshot's metadata needs no torch)

    h = hashlib.sha256()
    for name in sorted(tensors):
        t = tensors[name].detach().to("cpu").contiguous()
        head = json.dumps([name, str(t.dtype).removeprefix("torch."), list(t.shape)], separators=(",", ":"))
        head_bytes = head.encode()
        data = t.reshape(-1).view(torch.uint8).numpy()
        h.update(struct.pack("<Q", len(head_bytes)))
        h.update(head_bytes)
        h.update(struct.pack("<Q", data.nbytes))
        h.update(data)
    return h.hexdigest()


def file_sha256(path: str | os.PathLike[str]) -> str:
    """sha256 of the whole file, streamed."""
    try:
        return files.file_sha256(path)
    except FileNotFoundError:
        raise SnapshotError(f"{path}: no such file") from None
    except OSError as e:
        raise SnapshotError(f"{path}: cannot read ({e.strerror or e})") from None

# --------------------------------------------------------------------------------------------------------------
# The tensors a network has, worked out from its description alone, and the rules a file's weights keep


def expected_tensors(obs_shape: tuple[int, ...], action: int | spaces.Space | ActionHead,
                     arch: Arch) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every tensor of the network ``arch`` describes for observations of ``obs_shape`` and the
    action space ``action`` (an int n: ``Discrete(n)``), as :class:`MLPNet` names them, computed without building
    anything, after checking the description against :data:`LIMITS` (:class:`SnapshotError`). A cnn's conv layers
    must fit the image they are given (a layer whose kernel is wider than what reaches it is refused)."""
    check_obs_shape(tuple(obs_shape))
    obs_dim = math.prod(obs_shape)
    if isinstance(action, (int, np.integer)) and not isinstance(action, bool) and not 1 <= action <= MAX_ACTIONS:
        raise SnapshotError(f"{action} actions is out of bounds (1 to {MAX_ACTIONS:,})")
    try:
        head = action if isinstance(action, ActionHead) else ActionHead.of(action)
    except SpaceError as e:
        raise SnapshotError(str(e)) from None
    if not 1 <= head.outputs <= MAX_ACTIONS:
        raise SnapshotError(f"an action head of {head.outputs:,} outputs is out of bounds (1 to {MAX_ACTIONS:,})")
    if arch.dueling and head.kind != "discrete":
        raise SnapshotError(f"a dueling head is for Discrete actions (Q-values), not {head.describe()}")
    if arch.squash and head.kind != "box":
        raise SnapshotError(f"a squashed Gaussian head is for Box actions, not {head.describe()}")
    if len(arch.hidden) > MAX_LAYERS:
        raise SnapshotError(f"{len(arch.hidden)} hidden layers is more than marl builds ({MAX_LAYERS})")
    if any(h > MAX_WIDTH for h in arch.hidden):
        raise SnapshotError(f"hidden layer sizes {list(arch.hidden)} exceed {MAX_WIDTH:,}")
    shapes: dict[str, tuple[int, ...]] = {}
    width = obs_dim
    if arch.kind == "cnn":  # the conv encoder: its weights from the image's shape, layer by layer
        weights, width = conv_shapes(tuple(obs_shape), arch)
        for i, w in enumerate(weights):
            shapes[f"encoder.{2 * i}.weight"], shapes[f"encoder.{2 * i}.bias"] = w, (w[0],)
    elif arch.layout:
        raise SnapshotError(f"an mlp network has no image layout ({arch.layout!r})")
    for i, h in enumerate(arch.hidden):
        shapes[f"trunk.{2 * i}.weight"], shapes[f"trunk.{2 * i}.bias"] = (h, width), (h,)
        width = h
    n = head.outputs
    shapes["action_head.weight"], shapes["action_head.bias"] = (n, width), (n,)
    if head.kind == "box" and not arch.squash:
        shapes["log_std"] = (n,)
    if arch.value_head:
        shapes["value_head.weight"], shapes["value_head.bias"] = (1, width), (1,)
    if arch.dueling:
        shapes["state_value.weight"], shapes["state_value.bias"] = (1, width), (1,)
    if arch.squash:  # SAC's actor: a state-dependent log-std head instead of the log_std parameter
        shapes["log_std_head.weight"], shapes["log_std_head.bias"] = (n, width), (n,)
    params = sum(math.prod(s) for s in shapes.values())
    if params > MAX_PARAMS:
        raise SnapshotError(f"a {arch.describe()} network has {params:,} parameters, more than marl loads "
                            f"({MAX_PARAMS:,})")
    return shapes


def fit_problems(found: dict[str, tuple[int, ...]], expected: dict[str, tuple[int, ...]]) -> list[str]:
    problems = []
    missing = sorted(set(expected) - set(found))
    unexpected = sorted(set(found) - set(expected))
    if missing:
        problems.append(f"missing {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}")
    if unexpected:
        shown = ", ".join(printable(n, 40) for n in unexpected[:4])
        problems.append(f"unexpected {shown}{' ...' if len(unexpected) > 4 else ''}")
    for k in sorted(set(expected) & set(found)):
        if tuple(found[k]) != tuple(expected[k]):
            problems.append(f"{k} is {list(found[k])}, expected {list(expected[k])}")
    return problems


def check_fits(path: Any, found: dict[str, tuple[int, ...]], meta: SnapshotMeta) -> None:
    """Refuse tensors (name -> shape) that are not exactly those of the network ``meta`` describes."""
    try:
        expected = expected_tensors(meta.obs_shape, meta.head, meta.arch)  # type: ignore[arg-type]
    except (SnapshotError, SpaceError) as e:
        raise SnapshotError(f"{path}: {e}") from None
    problems = fit_problems(found, expected)
    if problems:
        raise SnapshotError(f"{path}: weights do not fit the {meta.arch.describe()} network ({'; '.join(problems)})")


def check_values(path: Any, arrays: dict[str, np.ndarray]) -> None:
    """Refuse weights a network cannot play: a NaN or infinite number in any tensor, or a Gaussian head's
    ``log_std`` outside +-:data:`MAX_LOG_STD`. One min and one max per tensor (NaN propagates through both): nothing
    is allocated beside the weights themselves, whatever their size."""
    for name in sorted(arrays):
        a = arrays[name]
        if not a.size:
            continue
        lo, hi = float(a.min()), float(a.max())
        if not (math.isfinite(lo) and math.isfinite(hi)):
            kind = "NaN" if math.isnan(lo) or math.isnan(hi) else "inf" if hi == math.inf else "-inf"
            raise SnapshotError(f"{path}: weights are not finite ({printable(name, 40)} holds {kind})")
        if name == "log_std" and not -MAX_LOG_STD <= lo <= hi <= MAX_LOG_STD:
            raise SnapshotError(f"{path}: log_std holds {lo if lo < -MAX_LOG_STD else hi:g}, outside the "
                                f"{-MAX_LOG_STD:g} to {MAX_LOG_STD:g} a Gaussian head's log-std may take")


def printable(text: str, limit: int = 60) -> str:
    """``text`` safe to print on a terminal: control and format characters escaped, cut short."""
    cut = text[:limit]
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in cut)
    return out + ("..." if len(text) > limit else "")

def is_int(x: Any) -> bool:
    """An integer of the JSON a file holds (not a bool, which Python counts as one)."""
    return isinstance(x, int) and not isinstance(x, bool)


def joint_of(path: Any, meta: SnapshotMeta) -> tuple[int, int] | None:
    """``(seats, base)`` of a joint (SA) snapshot, None for any other; a malformed record is a SnapshotError, and so
    is one the action head contradicts: a joint agent plays Discrete(base ** seats), one digit of base a seat (with
    the game's check that the head is its seats' joint space, the base is then the game's seat action count)."""
    joint = (meta.extra or {}).get("joint")
    if joint is None:
        return None
    seats, base = (joint.get("seats"), joint.get("base")) if isinstance(joint, dict) else (None, None)
    if not (is_int(seats) and is_int(base) and 1 <= seats <= 64 and 2 <= base <= MAX_JOINT_ACTIONS):
        raise SnapshotError(f"{path}: bad joint record in the snapshot's metadata ({printable(str(joint), 80)})")
    head = meta.head
    if head.kind != "discrete" or head.nvec[0] != base ** seats:
        raise SnapshotError(f"{path}: bad joint record in the snapshot's metadata: {seats} seats of {base} actions "
                            f"make {base ** seats:,} joint actions, but its network plays {head.describe()}")
    return int(seats), int(base)

def snapshot_roles(meta: SnapshotMeta, spec: Any) -> frozenset[str] | None:
    """The roles of its game a snapshot may play (the seats of other roles read and act differently, or mean
    something else): the role it learned, as its metadata records it (``role``, or the role of its ``seat``); for a
    file that records neither (one written before roles were), every role whose seats have its spaces. None where
    that is every role of the game (it plays any seat), and for a joint agent (it flies its whole team)."""
    if (meta.extra or {}).get("joint") is not None:
        return None
    sized = spec.for_options(**meta.env_options)
    cfg = sized.config(**meta.env_options)
    roles = sized.seat_roles(cfg)
    if len(set(roles)) == 1:
        return None
    if meta.role in roles:
        return frozenset((meta.role,))
    if meta.seat in sized.agents:
        return frozenset((roles[sized.agents.index(meta.seat)],))
    fit = set()
    for role, seat in zip(roles, sized.seat_spaces(cfg), strict=True):
        with contextlib.suppress(SpaceError):
            seen = stacked_space(seat.observation, meta.frame_stack)
            if tuple(seen.shape) == tuple(meta.obs_shape or ()) and ActionHead.of(seat.action) == meta.head:
                fit.add(role)
    return None if fit == set(roles) else frozenset(fit)

# --------------------------------------------------------------------------------------------------------------
# Saving


def _state_dict(net_or_state_dict: torch.nn.Module | dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    import torch

    sd = net_or_state_dict.state_dict() if isinstance(net_or_state_dict, torch.nn.Module) else net_or_state_dict
    # Cloned: CPU, contiguous and never sharing storage (safetensors refuses shared tensors).
    return {str(k): v.detach().to("cpu").contiguous().clone() for k, v in sd.items()}


def save_snapshot(
    path: str | os.PathLike[str],
    net_or_state_dict: torch.nn.Module | dict[str, torch.Tensor],
    meta: SnapshotMeta,
) -> SnapshotMeta:
    """Write weights + ``meta`` to ``path`` atomically (temp file, fsync, rename); parent dirs are created.

    The weights must fit the network ``meta`` describes, in float32 and within :data:`LIMITS`, every one finite, and
    a joint record in ``meta`` must agree with the action head (checked, so a saved file always loads). Returns
    ``meta`` with ``weights_sha256`` filled in.
    """
    import torch
    from safetensors.torch import save as st_save

    path = Path(path)
    tensors = _state_dict(net_or_state_dict)
    odd = sorted(k for k, v in tensors.items() if v.dtype != torch.float32)
    if odd:
        raise SnapshotError(f"{path}: weights must be float32 ({', '.join(odd[:4])} are not)")
    check_fits(path, {k: tuple(v.shape) for k, v in tensors.items()}, meta)
    check_values(path, {k: v.numpy() for k, v in tensors.items()})
    joint_of(path, meta)
    meta = dataclasses.replace(meta, weights_sha256=weights_sha256(tensors))
    try:
        meta_json = json.dumps(meta.to_dict(), sort_keys=True)
    except (TypeError, ValueError) as e:
        raise SnapshotError(f"{path}: metadata is not JSON-serialisable ({e})") from None
    header = {"format": FORMAT, "format_version": str(FORMAT_VERSION), "marl": meta_json}
    data = st_save(tensors, metadata=header)
    if len(data) > MAX_FILE_BYTES or struct.unpack("<Q", data[:8])[0] > MAX_HEADER:
        raise SnapshotError(f"{path}: snapshot would be bigger than marl reads (metadata too large?)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        files.write_atomic(path, data)
    except OSError as e:
        raise SnapshotWriteError(f"{path}: cannot write ({e.strerror or e})") from None
    return meta
