"""The league's database: the engine, one session per unit of work, the schema and its version.

:class:`Database` is the base of :class:`~selfplay_cli.league.store.League`: it opens any SQLAlchemy URL (the default
is SQLite at ``<home>/league.db``), creates or checks the schema, and runs every unit of work in one transaction
(:meth:`Database._unit`), retried when SQLite reports a lock (PostgreSQL: see below; what each failure means:
:mod:`selfplay_cli.league.failures`). The home's layout is :mod:`selfplay_cli.league.home`. What is stored is in
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
SQLite's locks are not to be trusted on a network file system (NFS, SMB, sshfs, cluster file systems): a league file
there is refused (:mod:`selfplay_cli.league.url`) with a line that says to use PostgreSQL.

PostgreSQL
----------
``postgresql://`` and ``postgres://`` URLs mean psycopg 3 (``postgresql+psycopg://``), the driver of the
``[postgres]`` extra. Connections are checked before use (``pool_pre_ping``); a read-only unit of work runs in a
``READ ONLY`` transaction. A unit that fails on a serialization failure or a deadlock is retried like a SQLite lock;
one that loses the server (restarted, unreachable) is retried with backoff for up to :attr:`Database.reconnect_for`
seconds, saying once on stderr that it is waiting, then ends with a :class:`LeagueIOError` (exit 4). A unit whose
COMMIT went out but whose answer never came back is not retried (it may have been stored): that too is a
:class:`LeagueIOError`, and the command resumes from the league as it is; a unit keyed by its work (a unique work key
it looks for first: ``idempotent``) is, since done twice it counts once. A database with no tables yet, opened to
read, reads as an empty league and is left as it is.

The schema
----------
Versioned with Alembic (:mod:`selfplay_cli.league.migrations`). Opening a league creates a new one (``create_all``,
stamped with the newest revision), or checks the stored revision: a league written by a newer marl is refused, and
an older one (also one from before Alembic, by its ``meta.schema_version``) is upgraded in place by a command that
writes, in the opening transaction, with one line on stderr; a command that only reads reads it as it is. Two
processes opening a new or old league at once do not both create or upgrade it: SQLite's ``BEGIN IMMEDIATE`` and,
on PostgreSQL, a transaction-scoped advisory lock serialise the opening transactions.
"""

from __future__ import annotations

import os
import random
import sqlite3
import sys
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

from selfplay_cli.league import bounded_json, migrations
from selfplay_cli.league.failures import (
    IO_REASONS,
    PG_GONE,
    PG_REFUSED,
    PG_RETRY,
    LeagueError,
    LeagueIOError,
    LeagueUnreachable,
    NoLeagueYet,
    driver_reason,
    is_locked,
    shown,
    sqlstate,
)
from selfplay_cli.league.home import DB_FILENAME, DEFAULT_HOME, NEW_HOMES, SNAPSHOTS
from selfplay_cli.league.models import Base, Meta, utcnow
from selfplay_cli.league.rows import PlayerRow
from selfplay_cli.league.url import driver_url, refuse_network_sqlite, sqlite_file
from selfplay_cli.signals import signals_held

__all__ = ["Database", "Part"]

_LOCK_RETRIES = 8
_RECONNECT_FOR = 60.0
_SCHEMA_LOCK = 0x6D61726C  # "marl": the key of the advisory lock that serialises the opening of a PostgreSQL league
T = TypeVar("T")
D = TypeVar("D", bound="Database")


def _to_stderr(line: str) -> None:
    sys.stderr.write(line + "\n")
    sys.stderr.flush()



