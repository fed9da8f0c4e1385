"""A league's database URL: the driver it means (:func:`driver_url`: psycopg 3 for ``postgresql://``), the SQLite
file it names (:func:`sqlite_file`), and whether that file may be used where it lies.

SQLite's locks are not to be trusted on a network file system (NFS, SMB, sshfs, cluster file systems): a league file
there is refused (:func:`network_filesystem`, :func:`refuse_network_sqlite`) with a line that says to use PostgreSQL,
unless the user sets :data:`ALLOW_NETWORK_SQLITE`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from sqlalchemy.engine import URL

from selfplay_cli.league.failures import LeagueError

__all__ = ["ALLOW_NETWORK_SQLITE", "NETWORK_FILESYSTEMS", "driver_url", "network_filesystem", "refuse_network_sqlite",
           "sqlite_file"]

ALLOW_NETWORK_SQLITE = "MARL_ALLOW_NETWORK_SQLITE"
"""The environment variable that, set to 1, lets a SQLite league lie on a network file system (for users who know
their file system's locks work)."""

NETWORK_FILESYSTEMS = ("nfs", "nfs4", "cifs", "smb3", "smbfs", "ncpfs", "afs", "ceph", "glusterfs", "lustre", "gpfs",
                       "beegfs", "ocfs2", "gfs2", "davfs", "fuse.sshfs", "fuse.s3fs", "fuse.gcsfuse", "fuse.rclone",
                       "fuse.glusterfs", "fuse.juicefs", "fuse.davfs2", "fuse.cephfs", "fuse.beegfs")
"""File systems whose locks SQLite cannot rely on (shared across machines, or over a network)."""


def _read_mountinfo() -> str:
    """The mounts of this process (Linux); empty where there is no such file."""
    try:
        return Path("/proc/self/mountinfo").read_text(errors="surrogateescape")
    except OSError:
        return ""


def network_filesystem(path: Path, mountinfo: str | None = None) -> str | None:
    """The type of the network file system ``path`` lies on (``nfs4``, ``cifs``, ``fuse.sshfs``...), or None.

    Read from ``mountinfo`` (the text of ``/proc/self/mountinfo``; read here when None: off Linux there is none,
    and the answer is None): the mount whose mount point is the longest prefix of the path, its nearest existing folder
    resolved (symlinks followed)."""
    if mountinfo is None:
        mountinfo = _read_mountinfo()
    where = Path(path).expanduser().absolute()
    while not where.exists() and where != where.parent:
        where = where.parent
    where = where.resolve()
    best, fstype = -1, None
    for line in mountinfo.splitlines():
        fields = line.split()
        try:
            kind = fields[fields.index("-", 6) + 1]  # after the optional fields and their "-": the type
        except (ValueError, IndexError):
            continue
        point = Path(re.sub(r"\\([0-7]{3})", lambda m: chr(int(m[1], 8)), fields[4]))  # "\040" is a space
        if (where == point or point in where.parents) and len(point.parts) > best:
            best, fstype = len(point.parts), kind
    return fstype if fstype in NETWORK_FILESYSTEMS else None


def refuse_network_sqlite(db_file: Path) -> None:
    """A :class:`LeagueError` if the SQLite file ``db_file`` lies on a network file system (unless the user said
    :data:`ALLOW_NETWORK_SQLITE`)."""
    if os.environ.get(ALLOW_NETWORK_SQLITE) == "1":
        return
    fstype = network_filesystem(db_file.parent)
    if fstype is not None:
        raise LeagueError(
            f"{db_file} is on a network file system ({fstype}), where SQLite's locks cannot be trusted and a "
            f"league gets corrupted: use a PostgreSQL league for several machines (--db postgresql://user@host/db; "
            f"docs: A league on PostgreSQL), or set {ALLOW_NETWORK_SQLITE}=1")


def driver_url(url: URL) -> URL:
    """``postgresql://`` (which SQLAlchemy takes to mean psycopg2) and ``postgres://`` as psycopg 3, the driver that
    ``pip install "selfplay-cli[postgres]"`` brings."""
    if url.drivername in ("postgresql", "postgres"):
        return url.set(drivername="postgresql+psycopg")
    return url



def sqlite_file(url: URL) -> Path | None:
    """The database file of a SQLite URL, or None (other backends, in-memory or URI databases)."""
    if url.get_backend_name() != "sqlite":
        return None
    db = url.database or ""
    if db in ("", ":memory:") or db.startswith("file:"):
        return None
    return Path(db).expanduser()
