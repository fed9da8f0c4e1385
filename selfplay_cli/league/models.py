"""ORM schema of the league ledger (SQLAlchemy 2.0 typed declarative mappings).

Tables
------
* ``meta(key, value)``: ``schema_version`` and other bookkeeping strings.
* ``runs``: one row per training run (globally unique name).
* ``players``: scripted bots (``kind = "bot"``, no run) and policy snapshots (``kind = "snapshot"``).
  ``(env, run_id, name)`` is unique; because SQL treats NULLs as distinct, a second, partial unique
  index ``(env, name) WHERE run_id IS NULL`` makes bot names (and run-less snapshot names) unique per
  env. The player row also carries the *online* Elo (``elo``, ``games``), a cache that
  :meth:`selfplay_cli.league.store.League.recompute_online_elo` can always rebuild from the ledger.
  Snapshots are never deleted, only marked ``removed`` (the ledger keeps referencing them). A snapshot's
  ``sha256`` is its file's: the row and the file are checked against each other on every load.
* ``tags(env, tag) -> player_id``: human names for players, unique per env.
* ``matches``: one row per match / tournament / gate / training / eval session that produced games; its
  ``params`` say how it was played (and, for rated matches, ``status``: ``running``, ``finished``,
  ``interrupted`` or ``failed``, with the number of ``games_stored``). ``work_key`` (unique where set) names the
  unit of work that stored it, where a unit may be done twice (schema version 2).
* ``games`` + ``game_seats``: the append-only ledger. A game has ``n_seats`` seat rows holding the
  player, its raw score and its points (1 win, 0.5 draw, 0 loss).
* ``blobs``: snapshot files by the sha256 of their bytes, so that a machine that has only the database URL can play
  any snapshot (the bytes in the row, or at a ``url`` the league names); never trusted by name, always re-hashed.
* ``workers`` and ``jobs``: the work queue. A job is a few minutes of rating games (its ``spec``), queued in a
  ``batch`` (a tournament, an SPRT, a run's gauntlets), leased by one worker at a time that beats a heart on it; a job
  whose heart stopped goes back to the queue, one that failed is tried again later, and its games are stored with
  the job marked done in one transaction under the match key ``job:<id>``, so a job finished twice counts once.
* ``seed_ranges``: the seeds games between two players were taken for before they were played, a range of rounds at a
  time (a queued job's, or a command's playing them itself), each the pair's ``seq``-th: ``(lo, hi, seq)`` is unique,
  so two commands that planned new games of one pair from the same look both write its next range and the database
  keeps one (schema revision 0004; :mod:`selfplay_cli.league.seeds`).
* ``videos``: the recordings ``marl record`` made under the league home's ``videos/`` folder, each by its path there
  (relative, checked again by every reader), the players it shows and the stored game it replays, if any (schema
  revision 0005; :mod:`selfplay_cli.league.videos`): what ``marl serve`` plays, and nothing else.

Every JSON column is a :class:`BoundedJSON`: read within a size of its own and a depth, a bad value one unusable row
(:mod:`selfplay_cli.league.bounded_json`), never a failed command.

All timestamps are stored as naive UTC and returned as timezone-aware UTC datetimes.
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Dialect,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship
from sqlalchemy.types import TypeDecorator

from selfplay_cli.league.bounded_json import read_column

__all__ = ["Base", "Blob", "BoundedJSON", "Game", "GameSeat", "Job", "Match", "Meta", "Player", "Run", "SeedRange",
           "Tag", "UTCDateTime", "Video", "Worker", "utcnow"]


def utcnow() -> datetime:
    """The current time as a timezone-aware UTC datetime."""
    return datetime.now(timezone.utc)


class UTCDateTime(TypeDecorator[datetime]):
    """A DateTime stored as naive UTC and always read back as an aware UTC datetime.

    SQLite has no time zones; storing naive UTC everywhere keeps every backend consistent.
    Naive datetimes given to the database are taken to be UTC already.
    """

    impl = DateTime
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        """Convert an aware datetime to naive UTC before it is stored."""
        if value is None or value.tzinfo is None:
            return value
        return value.astimezone(timezone.utc).replace(tzinfo=None)

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        """Attach the UTC time zone to a stored (naive UTC) datetime."""
        if value is None:
            return None
        if value.tzinfo is None:
            return value.replace(tzinfo=timezone.utc)
        return value.astimezone(timezone.utc)


class BoundedJSON(TypeDecorator[Any]):
    """A JSON column read with bounds (:mod:`selfplay_cli.league.bounded_json`): a value over ``max_bytes``, nested too
    deep, not JSON, or not of the column's ``kind`` (dict or list) reads as an
    :class:`~selfplay_cli.league.bounded_json.Unreadable` saying why, never as an error of the whole query. The
    engine hands the column's stored text over unparsed (:func:`~selfplay_cli.league.bounded_json.raw`); a value a
    driver parsed anyway is only checked for its kind. Stored as JSON, as before: no migration."""

    impl = JSON
    cache_ok = True

    def __init__(self, max_bytes: int, kind: type = dict) -> None:
        super().__init__()
        self.max_bytes, self.kind = int(max_bytes), kind

    def process_result_value(self, value: Any, dialect: Dialect) -> Any:
        return read_column(value, max_bytes=self.max_bytes, kind=self.kind)


META_BYTES = 256 * 1024
"""A player's ``meta`` (its learner, role, league role, exploitability: a few hundred bytes)."""
CONFIG_BYTES = 1024 * 1024
"""A run's ``config`` (its resolved settings: a few kilobytes)."""
PARAMS_BYTES = 1024 * 1024
"""A match's ``params`` (how it was played, the game's options and rules)."""
SPEC_BYTES = 256 * 1024
"""A job's ``spec`` (player ids, seeds, counts; a gauntlet's snapshot names)."""
RESULT_BYTES = 1024 * 1024
"""A job's ``result`` (counts, and a games job's points round by round)."""
SERVES_BYTES = 64 * 1024
"""A worker's ``serves`` (the batches it takes jobs from)."""
VIDEO_BYTES = 64 * 1024
"""A video's ``players`` (the ids of the players it shows, seat by seat) and its ``meta`` (names, scores, fps)."""


