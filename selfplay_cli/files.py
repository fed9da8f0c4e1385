"""Temporary files and what killed processes leave of them.

Every file marl writes goes to a temporary name beside its destination and is renamed into place when complete,
so a destination never holds half a file. The temporary names carry the writer's process id:

* ``<name>.tmp-<pid>`` (snapshots, run state, configuration, locks), from :func:`temp_path`;
* ``.<name>.<pid>.part`` (videos, which ffmpeg writes) and ``.<name>.<pid>.check`` (the probe that a folder is
  writable), hidden.

A process killed with SIGKILL (or a power cut) leaves its temporary file behind. :func:`sweep` removes, from one
folder, the temporary files whose process is gone; commands that write into a folder sweep it when they start.
A process id names a process of this machine: a league home is written by the processes of one machine (another
machine sharing the folder would see our live processes as gone). A temporary file is always made anew (``O_EXCL``:
a symbolic link planted under its name is removed, never followed), so a write lands in its own folder.

Folders that others may reach into (marl's cache, a shared folder of snapshot files) are written through an open
descriptor of the folder (:func:`folder_inside`, :func:`write_atomic_at`, :func:`sha256_at`): its real path is
checked to lie inside the root it belongs to, and nothing below is created or written when a level leads out (a
symbolic link to somewhere else).

Nothing here imports from the rest of marl but :mod:`selfplay_cli.errors`, so every room can use it.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import secrets
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from .errors import MarlError

__all__ = ["STALE_PATTERNS", "atomic_write", "cache_home", "describe_removed", "file_sha256", "folder_inside",
           "is_inside", "opened_path", "pid_alive", "publish", "sha256_at", "sweep", "sweep_home", "temp_path",
           "write_atomic", "write_atomic_at"]

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)
_DIRECTORY = getattr(os, "O_DIRECTORY", 0)

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
    Parent folders are not made: a missing folder is the caller's ``OSError``. The temporary file is made anew
    (whatever had its name, a symbolic link included, is removed first, never followed)."""
    p = Path(path)
    tmp = temp_path(p)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(tmp)
    try:
        with open(tmp, mode.replace("w", "x")) as f:
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


def is_inside(path: str | os.PathLike[str], root: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is the folder ``root`` or lies below it (both absolute and already resolved: compared as
    text, nothing is touched)."""
    path, root = os.fspath(path), os.fspath(root).rstrip(os.sep)
    return path == root or path.startswith(root + os.sep)


def opened_path(fd: int) -> str | None:
    """The real path of the open file or folder ``fd`` (Linux: ``/proc/self/fd``); None where it cannot be told."""
    try:
        return os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return None


@contextlib.contextmanager
def folder_inside(root: str | os.PathLike[str], *parts: str, make: bool = True) -> Iterator[int]:
    """An open descriptor of the folder ``root/parts...`` for :func:`write_atomic_at` and :func:`sha256_at`.

    Each level is opened from the one above it and its real path checked to lie inside ``root``'s real path before
    anything is made or opened below it: a level that leads out of the root (a symbolic link to another folder) is
    a :class:`MarlError` in one line, and nothing was created or written there. With ``make`` the root and missing
    levels are created (only ever inside the root); without, a missing one is the caller's ``OSError``."""
    root = Path(root)
    if make:
        root.mkdir(parents=True, exist_ok=True)
    real_root = os.path.realpath(root)
    fd = os.open(real_root, os.O_RDONLY | _DIRECTORY | _CLOEXEC)
    try:
        where = root
        for part in parts:
            if part in ("", ".", "..") or os.sep in part:
                raise MarlError(f"{where / part}: not a plain folder name")
            where = where / part
            if make:
                with contextlib.suppress(FileExistsError):
                    os.mkdir(part, dir_fd=fd)
            sub = os.open(part, os.O_RDONLY | _DIRECTORY | _CLOEXEC, dir_fd=fd)
            os.close(fd)
            fd = sub
            real = opened_path(fd) or os.path.realpath(where)
            if not is_inside(real, real_root):
                raise MarlError(f"{where} leads to {real}, outside {root}: nothing is written there (remove the "
                                "link)")
        yield fd
    finally:
        os.close(fd)


def write_atomic_at(folder: int, name: str, data: bytes) -> None:
    """Write ``data`` as the file ``name`` of the open folder ``folder`` (:func:`folder_inside`): to a temporary name
    made anew (``<name>.<random>.tmp-<pid>``, ``O_EXCL``: a symbolic link never followed; its own for each writer, so
    two threads fetching the same file never share one), flushed, fsynced and renamed over ``name`` in the same
    folder (a symbolic link named ``name`` is replaced, not followed). On any exception the temporary file is
    removed."""
    tmp = f"{name}.{secrets.token_hex(4)}.tmp-{os.getpid()}"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW | _CLOEXEC, 0o666, dir_fd=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, name, src_dir_fd=folder, dst_dir_fd=folder)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp, dir_fd=folder)
        raise
    with contextlib.suppress(OSError):
        os.fsync(folder)


def sha256_at(folder: int, name: str, limit: int) -> str | None:
    """The sha256 of the regular file ``name`` of the open folder ``folder``, streamed; None when there is no such
    file (absent, a symbolic link, not a regular file, more than ``limit`` bytes) or it cannot be read."""
    try:
        fd = os.open(name, os.O_RDONLY | _NOFOLLOW | _NONBLOCK | _CLOEXEC, dir_fd=folder)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size > limit:
            return None
        h, total = hashlib.sha256(), 0
        while chunk := os.read(fd, 1 << 20):
            total += len(chunk)
            if total > limit:
                return None
            h.update(chunk)
        return h.hexdigest()
    except OSError:
        return None
    finally:
        os.close(fd)


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
