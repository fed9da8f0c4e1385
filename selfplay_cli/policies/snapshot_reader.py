"""The hostile-input reader: a snapshot file is refused, in one :class:`~selfplay_cli.policies.network.SnapshotError`
whose message starts with the path and prints no control characters, before anything is built or allocated from it.

Loading never unpickles anything: the header is parsed as JSON and the tensors are read from the validated byte
ranges it declares (no ``torch.load``). A file is a hostile input until proven otherwise (models contributed to a CI
gate are imported this way): its size, its header (bounded, plain JSON), its format and metadata, the tensors it
declares against the network its metadata describes (names, dtypes, shapes, byte ranges,
:data:`~selfplay_cli.policies.snapshot_format.LIMITS`), the game and its spaces, and only then are the weights read,
checksummed and checked to be finite (:func:`read_snapshot`). The format itself:
:mod:`~selfplay_cli.policies.snapshot_format`; a policy from a checked file:
:mod:`~selfplay_cli.policies.snapshot_policy`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import struct
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..envs import EnvError, UnknownEnvError, get_env, known_env
from ..envs.obs_spaces import stacked_space
from ..errors import MarlError
from .arch import Arch, SnapshotError
from .joint import joint_spaces
from .snapshot_format import (
    FORMAT,
    FORMAT_VERSION,
    MAX_FILE_BYTES,
    MAX_HEADER,
    SnapshotMeta,
    check_fits,
    check_values,
    is_int,
    joint_of,
    printable,
    save_snapshot,
    weights_sha256,
)
from .spaces import ActionHead, SpaceError

if TYPE_CHECKING:
    import torch

_HEX64 = re.compile(r"[0-9a-f]{64}")


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
        shown = printable(name, 40)
        if not isinstance(info, dict):
            raise SnapshotError(f"{path}: not a marl snapshot (bad header entry for {shown!r})")
        offsets, shape, dtype = info.get("data_offsets"), info.get("shape"), info.get("dtype")
        if not (isinstance(offsets, list) and len(offsets) == 2 and all(is_int(o) and o >= 0 for o in offsets)
                and offsets[0] <= offsets[1]):
            raise SnapshotError(f"{path}: not a marl snapshot (bad header entry for {shown!r})")
        if not (isinstance(shape, list) and len(shape) <= 8 and all(is_int(d) and 0 <= d < 2**40 for d in shape)):
            raise SnapshotError(f"{path}: not a marl snapshot (bad shape for {shown!r})")
        if not isinstance(dtype, str):
            raise SnapshotError(f"{path}: not a marl snapshot (bad dtype for {shown!r})")
        spans.append((offsets[0], offsets[1], name))
    end = 0
    for begin, stop, name in sorted(spans):
        if begin != end:
            raise SnapshotError(f"{path}: not a marl snapshot (tensor data of {printable(name, 40)!r} "
                                f"{'overlaps another' if begin < end else 'leaves a gap'})")
        end = stop
    data_len = size - 8 - n
    if data_len < end:
        raise SnapshotError(f"{path}: truncated snapshot ({data_len} of {end} data bytes present)")
    if data_len > end:
        raise SnapshotError(f"{path}: unexpected data after the weights ({data_len - end} bytes; file corrupt?)")
    return header, 8 + n



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
    """The whole file (bounded by :data:`~selfplay_cli.policies.snapshot_format.MAX_FILE_BYTES`), its checked
    header and where its data starts."""
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
        raise SnapshotError(f"{path}: not a marl snapshot (format {printable(str(md.get('format')))!r}, "
                            f"expected {FORMAT!r})")
    try:
        version = int(md.get("format_version", ""))
    except (TypeError, ValueError):
        raise SnapshotError(f"{path}: not a marl snapshot (bad format version "
                            f"{printable(str(md.get('format_version')))!r})") from None
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
        raise SnapshotError(f"{path}: bad snapshot metadata ({printable(str(e), 200)})") from None
    if meta.weights_sha256 and not _HEX64.fullmatch(meta.weights_sha256):
        raise SnapshotError(f"{path}: bad snapshot metadata (weights_sha256 is not a sha256)")
    return meta


def read_meta(path: str | os.PathLike[str]) -> SnapshotMeta:
    """The snapshot's metadata from its header only (cheap: the weights are neither read nor verified)."""
    return _meta_of(path, _read_header(path))

