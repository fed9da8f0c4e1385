"""Snapshot files: a policy's weights plus everything needed to rebuild and identify it, in one file.

A snapshot is a ``*.safetensors`` file. Its header's ``__metadata__`` (a str -> str map) holds
``format = "marl-snapshot"``, ``format_version = "1"`` and ``marl``: the JSON of :class:`SnapshotMeta` (env and
its options, observation shape, action count, network arch, algorithm, training counters, lineage). The
weights are checksummed (:func:`weights_sha256`) on save and verified on every load.

Loading never unpickles anything: the header is parsed as JSON and the tensors are read with ``safetensors``
(no ``torch.load``). Every problem with a file is a :class:`SnapshotError` whose message starts with the path.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import struct
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file
from safetensors.torch import save as st_save

from ..envs import UnknownEnvError, get_env
from .network import Arch, MLPNet, NetworkPolicy, SnapshotError, build_network

FORMAT = "marl-snapshot"
FORMAT_VERSION = 1
SUFFIX = ".safetensors"
_MAX_HEADER = 100 * 1024 * 1024  # safetensors' own limit

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "SnapshotError",
    "SnapshotMeta",
    "export_snapshot",
    "file_sha256",
    "import_check",
    "load_policy",
    "load_snapshot",
    "read_meta",
    "save_snapshot",
    "weights_sha256",
]


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


@dataclass(frozen=True, kw_only=True)
class SnapshotMeta:
    """What a snapshot is: the game it plays, the network's shape and where it came from.

    Keyword-only. ``parent`` is the snapshot it was trained from (``"run/ep80"``); ``seat`` names the seat
    of a per-seat learner (``"left"``), ``None`` when one network plays every seat; ``created`` is ISO UTC;
    ``weights_sha256`` is filled by :func:`save_snapshot`; ``extra`` is free-form JSON (hyperparameters...).
    ``env_options`` and ``extra`` go through JSON, so tuples in them come back as lists.
    """

    env: str
    env_options: dict[str, Any] = field(default_factory=dict)
    obs_shape: tuple[int, ...]
    n_actions: int
    arch: Arch = field(default_factory=Arch)
    algo: str = ""
    step: int = 0
    episode: int = 0
    run: str | None = None
    name: str
    parent: str | None = None
    created: str = field(default_factory=utc_now)
    seat: str | None = None
    weights_sha256: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "obs_shape", tuple(int(d) for d in self.obs_shape))
        object.__setattr__(self, "n_actions", int(self.n_actions))
        object.__setattr__(self, "env_options", dict(self.env_options or {}))
        object.__setattr__(self, "extra", dict(self.extra or {}))
        if isinstance(self.arch, dict):
            object.__setattr__(self, "arch", Arch.from_dict(self.arch))

    @property
    def id(self) -> str:
        """The player id: ``run/name``, or ``name`` for a run-less snapshot."""
        return f"{self.run}/{self.name}" if self.run else self.name

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["obs_shape"] = list(self.obs_shape)
        d["arch"] = self.arch.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Any) -> SnapshotMeta:
        """Inverse of :meth:`to_dict`. Unknown keys are ignored (informational additions); missing required
        keys or wrongly typed values raise ``ValueError`` (or :class:`SnapshotError` for a bad arch)."""
        if not isinstance(data, dict):
            raise ValueError(f"metadata must be an object, not {type(data).__name__}")
        missing = [k for k in ("env", "obs_shape", "n_actions", "name") if k not in data]
        if missing:
            raise ValueError(f"missing field(s) {', '.join(missing)}")
        names = {f.name for f in dataclasses.fields(cls)}
        kw = {k: v for k, v in data.items() if k in names}
        for key in ("env", "name", "algo", "created", "weights_sha256"):
            if key in kw and not isinstance(kw[key], str):
                raise ValueError(f"field {key!r} must be a string")
        for key in ("run", "parent", "seat"):
            if kw.get(key) is not None and not isinstance(kw[key], str):
                raise ValueError(f"field {key!r} must be a string or null")
        for key in ("env_options", "extra"):
            if key in kw and not isinstance(kw[key], dict):
                raise ValueError(f"field {key!r} must be an object")
        for key in ("n_actions", "step", "episode"):
            if key in kw and (not isinstance(kw[key], int) or isinstance(kw[key], bool)):
                raise ValueError(f"field {key!r} must be an integer")
        shape = kw["obs_shape"]
        if not isinstance(shape, list) or not all(isinstance(d, int) and not isinstance(d, bool) for d in shape):
            raise ValueError("field 'obs_shape' must be a list of integers")
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
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                h.update(chunk)
    except FileNotFoundError:
        raise SnapshotError(f"{path}: no such file") from None
    except OSError as e:
        raise SnapshotError(f"{path}: cannot read ({e.strerror or e})") from None
    return h.hexdigest()


# --------------------------------------------------------------------------------------------------------------
# Saving


def _state_dict(net_or_state_dict: torch.nn.Module | dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    sd = net_or_state_dict.state_dict() if isinstance(net_or_state_dict, torch.nn.Module) else net_or_state_dict
    # Cloned: CPU, contiguous and never sharing storage (safetensors refuses shared tensors).
    return {str(k): v.detach().to("cpu").contiguous().clone() for k, v in sd.items()}


def _fit_problems(tensors: dict[str, torch.Tensor], net: MLPNet) -> list[str]:
    expected = net.state_dict()
    problems = []
    missing = sorted(set(expected) - set(tensors))
    unexpected = sorted(set(tensors) - set(expected))
    if missing:
        problems.append(f"missing {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}")
    if unexpected:
        problems.append(f"unexpected {', '.join(unexpected[:4])}{' ...' if len(unexpected) > 4 else ''}")
    for k in sorted(set(expected) & set(tensors)):
        if tuple(tensors[k].shape) != tuple(expected[k].shape):
            problems.append(f"{k} is {list(tensors[k].shape)}, expected {list(expected[k].shape)}")
    return problems


def _check_fits(path: Any, tensors: dict[str, torch.Tensor], meta: SnapshotMeta) -> MLPNet:
    """The network ``meta`` describes, with ``tensors`` checked to fit it exactly (not loaded)."""
    try:
        net = build_network(meta.obs_shape, meta.n_actions, meta.arch, seed=0)
    except SnapshotError as e:
        raise SnapshotError(f"{path}: {e}") from None
    problems = _fit_problems(tensors, net)
    if problems:
        raise SnapshotError(f"{path}: weights do not fit the {meta.arch.describe()} network ({'; '.join(problems)})")
    return net


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    try:  # make the rename itself durable (best effort; not possible on every platform)
        fd = os.open(path.parent, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def save_snapshot(
    path: str | os.PathLike[str],
    net_or_state_dict: torch.nn.Module | dict[str, torch.Tensor],
    meta: SnapshotMeta,
) -> SnapshotMeta:
    """Write weights + ``meta`` to ``path`` atomically (temp file, fsync, rename); parent dirs are created.

    The weights must fit the network ``meta`` describes (checked, so a saved file always loads). Returns
    ``meta`` with ``weights_sha256`` filled in.
    """
    path = Path(path)
    tensors = _state_dict(net_or_state_dict)
    _check_fits(path, tensors, meta)
    meta = dataclasses.replace(meta, weights_sha256=weights_sha256(tensors))
    try:
        meta_json = json.dumps(meta.to_dict(), sort_keys=True)
    except (TypeError, ValueError) as e:
        raise SnapshotError(f"{path}: metadata is not JSON-serialisable ({e})") from None
    header = {"format": FORMAT, "format_version": str(FORMAT_VERSION), "marl": meta_json}
    try:
        _atomic_write(path, st_save(tensors, metadata=header))
    except OSError as e:
        raise SnapshotError(f"{path}: cannot write ({e.strerror or e})") from None
    return meta


# --------------------------------------------------------------------------------------------------------------
# Reading


def _read_header(path: Any) -> dict[str, Any]:
    """The safetensors header, checked for shape and for the file holding exactly the data it describes."""
    p = Path(path)
    if not p.exists():
        raise SnapshotError(f"{path}: no such snapshot file")
    if not p.is_file():
        raise SnapshotError(f"{path}: not a file")
    try:
        size = p.stat().st_size
        with open(p, "rb") as f:
            prefix = f.read(8)
            if len(prefix) < 8:
                raise SnapshotError(f"{path}: not a marl snapshot (file too short: {size} bytes)")
            (n,) = struct.unpack("<Q", prefix)
            if n == 0 or n > _MAX_HEADER:
                raise SnapshotError(f"{path}: not a marl snapshot (bad header)")
            if n > size - 8:
                first = f.read(1)
                why = "header cut short: truncated?" if first == b"{" else "bad header"
                raise SnapshotError(f"{path}: not a marl snapshot ({why})")
            raw = f.read(n)
    except OSError as e:
        raise SnapshotError(f"{path}: cannot read ({e.strerror or e})") from None
    try:
        header = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise SnapshotError(f"{path}: not a marl snapshot (bad header)") from None
    if not isinstance(header, dict):
        raise SnapshotError(f"{path}: not a marl snapshot (bad header)")
    end = 0
    for name, info in header.items():
        if name == "__metadata__":
            continue
        offsets = info.get("data_offsets") if isinstance(info, dict) else None
        if not (isinstance(offsets, list) and len(offsets) == 2 and all(isinstance(o, int) for o in offsets)):
            raise SnapshotError(f"{path}: not a marl snapshot (bad header entry for {name!r})")
        end = max(end, offsets[1])
    data_len = size - 8 - n
    if data_len < end:
        raise SnapshotError(f"{path}: truncated snapshot ({data_len} of {end} data bytes present)")
    if data_len > end:
        raise SnapshotError(f"{path}: unexpected data after the weights ({data_len - end} bytes; file corrupt?)")
    return header


def read_meta(path: str | os.PathLike[str]) -> SnapshotMeta:
    """The snapshot's metadata from its header only (cheap: the weights are neither read nor verified)."""
    header = _read_header(path)
    md = header.get("__metadata__")
    if not isinstance(md, dict) or "format" not in md:
        raise SnapshotError(f"{path}: not a marl snapshot (a safetensors file without marl metadata)")
    if md.get("format") != FORMAT:
        raise SnapshotError(f"{path}: not a marl snapshot (format {md.get('format')!r}, expected {FORMAT!r})")
    try:
        version = int(md.get("format_version", ""))
    except (TypeError, ValueError):
        raise SnapshotError(f"{path}: not a marl snapshot (bad format version {md.get('format_version')!r})") from None
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
        return SnapshotMeta.from_dict(json.loads(raw))
    except json.JSONDecodeError:
        raise SnapshotError(f"{path}: bad snapshot metadata (not JSON)") from None
    except (ValueError, TypeError, SnapshotError) as e:
        raise SnapshotError(f"{path}: bad snapshot metadata ({e})") from None


