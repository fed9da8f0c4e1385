"""The league ledger: players (bots and snapshots), runs, matches and the append-only game ledger.

A :class:`League` wraps one SQLAlchemy engine. The default database is SQLite at
``<home>/league.db`` (home: ``MARL_HOME`` or ``./league``), but any SQLAlchemy URL works
(``MARL_DB``). Every rating is derived from the ``games`` / ``game_seats`` ledger; the online Elo kept on
each player row is a cache updated in the same transaction as the games it counts, and
:meth:`League.recompute_online_elo` rebuilds it from scratch.

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
locked" covers what is left. Each batch of games is one transaction, so a crash never leaves half a batch.

Objects returned to callers are frozen dataclasses (:class:`RunRow`, :class:`PlayerRow`, :class:`GameTable`),
never ORM instances, so nothing lazy-loads after a session has closed. A :class:`League` must not be
shared across ``fork``; open one per process.
"""

from __future__ import annotations

import math
import os
import random
import re
import sqlite3
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from sqlalchemy import Connection, Engine, and_, case, create_engine, event, func, inspect, or_, select
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, DBAPIError, IntegrityError, NoSuchModuleError, OperationalError
from sqlalchemy.orm import Session, aliased, raiseload, sessionmaker
from sqlalchemy.pool import StaticPool

from selfplay_cli.errors import EXIT_IO, MarlError, MarlIOError
from selfplay_cli.files import file_sha256
from selfplay_cli.league.models import Base, Game, GameSeat, Match, Meta, Player, Run, Tag, utcnow
from selfplay_cli.stats.elo import elo_update

__all__ = [
    "DEFAULT_ELO",
    "DEFAULT_HOME",
    "DB_FILENAME",
    "MATCH_KINDS",
    "MIGRATIONS",
    "RESERVED_NAMES",
    "RUN_STATUSES",
    "SCHEMA_VERSION",
    "GameRecord",
    "GameRow",
    "GameTable",
    "League",
    "LeagueError",
    "LeagueIOError",
    "PlayerRow",
    "RunRow",
    "check_existing_name",
    "check_name",
]

SCHEMA_VERSION = 1
"""Version of the schema in :mod:`selfplay_cli.league.models`, stored in ``meta.schema_version``."""

MIGRATIONS: dict[int, Callable[[Connection], None]] = {}
"""``MIGRATIONS[v](conn)`` upgrades a version-``v`` database to ``v + 1`` inside the opening transaction.

Empty for now; an older database is accepted only if every step up to :data:`SCHEMA_VERSION` is here."""

DEFAULT_HOME = "./league"
DB_FILENAME = "league.db"
DEFAULT_ELO = 1000.0
MATCH_KINDS = ("match", "tournament", "gate", "training", "eval")
RUN_STATUSES = ("running", "finished", "killed", "failed", "interrupted")
"""Run statuses the rest of marl uses; :meth:`League.set_run_status` accepts any short word."""
RESERVED_NAMES = ("latest", "best")
"""Names resolved by higher-level code; no tag may take them."""

_MAX_NAME = 200
_LOCK_RETRIES = 8
T = TypeVar("T")


class LeagueError(MarlError):
    """A user-facing league problem (unknown or duplicate name, bad database, version mismatch)."""


class LeagueIOError(LeagueError, MarlIOError):
    """The league's database or files could not be read or written for a reason outside marl (disk full, I/O error,
    file size limit, read-only file system, permissions); the message names the path and the cause."""

    exit_code = EXIT_IO


_IO_REASONS = ("disk i/o error", "database or disk is full", "readonly database", "unable to open database file",
               "read-only file system", "permission denied", "file too large", "no space left")


# --------------------------------------------------------------------------------------------------
# Plain data returned to callers
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunRow:
    """A training run."""

    id: int
    name: str
    env: str
    algo: str | None
    config: dict[str, Any]
    status: str
    created_at: datetime


@dataclass(frozen=True)
class PlayerRow:
    """A bot or snapshot. ``elo`` / ``games`` are the online Elo and the number of games played."""

    id: int
    env: str
    kind: str
    name: str
    run: str | None
    step: int
    episode: int
    algo: str | None
    path: str | None
    sha256: str | None
    parent_id: int | None
    tags: tuple[str, ...]
    elo: float
    games: int
    removed: bool
    created_at: datetime
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def full_name(self) -> str:
        """``run/name`` for a snapshot of a run, else the bare name (bots, run-less snapshots)."""
        return f"{self.run}/{self.name}" if self.run else self.name

    @property
    def is_bot(self) -> bool:
        """True for scripted bots."""
        return self.kind == "bot"