def _check_layout(path: Any, header: dict[str, Any], meta: SnapshotMeta) -> None:
    """The tensors the header declares must be exactly those of the network ``meta`` describes: names, float32,
    shapes and byte sizes, within :data:`~selfplay_cli.policies.snapshot_format.LIMITS`. Nothing is allocated: a
    file describing a giant network is refused here, from its few kilobytes of header."""
    declared = {k: v for k, v in header.items() if k != "__metadata__"}
    check_fits(path, {k: tuple(v["shape"]) for k, v in declared.items()}, meta)
    for name, info in declared.items():
        if info["dtype"] != "F32":
            raise SnapshotError(f"{path}: {name} is {printable(info['dtype'], 10)}, snapshots hold float32 (F32)")
        begin, end = info["data_offsets"]
        if end - begin != 4 * math.prod(info["shape"]):
            raise SnapshotError(f"{path}: {name} declares {list(info['shape'])} but holds {end - begin} bytes")

def _check_env(path: Any, meta: SnapshotMeta, expect_env: str | None) -> None:
    """The game must exist, take the snapshot's options, and have a seat with the snapshot's spaces (the seat the
    snapshot names, when it names one of the game's): the observation's shape and the action space exactly.

    The game is the one the caller expects (a name a user gave, or the league row's), which is loaded only if it is
    registered or this machine names it (:func:`~selfplay_cli.envs.loading.get_env`: a row's name alone imports
    nothing); without one, the file's own name is looked up among the games already known and never imported
    (:func:`~selfplay_cli.envs.loading.known_env`): a file must not run the module it names."""
    if expect_env is not None and meta.env != expect_env:
        raise SnapshotError(f"{path}: snapshot plays {printable(meta.env, 80)!r}, not {printable(expect_env, 80)!r}")
    try:
        spec = get_env(expect_env) if expect_env is not None else known_env(meta.env)
    except EnvError as e:  # a game that does not load, or breaks the contract
        raise SnapshotError(f"{path}: {printable(str(e), 300)}") from None
    except UnknownEnvError as e:
        raise SnapshotError(f"{path}: snapshot plays an {e}") from None
    if spec is None:
        raise SnapshotError(f"{path}: snapshot plays an unknown env {printable(meta.env, 80)!r}: it is not a "
                            "registered game, and a game named by a file is never imported from it (if you trust "
                            "that module, name the game yourself with --env)")
    try:
        cfg = spec.config(**meta.env_options)
        seats = spec.seat_spaces(cfg)
    except (ValueError, TypeError, UnknownEnvError) as e:
        raise SnapshotError(f"{path}: bad {meta.env} options in snapshot ({printable(str(e), 200)})") from None
    except MemoryError:  # an option that sizes the game (the game should bound it; this is the last line)
        raise SnapshotError(f"{path}: the {meta.env} options in the snapshot ask for more memory than there is "
                            f"({printable(json.dumps(meta.env_options), 120)})") from None
    joint = joint_of(path, meta)
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
    shapes = [tuple(stacked_space(seat.observation, meta.frame_stack).shape or ()) for seat in seats]
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

@dataclass(frozen=True)
class Snapshot:
    """A snapshot file read and fully validated: its weights (CPU float32 tensors), its metadata, and the sha256
    of the whole file as it was read (the league's rows name their file by it)."""

    tensors: dict[str, torch.Tensor]
    meta: SnapshotMeta
    sha256: str


