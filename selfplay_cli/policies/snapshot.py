"""Snapshot files: a policy's weights plus everything needed to rebuild and identify it, in one file.

A snapshot is a ``*.safetensors`` file. Its header's ``__metadata__`` (a str -> str map) holds
``format = "marl-snapshot"``, ``format_version = "2"`` and ``marl``: the JSON of :class:`SnapshotMeta` (env and
its options, the seat's observation and action spaces, network arch, algorithm, training counters, lineage). The
weights are checksummed (:func:`weights_sha256`) on save and verified on every load.

Format versions: 2 records the spaces (``obs_space``, ``act_space``: JSON of
:func:`~selfplay_cli.policies.spaces.space_to_dict`); 1 (files written before) recorded ``obs_shape`` and
``n_actions``, and still loads, as an unbounded float32 Box and ``Discrete(n_actions)``.

Loading never unpickles anything: the header is parsed as JSON and the tensors are read from the validated byte
ranges it declares (no ``torch.load``). A file is a hostile input until proven otherwise (models contributed to a CI
gate are imported this way): its size, its header, the tensors it declares against the network its metadata
describes and :data:`LIMITS` are all checked before anything is built or allocated (:func:`read_snapshot`). Every
problem with a file is a :class:`SnapshotError` whose message starts with the path and prints no control
characters.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import re
import struct
import unicodedata
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from safetensors.torch import save as st_save

from .. import files
from ..envs import EnvError, UnknownEnvError, get_env, known_env
from ..errors import MarlError
from ..typecheck import MAX_INT
from .joint import MAX_JOINT_ACTIONS, JointPolicy, joint_spaces
from .network import Arch, NetworkPolicy, SnapshotError, build_network
from .spaces import ActionHead, SpaceError, canonical_space, space_from_dict

FORMAT = "marl-snapshot"
FORMAT_VERSION = 2
SUFFIX = ".safetensors"

# Limits of what marl reads (and writes): far above any network it trains (seed 000's 512-512-256-128-64 MLP has
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
_HEX64 = re.compile(r"[0-9a-f]{64}")

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "LIMITS",
    "Snapshot",
    "SnapshotError",
    "SnapshotMeta",
    "expected_tensors",
    "export_snapshot",
    "file_sha256",
    "import_check",
    "load_policy",
    "load_snapshot",
    "policy_of",
    "read_meta",
    "read_snapshot",
    "save_snapshot",
    "weights_sha256",
]


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _check_obs_shape(shape: tuple[int, ...]) -> None:
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
    ``created`` is ISO UTC;
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
    obs_shape: tuple[int, ...] | None = None
    n_actions: int | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.obs_space is None:
            if self.obs_shape is None:
                raise ValueError("a snapshot needs its observation space (obs_space, or obs_shape)")
            shape = tuple(int(d) for d in self.obs_shape)
            _check_obs_shape(shape)
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
        _check_obs_shape(shape)
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
# The tensors a network has, worked out from its description alone


def expected_tensors(obs_shape: tuple[int, ...], action: int | spaces.Space | ActionHead,
                     arch: Arch) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every tensor of the network ``arch`` describes for observations of ``obs_shape`` and the
    action space ``action`` (an int n: ``Discrete(n)``), as :class:`MLPNet` names them, computed without building
    anything, after checking the description against :data:`LIMITS` (:class:`SnapshotError`)."""
    _check_obs_shape(tuple(obs_shape))
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


def _fit_problems(found: dict[str, tuple[int, ...]], expected: dict[str, tuple[int, ...]]) -> list[str]:
    problems = []
    missing = sorted(set(expected) - set(found))
    unexpected = sorted(set(found) - set(expected))
    if missing:
        problems.append(f"missing {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}")
    if unexpected:
        shown = ", ".join(_printable(n, 40) for n in unexpected[:4])
        problems.append(f"unexpected {shown}{' ...' if len(unexpected) > 4 else ''}")
    for k in sorted(set(expected) & set(found)):
        if tuple(found[k]) != tuple(expected[k]):
            problems.append(f"{k} is {list(found[k])}, expected {list(expected[k])}")
    return problems


def _check_fits(path: Any, found: dict[str, tuple[int, ...]], meta: SnapshotMeta) -> None:
    """Refuse tensors (name -> shape) that are not exactly those of the network ``meta`` describes."""
    try:
        expected = expected_tensors(meta.obs_shape, meta.head, meta.arch)  # type: ignore[arg-type]
    except (SnapshotError, SpaceError) as e:
        raise SnapshotError(f"{path}: {e}") from None
    problems = _fit_problems(found, expected)
    if problems:
        raise SnapshotError(f"{path}: weights do not fit the {meta.arch.describe()} network ({'; '.join(problems)})")


