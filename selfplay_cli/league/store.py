"""The league: players (bots and snapshots), runs, matches and the append-only game ledger, in one database.

A :class:`League` is one SQLAlchemy engine with its parts, each a concern in a module of its own, over it. The
default database is SQLite at ``<home>/league.db`` (home: ``MARL_HOME`` or ``./league``), but any SQLAlchemy URL
works (``MARL_DB``). Every rating is derived from the ``games`` / ``game_seats`` ledger; the online Elo kept on each
player row is a cache updated in the same transaction as the games it counts, and ``league.ledger
.recompute_online_elo()`` rebuilds it from scratch.

* the league itself (:mod:`selfplay_cli.league.db`): the engine, one session per unit of work (retried on SQLite's
  "database is locked", PostgreSQL's conflicts and a lost server), the schema and its Alembic revision, the home
  folder and the rule that keeps a snapshot row's path inside it (:meth:`~selfplay_cli.league.db.Database
  .snapshot_file`: where this machine has no such file, the snapshot is played from its blob,
  :func:`selfplay_cli.players.files.snapshot_path`); the league's errors and what a driver's failure means
  (:mod:`selfplay_cli.league.failures`), what a database URL names and the refusal of a SQLite file on a network file
  system (:mod:`selfplay_cli.league.url`), and the home's layout with the homes a refused command leaves behind
  (:mod:`selfplay_cli.league.home`);
* ``league.roster`` (:mod:`selfplay_cli.league.roster`): runs, players and tags, and the rule every name follows;
* ``league.ledger`` (:mod:`selfplay_cli.league.ledger`): matches, the games with their seats, the online Elo and the
  rating table (:mod:`selfplay_cli.league.game_table`) derived for every kind of game
  (:mod:`selfplay_cli.league.derivation`);
* ``league.seeds`` (:mod:`selfplay_cli.league.seeds`): the seed ranges a pair of players has played or taken, so
  that no two commands play the same games;
* ``league.blobs`` (:mod:`selfplay_cli.league.blobs`): the snapshot files' bytes by their sha256, so that a machine
  that has only the database can play any snapshot;
* ``league.queue`` (:mod:`selfplay_cli.league.queue`): the work queue's jobs, leases and workers (their records,
  the queue's timings and limits: :mod:`selfplay_cli.league.job_rows`);
* ``league.videos`` (:mod:`selfplay_cli.league.videos`): the recordings made under the league home.

Objects returned to callers are frozen dataclasses (:class:`RunRow`, :class:`PlayerRow`, :class:`GameTable`,
:class:`GameRow`), never ORM instances, so nothing lazy-loads after a session has closed. A :class:`League` must not
be shared across ``fork``; open one per process.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.engine import URL

from selfplay_cli.league.blobs import Blobs, BlobsReport
from selfplay_cli.league.db import Database
from selfplay_cli.league.derivation import rules_for_env
from selfplay_cli.league.failures import LeagueError, LeagueIOError, LeagueUnreachable, shown
from selfplay_cli.league.game_table import KIND_CODES, GameRow, GameTable
from selfplay_cli.league.home import DB_FILENAME, DEFAULT_HOME, SNAPSHOTS
from selfplay_cli.league.ledger import MATCH_KINDS, Ledger
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
from selfplay_cli.league.videos import Videos
from selfplay_cli.results import GameResult

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


class League(Database):
    """The league database: its parts over one engine (see the module docstring).

    Attributes:
        roster: runs, players (bots and snapshots) and tags (:class:`~selfplay_cli.league.roster.Roster`).
        ledger: matches, the games with their seats, the online Elo and the rating table
            (:class:`~selfplay_cli.league.ledger.Ledger`).
        seeds: the seed ranges each pair of players has played or taken (:class:`~selfplay_cli.league.seeds.Seeds`).
        blobs: the snapshot files' bytes by their sha256 (:class:`~selfplay_cli.league.blobs.Blobs`).
        queue: the work queue's jobs and workers (:class:`~selfplay_cli.league.queue.Queue`).
        videos: the recordings made under the league home (:class:`~selfplay_cli.league.videos.Videos`).
    """

    def __init__(self, url: str | URL, **options: Any) -> None:
        """Open the league at ``url`` (the options: :class:`~selfplay_cli.league.db.Database`'s)."""
        super().__init__(url, **options)
        self.roster = Roster(self)
        self.seeds = Seeds(self)
        self.ledger = Ledger(self, self.seeds)
        self.blobs = Blobs(self)
        self.queue = Queue(self, self.ledger, self.seeds)
        self.videos = Videos(self)
