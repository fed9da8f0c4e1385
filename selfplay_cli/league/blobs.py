"""Snapshot files by their hash: the league keeps every snapshot's bytes, so that a machine that has only the
database URL can play any snapshot.

A blob is the whole file of a snapshot, keyed by the sha256 of its bytes (the ``sha256`` of the snapshot's row,
:attr:`selfplay_cli.league.models.Player.sha256`). Its bytes are in the row (``data``, the default), or at a ``url``
the row names (``file://`` on a shared disk, ``http(s)://``). Whoever reads a blob hashes what it read and refuses
bytes that do not hash to the key (:meth:`Blobs.blob_bytes`): a blob is never trusted by its name, wherever it comes
from. Nor is it read past a size: the caller gives the limit (the largest snapshot file marl reads), and a blob
whose row says more is refused before any of it is read.

Where a blob may be read from or written to is this machine's setting, never a row's: ``MARL_BLOB_LOCATIONS``, the
folders and ``http(s)://`` prefixes this machine allows (:mod:`selfplay_cli.league.locations`; none by default). A
row whose ``url`` lies elsewhere is refused without that location being touched, and an allowed one is read as a
stream, within a deadline, following no redirect; errors say what failed, never what a location holds.

A league may keep its new blobs in a folder instead of the database (:meth:`Blobs.set_blob_location`, ``meta``
key ``blob_url``): a ``file://`` URL of a disk that every machine of the league mounts at the same path, and lists
in its ``MARL_BLOB_LOCATIONS``. A blob is then written there as ``<sha256>`` (through a temporary name, inside the
allowed folder: a level that leads out by a symbolic link is never written through) before its row, which names it
by URL, is inserted. A machine that does not allow the folder (or cannot write it) stores the blob in the database
instead, with one warning line per command: a snapshot is never lost over it, and a row never makes a machine write
where its user did not say.

Training and ``marl checkpoint import`` store a snapshot's blob in the same transaction as its row
(:meth:`~selfplay_cli.league.roster.Roster.add_snapshots`); leagues made before blobs existed get theirs from the
files on the machine that has them (:meth:`Blobs.ensure_blobs`, ``marl checkpoint push``).

Storing is idempotent and safe under concurrency: the insert does nothing where the key is already there (``INSERT
... ON CONFLICT DO NOTHING`` on SQLite and PostgreSQL), so two writers of the same blob both succeed and one row is
kept.
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import unquote, urlparse

from sqlalchemy import func, insert, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from selfplay_cli.errors import MarlError
from selfplay_cli.files import folder_inside, sha256_at, write_atomic_at
from selfplay_cli.league.bounded_json import say_once
from selfplay_cli.league.db import Part
from selfplay_cli.league.failures import LeagueError, LeagueIOError, shown
from selfplay_cli.league.locations import LOCATIONS_VARIABLE, altered, read_location, writable_folder
from selfplay_cli.league.models import Blob, Meta, Player, utcnow

if TYPE_CHECKING:
    from selfplay_cli.league.rows import PlayerRow

__all__ = ["BLOB_URL", "Blobs", "BlobsReport", "blob_folder", "check_sha", "store_blob"]

BLOB_URL = "blob_url"
"""The ``meta`` key of the folder (a ``file://`` URL) a league keeps its new blobs in; none: in the database."""

FAILED_FOR = 60.0
"""Seconds a blob that could not be fetched from its location is not asked for there again (the same error)."""

SHA256_HEX = frozenset("0123456789abcdef")


def check_sha(sha: object) -> str:
    """``sha`` if it is a sha256 in lowercase hex; a :class:`LeagueError` otherwise."""
    if not isinstance(sha, str) or len(sha) != 64 or not set(sha) <= SHA256_HEX:
        raise LeagueError(f"{shown(sha)} is not a sha256 (64 lowercase hex digits)")
    return sha


def store_blob(s: Session, sha: str, data: bytes) -> bool:
    """Store ``data`` under ``sha`` (its sha256, which the caller computed from these very bytes) in the unit of work
    ``s``; True if it was stored, False if the league had it already. A blob already there is not sent again; two
    writers racing for the same key both succeed (the second insert does nothing). Where the league keeps its blobs
    in a folder this machine allows, the file is written there first (:func:`_into_folder`); anywhere else, the bytes
    go into the row."""
    if s.execute(select(Blob.sha256).where(Blob.sha256 == sha)).first() is not None:
        return False
    table = Blob.__table__
    values = dict(sha256=sha, size=len(data), data=data, url=None, created_at=utcnow())
    location = s.execute(select(Meta.value).where(Meta.key == BLOB_URL)).scalar()
    if location:  # the league keeps its blobs in a folder: the file first, then the row that names it
        url = _into_folder(str(location), sha, data)
        if url is not None:
            values.update(data=None, url=url)
    dialect = s.get_bind().dialect.name
    if dialect == "postgresql":  # (psycopg reports no row count here: the row it returns says it was stored)
        from sqlalchemy.dialects.postgresql import insert as pg_insert

        stmt = pg_insert(table).values(**values).on_conflict_do_nothing(index_elements=["sha256"])
        return s.execute(stmt.returning(table.c.sha256)).first() is not None
    if dialect == "sqlite":
        from sqlalchemy.dialects.sqlite import insert as sqlite_insert

        stmt = sqlite_insert(table).values(**values).on_conflict_do_nothing(index_elements=["sha256"])
        return s.execute(stmt).rowcount == 1
    try:  # another database: the insert in a savepoint, a lost race undone alone
        with s.begin_nested():
            s.execute(insert(table).values(**values))
        return True
    except IntegrityError:
        return False


def blob_folder(url: str) -> Path:
    """The folder a league's ``blob_url`` names (``file:///path``, an absolute path); a :class:`LeagueError`
    otherwise."""
    parsed = urlparse(url)
    folder = Path(unquote(parsed.path))
    if parsed.scheme != "file" or parsed.netloc not in ("", "localhost") or not folder.is_absolute():
        raise LeagueError(f"{shown(url, 200)} is not the file:// URL of a folder (file:///mnt/shared/marl-blobs): "
                          "blobs are written only to a disk this machine mounts")
    return folder


def _into_folder(location: str, sha: str, data: bytes) -> str | None:
    """Write ``data`` as ``<sha>`` into the league's blob folder ``location`` when this machine allows it (and the
    file is not there already) and return the URL its row names it by; None when the folder is not allowed here
    (then it is not touched) or cannot be written: the blob goes into the database, said once per command."""
    try:
        where = writable_folder(location)
    except LeagueError as exc:  # (this machine's MARL_BLOB_LOCATIONS is not a list of locations)
        say_once(f"{BLOB_URL}\0{exc}", f"{exc}; new snapshot files are stored in the league's database")
        return None
    if where is None:
        say_once(f"{BLOB_URL}\0{location}",
                 f"the league keeps its snapshot files in {shown(location, 200)}, which this machine does not allow "
                 f"({LOCATIONS_VARIABLE}); new ones are stored in the league's database instead")
        return None
    root, below, named = where
    try:
        with folder_inside(root, *below, make=False) as folder:
            if sha256_at(folder, sha, len(data)) != sha:  # (a file left by a unit that was rolled back is kept)
                write_atomic_at(folder, sha, data)
    except (OSError, MarlError) as exc:
        reason = getattr(exc, "strerror", None) or exc
        say_once(f"{BLOB_URL}\0{location}",
                 f"cannot write {named / sha}, in the folder the league keeps its snapshot files in ({reason}); new "
                 "ones are stored in the league's database instead")
        return None
    return (named / sha).as_uri()


@dataclass
class BlobsReport:
    """What :meth:`Blobs.ensure_blobs` did: snapshots whose blob it stored, that the league had already, whose file
    is not on this machine (and whose blob is not in the league), and whose file is not the one the row registered
    (not stored: the file was replaced or edited). Each list holds ``run/name``s; bytes count the files."""

    stored: list[str] = field(default_factory=list)
    stored_bytes: int = 0
    present: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    reasons: dict[str, str] = field(default_factory=dict)
    """Why each missing or refused snapshot was not stored (one line)."""

    def to_dict(self) -> dict[str, object]:
        return {"stored": len(self.stored), "stored_bytes": self.stored_bytes, "already_there": len(self.present),
                "missing": self.missing, "refused": self.refused, "reasons": self.reasons}


LegacyCheck = Callable[["PlayerRow", Path], str]
"""Accepts the file of a row whose ``sha256`` is not the file's (a row written before it meant the file: it holds the
weights' checksum) when the file is that snapshot, returning the sha256 of the bytes it checked, and raises
otherwise. Reading a snapshot file is the policies' business, so the check is given by the caller
(:func:`selfplay_cli.players.files.check_legacy_file`)."""


class Blobs(Part):
    """Snapshot blobs of the league (``league.blobs``; see the module docstring)."""


    def put_blob(self, source: bytes | str | os.PathLike[str]) -> str:
        """Store a snapshot file's bytes (``source``: the bytes, or a file) in the league and return their sha256.
        Idempotent: a blob the league has is not written again."""
        if isinstance(source, bytes):
            data = source
        else:
            try:
                data = Path(source).read_bytes()
            except OSError as exc:
                raise LeagueIOError(f"{source}: cannot read ({exc.strerror or exc})") from None
        sha = hashlib.sha256(data).hexdigest()
        if sha not in self.has_blobs([sha]):
            self._unit(lambda s: store_blob(s, sha, data))
        return sha

    def blob_location(self) -> str | None:
        """The folder (a ``file://`` URL) this league keeps its new blobs in, or None: in the database."""
        return self._read(lambda s: s.execute(select(Meta.value).where(Meta.key == BLOB_URL)).scalar()) or None

    def set_blob_location(self, url: str | None) -> str | None:
        """Keep the league's new blobs in the folder ``url`` names (``file:///path``: a disk every machine of the
        league mounts at the same path, which this machine's ``MARL_BLOB_LOCATIONS`` allows and which must exist and
        be writable here), or, with None, in the database again; blobs stored before stay where they are (each row
        says where). Returns the URL stored."""
        if url is not None:
            folder = blob_folder(url)
            if writable_folder(folder.as_uri()) is None:
                raise LeagueError(f"{folder} is not a folder this machine allows for snapshot files: add it to "
                                  f"{LOCATIONS_VARIABLE} first (export {LOCATIONS_VARIABLE}={folder.as_uri()}), on "
                                  "every machine of the league that reads or writes it")
            if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
                raise LeagueError(f"{folder} is not a folder this machine can write (make it, or mount the shared "
                                  "disk, first)")
            url = folder.as_uri()

        def work(s: Session) -> None:
            row = s.get(Meta, BLOB_URL)
            if url is None and row is not None:
                s.delete(row)
            elif url is not None and row is None:
                s.add(Meta(key=BLOB_URL, value=url))
            elif url is not None and row is not None:
                row.value = url

        self._unit(work)
        return url

    def has_blobs(self, shas: Iterable[str]) -> set[str]:
        """Which of ``shas`` the league holds a blob for."""
        wanted = list(dict.fromkeys(s for s in shas if s))
        if not wanted:
            return set()

        def work(s: Session) -> set[str]:
            found: set[str] = set()
            for i in range(0, len(wanted), 500):  # (bounded IN lists)
                found.update(s.execute(select(Blob.sha256).where(Blob.sha256.in_(wanted[i:i + 500]))).scalars())
            return found

        return self._read(work)

    def blob_bytes(self, sha: str, name: str | None = None, *, limit: int, deadline: float | None = None) -> bytes:
        """The bytes of the blob ``sha``, read from its row or its URL and hashed: bytes that do not hash to ``sha``
        are refused (:class:`LeagueError` naming the blob), so a blob altered in the database or at its URL never
        plays. A :class:`LeagueError` too when the league has no such blob, when it holds more than ``limit`` bytes
        (the largest file the caller reads: refused before they are read), and when its URL is not a location this
        machine allows (:func:`~selfplay_cli.league.locations.read_location`, which reads it, ``deadline`` seconds
        at most). ``name`` (the snapshot whose file it is) starts the messages."""
        check_sha(sha)
        where = f"{name}: snapshot blob {sha}" if name else f"snapshot blob {sha}"

        def work(s: Session) -> tuple[int, str | None, int | None, bytes | None] | None:
            row = s.execute(select(Blob.size, Blob.url, func.length(Blob.data).label("held"))
                            .where(Blob.sha256 == sha)).first()
            if row is None:
                return None
            held = None if row.held is None else int(row.held)
            data = None
            if held is not None and held <= limit:
                data = s.execute(select(Blob.data).where(Blob.sha256 == sha)).scalar()
            return int(row.size), row.url, held, data

        found = self._read(work)
        if found is None:
            raise LeagueError(f"{where} is not in the league: run `marl checkpoint push` where its file is (the "
                              "machine that trained or imported it)")
        size, url, held, data = found
        if held is not None and held > limit:
            raise LeagueError(f"{where}: {held:,} bytes, more than any snapshot file marl reads ({limit:,}), nothing "
                              "was loaded from it")
        if data is None:
            if not url:
                raise LeagueError(f"{where} has neither bytes nor a URL: the row was not written by marl")
            return self._fetch(url, sha=sha, size=size, limit=limit, deadline=deadline, where=where)
        data = bytes(data)
        if hashlib.sha256(data).hexdigest() != sha:
            raise altered(where)
        return data

    def _fetch(self, url: str, **how: Any) -> bytes:
        """:func:`read_location`, a failure remembered for :data:`FAILED_FOR` seconds: asked again for the same
        blob at the same location meanwhile (a command whose first look at a snapshot only wanted its roles, then
        loads it), the same error is raised again at once, and a location that holds a worker until its deadline
        holds it once. (This machine's settings are part of the key: changed, the location is asked again.)"""
        key = (url, how["sha"], how["size"], how["limit"], os.environ.get(LOCATIONS_VARIABLE, ""))
        failed = getattr(self, "_failed_fetches", None)
        if failed is None:
            failed = self._failed_fetches = {}
        seen = failed.get(key)
        if seen is not None and time.monotonic() - seen[0] < FAILED_FOR:
            raise type(seen[1])(str(seen[1]))
        try:
            return read_location(url, **how)
        except LeagueError as exc:
            failed[key] = (time.monotonic(), exc)
            raise

    def ensure_blobs(self, rows: Iterable[PlayerRow], check_legacy: LegacyCheck | None = None,
                     advance: Callable[[int], None] | None = None) -> BlobsReport:
        """Store the blob of every snapshot among ``rows`` that the league does not have yet, from its file in this
        league's home, each checked by hash before it is stored (leagues made before blobs existed; a command that
        hands snapshots to other machines calls this first). Bots and rows the league has the blob of are skipped.

        A row whose ``sha256`` is not its file's hash is stored only if it is an older row that holds its weights'
        checksum and ``check_legacy`` accepts the file as that snapshot: its ``sha256`` then becomes the file's, as
        every newer row's is, in the same transaction as the blob (its weights' checksum stays in
        ``meta["weights_sha256"]``), so that any machine finds its blob by it. Any other row whose file does not hash
        to it is refused (the file was replaced or edited), and nothing of it is stored. ``advance(1)`` is called
        after each snapshot (a progress bar)."""
        snaps = [r for r in rows if not r.is_bot]
        have = self.has_blobs(r.sha256 for r in snaps if r.sha256)
        report = BlobsReport()
        for row in snaps:
            self._ensure_one(row, have, report, check_legacy)
            if advance is not None:
                advance(1)
        return report

    def _ensure_one(self, row: PlayerRow, have: set[str], report: BlobsReport,
                    check_legacy: LegacyCheck | None) -> None:
        name = row.full_name
        if row.sha256 in have:
            report.present.append(name)
            return
        try:
            path = self.db.snapshot_file(row)  # (paths kept inside the home)
            data = path.read_bytes() if path.is_file() else None
        except (LeagueError, OSError) as exc:
            report.missing.append(name)
            report.reasons[name] = str(getattr(exc, "strerror", None) or exc)
            return
        if data is None:
            report.missing.append(name)
            report.reasons[name] = f"no file at {path} and no blob in the league"
            return
        sha = hashlib.sha256(data).hexdigest()
        legacy = sha != row.sha256
        if legacy:
            try:
                if check_legacy is None:
                    raise LeagueError(f"{path}: the file's sha256 {sha[:12]}... is not the "
                                      f"{str(row.sha256)[:12]}... registered")
                if check_legacy(row, path) != sha:  # (the bytes checked must be the bytes stored)
                    raise LeagueError(f"{path}: the file changed while its blob was being stored")
            except MarlError as exc:
                report.refused.append(name)
                report.reasons[name] = str(exc)
                return
        old = row.sha256

        def work(s: Session) -> bool:
            if legacy:
                moved = s.execute(update(Player).where(Player.id == row.id, Player.sha256 == old)
                                  .values(sha256=sha, meta={**row.meta, "weights_sha256": old}))
                if moved.rowcount != 1:
                    raise LeagueError(f"{name} changed while its blob was being stored; run the command again")
            return store_blob(s, sha, data)

        if self._unit(work):
            report.stored.append(name)
            report.stored_bytes += len(data)
        else:
            report.present.append(name)
        have.add(sha)
