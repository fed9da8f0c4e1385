"""The league: players (bots and snapshots), runs, matches and the append-only game ledger, in one database.

A :class:`League` wraps one SQLAlchemy engine. The default database is SQLite at ``<home>/league.db`` (home:
``MARL_HOME`` or ``./league``), but any SQLAlchemy URL works (``MARL_DB``). Every rating is derived from the ``games``
/ ``game_seats`` ledger; the online Elo kept on each player row is a cache updated in the same transaction as the
games it counts, and :meth:`League.recompute_online_elo` rebuilds it from scratch.

The league is made of four concerns, each in its own module:

* :mod:`selfplay_cli.league.db`: the engine, one session per unit of work (retried on SQLite's "database is
  locked", PostgreSQL's conflicts and a lost server), the schema and its Alembic revision (SQLite concurrency and
  PostgreSQL are described there);
* :mod:`selfplay_cli.league.roster`: runs, players and tags, and the rule every name follows;
* :mod:`selfplay_cli.league.ledger`: matches, the games with their seats, the online Elo and the rating table
  derived for every kind of game;
* :mod:`selfplay_cli.league.blobs`: the snapshot files' bytes by their sha256, so that a machine that has only the
  database can play any snapshot.

A snapshot row's path becomes a file only through :meth:`League.snapshot_file`, which keeps it inside the home's
``snapshots`` folder whatever the database says; where this machine has no such file, the snapshot is played from
its blob (:func:`selfplay_cli.players.files.snapshot_path`).

Objects returned to callers are frozen dataclasses (:class:`RunRow`, :class:`PlayerRow`, :class:`GameTable`,
:class:`GameRow`), never ORM instances, so nothing lazy-loads after a session has closed. A :class:`League` must not
be shared across ``fork``; open one per process. Everything importable from here before the split still is.
"""

from __future__ import annotations

from pathlib import Path

from selfplay_cli.league.blobs import Blobs, BlobsReport
from selfplay_cli.league.db import (
    DB_FILENAME,
    DEFAULT_HOME,
    Database,
    LeagueError,
    LeagueIOError,
    LeagueUnreachable,
    shown,
)
from selfplay_cli.league.ledger import KIND_CODES, MATCH_KINDS, GameRow, GameTable, Ledger, rules_for_env
from selfplay_cli.league.queue import Queue
from selfplay_cli.league.roster import (
    DEFAULT_ELO,
    ENV_NAME_PATTERN,
    NAME_PATTERN,
    RESERVED_NAMES,
    PlayerRow,
    Roster,
    RunRow,
    RunStatus,
    check_env_name,
    check_existing_name,
    check_name,
)
from selfplay_cli.league.seeds import Seeds
from selfplay_cli.results import GameResult

SNAPSHOTS = "snapshots"
"""The folder of the league home that holds every snapshot file (``snapshots/<run>/<name>.safetensors``)."""

__all__ = [
    "DEFAULT_ELO",
    "DEFAULT_HOME",
    "DB_FILENAME",
    "ENV_NAME_PATTERN",
    "KIND_CODES",
    "MATCH_KINDS",
    "NAME_PATTERN",
    "RESERVED_NAMES",
    "SNAPSHOTS",
    "BlobsReport",
    "GameResult",
    "GameRow",
    "GameTable",
    "League",
    "LeagueError",
    "LeagueIOError",
    "LeagueUnreachable",
    "PlayerRow",
    "RunRow",
    "RunStatus",
    "check_env_name",
    "check_existing_name",
    "check_name",
    "rules_for_env",
    "shown",
]


class League(Queue, Seeds, Ledger, Roster, Blobs, Database):
    """The league database: players, runs, matches and the game ledger (see the module docstring)."""

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