def _check_env(path: Any, meta: SnapshotMeta, expect_env: str | None) -> None:
    if expect_env is not None and meta.env != expect_env:
        raise SnapshotError(f"{path}: snapshot plays {meta.env!r}, not {expect_env!r}")
    try:
        spec = get_env(meta.env)
    except UnknownEnvError as e:
        raise SnapshotError(f"{path}: snapshot plays an {e}") from None
    try:
        cfg = spec.config(**meta.env_options)
        obs_space = spec.observation_space(cfg)
        act_space = spec.action_space(cfg)
    except (ValueError, TypeError) as e:
        raise SnapshotError(f"{path}: bad {meta.env} options in snapshot ({e})") from None
    if tuple(obs_space.shape or ()) != meta.obs_shape:
        raise SnapshotError(
            f"{path}: snapshot observations are {list(meta.obs_shape)} but {meta.env} with these options "
            f"observes {list(obs_space.shape or ())}"
        )
    n = getattr(act_space, "n", None)  # a Discrete space; anything else cannot match
    n = int(n) if n is not None else None
    if n != meta.n_actions:
        raise SnapshotError(f"{path}: snapshot has {meta.n_actions} actions but {meta.env} has {n}")


def load_snapshot(
    path: str | os.PathLike[str], expect_env: str | None = None
) -> tuple[dict[str, torch.Tensor], SnapshotMeta]:
    """Weights (CPU tensors) and metadata, fully validated: header, format and version, env (and
    ``expect_env``), observation/action shapes against the env's spaces, and the weights' checksum."""
    meta = read_meta(path)
    _check_env(path, meta, expect_env)
    try:
        tensors = load_file(os.fspath(path), device="cpu")
    except Exception as e:  # safetensors raises its own error types; any failure here means a bad file
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise SnapshotError(f"{path}: cannot read the weights ({msg})") from None
    if not meta.weights_sha256:
        raise SnapshotError(f"{path}: snapshot has no weights checksum")
    if weights_sha256(tensors) != meta.weights_sha256:
        raise SnapshotError(f"{path}: weights do not match their checksum (file corrupt?)")
    return tensors, meta