@dataclass(frozen=True)
class GameRecord:
    """One finished game, the input of :meth:`League.record_games`.

    Attributes:
        env: environment id (must be the match's env and every player's env).
        players: player id per seat.
        seed: the environment seed of the game.
        scores: raw score per seat (e.g. points in Pong).
        outcome: result points per seat: 1 win, 0.5 draw, 0 loss (2-seat games: must sum to 1).
        length: number of steps.
        truncated: True if the game hit the step limit.
        actions: optional compressed action record, for replays.
    """

    env: str
    players: tuple[int, ...]
    seed: int
    scores: tuple[float, ...]
    outcome: tuple[float, ...]
    length: int
    truncated: bool
    actions: bytes | None = None


@dataclass(frozen=True)
class GameRow:
    """One stored game with everything needed to replay it: :meth:`League.game`.

    ``players`` are player ids per seat; ``match_params`` are the parameters of the match that played it (for
    rated and training matches, ``env_options``: the game options it was played under); ``actions`` the encoded
    action record, None for games stored without one (by an older marl).
    """

    id: int
    match_id: int
    match_kind: str
    match_params: dict[str, Any]
    env: str
    seed: int
    length: int
    truncated: bool
    players: tuple[int, ...]
    scores: tuple[float, ...]
    outcome: tuple[float, ...]
    actions: bytes | None
    created_at: datetime