@dataclass(frozen=True)
class Registered:
    """What a league's row says its snapshot file is (:func:`selfplay_cli.players.files.registered`), in plain values:
    the reader holds a file to it without knowing leagues. ``sha256`` is the whole file's; a row written before it
    meant the whole file holds the weights' checksum there instead, and then the file's own run, name and step must
    be the row's."""

    full_name: str
    sha256: str | None
    run: str
    name: str
    step: int


def _check_registered(path: Any, file_sha: str, meta: SnapshotMeta, row: Registered) -> None:
    """Refuse a snapshot file that is not the one ``row`` registered (:class:`SnapshotError` naming the file)."""
    if row.sha256 and file_sha == row.sha256:
        return
    if (row.sha256 and row.sha256 == meta.weights_sha256 and meta.run == row.run and meta.name == row.name
            and meta.step == row.step):
        return  # (an older row: the weights are checked against that checksum before the file is used)
    is_of = f"{meta.id} at step {meta.step:,}" if meta.name else "another snapshot"
    raise SnapshotError(
        f"{path}: this file is not the snapshot {row.full_name} the league registered (sha256 {file_sha[:12]}, "
        f"registered {str(row.sha256 or '')[:12] or 'none'}; the file holds {is_of}): it was replaced or changed "
        "since; put the original back, or import this file under a name of its own with marl checkpoint import"
    )


def read_snapshot(path: str | os.PathLike[str], expect_env: str | None = None,
                  registered: Registered | None = None) -> Snapshot:
    """Read one snapshot file, checking everything before building anything from it: the file's size, its header,
    format and version, metadata, the declared tensors against the network the metadata describes (names, dtypes,
    shapes, byte ranges, :data:`~selfplay_cli.policies.snapshot_format.LIMITS`), the game (and ``expect_env``) and
    its spaces, then the weights' checksum and their values (every one finite; a Gaussian head's log-std within
    bounds). Where a league's row is given (``registered``), the file must be the one it registered, checked as soon
    as its metadata is read: a file copied over it, or edited, is refused naming it.
    The file is read once: the weights, the checksum and the file's hash all come from the same bytes."""
    data, header, start = _read_whole(path)
    meta = _meta_of(path, header)
    file_sha = hashlib.sha256(data).hexdigest()
    if registered is not None:  # (a file that is not the row's is refused first, whatever else it holds)
        _check_registered(path, file_sha, meta, registered)
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
    import torch  # (here: reading a snapshot's metadata needs no torch)

    tensors = {name: torch.from_numpy(a) for name, a in arrays.items()}
    if weights_sha256(tensors) != meta.weights_sha256:
        raise SnapshotError(f"{path}: weights do not match their checksum (file corrupt?)")
    check_values(path, arrays)
    return Snapshot(tensors=tensors, meta=meta, sha256=file_sha)


def load_snapshot(
    path: str | os.PathLike[str], expect_env: str | None = None, registered: Registered | None = None
) -> tuple[dict[str, torch.Tensor], SnapshotMeta]:
    """Weights (CPU tensors) and metadata, fully validated (:func:`read_snapshot`)."""
    snap = read_snapshot(path, expect_env=expect_env, registered=registered)
    return snap.tensors, snap.meta

# --------------------------------------------------------------------------------------------------------------
# Moving snapshots around


def export_snapshot(src: str | os.PathLike[str], dst: str | os.PathLike[str], expect_env: str | None = None,
                    registered: Registered | None = None, **overrides: Any) -> SnapshotMeta:
    """Validate ``src`` (playing ``expect_env``, and the file a league's row ``registered`` where given, as
    :func:`read_snapshot`) and write it as one portable file at ``dst`` (atomically), with optional metadata
    overrides (``run=``, ``name=``, ``parent=``, ...). If ``dst`` is an existing directory the file keeps its name.
    ``weights_sha256`` cannot be overridden (it is recomputed)."""
    tensors, meta = load_snapshot(src, expect_env=expect_env, registered=registered)
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