def load_policy(
    path: str | os.PathLike[str],
    id: str | None = None,
    device: str | torch.device = "cpu",
    greedy: bool = True,
    expect_env: str | None = None,
    seed: int = 0,
) -> NetworkPolicy:
    """A playable policy from a snapshot file (validated like :func:`load_snapshot`, weights loaded strictly).

    ``id`` defaults to ``run/name`` (``name`` for a run-less snapshot). The policy's ``meta`` is the file's.
    """
    tensors, meta = load_snapshot(path, expect_env=expect_env)
    net = _check_fits(path, tensors, meta)
    try:
        net.load_state_dict(tensors, strict=True)
    except RuntimeError as e:
        raise SnapshotError(f"{path}: weights do not fit the network ({str(e).splitlines()[0]})") from None
    return NetworkPolicy(net, id if id is not None else meta.id, meta.env, device=device, greedy=greedy,
                         seed=seed, meta=meta)


# --------------------------------------------------------------------------------------------------------------
# Moving snapshots around


def export_snapshot(src: str | os.PathLike[str], dst: str | os.PathLike[str], **overrides: Any) -> SnapshotMeta:
    """Validate ``src`` and write it as one portable file at ``dst`` (atomically), with optional metadata
    overrides (``run=``, ``name=``, ``parent=``, ...). If ``dst`` is an existing directory the file keeps its
    name. ``weights_sha256`` cannot be overridden (it is recomputed)."""
    tensors, meta = load_snapshot(src)
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
    """Full validation of a snapshot file someone handed over: header, env and shapes, checksum, and that the
    weights fit the network the metadata describes. Returns its metadata."""
    tensors, meta = load_snapshot(path, expect_env=env)
    _check_fits(path, tensors, meta)
    return meta