@dataclass(frozen=True)
class GameTable:
    """Two-player games of the ledger as numpy arrays, in game-id order, for rating fits.

    Only games with exactly two seats held by two different players are included (a player against
    itself carries no rating information). ``score_a`` is seat 0's points (1 / 0.5 / 0).
    """

    game_id: npt.NDArray[np.int64]
    match_id: npt.NDArray[np.int64]
    player_a: npt.NDArray[np.int64]
    player_b: npt.NDArray[np.int64]
    score_a: npt.NDArray[np.float64]
    seed: npt.NDArray[np.int64]
    length: npt.NDArray[np.int64]
    truncated: npt.NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.game_id.size)

    def player_ids(self) -> npt.NDArray[np.int64]:
        """Sorted distinct player ids that appear in the table."""
        return np.unique(np.concatenate([self.player_a, self.player_b])).astype(np.int64)

    def indexed(
        self, ids: Sequence[int] | npt.ArrayLike | None = None
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Map player ids to indices ``0..n-1`` for :func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`.

        Args:
            ids: the population (default :meth:`player_ids`); every player in the table must be in it.

        Returns:
            ``(ids, a, b)``: the id of each index and the per-game index arrays of seat 0 and seat 1.
        """
        pop = self.player_ids() if ids is None else np.asarray(ids, dtype=np.int64).ravel()
        order = np.argsort(pop, kind="stable")
        sorted_ids = pop[order]

        def lookup(x: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
            pos = np.searchsorted(sorted_ids, x)
            pos = np.clip(pos, 0, max(sorted_ids.size - 1, 0))
            if x.size and (sorted_ids.size == 0 or np.any(sorted_ids[pos] != x)):
                raise ValueError("GameTable.indexed: a player of the table is missing from ids")
            return order[pos].astype(np.int64)

        return pop, lookup(self.player_a), lookup(self.player_b)

    def select(self, mask: npt.NDArray[np.bool_]) -> GameTable:
        """The sub-table of the games where ``mask`` is True."""
        return GameTable(*(getattr(self, f)[mask] for f in _GAME_TABLE_FIELDS))

    @classmethod
    def empty(cls) -> GameTable:
        """A table without games."""
        i = np.zeros(0, dtype=np.int64)
        return cls(i, i.copy(), i.copy(), i.copy(), np.zeros(0), i.copy(), i.copy(), np.zeros(0, dtype=bool))


_GAME_TABLE_FIELDS = ("game_id", "match_id", "player_a", "player_b", "score_a", "seed", "length", "truncated")


# --------------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------------


NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*")
"""What a run, snapshot, tag, bot or env name may be: ASCII letters, digits and ``. _ + -``, starting with a letter or
digit (so never ``.``, ``..``, a hidden file or something that reads as an option). A name becomes a folder or file
name under the league home and is printed on terminals, so nothing else gets in: no ``/``, no spaces, no control
characters (escape sequences)."""


def shown(value: object, limit: int = 60) -> str:
    """``value`` for an error message: quoted, control characters escaped (never raw on a terminal), cut short."""
    text = value if isinstance(value, str) else str(value)
    cut = text[:limit]
    return repr(cut)[:-1] + ("..." + repr(cut)[-1] if len(text) > limit else repr(cut)[-1])


def check_name(what: str, value: object) -> str:
    """Validate a run / snapshot / bot / tag / env name (:data:`NAME_PATTERN`, at most 200 characters) and return
    it; a :class:`LeagueError` saying what is allowed otherwise. The one place names are checked: the store calls it
    before every insert, and code that builds paths from names calls it before creating anything."""
    if not isinstance(value, str) or not value:
        raise LeagueError(f"invalid {what} {shown(value)}: a name must not be empty")
    if len(value) > _MAX_NAME:
        raise LeagueError(f"invalid {what} {shown(value)}: longer than {_MAX_NAME} characters")
    if not NAME_PATTERN.fullmatch(value):
        raise LeagueError(f"invalid {what} {shown(value)}: use letters, digits and . _ + - "
                          "(starting with a letter or digit)")
    return value


_check_name = check_name


def check_existing_name(what: str, value: object) -> str:
    """The looser check for a name already in a league (a run an older marl created, which :func:`check_name`
    might refuse for a space or an accent): still a plain folder name, never ``.``/``..``, no separator, nothing
    unprintable. New names always go through :func:`check_name`."""
    if (not isinstance(value, str) or not value or len(value) > _MAX_NAME or value in (".", "..")
            or any(c in value for c in "/\\") or not value.isprintable()):
        raise LeagueError(f"invalid {what} {shown(value)}: not a plain name")
    return value


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


def _player_row(p: Player) -> PlayerRow:
    """Copy an ORM player (with its run and tags loaded) into a :class:`PlayerRow`."""
    return PlayerRow(
        id=p.id, env=p.env, kind=p.kind, name=p.name, run=p.run.name if p.run is not None else None,
        step=int(p.step or 0), episode=int(p.episode or 0), algo=p.algo, path=p.path, sha256=p.sha256,
        parent_id=p.parent_id, tags=tuple(t.tag for t in p.tags), elo=float(p.elo), games=int(p.games),
        removed=bool(p.removed), created_at=p.created_at, meta=dict(p.meta or {}),
    )


def _run_row(r: Run) -> RunRow:
    """Copy an ORM run into a :class:`RunRow`."""
    return RunRow(id=r.id, name=r.name, env=r.env, algo=r.algo, config=dict(r.config or {}), status=r.status,
                  created_at=r.created_at)


# --------------------------------------------------------------------------------------------------
# The league
# --------------------------------------------------------------------------------------------------


class League:
    """The league database: players, runs, matches and the game ledger.

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
    def open(cls, home: str | Path | None = None, url: str | None = None, *, readonly: bool = False,
             **kwargs: Any) -> League:
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

    def __enter__(self) -> League:
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
                with self.session(readonly=readonly) as s:
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

    # ---------------------------------------------------------------- runs

    def create_run(self, name: str, env: str, config: dict[str, Any], algo: str | None = None,
                   status: str = "running") -> RunRow:
        """Register a new training run. Raises LeagueError if the name is taken."""
        _check_name("run name", name)
        _check_name("env", env)

        def work(s: Session) -> RunRow:
            if s.execute(select(Run.id).where(Run.name == name)).first() is not None:
                raise LeagueError(f"run {name!r} already exists")
            run = Run(name=name, env=env, algo=algo, config=dict(config or {}), status=status)
            s.add(run)
            s.flush()
            return _run_row(run)

        try:
            return self._unit(work)
        except IntegrityError as exc:  # lost a race against another process
            raise LeagueError(f"run {name!r} already exists") from exc

    def get_run(self, name: str) -> RunRow | None:
        """The run called ``name``, or None."""

        def work(s: Session) -> RunRow | None:
            run = s.execute(select(Run).where(Run.name == name)).scalar_one_or_none()
            return _run_row(run) if run is not None else None

        return self._read(work)

    def set_run_status(self, name: str, status: str) -> None:
        """Set a run's status (``running``, ``finished``, ``killed``, ...). Raises LeagueError if unknown."""
        if not status or not status.strip():
            raise LeagueError("run status must not be empty")

        def work(s: Session) -> None:
            run = s.execute(select(Run).where(Run.name == name)).scalar_one_or_none()
            if run is None:
                raise LeagueError(f"no run named {name!r}")
            run.status = status

        self._unit(work)

    def list_runs(self, env: str | None = None) -> list[RunRow]:
        """All runs (of ``env``), oldest first."""

        def work(s: Session) -> list[RunRow]:
            q = select(Run).order_by(Run.id)
            if env is not None:
                q = q.where(Run.env == env)
            return [_run_row(r) for r in s.execute(q).scalars()]

        return self._read(work)

    # ---------------------------------------------------------------- players

    def ensure_bots(self, env: str, names: Iterable[str]) -> None:
        """Make sure a bot player exists for each name in ``env`` (idempotent)."""
        _check_name("env", env)
        wanted = [_check_name("bot name", n) for n in dict.fromkeys(names)]
        if not wanted:
            return

        def have(s: Session) -> set[str]:
            q = select(Player.name).where(Player.env == env, Player.run_id.is_(None), Player.name.in_(wanted))
            return set(s.execute(q).scalars())

        if set(wanted) <= self._read(have):  # the common case: nothing to write, no write lock
            return

        def work(s: Session) -> None:
            rows = s.execute(select(Player).where(Player.env == env, Player.run_id.is_(None),
                                                  Player.name.in_(wanted))).scalars().all()
            existing = {p.name: p for p in rows}
            for n in wanted:
                p = existing.get(n)
                if p is None:
                    s.add(Player(env=env, kind="bot", name=n))
                elif p.kind != "bot":
                    raise LeagueError(f"bot name {n!r} is taken by a snapshot without run in env {env!r}")

        try:
            self._unit(work)
        except IntegrityError:  # another process added the same bots first (non-SQLite backends)
            self._unit(work)

    def add_snapshot(self, *, env: str, run: str | None, name: str, path: str, sha256: str | None = None,
                     step: int = 0, episode: int = 0, algo: str | None = None, parent_id: int | None = None,
                     meta: dict[str, Any] | None = None, run_config: dict[str, Any] | None = None) -> PlayerRow:
        """Register a policy snapshot. Raises LeagueError if ``(env, run, name)`` exists or run/parent is unknown.

        ``path`` is the file, relative to the home (or absolute); ``sha256`` the sha256 of the whole file (see
        :attr:`Player.sha256 <selfplay_cli.league.models.Player.sha256>`). With the file in place the store hashes it
        itself: ``sha256`` may be left out, and one given must be the file's or, as callers passed before it meant
        the file, the weights' checksum of ``meta["weights_sha256"]`` (the file's hash is stored then). Without the
        file (kept elsewhere) the given ``sha256`` is stored as it is.

        ``run_config``: a ``run`` that does not exist yet is created with it (status ``finished``), in the same
        transaction as the snapshot (an import that fails leaves no empty run behind).
        """
        return self.add_snapshots([dict(env=env, run=run, name=name, path=path, sha256=sha256, step=step,
                                        episode=episode, algo=algo, parent_id=parent_id, meta=meta)],
                                  run_config=run_config)[0]

    def add_snapshots(self, items: Sequence[dict[str, Any]], run_config: dict[str, Any] | None = None
                      ) -> list[PlayerRow]:
        """Register several snapshots (the keyword arguments of :meth:`add_snapshot`, one dict each) in ONE
        transaction: all of them or none (a training run's snapshots of one moment are one unit). ``run_config``
        as in :meth:`add_snapshot`."""
        for item in items:
            _check_name("env", item["env"])
            _check_name("snapshot name", item["name"])
            if item.get("run") is not None:  # a new run is checked like any new name; an existing one stays usable
                (check_name if run_config is not None else check_existing_name)("run name", item["run"])
        items = [{**item, "sha256": self._file_hash(item)} for item in items]

        def insert(s: Session, env: str, run: str | None, name: str, path: str, sha256: str, step: int = 0,
                   episode: int = 0, algo: str | None = None, parent_id: int | None = None,
                   meta: dict[str, Any] | None = None) -> Player:
            where = f"{run}/{name}" if run else name
            run_row: Run | None = None
            if run is not None:
                run_row = s.execute(select(Run).where(Run.name == run)).scalar_one_or_none()
                if run_row is None and run_config is not None:
                    run_row = Run(name=run, env=env, algo=algo, config=dict(run_config), status="finished")
                    s.add(run_row)
                    s.flush()
                if run_row is None:
                    raise LeagueError(f"no run named {run!r}")
                if run_row.env != env:
                    raise LeagueError(f"run {run!r} trains env {run_row.env!r}, not {env!r}")
            dup = select(Player.id).where(Player.env == env, Player.name == name)
            dup = dup.where(Player.run_id == run_row.id) if run_row is not None else dup.where(Player.run_id.is_(None))
            if s.execute(dup).first() is not None:
                raise LeagueError(f"snapshot {where!r} already exists in env {env!r}")
            if parent_id is not None:
                parent = s.get(Player, parent_id)
                if parent is None:
                    raise LeagueError(f"no player with id {parent_id} (parent of {where!r})")
            p = Player(env=env, kind="snapshot", name=name, run=run_row, step=int(step), episode=int(episode),
                       algo=algo, path=str(path), sha256=sha256, parent_id=parent_id, meta=dict(meta or {}),
                       elo=DEFAULT_ELO, games=0, removed=False)
            s.add(p)
            s.flush()
            return p

        def work(s: Session) -> list[PlayerRow]:
            players = [insert(s, **item) for item in items]
            for p in players:
                s.refresh(p, ["tags"])
            return [_player_row(p) for p in players]

        try:
            return self._unit(work)
        except IntegrityError as exc:
            names = ", ".join(f"{i['run']}/{i['name']}" if i["run"] else i["name"] for i in items)
            raise LeagueError(f"snapshot {names} already exists") from exc

    def _file_hash(self, item: dict[str, Any]) -> str:
        """The sha256 a snapshot row gets: its file's (see :meth:`add_snapshot`)."""
        given, where = item.get("sha256"), item["path"]
        file = Path(where)
        if not file.is_absolute():
            if self.home is None:
                file = None  # type: ignore[assignment]
            else:
                file = self.home_path(*Path(where).parts)
        if file is not None and file.is_file():
            try:
                actual = file_sha256(file)
            except OSError as exc:
                raise LeagueError(f"{file}: cannot read ({exc.strerror or exc})") from exc
            legacy = (item.get("meta") or {}).get("weights_sha256")
            if given is not None and given != actual and given != legacy:
                raise LeagueError(f"{file}: the file's sha256 is not the {given[:12]}... given for it (changed while "
                                  "it was being registered?)")
            return actual
        if not given:
            raise LeagueError(f"no snapshot file at {file or where} to register")
        return str(given)

    def get_player(self, player_id: int) -> PlayerRow:
        """The player with this id (removed ones included). Raises LeagueError if there is none."""

        def work(s: Session) -> PlayerRow:
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            return _player_row(p)

        return self._read(work)

    def players(self, env: str | None = None, kind: str | None = None,
                include_removed: bool = False) -> list[PlayerRow]:
        """Players (of ``env``, of ``kind`` "bot" / "snapshot") in id order."""

        def work(s: Session) -> list[PlayerRow]:
            q = select(Player).order_by(Player.id)
            if env is not None:
                q = q.where(Player.env == env)
            if kind is not None:
                q = q.where(Player.kind == kind)
            if not include_removed:
                q = q.where(Player.removed.is_(False))
            return [_player_row(p) for p in s.execute(q).unique().scalars()]

        return self._read(work)

    def find_players(self, name: str, env: str | None = None, include_removed: bool = False) -> list[PlayerRow]:
        """Every player that ``name`` could mean, in id order (empty if none; several if ambiguous).

        ``name`` is matched as: an integer id (``"12"``), a bot name, a snapshot name in any run
        (``"ep90"``), ``"run/name"``, or a tag. The special names ``latest`` / ``best`` are left to the
        caller (see :meth:`latest`). Removed snapshots are skipped unless ``include_removed``.
        """
        name = name.strip()
        if not name:
            return []

        def work(s: Session) -> list[PlayerRow]:
            conds = [Player.name == name]  # bot or snapshot name
            if name.isdigit():
                conds.append(Player.id == int(name))
            if "/" in name:
                run_name, _, snap = name.partition("/")
                run_ids = select(Run.id).where(Run.name == run_name).scalar_subquery()
                conds.append(and_(Player.name == snap, Player.run_id == run_ids))
            tag_q = select(Tag.player_id).where(Tag.tag == name)
            if env is not None:
                tag_q = tag_q.where(Tag.env == env)
            conds.append(Player.id.in_(tag_q))
            q = select(Player).where(or_(*conds)).order_by(Player.id)
            if env is not None:
                q = q.where(Player.env == env)
            if not include_removed:
                q = q.where(Player.removed.is_(False))
            return [_player_row(p) for p in s.execute(q).unique().scalars()]

        return self._read(work)

    def latest(self, env: str | None = None, run: str | None = None) -> PlayerRow | None:
        """The most recently created (not removed) snapshot, of ``env`` / ``run`` if given."""

        def work(s: Session) -> PlayerRow | None:
            q = select(Player).where(Player.kind == "snapshot", Player.removed.is_(False))
            if env is not None:
                q = q.where(Player.env == env)
            if run is not None:
                q = q.join(Run, Run.id == Player.run_id).where(Run.name == run)
            p = s.execute(q.order_by(Player.id.desc()).limit(1)).unique().scalar_one_or_none()
            return _player_row(p) if p is not None else None

        return self._read(work)

    def tag(self, player_id: int, tag: str) -> None:
        """Tag a player; a tag already on another player of the env moves to this one.

        Raises LeagueError for an unknown or removed player, a tag equal to a bot name of the env, a
        reserved name (``latest``, ``best``) or an all-digit tag (it would read as an id).
        """
        _check_name("tag", tag)
        if tag in RESERVED_NAMES:
            raise LeagueError(f"tag {tag!r} is reserved")
        if tag.isdigit():
            raise LeagueError(f"tag {tag!r} would be read as a player id")

        def work(s: Session) -> None:
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            if p.removed:
                raise LeagueError(f"player {p.id} ({p.name}) has been removed")
            bot = select(Player.id).where(Player.env == p.env, Player.kind == "bot", Player.name == tag)
            if s.execute(bot).first() is not None:
                raise LeagueError(f"tag {tag!r} would shadow the bot of that name in env {p.env!r}")
            old = s.execute(select(Tag).where(Tag.env == p.env, Tag.tag == tag)).scalar_one_or_none()
            if old is not None:
                if old.player_id == p.id:
                    return
                s.delete(old)
                s.flush()
            s.add(Tag(env=p.env, tag=tag, player_id=p.id))

        self._unit(work)

    def untag(self, tag: str, env: str | None = None) -> None:
        """Remove a tag. Raises LeagueError if it does not exist, or exists in several envs and env is None."""

        def work(s: Session) -> None:
            q = select(Tag).where(Tag.tag == tag)
            if env is not None:
                q = q.where(Tag.env == env)
            rows = s.execute(q).scalars().all()
            if not rows:
                raise LeagueError(f"no tag {tag!r}" + (f" in env {env!r}" if env else ""))
            if len(rows) > 1:
                envs = ", ".join(sorted(r.env for r in rows))
                raise LeagueError(f"tag {tag!r} exists in several envs ({envs}); choose one with --env")
            s.delete(rows[0])

        self._unit(work)

    def remove_snapshot(self, player_id: int) -> PlayerRow:
        """Mark a snapshot removed (soft delete) and drop its tags; its games stay in the ledger.

        Returns the player row as it was just before removal (with its path, so the caller can delete
        the file, and its former tags). Raises LeagueError for bots, unknown or already removed players.
        """

        def work(s: Session) -> PlayerRow:
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            if p.kind != "snapshot":
                raise LeagueError(f"player {p.id} ({p.name}) is a bot; only snapshots can be removed")
            if p.removed:
                raise LeagueError(f"snapshot {p.id} ({p.name}) is already removed")
            before = _player_row(p)
            for t in list(p.tags):
                s.delete(t)
            p.removed = True
            p.removed_at = utcnow()
            return replace(before, removed=True)

        return self._unit(work)

    # ---------------------------------------------------------------- matches and games

    def create_match(self, env: str, kind: str, params: dict[str, Any] | None = None) -> int:
        """Open a match record (kind: match, tournament, gate, training, eval) and return its id."""
        _check_name("env", env)
        if kind not in MATCH_KINDS:
            raise LeagueError(f"unknown match kind {kind!r} (expected one of {', '.join(MATCH_KINDS)})")

        def work(s: Session) -> int:
            m = Match(env=env, kind=kind, params=dict(params or {}))
            s.add(m)
            s.flush()
            return m.id

        return self._unit(work)

    def record_games(self, match_id: int, games: Sequence[GameRecord]) -> list[int]:
        """Append a batch of games to the ledger in ONE transaction and update the online Elo.

        The online Elo of the two players of every 2-seat game between different players is updated
        with :func:`~selfplay_cli.stats.elo.elo_update` (K = :attr:`elo_k`) in game order; every
        player's ``games`` counter counts each game it sat in once. Games with more seats are stored
        but leave the Elo alone. Either the whole batch is stored or nothing is.

        Returns:
            The new game ids, in the order of ``games``.

        Raises:
            LeagueError: unknown match or player, env mismatch, malformed record.
        """
        games = list(games)
        if not games:
            return []
        pids = _check_games(games)

        def work(s: Session) -> list[int]:
            match = s.get(Match, int(match_id))
            if match is None:
                raise LeagueError(f"no match with id {match_id}")
            return self._insert_games(s, match, games, pids)

        return self._unit(work)

    def create_match_with_games(self, env: str, kind: str, params: dict[str, Any] | None,
                                games: Sequence[GameRecord]) -> tuple[int, list[int]]:
        """Open a match record and store its first games in ONE transaction (a match row never exists without
        games, whatever instant the process is killed at). Returns the match id and the game ids."""
        _check_name("env", env)
        if kind not in MATCH_KINDS:
            raise LeagueError(f"unknown match kind {kind!r} (expected one of {', '.join(MATCH_KINDS)})")
        games = list(games)
        pids = _check_games(games)

        def work(s: Session) -> tuple[int, list[int]]:
            m = Match(env=env, kind=kind, params=dict(params or {}))
            s.add(m)
            s.flush()
            return m.id, self._insert_games(s, m, games, pids) if games else []

        return self._unit(work)

    def update_match(self, match_id: int, **params: Any) -> None:
        """Merge ``params`` into a match's parameters (e.g. ``status="interrupted"``). LeagueError if unknown."""

        def work(s: Session) -> None:
            m = s.get(Match, int(match_id))
            if m is None:
                raise LeagueError(f"no match with id {match_id}")
            m.params = {**dict(m.params or {}), **params}

        self._unit(work)

    def _insert_games(self, s: Session, match: Match, games: list[GameRecord], pids: set[int]) -> list[int]:
        """Store checked ``games`` of ``match`` inside the session's transaction; the online Elo goes with them."""
        q = select(Player).where(Player.id.in_(pids)).options(raiseload("*")).with_for_update()
        rows = s.execute(q).scalars().all()
        players = {p.id: p for p in rows}
        for i, g in enumerate(games):
            if g.env != match.env:
                raise LeagueError(f"game {i}: env {g.env!r} differs from match {match.id}'s env {match.env!r}")
            for pid in g.players:
                p = players.get(int(pid))
                if p is None:
                    raise LeagueError(f"game {i}: no player with id {pid}")
                if p.env != g.env:
                    raise LeagueError(f"game {i}: player {p.id} ({p.name}) belongs to env {p.env!r}")
        now = utcnow()
        game_rows = [
            {"match_id": match.id, "env": g.env, "n_seats": len(g.players), "seed": int(g.seed),
             "length": int(g.length), "truncated": bool(g.truncated), "created_at": now, "actions": g.actions}
            for g in games
        ]
        ids = list(s.scalars(Game.__table__.insert().returning(Game.__table__.c.id, sort_by_parameter_order=True),
                             game_rows))
        seat_rows = [
            {"game_id": gid, "seat": k, "player_id": int(pid), "score": float(g.scores[k]),
             "points": float(g.outcome[k])}
            for gid, g in zip(ids, games, strict=True)
            for k, pid in enumerate(g.players)
        ]
        s.execute(GameSeat.__table__.insert(), seat_rows)
        for g in games:
            _apply_game(players, [int(p) for p in g.players], float(g.outcome[0]), self.elo_k)
        return ids

    def games(self, env: str | None = None, players: Iterable[int] | None = None,
              any_seat: bool = False, rated: bool = True) -> GameTable:
        """The two-player games of the ledger (of ``env``) as numpy arrays, in id order.

        ``players`` restricts the table to games between those players (both seats in the set), or,
        with ``any_seat=True``, to games in which at least one of them played.

        ``rated`` (the default) leaves out the games of training matches: there a learner that kept learning after
        its latest snapshot played under that snapshot's name, so they measure no fixed player. Every rating is
        fitted from the others (matches, tournaments, gates and the evaluation games after each snapshot);
        ``rated=False`` includes the training games too.
        """

        def work(s: Session) -> list[Any]:
            s0, s1 = aliased(GameSeat), aliased(GameSeat)
            q = (
                select(Game.id, Game.match_id, s0.player_id, s1.player_id, s0.points, Game.seed, Game.length,
                       Game.truncated)
                .join(s0, and_(s0.game_id == Game.id, s0.seat == 0))
                .join(s1, and_(s1.game_id == Game.id, s1.seat == 1))
                .where(Game.n_seats == 2, s0.player_id != s1.player_id)
                .order_by(Game.id)
            )
            if env is not None:
                q = q.where(Game.env == env)
            if rated:
                q = q.join(Match, Match.id == Game.match_id).where(Match.kind != "training")
            return list(s.execute(q).all())

        rows = self._read(work)
        if not rows:
            return GameTable.empty()
        cols = list(zip(*rows, strict=True))
        table = GameTable(
            game_id=np.asarray(cols[0], dtype=np.int64), match_id=np.asarray(cols[1], dtype=np.int64),
            player_a=np.asarray(cols[2], dtype=np.int64), player_b=np.asarray(cols[3], dtype=np.int64),
            score_a=np.asarray(cols[4], dtype=np.float64), seed=np.asarray(cols[5], dtype=np.int64),
            length=np.asarray(cols[6], dtype=np.int64), truncated=np.asarray(cols[7], dtype=bool),
        )
        if players is not None:
            pop = np.fromiter((int(p) for p in players), dtype=np.int64)
            in_a, in_b = np.isin(table.player_a, pop), np.isin(table.player_b, pop)
            table = table.select(in_a | in_b if any_seat else in_a & in_b)
        return table

    def match_info(self, match_id: int) -> tuple[str, dict[str, Any]]:
        """The kind and parameters of a match. Raises LeagueError if unknown."""

        def work(s: Session) -> tuple[str, dict[str, Any]]:
            m = s.get(Match, int(match_id))
            if m is None:
                raise LeagueError(f"no match with id {match_id}")
            return m.kind, dict(m.params or {})

        return self._read(work)

    def game(self, game_id: int) -> GameRow:
        """The stored game ``game_id`` with its seats, its match and its actions. Raises LeagueError if unknown."""

        def work(s: Session) -> GameRow:
            g = s.get(Game, int(game_id))
            if g is None:
                raise LeagueError(f"no game with id {game_id} in the ledger")
            match = s.get(Match, g.match_id)
            seats = s.execute(select(GameSeat).where(GameSeat.game_id == g.id).order_by(GameSeat.seat)).scalars().all()
            return GameRow(
                id=g.id, match_id=g.match_id, match_kind=match.kind if match else "", env=g.env,
                match_params=dict(match.params or {}) if match else {}, seed=int(g.seed), length=int(g.length),
                truncated=bool(g.truncated), players=tuple(int(x.player_id) for x in seats),
                scores=tuple(float(x.score) for x in seats), outcome=tuple(float(x.points) for x in seats),
                actions=g.actions, created_at=g.created_at,
            )

        return self._read(work)

    def count_games(self, env: str | None = None) -> int:
        """Number of games in the ledger (any number of seats)."""

        def work(s: Session) -> int:
            q = select(func.count(Game.id))
            if env is not None:
                q = q.where(Game.env == env)
            return int(s.execute(q).scalar_one())

        return self._read(work)

    def pair_counts(self, a: int, b: int) -> tuple[int, int, int]:
        """Wins, draws and losses of player ``a`` against player ``b`` over all stored 2-seat games."""
        if int(a) == int(b):
            raise LeagueError(f"player {a} cannot be paired with itself")

        def work(s: Session) -> tuple[int, int, int]:
            sa, sb = aliased(GameSeat), aliased(GameSeat)
            q = (
                select(
                    func.coalesce(func.sum(case((sa.points > 0.5, 1), else_=0)), 0),
                    func.coalesce(func.sum(case((sa.points == 0.5, 1), else_=0)), 0),
                    func.coalesce(func.sum(case((sa.points < 0.5, 1), else_=0)), 0),
                )
                .select_from(sa)
                .join(sb, and_(sb.game_id == sa.game_id, sb.seat != sa.seat))
                .join(Game, Game.id == sa.game_id)
                .where(sa.player_id == int(a), sb.player_id == int(b), Game.n_seats == 2)
            )
            w, d, lo = s.execute(q).one()
            return int(w), int(d), int(lo)

        return self._read(work)

    def recompute_online_elo(self, env: str | None = None) -> None:
        """Rebuild every player's online Elo and game count by replaying the ledger in game-id order.

        All players (of ``env``) restart from 1000 and 0 games; the result equals the incrementally
        stored values, because games are numbered in commit order under SQLite's single writer.
        """

        def work(s: Session) -> None:
            pq = select(Player)
            gq = (
                select(GameSeat.game_id, GameSeat.seat, GameSeat.player_id, GameSeat.points)
                .join(Game, Game.id == GameSeat.game_id)
                .order_by(GameSeat.game_id, GameSeat.seat)
            )
            if env is not None:
                pq = pq.where(Player.env == env)
                gq = gq.where(Game.env == env)
            pq = pq.options(raiseload("*")).with_for_update()
            players = {p.id: p for p in s.execute(pq).scalars()}
            for p in players.values():
                p.elo, p.games = DEFAULT_ELO, 0
            current: int | None = None
            seats: list[int] = []
            score0 = 0.5
            for gid, seat, pid, points in s.execute(gq):
                if gid != current:
                    if seats:
                        _apply_game(players, seats, score0, self.elo_k)
                    current, seats = gid, []
                if seat == 0:
                    score0 = float(points)
                seats.append(int(pid))
            if seats:
                _apply_game(players, seats, score0, self.elo_k)

        self._unit(work)


def _check_games(games: list[GameRecord]) -> set[int]:
    """The ids of the players of ``games``, each game checked for shape and result (LeagueError if malformed)."""
    pids: set[int] = set()
    for i, g in enumerate(games):
        n = len(g.players)
        if n < 1 or len(g.scores) != n or len(g.outcome) != n:
            raise LeagueError(f"game {i}: players, scores and outcome must have one entry per seat")
        if any(not (0.0 <= float(o) <= 1.0) or math.isnan(float(o)) for o in g.outcome):
            raise LeagueError(f"game {i}: outcome points must lie in [0, 1], got {g.outcome}")
        if n == 2 and abs(float(g.outcome[0]) + float(g.outcome[1]) - 1.0) > 1e-9:
            raise LeagueError(f"game {i}: two-player outcome must sum to 1, got {g.outcome}")
        pids.update(int(p) for p in g.players)
    return pids


def _apply_game(players: dict[int, Player], seats: list[int], score0: float, k: float) -> None:
    """Count one game for its players and, for a 2-seat game between two players, update their Elo."""
    for pid in dict.fromkeys(seats):
        p = players.get(pid)
        if p is not None:
            p.games = int(p.games or 0) + 1
    if len(seats) == 2 and seats[0] != seats[1]:
        a, b = players.get(seats[0]), players.get(seats[1])
        if a is not None and b is not None:
            a.elo, b.elo = elo_update(float(a.elo), float(b.elo), score0, k)
