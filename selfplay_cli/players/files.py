"""Where this machine reads a league snapshot's file from, and whether it is the file its row registered.

A row's ``sha256`` is the sha256 of its whole file (:attr:`selfplay_cli.league.models.Player.sha256`), and every
load of a league player checks it (:func:`read_row_snapshot`), so a file copied over another, or edited, never plays
under the row's name.

Where a snapshot is read from (:func:`snapshot_path`): its file in the league home where the league has a home and
the file is there (where a row's file lies is :meth:`League.snapshot_file`'s to say); otherwise (a database opened
on another machine, or without a home) its blob, fetched from the league by the row's sha256 into this machine's
cache (``$MARL_CACHE`` or ``~/.cache/marl``, ``blobs/<sha256[:2]>/<sha256>.safetensors``). A cached file is hashed
again before every use and fetched anew when it does not hash to its name: nothing is trusted by name. A blob is
fetched no larger than the largest snapshot file marl reads, from the locations this machine allows
(``MARL_BLOB_LOCATIONS``: :mod:`selfplay_cli.league.locations`), and written only inside the cache: a folder of it
that leads out (a symbolic link to another folder) is refused in one line, nothing written through it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import MarlError, MarlIOError
from ..files import cache_home, folder_inside, sha256_at, write_atomic_at
from ..league.blobs import check_sha
from ..league.store import SNAPSHOTS, League, PlayerRow, check_existing_name, check_name

if TYPE_CHECKING:
    from ..policies.snapshot_reader import Registered, Snapshot

__all__ = ["blob_cache_file", "cached_blob", "check_legacy_file", "read_row_snapshot", "registered", "snapshot_path",
           "snapshot_relpath"]


def snapshot_relpath(run: str, name: str) -> str:
    """``snapshots/<run>/<name>.safetensors``, the file of a snapshot relative to the league home; ``name`` is
    checked to be a league name and ``run`` a plain folder name first (a run of an older league may hold a space,
    a new run is checked in full when it is created), so the path is always a plain one under the home."""
    check_existing_name("run name", run)
    check_name("snapshot name", name)
    return f"{SNAPSHOTS}/{run}/{name}.safetensors"


def snapshot_path(league: League, row: PlayerRow) -> Path:
    """The file this machine reads the snapshot ``row`` from: its file in the league home when the league has a home
    and the file is there (checked to stay inside the home, :meth:`League.snapshot_file`), else the snapshot's blob
    from the league in this machine's cache (:func:`cached_blob`). Whether the file is the one the row registered is
    for the reader to check (:func:`read_row_snapshot`); a file in the home that is not is refused, never replaced."""
    home_file = None
    if league.home is not None:
        home_file = league.snapshot_file(row)
        if home_file.exists():
            return home_file
    if not row.sha256:
        raise MarlError(f"{row.full_name} has no snapshot file")
    return cached_blob(league, row.sha256, f"{row.full_name} (no file at {home_file})" if home_file else
                       row.full_name)


def blob_cache_file(sha: str) -> Path:
    """Where this machine caches the blob ``sha``: ``<cache>/blobs/<sha[:2]>/<sha>.safetensors``."""
    check_sha(sha)  # (a row's sha256 becomes a path: hex digits only)
    return cache_home() / "blobs" / sha[:2] / f"{sha}.safetensors"


def cached_blob(league: League, sha: str, name: str) -> Path:
    """The blob ``sha`` as a file of this machine's cache: the cached file when it hashes to ``sha``, else fetched
    from the league (:meth:`~selfplay_cli.league.blobs.Blobs.blob_bytes`, which refuses bytes that do not hash to it, or
    more of them than a snapshot file may hold) and written through a temporary name. The cache's folders are made and
    written only inside the cache (:func:`~selfplay_cli.files.folder_inside`). ``name`` (the snapshot) is for
    messages."""
    from ..policies.snapshot_format import MAX_FILE_BYTES

    path = blob_cache_file(sha)
    try:
        with folder_inside(cache_home(), "blobs", sha[:2]) as folder:
            if sha256_at(folder, path.name, MAX_FILE_BYTES) == sha:
                return path
            data = league.blobs.blob_bytes(sha, name, limit=MAX_FILE_BYTES)
            write_atomic_at(folder, path.name, data)
    except OSError as e:
        raise MarlIOError(f"cannot write {path}: {e.strerror or e} (MARL_CACHE names the folder of marl's cache)"
                          ) from None
    return path


def registered(row: PlayerRow) -> Registered:
    """What ``row`` registered its snapshot file as, for the reader to hold the file to."""
    from ..policies.snapshot_reader import Registered

    return Registered(row.full_name, row.sha256, row.run, row.name, row.step)


def read_row_snapshot(league: League, row: PlayerRow) -> tuple[Snapshot, Path]:
    """The snapshot ``row`` stands for, and the file it was read from (:func:`snapshot_path`): validated in full
    (:func:`~selfplay_cli.policies.snapshot_reader.read_snapshot`) and the file the row registered, else refused in
    one :class:`SnapshotError` naming the file."""
    from ..policies.snapshot_reader import read_snapshot

    expected = registered(row)
    path = snapshot_path(league, row)
    return read_snapshot(path, expect_env=row.env, registered=expected), path


def check_legacy_file(row: PlayerRow, path: Path) -> str:
    """Refuse (:class:`SnapshotError`) a file that is not the snapshot of a row written before ``sha256`` meant the
    whole file, else return the sha256 of the bytes checked: what
    :meth:`~selfplay_cli.league.blobs.Blobs.ensure_blobs` needs to store such a row's blob."""
    from ..policies.snapshot_reader import read_snapshot

    return read_snapshot(path, expect_env=row.env, registered=registered(row)).sha256
