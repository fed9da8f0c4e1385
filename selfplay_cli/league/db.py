"""The league's database: the engine, one session per unit of work, the schema and its version.

:class:`Database` is the base of :class:`~selfplay_cli.league.store.League`: it opens any SQLAlchemy URL (the default
is SQLite at ``<home>/league.db``), creates or checks the schema, and runs every unit of work in one transaction
(:meth:`Database._unit`), retried when SQLite reports a lock. What is stored is in
:mod:`selfplay_cli.league.roster` (runs, players, tags) and :mod:`selfplay_cli.league.ledger` (matches and games).

SQLite concurrency
------------------
Several processes (trainers, tournaments, the CLI) may write the same league file at once. Every SQLite
connection is set up by a ``connect`` event listener with ``journal_mode=WAL`` (readers never block the
writer), ``busy_timeout`` (a writer waits for the lock instead of failing), ``foreign_keys=ON`` and
``synchronous=NORMAL`` (durable against process crashes in WAL mode). pysqlite's own transaction handling
is switched off (``isolation_level = None``) and a ``begin`` event listener emits the ``BEGIN`` itself:
``BEGIN IMMEDIATE`` for write units of work, so the write lock is taken up front and waits under the busy
timeout (a deferred transaction that reads first and writes later can fail with ``SQLITE_BUSY`` without
waiting), and a plain deferred ``BEGIN`` for read-only units of work. A bounded retry on "database is
locked" covers what is left. Each batch of games is one transaction, so a crash never leaves half a batch, and
Ctrl-C or SIGTERM during a unit of work waits until it has committed or rolled back (:mod:`selfplay_cli.signals`):
an interrupt inside SQLAlchemy's own code could otherwise leave a connection in the middle of a transaction.
"""

from __future__ import annotations

import os
import random
import sqlite3
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from sqlalchemy import Connection, Engine, create_engine, event, inspect, select
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, DBAPIError, NoSuchModuleError, OperationalError
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.pool import StaticPool

from selfplay_cli.errors import EXIT_IO, MarlError, MarlIOError
from selfplay_cli.league.models import Base, Meta, utcnow
from selfplay_cli.signals import signals_held

__all__ = ["DB_FILENAME", "DEFAULT_HOME", "MIGRATIONS", "SCHEMA_VERSION", "Database", "LeagueError", "LeagueIOError",
           "shown"]

SCHEMA_VERSION = 3
"""Version of the schema in :mod:`selfplay_cli.league.models`, stored in ``meta.schema_version``. 2: matches have a
unique ``work_key``. 3: snapshot blobs and the work queue (``blobs``, ``workers``, ``jobs``)."""


def _add_work_keys(conn: Connection) -> None:
    """Version 1 to 2: ``matches.work_key`` (nullable; existing matches keep none) and its unique index."""
    if "work_key" not in {c["name"] for c in inspect(conn).get_columns("matches")}:
        conn.exec_driver_sql("ALTER TABLE matches ADD COLUMN work_key VARCHAR(200)")
    if "uq_matches_work_key" not in {i["name"] for i in inspect(conn).get_indexes("matches")}:
        conn.exec_driver_sql("CREATE UNIQUE INDEX uq_matches_work_key ON matches (work_key)")


def _add_queue(conn: Connection) -> None:
    """Version 2 to 3: the tables of snapshot blobs and the work queue."""
    from selfplay_cli.league.models import Blob, Job, Worker

    Base.metadata.create_all(conn, tables=[Blob.__table__, Worker.__table__, Job.__table__])


OLDEST_READABLE = 1
"""The oldest schema version a command that only reads reads as it is, without the upgrade it may not make:
version 2 added a column only writers use (``matches.work_key``, deferred in the mapping, so reads never select it)."""

MIGRATIONS: dict[int, Callable[[Connection], None]] = {1: _add_work_keys, 2: _add_queue}
"""``MIGRATIONS[v](conn)`` upgrades a version-``v`` database to ``v + 1`` inside the opening transaction; an older
database is accepted only if every step up to :data:`SCHEMA_VERSION` is here."""