class Base(DeclarativeBase):
    """Declarative base of the league schema."""

    type_annotation_map = {dict[str, Any]: BoundedJSON(1024 * 1024), datetime: UTCDateTime}


class Meta(Base):
    """Key/value bookkeeping (``schema_version``)."""

    __tablename__ = "meta"

    key: Mapped[str] = mapped_column(String(64), primary_key=True)
    value: Mapped[str] = mapped_column(Text)


class Run(Base):
    """A training run."""

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    env: Mapped[str] = mapped_column(String(100), index=True)
    algo: Mapped[str | None] = mapped_column(String(100))
    config: Mapped[dict[str, Any]] = mapped_column(BoundedJSON(CONFIG_BYTES), default=dict)
    status: Mapped[str] = mapped_column(String(32))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)


class Player(Base):
    """A scripted bot or a policy snapshot, with its online Elo."""

    __tablename__ = "players"
    __table_args__ = (
        UniqueConstraint("env", "run_id", "name", name="uq_players_env_run_name"),
        Index("ix_players_env_kind", "env", "kind"),
        Index("ix_players_env_name", "env", "name"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    env: Mapped[str] = mapped_column(String(100))
    kind: Mapped[str] = mapped_column(String(16))
    name: Mapped[str] = mapped_column(String(200))
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"), index=True)
    step: Mapped[int] = mapped_column(BigInteger, default=0)
    episode: Mapped[int] = mapped_column(BigInteger, default=0)
    algo: Mapped[str | None] = mapped_column(String(100))
    path: Mapped[str | None] = mapped_column(Text)
    sha256: Mapped[str | None] = mapped_column(String(64))
    """The sha256 of the snapshot's whole file (header with its metadata, and the weights): the file a player
    stands for. Every load of the player checks its file against it (``players.files.read_row_snapshot``), so a file
    replaced or edited after registration is refused. Leagues written before marl settled this hold the weights'
    checksum (``meta["weights_sha256"]``) here for trained snapshots; those rows are checked by that checksum and the
    file's run, name and step instead. None for bots."""
    parent_id: Mapped[int | None] = mapped_column(ForeignKey("players.id"))
    elo: Mapped[float] = mapped_column(Float, default=1000.0)
    games: Mapped[int] = mapped_column(Integer, default=0)
    removed: Mapped[bool] = mapped_column(Boolean, default=False)
    removed_at: Mapped[datetime | None] = mapped_column()
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    meta: Mapped[dict[str, Any]] = mapped_column(BoundedJSON(META_BYTES), default=dict)

    run: Mapped[Run | None] = relationship(lazy="joined")
    tags: Mapped[list[Tag]] = relationship(back_populates="player", lazy="selectin", order_by="Tag.tag")


# Bots (and run-less snapshots) have run_id NULL, which the unique constraint above does not cover:
# a partial unique index makes their names unique per env. Only emitted where partial indexes exist
# (elsewhere it would become a plain unique (env, name) index and forbid ep90 in two runs); the
# store checks the rule itself before every insert in any case.
Index(
    "uq_players_env_name_no_run",
    Player.env,
    Player.name,
    unique=True,
    sqlite_where=text("run_id IS NULL"),
    postgresql_where=text("run_id IS NULL"),
).ddl_if(dialect=("sqlite", "postgresql"))


class Tag(Base):
    """A tag naming a player, unique per env."""

    __tablename__ = "tags"
    __table_args__ = (UniqueConstraint("env", "tag", name="uq_tags_env_tag"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    env: Mapped[str] = mapped_column(String(100))
    tag: Mapped[str] = mapped_column(String(200))
    player_id: Mapped[int] = mapped_column(ForeignKey("players.id", ondelete="CASCADE"), index=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    player: Mapped[Player] = relationship(back_populates="tags")


class Match(Base):
    """A session that produced games (a match, tournament, gate, training run or evaluation)."""

    __tablename__ = "matches"
    __table_args__ = (Index("uq_matches_work_key", "work_key", unique=True),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    env: Mapped[str] = mapped_column(String(100), index=True)
    kind: Mapped[str] = mapped_column(String(32))
    params: Mapped[dict[str, Any]] = mapped_column(BoundedJSON(PARAMS_BYTES), default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    work_key: Mapped[str | None] = mapped_column(String(200), deferred=True)  # (only writers read it)
    """The unit of work whose games the match holds, where a unit may be done twice (a training run's gauntlet
    matchup, played again when the run resumes after a kill): stored with its games in one transaction, and unique,
    so the second time stores nothing and the games count once. None for everything else."""


class Game(Base):
    """One game of the ledger; its players and results are in :class:`GameSeat`."""

    __tablename__ = "games"
    __table_args__ = (Index("ix_games_env_id", "env", "id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    match_id: Mapped[int] = mapped_column(ForeignKey("matches.id"), index=True)
    env: Mapped[str] = mapped_column(String(100))
    n_seats: Mapped[int] = mapped_column(Integer)
    seed: Mapped[int] = mapped_column(BigInteger)
    length: Mapped[int] = mapped_column(Integer)
    truncated: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    actions: Mapped[bytes | None] = mapped_column(LargeBinary)


class GameSeat(Base):
    """The player in one seat of a game, with its raw score and points (1 / 0.5 / 0)."""

    __tablename__ = "game_seats"
    __table_args__ = (Index("ix_game_seats_player_game", "player_id", "game_id"),)

    game_id: Mapped[int] = mapped_column(ForeignKey("games.id", ondelete="CASCADE"), primary_key=True)
    seat: Mapped[int] = mapped_column(Integer, primary_key=True)
    player_id: Mapped[int] = mapped_column(ForeignKey("players.id"))
    score: Mapped[float] = mapped_column(Float)
    points: Mapped[float] = mapped_column(Float)


class Blob(Base):
    """A snapshot file's bytes, keyed by their sha256: stored in the row (``data``) or kept at ``url`` (a location the
    league names: ``file://``, ``http(s)://``), read back only after the bytes hash to the key."""

    __tablename__ = "blobs"

    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    size: Mapped[int] = mapped_column(BigInteger)
    data: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    url: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Worker(Base):
    """A ``marl worker`` (or a command playing its own queued work): where it runs and when its heart last beat."""

    __tablename__ = "workers"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    host: Mapped[str] = mapped_column(String(200))
    pid: Mapped[int] = mapped_column(Integer)
    started_at: Mapped[datetime] = mapped_column(default=utcnow)
    beat_at: Mapped[datetime] = mapped_column(default=utcnow)
    stopped_at: Mapped[datetime | None] = mapped_column()
    jobs_done: Mapped[int] = mapped_column(Integer, default=0)
    games: Mapped[int] = mapped_column(BigInteger, default=0)
    seconds: Mapped[float] = mapped_column(Float, default=0.0)
    """Seconds spent playing the jobs it finished (its games/s is ``games / seconds``)."""
    serves: Mapped[list[str] | None] = mapped_column(BoundedJSON(SERVES_BYTES, kind=list))
    """The batches it takes jobs from (``marl worker --batch``; a command playing its own batch), None: every batch."""


class Job(Base):
    """One unit of queued rating work (see the module docstring). ``state``: ``queued``, ``leased``, ``done``,
    ``dead`` (failed ``tries`` times; ``error`` says why) or ``cancelled``. ``after``: a job that must be done first
    (a run's gauntlets are played in order). ``not_before``: a failed job waits until then (backoff)."""

    __tablename__ = "jobs"
    __table_args__ = (Index("ix_jobs_state_priority", "state", "priority", "id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    batch: Mapped[str] = mapped_column(String(200), index=True)
    kind: Mapped[str] = mapped_column(String(32))
    env: Mapped[str] = mapped_column(String(100))
    spec: Mapped[dict[str, Any]] = mapped_column(BoundedJSON(SPEC_BYTES), default=dict)
    priority: Mapped[int] = mapped_column(Integer, default=0)
    state: Mapped[str] = mapped_column(String(16), default="queued")
    after: Mapped[int | None] = mapped_column(ForeignKey("jobs.id"))
    tries: Mapped[int] = mapped_column(Integer, default=0)
    worker_id: Mapped[int | None] = mapped_column(ForeignKey("workers.id"), index=True)
    leased_at: Mapped[datetime | None] = mapped_column()
    beat_at: Mapped[datetime | None] = mapped_column()
    not_before: Mapped[datetime | None] = mapped_column()
    error: Mapped[str | None] = mapped_column(Text)
    result: Mapped[dict[str, Any] | None] = mapped_column(BoundedJSON(RESULT_BYTES))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column()


class SeedRange(Base):
    """Seeds ``[first_seed, first_seed + rounds)`` taken for ``games`` games between players ``lo`` and ``hi``
    (``lo < hi``; which one sat where is the games' business) in the variant ``variant`` names, before they are
    played: by a queued job (``job_id``), or by a command that plays them itself (``job_id`` None, ``owner`` naming it).
    The pair's ``seq``-th range: ``(lo, hi, seq)`` is unique, so of two commands that planned the pair's next games
    from the same look, the database keeps one range and the other looks again (:mod:`selfplay_cli.league.seeds`)."""

    __tablename__ = "seed_ranges"
    __table_args__ = (UniqueConstraint("lo", "hi", "seq", name="uq_seed_ranges_pair_seq"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    lo: Mapped[int] = mapped_column(ForeignKey("players.id"))
    hi: Mapped[int] = mapped_column(ForeignKey("players.id"))
    seq: Mapped[int] = mapped_column(Integer)
    first_seed: Mapped[int] = mapped_column(BigInteger)
    rounds: Mapped[int] = mapped_column(BigInteger)
    games: Mapped[int] = mapped_column(BigInteger)
    variant: Mapped[str] = mapped_column(String(64), default="")
    """The variant the games count in: ``""`` for the game's default, else the sha256 of its key (a key is JSON of any
    length)."""
    owner: Mapped[str] = mapped_column(String(200))
    """The batch of the range's job, or the command playing the range itself (``marl@host:pid``)."""
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id"), index=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Video(Base):
    """A recording ``marl record`` made inside the league home: ``path`` is relative to ``<home>/videos`` (``/``
    between its parts), ``players`` the ids of the players seat by seat, ``game_id`` the stored game it replays (None
    for a new game, played on ``seed``), ``meta`` what the recording says of itself (names, scores, fps, seconds)."""

    __tablename__ = "videos"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    env: Mapped[str] = mapped_column(String(100), index=True)
    path: Mapped[str] = mapped_column(Text)
    format: Mapped[str] = mapped_column(String(8))
    players: Mapped[list[int]] = mapped_column(BoundedJSON(VIDEO_BYTES, kind=list), default=list)
    game_id: Mapped[int | None] = mapped_column(ForeignKey("games.id"))
    seed: Mapped[int] = mapped_column(BigInteger, default=0)
    length: Mapped[int] = mapped_column(Integer, default=0)
    meta: Mapped[dict[str, Any]] = mapped_column(BoundedJSON(VIDEO_BYTES), default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
