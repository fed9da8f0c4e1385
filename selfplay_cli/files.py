"""Temporary files and what killed processes leave of them.

Every file marl writes goes to a temporary name beside its destination and is renamed into place when complete,
so a destination never holds half a file. The temporary names carry the writer's process id:

* ``<name>.tmp-<pid>`` (snapshots, run state, configuration, locks), from :func:`temp_path`;
* ``.<name>.<pid>.part`` (videos, which ffmpeg writes) and ``.<name>.<pid>.check`` (the probe that a folder is
  writable), hidden.

A process killed with SIGKILL (or a power cut) leaves its temporary file behind. :func:`sweep` removes, from one
folder, the temporary files whose process is gone; commands that write into a folder sweep it when they start.
A process id names a process of this machine: a league home is written by the processes of one machine (another
machine sharing the folder would see our live processes as gone).

Nothing here imports from the rest of marl, so every room can use it.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

__all__ = ["STALE_PATTERNS", "atomic_write", "cache_home", "describe_removed", "file_sha256", "pid_alive", "publish",
           "sweep", "sweep_home", "temp_path", "write_atomic"]

STALE_PATTERNS = (
    re.compile(r"^.+\.tmp-(?P<pid>\d{1,10})$"),
    re.compile(r"^\..+\.(?P<pid>\d{1,10})\.(?:part|check)$"),
)
"""Names of marl's temporary files; the group ``pid`` is the process that writes it."""

HOME_FOLDERS = ("snapshots", "runs")
"""Folders of a league home whose subfolders (one per run) hold files written through temporary names."""


def temp_path(path: str | os.PathLike[str]) -> Path:
    """The temporary name beside ``path`` that this process writes before renaming: ``<name>.tmp-<pid>``."""
    p = Path(path)
    return p.with_name(f"{p.name}.tmp-{os.getpid()}")


def sync_folder(folder: str | os.PathLike[str]) -> None:
    """Make a rename in ``folder`` durable (best effort: not every platform can open a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def publish(tmp: str | os.PathLike[str], path: str | os.PathLike[str]) -> None:
    """Rename a complete temporary file over ``path`` and make the rename durable."""
    os.replace(tmp, path)
    sync_folder(Path(path).parent)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "wb") -> Iterator[IO]:
    """Open :func:`temp_path` of ``path`` for writing; once the block ends, flush, fsync and rename it over
    ``path``. On any exception (Ctrl-C included) the temporary file is removed and ``path`` is untouched.
    Parent folders are not made: a missing folder is the caller's ``OSError``."""
    p = Path(path)
    tmp = temp_path(p)
    try:
        with open(tmp, mode) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    sync_folder(p.parent)


def write_atomic(path: str | os.PathLike[str], data: bytes | str) -> None:
    """Write all of ``data`` to ``path`` through :func:`atomic_write` (text as UTF-8)."""
    with atomic_write(path, "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)


def file_sha256(path: str | os.PathLike[str]) -> str:
    """sha256 of a whole file, streamed (``OSError`` if it cannot be read)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def cache_home() -> Path:
    """The folder of this machine's cache (``$MARL_CACHE``, else ``~/.cache/marl``): what marl fetched and may fetch
    again (snapshot files from a league's database). Not created here."""
    return Path(os.environ.get("MARL_CACHE") or Path.home() / ".cache" / "marl").expanduser()


def pid_alive(pid: int) -> bool:
    """True if a process with this id exists on this machine (ours or another user's)."""
    if pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, it is someone else's
        return True
    except OSError:
        return True  # cannot tell: keep the file
    return True


def _stale_pid(name: str) -> int | None:
    for pattern in STALE_PATTERNS:
        m = pattern.match(name)
        if m:
            return int(m.group("pid"))
    return None


def sweep(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files in ``folder`` (not below it) left by processes that are gone; returns them.

    Only regular files with marl's temporary names are touched (never a folder, never a symlink's target); a file
    whose process is still running is being written and stays. Errors (a read-only folder, a file gone meanwhile)
    are skipped: sweeping is housekeeping and never fails a command.
    """
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        pid = _stale_pid(entry.name)
        if pid is None or pid_alive(pid):
            continue
        try:
            if not entry.is_file(follow_symlinks=False):
                continue
            os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed


def _subfolders(folder: Path) -> Iterable[Path]:
    try:
        return [Path(e.path) for e in os.scandir(folder) if e.is_dir(follow_symlinks=False)]
    except OSError:
        return []


def sweep_home(home: str | os.PathLike[str]) -> list[Path]:
    """:func:`sweep` every folder of a league home that marl writes files into: the home itself,
    ``snapshots/<run>/``, ``runs/<run>/`` and ``videos/``."""
    home = Path(home)
    removed = sweep(home) + sweep(home / "videos")
    for top in HOME_FOLDERS:
        for sub in _subfolders(home / top):
            removed += sweep(sub)
    return removed


def describe_removed(removed: list[Path], home: str | os.PathLike[str] | None = None) -> str:
    """One line naming what :func:`sweep` removed (the first few files, relative to ``home`` when under it)."""

    def rel(p: Path) -> str:
        if home is not None:
            try:
                return str(p.relative_to(home))
            except ValueError:
                pass
        return str(p)

    shown = ", ".join(rel(p) for p in removed[:3]) + (f" and {len(removed) - 3} more" if len(removed) > 3 else "")
    noun = "file" if len(removed) == 1 else "files"
    return f"removed {len(removed)} temporary {noun} left by killed processes: {shown}"