class Database:
    """A league database: the engine, its sessions and its schema (see the module docstring).

    Attributes:
        url: the SQLAlchemy URL (password hidden when rendered).
        home: the league home directory (snapshot files live under it); for a direct ``League(url)``
            it defaults to the directory of a SQLite file, else None.
        db_path: the SQLite database file, or None for other backends / in-memory databases.
        is_sqlite, is_postgres: the backend (for code that must differ, such as the work queue's
            ``FOR UPDATE SKIP LOCKED`` on PostgreSQL).
        elo_k: K factor of the online Elo updates (default 16).
        lock_retries: how many times a unit of work was retried after "database is locked", a serialization
            failure or a deadlock (diagnostic).
        reconnects: how many times a unit of work was retried after losing the server (diagnostic).
        reconnect_for: seconds a unit of work waits for a lost PostgreSQL server to come back (default 60).
        note: where a line for the user goes (an upgrade made, the server lost): stderr unless given.
    """

    def __init__(self, url: str | URL, *, home: str | Path | None = None, elo_k: float = 16.0,
                 busy_timeout: float = 30.0, readonly: bool = False, reconnect_for: float = _RECONNECT_FOR,
                 note: Callable[[str], None] | None = None, read_only_connection: bool = False) -> None:
        """Open (creating if new) the league at ``url``; with ``readonly`` open an existing one for reading only.

        A read-only league creates nothing (no folder, no database, no tables) and writes nothing: every method
        that would write raises :class:`LeagueError`. On SQLite it opens the file read-write but with
        ``query_only`` (so that, as the last connection, it tidies WAL files away like any other), falls back to
        ``mode=ro`` where the file or its folder cannot be written, and to ``immutable=1`` on read-only media where
        SQLite cannot even make its shared-memory file (no writer can be at work there then).
        ``read_only_connection`` (with ``readonly``; ``marl serve``): the connection itself cannot write, whatever is
        run through it: SQLite opens the file with ``mode=ro`` from the start, PostgreSQL's sessions start with
        ``default_transaction_read_only=on``.

        A league that a command that writes opens is brought to the newest schema first (one line through ``note``
        says so); a league written by a newer marl is refused.

        Raises:
            LeagueError: invalid URL, missing driver, unreadable or foreign database, wrong user, password or
                database name, schema this code cannot handle (written by a newer marl), SQLite on a network file
                system; read-only: no database there.
            LeagueIOError: the server cannot be reached, or the file cannot be read or written.
        """
        try:
            self.url: URL = driver_url(make_url(url))
        except ArgumentError as exc:
            raise LeagueError(f"invalid database URL {shown(str(url))}") from exc
        self.db_path: Path | None = sqlite_file(self.url)
        self.is_sqlite = self.url.get_backend_name() == "sqlite"
        self.is_postgres = self.url.get_backend_name() == "postgresql"
        self.readonly = bool(readonly or read_only_connection)
        self.read_only_connection = bool(read_only_connection)
        self.reconnect_for = float(reconnect_for)
        self.reconnects = 0
        self._lost_said = False  # "unreachable" said for the loss under way (once, whatever the threads)
        self.note: Callable[[str], None] = note or _to_stderr
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
        if self.db_path is not None:
            refuse_network_sqlite(self.db_path)
        self._empty = False
        if self.db_path is not None and not self.readonly:
            try:
                self.db_path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise LeagueIOError(f"cannot create {self.db_path.parent}: {exc.strerror or exc}") from exc
        modes = ["rw", "ro", "ro&immutable=1"] if self.readonly and self.db_path is not None else [None]
        if self.read_only_connection and self.db_path is not None:
            modes = modes[1:]
        for i, mode in enumerate(modes):
            try:
                self._connect(mode)
                return
            except NoLeagueYet:  # (a database just made for the league): read an empty one, create nothing
                self.engine.dispose()
                self._connect(None, empty=True)
                return
            except LeagueError:
                if hasattr(self, "engine"):  # (none where the driver is missing)
                    self.engine.dispose()
                raise
            except DBAPIError as exc:
                self.engine.dispose()
                reason = driver_reason(exc)
                if i + 1 < len(modes) and ("unable to open" in reason or "readonly" in reason):
                    continue  # read-only file, folder or medium: the next, more restricted way to read it
                if self.is_postgres and self._refused(exc):
                    raise LeagueError(f"cannot open league database {self._where}: {reason}") from exc
                if self.is_postgres and self._unreachable(exc):
                    raise LeagueUnreachable(f"cannot reach league database {self._where}: {reason}", self._where,
                                            reason) from exc
                error = LeagueIOError if any(w in reason.lower() for w in IO_REASONS) else LeagueError
                raise error(f"cannot open league database {self._where}: {reason}") from exc

    def _connect(self, mode: str | None, empty: bool = False) -> None:
        """Make the engine (a read-only SQLite file through a ``file:`` URI with ``mode``; ``empty``: an empty league
        in memory, to read) and check the schema."""
        engine_url = self.url
        if mode is not None:
            assert self.db_path is not None
            uri = f"{self.db_path.resolve().as_uri()}?mode={mode}"
            engine_url = URL.create("sqlite", database=uri, query={"uri": "true"})
        self._empty = empty or (self.readonly and self.is_sqlite and self.db_path is None
                                and self.url.database == ":memory:")
        if empty:
            engine_url = URL.create("sqlite", database=":memory:")
        try:
            # (JSON columns get their stored text and parse it with their bounds: models.BoundedJSON)
            if self._empty:  # an empty league to read: one connection (every thread sees the same tables)
                self.engine: Engine = create_engine(engine_url, poolclass=StaticPool,
                                                    json_deserializer=bounded_json.raw,
                                                    connect_args={"check_same_thread": False})
            else:  # a connection the server dropped (restarted) is found out before use, not by the unit of work
                connect_args = ({"options": "-c default_transaction_read_only=on"}
                                if self.is_postgres and self.read_only_connection else {})
                self.engine = create_engine(engine_url, pool_pre_ping=not self.is_sqlite,
                                            json_deserializer=bounded_json.raw, connect_args=connect_args)
        except (NoSuchModuleError, ImportError) as exc:
            extra = ' (pip install "selfplay-cli[postgres]")' if self.is_postgres else ""
            raise LeagueError(f"cannot use database {self._where}: no driver{extra} ({exc})") from exc
        if engine_url.get_backend_name() == "sqlite":
            self._install_sqlite_listeners()
        elif self.is_postgres:
            readonly_league = self.readonly

            @event.listens_for(self.engine, "begin")
            def _on_begin(conn: Connection) -> None:  # a unit that only reads cannot write, whatever it runs
                if readonly_league or conn.get_execution_options().get("marl_readonly", False):
                    conn.exec_driver_sql("SET TRANSACTION READ ONLY")
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
                refuse_network_sqlite(home_path / DB_FILENAME)  # before the home is made there
                if not home_path.exists():
                    NEW_HOMES.append(home_path)
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
                        if not is_locked(exc) or attempt == _LOCK_RETRIES - 1:
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
        """Create the tables of a new database, or check the stored schema and bring it to the newest (see the
        module docstring), in one transaction."""
        for attempt in range(_LOCK_RETRIES + 1):
            try:
                with self.engine.begin() as conn:
                    if self.is_postgres and not self.readonly:  # one opener at a time creates or upgrades
                        conn.exec_driver_sql(f"SELECT pg_advisory_xact_lock({_SCHEMA_LOCK})")
                    said = self._schema(conn)
                break
            except OperationalError as exc:
                if not self._transient(exc) or attempt == _LOCK_RETRIES:
                    raise
                self._backoff(attempt)
        if said:
            self.note(f"marl: {said}")

    def _schema(self, conn: Connection) -> str | None:
        """The work of :meth:`_init_schema`; what was upgraded, as a line for the user, or None."""
        tables = set(inspect(conn).get_table_names())
        if "meta" not in tables:
            if tables:
                raise LeagueError(f"{self._where} is not a marl league database (it holds other tables: "
                                  f"{', '.join(sorted(tables)[:3])}{', ...' if len(tables) > 3 else ''})")
            if self.readonly and not self._empty:
                if self.db_path is None:
                    raise NoLeagueYet(f"{self._where} holds no league yet")
                raise LeagueError(f"{self._where} holds no league yet (no tables)")
            Base.metadata.create_all(conn)
            migrations.stamp_head(conn)
            conn.execute(Meta.__table__.insert().values(key="schema_version", value=str(migrations.ALEMBIC_MARK)))
            conn.execute(Meta.__table__.insert().values(key="created_at", value=utcnow().isoformat()))
            return None
        revision = migrations.current(conn)
        legacy = None
        if revision is None:  # written before Alembic: its meta.schema_version says where it stands
            raw = conn.execute(select(Meta.value).where(Meta.key == "schema_version")).scalar()
            try:
                legacy = int(raw) if raw is not None else None
            except ValueError:
                legacy = None
            if legacy is None or legacy < 1:
                raise LeagueError(f"league database {self._where} has no valid schema version ({raw!r})")
            if legacy > migrations.ALEMBIC_MARK:
                raise LeagueError(f"league database {self._where} was written by a newer marl (schema {legacy}); "
                                  "upgrade marl")
        elif not migrations.known(revision):
            raise LeagueError(f"league database {self._where} was written by a newer marl (schema {revision}); "
                              "upgrade marl")
        if revision == migrations.head() or self.readonly:
            return None  # a command that only reads reads any schema this marl knows as it is
        start = revision if legacy is None else migrations.legacy_revision(conn, legacy)
        applied = migrations.upgrade(conn, start)
        conn.execute(Meta.__table__.update().where(Meta.key == "schema_version")
                     .values(value=str(migrations.ALEMBIC_MARK)))
        what = (["match work keys"] if legacy == 1 else []) + ([migrations.summary(applied)] if applied else [])
        return (f"upgraded league database {self._where} from schema {revision or legacy} to {migrations.head()}"
                f" ({'; '.join(what) or 'its version now kept by Alembic'})")

    def schema_revision(self) -> str:
        """The schema the database is at: its Alembic revision, or ``"legacy N"`` for a league from before Alembic
        that a command that only reads opened (``meta.schema_version`` N)."""

        def work(s: Session) -> str:
            conn = s.connection()
            revision = migrations.current(conn)
            if revision is not None:
                return revision
            return f"legacy {s.execute(select(Meta.value).where(Meta.key == 'schema_version')).scalar_one()}"

        return self._read(work)

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

    def snapshot_file(self, row: PlayerRow) -> Path:
        """The file of a snapshot row, checked to stay inside the league: the one way marl turns a path read from the
        database into a file it reads or deletes.

        A row's path is relative to the home and lies under its ``snapshots`` folder (``snapshots/<run>/<name>
        .safetensors``, as :func:`~selfplay_cli.players.files.snapshot_relpath` writes it): plain names only (no
        ``..``, no NUL byte), and, symlinks followed, still under ``snapshots`` (which may itself be a symlink to
        another disk). A path that is absolute, climbs out, or ends outside through a symlink is a row that was
        written by something else than marl or edited: a :class:`LeagueError` naming the snapshot, before anything
        is read or deleted. A league without a home (a database URL opened without ``--home``) has no files."""
        if not row.path:
            raise LeagueError(f"{row.full_name} has no snapshot file")
        if self.home is None:
            raise LeagueError(f"{row.full_name}: this league has no home directory for its snapshot files: pass "
                              "--home")
        leaves = LeagueError(f"{row.full_name}: its file path {shown(row.path)} leaves the league (snapshot files "
                             f"lie under {self.home / SNAPSHOTS}): the row was not written by marl; nothing was read "
                             "or deleted")
        parts = Path(row.path).parts if "\0" not in row.path else ()
        if len(parts) < 2 or parts[0] != SNAPSHOTS:  # absolute ('/' first), another folder, or a bare name
            raise leaves
        try:
            return self.home_path(*parts)  # plain names; symlinks followed, still under snapshots/
        except LeagueError:
            raise leaves from None

    def _backoff(self, attempt: int) -> None:
        self.lock_retries += 1
        time.sleep(min(0.05 * 2**attempt, 2.0) * (0.5 + random.random()))

    def _transient(self, exc: OperationalError) -> bool:
        """True for a failure that retrying the unit at once cures: SQLite's lock, PostgreSQL's serialization
        failure or deadlock."""
        return is_locked(exc) if self.is_sqlite else sqlstate(exc) in PG_RETRY

    def _refused(self, exc: DBAPIError) -> bool:
        """True if the PostgreSQL server refused the URL's user, password or database (the user's to fix)."""
        return any(w in driver_reason(exc).lower() for w in PG_REFUSED)

    def _unreachable(self, exc: DBAPIError) -> bool:
        """True if the PostgreSQL server was lost or cannot be reached: the connection broke, the server is
        shutting down or starting up, or no server answers at the URL."""
        if not self.is_postgres or self._refused(exc):
            return False
        state = sqlstate(exc)
        return (bool(exc.connection_invalidated) or (state or "").startswith("08") or state in PG_GONE
                or (state is None and isinstance(exc, OperationalError)))

    def _unit(self, fn: Callable[[Session], T], readonly: bool = False, idempotent: bool = False) -> T:
        """Run ``fn`` in one transaction, retrying the whole unit a few times if SQLite reports a lock or PostgreSQL a
        serialization failure or deadlock, and for up to :attr:`reconnect_for` seconds while the PostgreSQL server
        is lost (one line says so, once). A unit whose COMMIT was sent when the server was lost is not retried: it
        may have been stored (:class:`LeagueIOError`); unless it is ``idempotent`` (done twice, it counts once: its
        rows are keyed by a unique work key that it looks for first).

        A write unit of a read-only league is refused before anything starts."""
        if self.readonly and not readonly:
            raise LeagueError(f"league {self.home or self._where} is open read-only: this needs a command that writes")
        attempt = tries = 0
        lost_since: float | None = None
        while True:
            committing = False
            try:
                with signals_held(), self.session(readonly=readonly) as s:  # Ctrl-C waits for commit or rollback
                    result = fn(s)
                    committing = True  # leaving the block commits
                if lost_since is not None:
                    self._lost_said = False  # back: a later loss is said again
                return result
            except DBAPIError as exc:
                if self._transient(exc):
                    if attempt == _LOCK_RETRIES:
                        busy = "locked by another process" if self.is_sqlite else "in conflict with other writers"
                        raise LeagueError(f"league database {self._where} stayed {busy}; try again") from exc
                    self._backoff(attempt)
                    attempt += 1
                    continue
                if not self._unreachable(exc):
                    error = self._io_error(exc) if isinstance(exc, OperationalError) else exc
                    if error is exc:
                        raise
                    raise error from exc
                if committing and not (readonly or idempotent):
                    raise LeagueIOError(f"lost league database {self._where} while committing (the last write may or "
                                        f"may not be stored; run the command again): {driver_reason(exc)}") from exc
                now = time.monotonic()
                if lost_since is None:
                    lost_since = now
                    if not self._lost_said:  # once for the process, whatever its threads that wait
                        self._lost_said = True
                        self.note(f"marl: league database {self._where} unreachable, retrying for up to "
                                  f"{self.reconnect_for:.0f} s ({driver_reason(exc)})")
                if now - lost_since >= self.reconnect_for:
                    raise LeagueUnreachable(f"league database {self._where} unreachable for {self.reconnect_for:.0f} "
                                            f"s: {driver_reason(exc)}", self._where, driver_reason(exc)) from exc
                self.reconnects += 1
                tries += 1
                time.sleep(min(0.25 * 2 ** min(tries, 5), 5.0, lost_since + self.reconnect_for - now))

    def _io_error(self, exc: OperationalError) -> Exception:
        """The error to raise for a database failure: one naming the database and the cause where the cause is
        outside marl (disk full, I/O error, read-only, cannot open; :class:`LeagueIOError`), a corrupt file
        (:class:`LeagueError`), else the error itself."""
        reason = str(exc.orig).splitlines()[0] if exc.orig is not None else str(exc)
        low = reason.lower()
        if any(w in low for w in IO_REASONS):
            return LeagueIOError(f"league database {self._where}: {reason}")
        if "malformed" in low or "not a database" in low:
            return LeagueError(f"league database {self._where} is damaged ({reason})")
        return exc

    def _read(self, fn: Callable[[Session], T]) -> T:
        return self._unit(fn, readonly=True)


class Part:
    """One concern of a league (its roster, ledger, seed ranges, blobs or work queue) over the database the league's
    parts share: every unit of work runs through :attr:`db` (one transaction, retried as :meth:`Database._unit`
    says)."""

    def __init__(self, db: Database) -> None:
        self.db = db

    def _unit(self, fn: Callable[[Session], T], readonly: bool = False, idempotent: bool = False) -> T:
        return self.db._unit(fn, readonly=readonly, idempotent=idempotent)

    def _read(self, fn: Callable[[Session], T]) -> T:
        return self.db._read(fn)