DEFAULT_HOME = "./league"
DB_FILENAME = "league.db"

_LOCK_RETRIES = 8
T = TypeVar("T")
D = TypeVar("D", bound="Database")


class LeagueError(MarlError):
    """A user-facing league problem (unknown or duplicate name, bad database, version mismatch)."""


class LeagueIOError(LeagueError, MarlIOError):
    """The league's database or files could not be read or written for a reason outside marl (disk full, I/O error,
    file size limit, read-only file system, permissions); the message names the path and the cause."""

    exit_code = EXIT_IO


_IO_REASONS = ("disk i/o error", "database or disk is full", "readonly database", "unable to open database file",
               "read-only file system", "permission denied", "file too large", "no space left")


def shown(value: object, limit: int = 60) -> str:
    """``value`` for an error message: quoted, control characters escaped (never raw on a terminal), cut short."""
    text = value if isinstance(value, str) else str(value)
    cut = text[:limit]
    return repr(cut)[:-1] + ("..." + repr(cut)[-1] if len(text) > limit else repr(cut)[-1])


def _is_locked(exc: BaseException) -> bool:
    """True if a DB error is SQLite's transient "database is locked" / "busy"."""
    msg = str(getattr(exc, "orig", exc)).lower()
    return "database is locked" in msg or "database table is locked" in msg


def _sqlite_file(url: URL) -> Path | None:
    """The database file of a SQLite URL, or None (other backends, in-memory or URI databases)."""
    if url.get_backend_name() != "sqlite":
        return None
    db = url.database or ""
    if db in ("", ":memory:") or db.startswith("file:"):
        return None
    return Path(db).expanduser()