def _check_values(path: Any, arrays: dict[str, np.ndarray]) -> None:
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
            raise SnapshotError(f"{path}: weights are not finite ({_printable(name, 40)} holds {kind})")
        if name == "log_std" and not -MAX_LOG_STD <= lo <= hi <= MAX_LOG_STD:
            raise SnapshotError(f"{path}: log_std holds {lo if lo < -MAX_LOG_STD else hi:g}, outside the "
                                f"{-MAX_LOG_STD:g} to {MAX_LOG_STD:g} a Gaussian head's log-std may take")


def _printable(text: str, limit: int = 60) -> str:
    """``text`` safe to print on a terminal: control and format characters escaped, cut short."""
    cut = text[:limit]
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in cut)
    return out + ("..." if len(text) > limit else "")


# --------------------------------------------------------------------------------------------------------------
# Saving


def _state_dict(net_or_state_dict: torch.nn.Module | dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
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
    path = Path(path)
    tensors = _state_dict(net_or_state_dict)
    odd = sorted(k for k, v in tensors.items() if v.dtype != torch.float32)
    if odd:
        raise SnapshotError(f"{path}: weights must be float32 ({', '.join(odd[:4])} are not)")
    _check_fits(path, {k: tuple(v.shape) for k, v in tensors.items()}, meta)
    _check_values(path, {k: v.numpy() for k, v in tensors.items()})
    _joint_of(path, meta)
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
        raise SnapshotError(f"{path}: cannot write ({e.strerror or e})") from None
    return meta


# --------------------------------------------------------------------------------------------------------------
# Reading. Everything about a file is checked before anything is built from it: its size, its header (bounded,
# plain JSON), the tensors it declares against the network its metadata describes (names, dtypes, shapes, byte
# ranges, limits), the game, and only then are the weights read, checksummed and loaded.


def _parse_header(path: Any, prefix: bytes, raw: bytes, size: int) -> tuple[dict[str, Any], int]:
    """The safetensors header from its 8-byte length ``prefix`` and its bytes; returns it with the data start."""
    (n,) = struct.unpack("<Q", prefix)
    try:
        header = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise SnapshotError(f"{path}: not a marl snapshot (bad header)") from None
    if not isinstance(header, dict):
        raise SnapshotError(f"{path}: not a marl snapshot (bad header)")
    spans = []
    for name, info in header.items():
        if name == "__metadata__":
            if not isinstance(info, dict) or not all(isinstance(v, str) for v in info.values()):
                raise SnapshotError(f"{path}: not a marl snapshot (bad header metadata)")
            continue
        shown = _printable(name, 40)
        if not isinstance(info, dict):
            raise SnapshotError(f"{path}: not a marl snapshot (bad header entry for {shown!r})")
        offsets, shape, dtype = info.get("data_offsets"), info.get("shape"), info.get("dtype")
        if not (isinstance(offsets, list) and len(offsets) == 2 and all(_is_int(o) and o >= 0 for o in offsets)
                and offsets[0] <= offsets[1]):
            raise SnapshotError(f"{path}: not a marl snapshot (bad header entry for {shown!r})")
        if not (isinstance(shape, list) and len(shape) <= 8 and all(_is_int(d) and 0 <= d < 2**40 for d in shape)):
            raise SnapshotError(f"{path}: not a marl snapshot (bad shape for {shown!r})")
        if not isinstance(dtype, str):
            raise SnapshotError(f"{path}: not a marl snapshot (bad dtype for {shown!r})")
        spans.append((offsets[0], offsets[1], name))
    end = 0
    for begin, stop, name in sorted(spans):
        if begin != end:
            raise SnapshotError(f"{path}: not a marl snapshot (tensor data of {_printable(name, 40)!r} "
                                f"{'overlaps another' if begin < end else 'leaves a gap'})")
        end = stop
    data_len = size - 8 - n
    if data_len < end:
        raise SnapshotError(f"{path}: truncated snapshot ({data_len} of {end} data bytes present)")
    if data_len > end:
        raise SnapshotError(f"{path}: unexpected data after the weights ({data_len - end} bytes; file corrupt?)")
    return header, 8 + n


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _open_checked(path: Any) -> tuple[Any, int]:
    p = Path(path)
    if not p.exists():
        raise SnapshotError(f"{path}: no such snapshot file")
    if not p.is_file():
        raise SnapshotError(f"{path}: not a file")
    try:
        f = open(p, "rb")  # noqa: SIM115 - closed by the callers
        size = os.fstat(f.fileno()).st_size
    except OSError as e:
        raise SnapshotError(f"{path}: cannot read ({e.strerror or e})") from None
    if size > MAX_FILE_BYTES:
        f.close()
        raise SnapshotError(f"{path}: {size:,} bytes is bigger than any snapshot marl reads ({MAX_FILE_BYTES:,})")
    return f, size


def _header_length(path: Any, f: Any, size: int) -> tuple[bytes, int]:
    prefix = f.read(8)
    if len(prefix) < 8:
        raise SnapshotError(f"{path}: not a marl snapshot (file too short: {size} bytes)")
    (n,) = struct.unpack("<Q", prefix)
    if n == 0 or n > size - 8:
        first = f.read(1)
        why = "header cut short: truncated?" if n and first == b"{" else "bad header"
        raise SnapshotError(f"{path}: not a marl snapshot ({why})")
    if n > MAX_HEADER:
        raise SnapshotError(f"{path}: not a marl snapshot (a {n:,}-byte header; marl's are a few kilobytes, at most "
                            f"{MAX_HEADER:,})")
    return prefix, n


def _read_header(path: Any) -> dict[str, Any]:
    """The safetensors header alone, checked for shape and for the file holding exactly the data it describes."""
    f, size = _open_checked(path)
    try:
        with f:
            prefix, n = _header_length(path, f, size)
            raw = f.read(n)
    except OSError as e:
        raise SnapshotError(f"{path}: cannot read ({e.strerror or e})") from None
    return _parse_header(path, prefix, raw, size)[0]


def _read_whole(path: Any) -> tuple[bytearray, dict[str, Any], int]:
    """The whole file (bounded by :data:`MAX_FILE_BYTES`), its checked header and where its data starts."""
    f, size = _open_checked(path)
    try:
        with f:
            prefix, n = _header_length(path, f, size)
            data = bytearray(size)
            data[:8] = prefix
            view = memoryview(data)
            got = 8
            while got < size:
                k = f.readinto(view[got:])
                if not k:
                    break
                got += k
    except OSError as e:
        raise SnapshotError(f"{path}: cannot read ({e.strerror or e})") from None
    if got != size:
        raise SnapshotError(f"{path}: the file changed while it was read")
    header, start = _parse_header(path, prefix, bytes(view[8:8 + n]), size)
    return data, header, start


def _has_controls(value: Any, depth: int = 0) -> bool:
    """True if a string anywhere in the JSON ``value`` (keys too) holds control or format characters."""
    if depth > 32:
        return True
    if isinstance(value, str):
        return any(unicodedata.category(c) in ("Cc", "Cf") for c in value)
    if isinstance(value, dict):
        return any(_has_controls(k, depth + 1) or _has_controls(v, depth + 1) for k, v in value.items())
    if isinstance(value, list):
        return any(_has_controls(v, depth + 1) for v in value)
    return False


class _NotFinite(Exception):
    """NaN, Infinity or a number too large for a float in a file's metadata JSON (which Python's json reads as
    floats, and marl's own JSON output could then not print)."""


def _no_constant(name: str) -> Any:
    raise _NotFinite(name)


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise _NotFinite(text)
    return x


def _meta_of(path: Any, header: dict[str, Any]) -> SnapshotMeta:
    md = header.get("__metadata__")
    if not isinstance(md, dict) or "format" not in md:
        raise SnapshotError(f"{path}: not a marl snapshot (a safetensors file without marl metadata)")
    if md.get("format") != FORMAT:
        raise SnapshotError(f"{path}: not a marl snapshot (format {_printable(str(md.get('format')))!r}, "
                            f"expected {FORMAT!r})")
    try:
        version = int(md.get("format_version", ""))
    except (TypeError, ValueError):
        raise SnapshotError(f"{path}: not a marl snapshot (bad format version "
                            f"{_printable(str(md.get('format_version')))!r})") from None
    if version > FORMAT_VERSION:
        raise SnapshotError(
            f"{path}: snapshot format version {version} is newer than this marl reads ({FORMAT_VERSION}); "
            "upgrade marl"
        )
    if version < 1:
        raise SnapshotError(f"{path}: not a marl snapshot (bad format version {version})")
    raw = md.get("marl")
    if not isinstance(raw, str):
        raise SnapshotError(f"{path}: not a marl snapshot (no 'marl' metadata)")
    try:
        data = json.loads(raw, parse_constant=_no_constant, parse_float=_finite_float)
    except _NotFinite:
        raise SnapshotError(f"{path}: bad snapshot metadata (a number that is not finite)") from None
    except (ValueError, RecursionError):
        raise SnapshotError(f"{path}: bad snapshot metadata (not JSON)") from None
    if _has_controls(data):
        raise SnapshotError(f"{path}: bad snapshot metadata (control characters in its text)")
    if version >= 2 and isinstance(data, dict) and not {"obs_space", "act_space"} <= set(data):
        raise SnapshotError(f"{path}: bad snapshot metadata (a version {version} file without obs_space and "
                            "act_space)")
    try:
        meta = SnapshotMeta.from_dict(data)
    except (ValueError, TypeError, SnapshotError, SpaceError) as e:
        raise SnapshotError(f"{path}: bad snapshot metadata ({_printable(str(e), 200)})") from None
    if meta.weights_sha256 and not _HEX64.fullmatch(meta.weights_sha256):
        raise SnapshotError(f"{path}: bad snapshot metadata (weights_sha256 is not a sha256)")
    return meta


def read_meta(path: str | os.PathLike[str]) -> SnapshotMeta:
    """The snapshot's metadata from its header only (cheap: the weights are neither read nor verified)."""
    return _meta_of(path, _read_header(path))


def _check_layout(path: Any, header: dict[str, Any], meta: SnapshotMeta) -> None:
    """The tensors the header declares must be exactly those of the network ``meta`` describes: names, float32,
    shapes and byte sizes, within :data:`LIMITS`. Nothing is allocated: a file describing a giant network is
    refused here, from its few kilobytes of header."""
    declared = {k: v for k, v in header.items() if k != "__metadata__"}
    _check_fits(path, {k: tuple(v["shape"]) for k, v in declared.items()}, meta)
    for name, info in declared.items():
        if info["dtype"] != "F32":
            raise SnapshotError(f"{path}: {name} is {_printable(info['dtype'], 10)}, snapshots hold float32 (F32)")
        begin, end = info["data_offsets"]
        if end - begin != 4 * math.prod(info["shape"]):
            raise SnapshotError(f"{path}: {name} declares {list(info['shape'])} but holds {end - begin} bytes")


def _joint_of(path: Any, meta: SnapshotMeta) -> tuple[int, int] | None:
    """``(seats, base)`` of a joint (SA) snapshot, None for any other; a malformed record is a SnapshotError, and so
    is one the action head contradicts: a joint agent plays Discrete(base ** seats), one digit of base a seat (with
    the game's check that the head is its seats' joint space, the base is then the game's seat action count)."""
    joint = (meta.extra or {}).get("joint")
    if joint is None:
        return None
    seats, base = (joint.get("seats"), joint.get("base")) if isinstance(joint, dict) else (None, None)
    if not (_is_int(seats) and _is_int(base) and 1 <= seats <= 64 and 2 <= base <= MAX_JOINT_ACTIONS):
        raise SnapshotError(f"{path}: bad joint record in the snapshot's metadata ({_printable(str(joint), 80)})")
    head = meta.head
    if head.kind != "discrete" or head.nvec[0] != base ** seats:
        raise SnapshotError(f"{path}: bad joint record in the snapshot's metadata: {seats} seats of {base} actions "
                            f"make {base ** seats:,} joint actions, but its network plays {head.describe()}")
    return int(seats), int(base)


def _check_env(path: Any, meta: SnapshotMeta, expect_env: str | None) -> None:
    """The game must exist, take the snapshot's options, and have a seat with the snapshot's spaces (the seat the
    snapshot names, when it names one of the game's): the observation's shape and the action space exactly.

    The game is the one the caller expects (a name a user gave, or the league row's), which may be loaded; without
    one, the file's own name is looked up among the games already known and never imported
    (:func:`~selfplay_cli.envs.loading.known_env`): a file must not run the module it names."""
    if expect_env is not None and meta.env != expect_env:
        raise SnapshotError(f"{path}: snapshot plays {_printable(meta.env, 80)!r}, not {_printable(expect_env, 80)!r}")
    try:
        spec = get_env(expect_env) if expect_env is not None else known_env(meta.env)
    except EnvError as e:  # a game that does not load, or breaks the contract
        raise SnapshotError(f"{path}: {_printable(str(e), 300)}") from None
    except UnknownEnvError as e:
        raise SnapshotError(f"{path}: snapshot plays an {e}") from None
    if spec is None:
        raise SnapshotError(f"{path}: snapshot plays an unknown env {_printable(meta.env, 80)!r}: it is not a "
                            "registered game, and a game named by a file is never imported from it (if you trust "
                            "that module, name the game yourself with --env)")
    try:
        cfg = spec.config(**meta.env_options)
        seats = spec.seat_spaces(cfg)
    except (ValueError, TypeError, UnknownEnvError) as e:
        raise SnapshotError(f"{path}: bad {meta.env} options in snapshot ({_printable(str(e), 200)})") from None
    except MemoryError:  # an option that sizes the game (the game should bound it; this is the last line)
        raise SnapshotError(f"{path}: the {meta.env} options in the snapshot ask for more memory than there is "
                            f"({_printable(json.dumps(meta.env_options), 120)})") from None
    joint = _joint_of(path, meta)
    if joint is not None:  # one agent over the team (SA): the joint spaces of the game's seats
        try:
            j_obs, j_act = joint_spaces(seats[0].observation, seats[0].action, joint[0], meta.env)
        except MarlError as e:  # a joint space the game cannot give (too large, not Discrete)
            raise SnapshotError(f"{path}: {e}") from None
        if tuple(meta.obs_shape or ()) != tuple(j_obs.shape) or meta.head != ActionHead.of(j_act):
            raise SnapshotError(f"{path}: a joint snapshot of {joint[0]} seats must read {list(j_obs.shape)} and play "
                                f"{j_act.n} joint actions; it reads {list(meta.obs_shape or ())}")
        return
    if meta.seat in spec.agents:
        seats = [seats[spec.agents.index(meta.seat)]]
    elif meta.role is not None and len(seats) == spec.n_seats:  # the seats of the role it says it learned
        roles = spec.seat_roles(cfg)
        seats = [seat for seat, role in zip(seats, roles, strict=True) if role == meta.role] or seats
    shapes = [tuple(seat.observation.shape or ()) for seat in seats]
    if meta.obs_shape not in shapes:
        observes = " or ".join(sorted({str(list(s)) for s in shapes}))
        raise SnapshotError(f"{path}: snapshot observations are {list(meta.obs_shape or ())} but {meta.env} with "
                            f"these options observes {observes}")
    head = meta.head
    heads = []
    for seat in seats:
        try:
            heads.append(ActionHead.of(seat.action))
        except SpaceError:
            continue
    if head not in heads:
        if head.kind == "discrete" and all(h.kind == "discrete" for h in heads) and heads:
            raise SnapshotError(f"{path}: snapshot has {head.nvec[0]} actions but {meta.env} has "
                                f"{' or '.join(sorted({str(h.nvec[0]) for h in heads}))}")
        acts = " or ".join(sorted({h.describe() for h in heads})) or "actions marl cannot play"
        raise SnapshotError(f"{path}: snapshot acts in {head.describe()} but {meta.env} acts in {acts}")


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
            if tuple(seat.observation.shape) == tuple(meta.obs_shape or ()) and ActionHead.of(seat.action) == meta.head:
                fit.add(role)
    return None if fit == set(roles) else frozenset(fit)


@dataclass(frozen=True)
class Snapshot:
    """A snapshot file read and fully validated: its weights (CPU float32 tensors), its metadata, and the sha256
    of the whole file as it was read (the league's rows name their file by it)."""

    tensors: dict[str, torch.Tensor]
    meta: SnapshotMeta
    sha256: str


def read_snapshot(path: str | os.PathLike[str], expect_env: str | None = None) -> Snapshot:
    """Read one snapshot file, checking everything before building anything from it: the file's size, its header,
    format and version, metadata, the declared tensors against the network the metadata describes (names, dtypes,
    shapes, byte ranges, :data:`LIMITS`), the game (and ``expect_env``) and its spaces, then the weights' checksum
    and their values (every one finite; a Gaussian head's log-std within bounds).
    The file is read once: the weights, the checksum and the file's hash all come from the same bytes."""
    data, header, start = _read_whole(path)
    meta = _meta_of(path, header)
    _check_layout(path, header, meta)
    _check_env(path, meta, expect_env)
    if not meta.weights_sha256:
        raise SnapshotError(f"{path}: snapshot has no weights checksum")
    arrays = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        begin, end = info["data_offsets"]
        count = (end - begin) // 4
        array = np.frombuffer(data, dtype="<f4", count=count, offset=start + begin).astype(np.float32)
        arrays[name] = array.reshape(tuple(info["shape"]))
    tensors = {name: torch.from_numpy(a) for name, a in arrays.items()}
    if weights_sha256(tensors) != meta.weights_sha256:
        raise SnapshotError(f"{path}: weights do not match their checksum (file corrupt?)")
    _check_values(path, arrays)
    return Snapshot(tensors=tensors, meta=meta, sha256=hashlib.sha256(data).hexdigest())


def load_snapshot(
    path: str | os.PathLike[str], expect_env: str | None = None
) -> tuple[dict[str, torch.Tensor], SnapshotMeta]:
    """Weights (CPU tensors) and metadata, fully validated (:func:`read_snapshot`)."""
    snap = read_snapshot(path, expect_env=expect_env)
    return snap.tensors, snap.meta


def policy_of(
    snap: Snapshot,
    path: str | os.PathLike[str],
    id: str | None = None,
    device: str | torch.device = "cpu",
    greedy: bool = True,
    seed: int = 0,
) -> NetworkPolicy:
    """A playable policy from a snapshot :func:`read_snapshot` read from ``path`` (weights loaded strictly)."""
    meta = snap.meta
    obs_space, act_space = meta.spaces()
    net = build_network(obs_space, act_space, meta.arch, seed=0)  # the shapes were checked to fit
    try:
        net.load_state_dict(snap.tensors, strict=True)
    except RuntimeError as e:
        raise SnapshotError(f"{path}: weights do not fit the network ({str(e).splitlines()[0]})") from None
    policy = NetworkPolicy(net, id if id is not None else meta.id, meta.env, device=device, greedy=greedy,
                           seed=seed, meta=meta)
    joint = _joint_of(path, meta)
    if joint is None:
        return policy
    spec = get_env(meta.env)
    seat = spec.seat_spaces(spec.config(**meta.env_options))[0]
    return JointPolicy(policy, joint[0], joint[1], seat.observation, seat.action)  # type: ignore[return-value]


def load_policy(
    path: str | os.PathLike[str],
    id: str | None = None,
    device: str | torch.device = "cpu",
    greedy: bool = True,
    expect_env: str | None = None,
    seed: int = 0,
) -> NetworkPolicy:
    """A playable policy from a snapshot file (validated like :func:`read_snapshot`, weights loaded strictly).

    ``id`` defaults to ``run/name`` (``name`` for a run-less snapshot). The policy's ``meta`` is the file's.
    """
    return policy_of(read_snapshot(path, expect_env=expect_env), path, id=id, device=device, greedy=greedy,
                     seed=seed)


# --------------------------------------------------------------------------------------------------------------
# Moving snapshots around


def export_snapshot(src: str | os.PathLike[str], dst: str | os.PathLike[str], expect_env: str | None = None,
                    **overrides: Any) -> SnapshotMeta:
    """Validate ``src`` (playing ``expect_env``, as :func:`read_snapshot`) and write it as one portable file at
    ``dst`` (atomically), with optional metadata overrides (``run=``, ``name=``, ``parent=``, ...). If ``dst`` is
    an existing directory the file keeps its name. ``weights_sha256`` cannot be overridden (it is recomputed)."""
    tensors, meta = load_snapshot(src, expect_env=expect_env)
    names = {f.name for f in dataclasses.fields(SnapshotMeta)} - {"weights_sha256"}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise SnapshotError(f"{src}: cannot override snapshot field(s) {', '.join(unknown)}")
    if "arch" in overrides and isinstance(overrides["arch"], dict):
        overrides["arch"] = Arch.from_dict(overrides["arch"])
    meta = dataclasses.replace(meta, **overrides)
    out = Path(dst)
    if out.is_dir():
        out = out / Path(src).name
    return save_snapshot(out, tensors, meta)


def import_check(path: str | os.PathLike[str], env: str | None = None) -> SnapshotMeta:
    """Full validation of a snapshot file someone handed over (:func:`read_snapshot`: header, metadata, the
    weights against the network the metadata describes, game and spaces, checksum). Returns its metadata.
    Nothing is built: a crafted file is refused from its header, within a few kilobytes of memory."""
    return read_snapshot(path, expect_env=env).meta