class Database:
    """A league database: the engine, its sessions and its schema (see the module docstring).

    Attributes:
        url: the SQLAlchemy URL (password hidden when rendered).
        home: the league home directory (snapshot files live under it); for a direct ``League(url)``
            it defaults to the directory of a SQLite file, else None.
        db_path: the SQLite database file, or None for other backends / in-memory databases.
        elo_k: K factor of the online Elo updates (default 16).
        lock_retries: how many times a unit of work was retried after "database is locked" (diagnostic).
    """

    def __init__(self, url: str | URL, *, home: str | Path | None = None, elo_k: float = 16.0,
                 busy_timeout: float = 30.0, readonly: bool = False) -> None:
        """Open (creating if new) the league at ``url``; with ``readonly`` open an existing one for reading only.

        A read-only league creates nothing (no folder, no database, no tables) and writes nothing: every method
        that would write raises :class:`LeagueError`. On SQLite it opens the file read-write but with
        ``query_only`` (so that, as the last connection, it tidies WAL files away like any other), falls back to
        ``mode=ro`` where the file or its folder cannot be written, and to ``immutable=1`` on read-only media where
        SQLite cannot even make its shared-memory file (no writer can be at work there then).

        Raises:
            LeagueError: invalid URL, missing driver, unreadable or foreign database, schema version
                this code cannot handle; read-only: no database there.
        """
        try:
            self.url: URL = make_url(url)
        except ArgumentError as exc:
            raise LeagueError(f"invalid database URL {shown(str(url))}") from exc
        self.db_path: Path | None = _sqlite_file(self.url)
        self.is_sqlite = self.url.get_backend_name() == "sqlite"
        self.readonly = bool(readonly)
        if home is not None:
            self.home: Path | None = Path(home).expanduser().resolve()
        else:
            self.home = self.db_path.resolve().parent if self.db_path is not None else None
        self.elo_k = float(elo_k)
        self.busy_timeout = float(busy_timeout)
        self.lock_retries = 0
        self._where = str(self.db_path) if self.db_path is not None else self.url.render_as_string(True)
        if self.readonly and self.db_path is not None and not self.db_path.is_file():
            raise LeagueError(f"no league database at {self._where} (nothing trained or imported there yet)")
        self._empty = False
        if self.db_path is not None and not self.readonly:
            try:
                self.db_path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise LeagueIOError(f"cannot create {self.db_path.parent}: {exc.strerror or exc}") from exc
        modes = ["rw", "ro", "ro&immutable=1"] if self.readonly and self.db_path is not None else [None]
        for i, mode in enumerate(modes):
            try:
                self._connect(mode)
                return
            except LeagueError:
                self.engine.dispose()
                raise
            except DBAPIError as exc:
                self.engine.dispose()
                reason = str(exc.orig).splitlines()[0] if exc.orig is not None else type(exc).__name__
                if i + 1 < len(modes) and ("unable to open" in reason or "readonly" in reason):
                    continue  # read-only file, folder or medium: the next, more restricted way to read it
                error = LeagueIOError if any(w in reason.lower() for w in _IO_REASONS) else LeagueError
                raise error(f"cannot open league database {self._where}: {reason}") from exc

    def _connect(self, mode: str | None) -> None:
        """Make the engine (a read-only SQLite file through a ``file:`` URI with ``mode``) and check the schema."""
        engine_url = self.url
        if mode is not None:
            assert self.db_path is not None
            uri = f"{self.db_path.resolve().as_uri()}?mode={mode}"
            engine_url = URL.create("sqlite", database=uri, query={"uri": "true"})
        self._empty = self.readonly and self.is_sqlite and self.db_path is None and self.url.database == ":memory:"
        try:
            if self._empty:  # an empty league to read: one connection (every thread sees the same tables)
                self.engine: Engine = create_engine(engine_url, poolclass=StaticPool,
                                                    connect_args={"check_same_thread": False})
            else:
                self.engine = create_engine(engine_url)
        except (NoSuchModuleError, ImportError) as exc:
            raise LeagueError(f"cannot use database {self._where}: no driver ({exc})") from exc
        if self.is_sqlite:
            self._install_sqlite_listeners()
        self._sessions = sessionmaker(self.engine, expire_on_commit=False)
        self._read_sessions = sessionmaker(self.engine.execution_options(marl_readonly=True),
                                           expire_on_commit=False)
        self._init_schema()

    @classmethod
    def open(cls: type[D], home: str | Path | None = None, url: str | None = None, *, readonly: bool = False,
             **kwargs: Any) -> D:
        """Open the league of ``home`` (default ``$MARL_HOME`` or ``./league``).

        ``url`` (default ``$MARL_DB``) wins over the home's ``league.db``; without it the home directory is
        created and ``sqlite:///<home>/league.db`` is used. ``home`` is kept either way (snapshot files).
        ``readonly`` opens the league for reading and creates nothing, not even the home: where there is no league
        yet, it reads an empty one (held in memory).
        """
        home_path = Path(home if home is not None else os.environ.get("MARL_HOME") or DEFAULT_HOME)
        home_path = home_path.expanduser().resolve()
        url = url or os.environ.get("MARL_DB") or None
        if url is None:
            if readonly:
                if not (home_path / DB_FILENAME).exists():  # nothing there yet: read an empty league, create nothing
                    return cls(URL.create("sqlite", database=":memory:"), home=home_path, readonly=True, **kwargs)
            else:
                try:
                    home_path.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise LeagueIOError(f"cannot create league home {home_path}: {exc.strerror or exc}") from exc
            # A URL object, not a string: a path with '?', '#' or '%' in it must not be re-parsed.
            return cls(URL.create("sqlite", database=str(home_path / DB_FILENAME)), home=home_path,
                       readonly=readonly, **kwargs)
        return cls(url, home=home_path, readonly=readonly, **kwargs)

    def home_path(self, *parts: str) -> Path:
        """``<home>/<parts...>``, checked to stay inside the home: every part a plain name (no separator, not
        ``.`` or ``..``), and below the top folder (``snapshots``, ``runs``, ``videos``; it may itself be a symlink to
        another disk) the resolved path, symlinks followed, still inside it. A :class:`LeagueError` otherwise.
        Nothing is created."""
        if self.home is None:
            raise LeagueError("this league has no home directory for its files: pass --home")
        for part in parts:
            if not isinstance(part, str) or part in ("", ".", "..") or any(c in part for c in "/\\\0"):
                raise LeagueError(f"{shown(part)} is not a plain file or folder name")
        path = self.home.joinpath(*parts)
        if len(parts) > 1 and not path.resolve().is_relative_to((self.home / parts[0]).resolve()):
            raise LeagueError(f"{path} leads outside the league home {self.home} (through a symlink)")
        return path

    # ---------------------------------------------------------------- engine, sessions, schema

    def _install_sqlite_listeners(self) -> None:
        busy_ms = int(self.busy_timeout * 1000)
        readonly_league = self.readonly

        @event.listens_for(self.engine, "connect")
        def _on_connect(dbapi_conn: sqlite3.Connection, _record: Any) -> None:
            # Take transaction control away from pysqlite; the "begin" listener emits BEGIN itself.
            dbapi_conn.isolation_level = None
            cur = dbapi_conn.cursor()
            try:
                cur.execute(f"PRAGMA busy_timeout = {busy_ms}")
                if readonly_league:
                    if not self._empty:  # (the empty league in memory gets its tables first; _unit refuses writes)
                        cur.execute("PRAGMA query_only = ON")
                    return
                cur.execute("PRAGMA foreign_keys = ON")
                for attempt in range(_LOCK_RETRIES):  # switching to WAL needs a moment of exclusivity
                    try:
                        cur.execute("PRAGMA journal_mode = WAL")
                        break
                    except sqlite3.OperationalError as exc:
                        if not _is_locked(exc) or attempt == _LOCK_RETRIES - 1:
                            raise
                        time.sleep(0.05 * (attempt + 1))
                cur.execute("PRAGMA synchronous = NORMAL")
            finally:
                cur.close()

        @event.listens_for(self.engine, "begin")
        def _on_begin(conn: Connection) -> None:
            readonly = readonly_league or conn.get_execution_options().get("marl_readonly", False)
            conn.exec_driver_sql("BEGIN" if readonly else "BEGIN IMMEDIATE")

    def _init_schema(self) -> None:
        """Create the tables of a new database, or check (and migrate) the stored schema version."""

        def init(conn: Connection) -> None:
            tables = set(inspect(conn).get_table_names())
            if "meta" not in tables:
                if tables & {"players", "games", "runs"} or (tables and self.db_path is not None):
                    raise LeagueError(f"{self._where} is not a marl league database (no meta table)")
                if self.readonly and not self._empty:
                    raise LeagueError(f"{self._where} holds no league yet (no tables)")
                Base.metadata.create_all(conn)
                conn.execute(Meta.__table__.insert().values(key="schema_version", value=str(SCHEMA_VERSION)))
                conn.execute(Meta.__table__.insert().values(key="created_at", value=utcnow().isoformat()))
                return
            raw = conn.execute(select(Meta.value).where(Meta.key == "schema_version")).scalar()
            try:
                stored = int(raw) if raw is not None else None
            except ValueError:
                stored = None
            if stored is None:
                raise LeagueError(f"league database {self._where} has no valid schema version ({raw!r})")
            self._migrate(conn, stored)

        for attempt in range(_LOCK_RETRIES + 1):
            try:
                with self.engine.begin() as conn:
                    init(conn)
                return
            except OperationalError as exc:
                if not (self.is_sqlite and _is_locked(exc)) or attempt == _LOCK_RETRIES:
                    raise
                self._backoff(attempt)

    def _migrate(self, conn: Connection, stored: int) -> None:
        """Bring a version-``stored`` database to :data:`SCHEMA_VERSION` through :data:`MIGRATIONS`."""
        if stored == SCHEMA_VERSION:
            return
        if stored > SCHEMA_VERSION:
            raise LeagueError(
                f"league database {self._where} has schema version {stored}, newer than version "
                f"{SCHEMA_VERSION} of this marl: upgrade marl"
            )
        missing = [v for v in range(stored, SCHEMA_VERSION) if v not in MIGRATIONS]
        if self.readonly and stored >= OLDEST_READABLE:
            return
        if self.readonly and not missing:
            raise LeagueError(
                f"league database {self._where} has schema version {stored} and needs upgrading to version "
                f"{SCHEMA_VERSION}, which a command that only reads does not do: run one that writes first"
            )
        if missing:
            raise LeagueError(
                f"league database {self._where} has schema version {stored}, this marl needs version "
                f"{SCHEMA_VERSION} and has no migration from it"
            )
        for v in range(stored, SCHEMA_VERSION):
            MIGRATIONS[v](conn)
        conn.execute(
            Meta.__table__.update().where(Meta.key == "schema_version").values(value=str(SCHEMA_VERSION))
        )

    def schema_version(self) -> int:
        """The schema version stored in the database."""
        with self.session(readonly=True) as s:
            return int(s.execute(select(Meta.value).where(Meta.key == "schema_version")).scalar_one())

    def close(self) -> None:
        """Close every pooled connection."""
        self.engine.dispose()

    def __enter__(self: D) -> D:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"League({self._where!r})"

    @contextmanager
    def session(self, readonly: bool = False) -> Iterator[Session]:
        """A session inside one transaction: committed on success, rolled back on error, then closed.

        On SQLite, a write session starts with ``BEGIN IMMEDIATE`` (it waits for the write lock up to
        the busy timeout); ``readonly=True`` starts a deferred transaction that never takes it.
        """
        maker = self._read_sessions if readonly else self._sessions
        with maker.begin() as s:
            yield s

    def _backoff(self, attempt: int) -> None:
        self.lock_retries += 1
        time.sleep(min(0.05 * 2**attempt, 2.0) * (0.5 + random.random()))

    def _unit(self, fn: Callable[[Session], T], readonly: bool = False) -> T:
        """Run ``fn`` in one transaction, retrying the whole unit a few times if SQLite reports a lock.

        A write unit of a read-only league is refused before anything starts."""
        if self.readonly and not readonly:
            raise LeagueError(f"league {self.home or self._where} is open read-only: this needs a command that writes")
        for attempt in range(_LOCK_RETRIES + 1):
            try:
                with signals_held(), self.session(readonly=readonly) as s:  # Ctrl-C waits for commit or rollback
                    return fn(s)
            except OperationalError as exc:
                if not (self.is_sqlite and _is_locked(exc)):
                    error = self._io_error(exc)
                    if error is exc:
                        raise
                    raise error from exc
                if attempt == _LOCK_RETRIES:
                    raise LeagueError(
                        f"league database {self._where} stayed locked by another process; try again"
                    ) from exc
                self._backoff(attempt)
        raise AssertionError("unreachable")  # pragma: no cover

    def _io_error(self, exc: OperationalError) -> Exception:
        """The error to raise for a database failure: one naming the database and the cause where the cause is
        outside marl (disk full, I/O error, read-only, cannot open; :class:`LeagueIOError`), a corrupt file
        (:class:`LeagueError`), else the error itself."""
        reason = str(exc.orig).splitlines()[0] if exc.orig is not None else str(exc)
        low = reason.lower()
        if any(w in low for w in _IO_REASONS):
            return LeagueIOError(f"league database {self._where}: {reason}")
        if "malformed" in low or "not a database" in low:
            return LeagueError(f"league database {self._where} is damaged ({reason})")
        return exc

    def _read(self, fn: Callable[[Session], T]) -> T:
        return self._unit(fn, readonly=True)

