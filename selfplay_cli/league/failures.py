"""The league's errors and what a database driver's failure means.

The errors: :class:`LeagueError` (a user-facing league problem), :class:`LeagueIOError` (a cause outside marl: disk
full, I/O error, read-only, permissions), :class:`LeagueUnreachable` (a PostgreSQL server lost or not answering) and
:class:`NoLeagueYet` (a server's database with no tables yet, opened to read); :func:`shown` puts a value in a
message. A driver's failure: SQLite's "database is locked" (:func:`is_locked`), PostgreSQL's SQLSTATEs of a conflict
retried at once (:data:`PG_RETRY`) and of a server going or coming (:data:`PG_GONE`), the words of a refused user,
password or database (:data:`PG_REFUSED`) and of a cause outside marl (:data:`IO_REASONS`). What
:class:`~selfplay_cli.league.db.Database` does on each (retry, wait, say) is its own.
"""

from __future__ import annotations

from selfplay_cli.errors import EXIT_IO, MarlError, MarlIOError

__all__ = ["IO_REASONS", "PG_GONE", "PG_REFUSED", "PG_RETRY", "LeagueError", "LeagueIOError", "LeagueUnreachable",
           "NoLeagueYet", "driver_reason", "is_locked", "shown", "sqlstate"]


class LeagueError(MarlError):
    """A user-facing league problem (unknown or duplicate name, bad database, version mismatch)."""


class NoLeagueYet(LeagueError):
    """A database server's database with no tables yet, opened to read: read as an empty league instead."""


class LeagueIOError(LeagueError, MarlIOError):
    """The league's database or files could not be read or written for a reason outside marl (disk full, I/O error,
    file size limit, read-only file system, permissions); the message names the path and the cause."""

    exit_code = EXIT_IO


class LeagueUnreachable(LeagueIOError):
    """The league's PostgreSQL server cannot be reached (none answers at the URL, it is starting or shutting down,
    the connection broke): what waiting may cure, unlike a refused user or a full disk. ``where`` names the
    database, ``reason`` the driver's words."""

    def __init__(self, message: str, where: str = "", reason: str = "") -> None:
        super().__init__(message)
        self.where, self.reason = where, reason


IO_REASONS = ("disk i/o error", "database or disk is full", "readonly database", "unable to open database file",
              "read-only file system", "permission denied", "file too large", "no space left")


def shown(value: object, limit: int = 60) -> str:
    """``value`` for an error message: quoted, control characters escaped (never raw on a terminal), cut short."""
    text = value if isinstance(value, str) else str(value)
    cut = text[:limit]
    return repr(cut)[:-1] + ("..." + repr(cut)[-1] if len(text) > limit else repr(cut)[-1])


def is_locked(exc: BaseException) -> bool:
    """True if a DB error is SQLite's transient "database is locked" / "busy"."""
    msg = str(getattr(exc, "orig", exc)).lower()
    return "database is locked" in msg or "database table is locked" in msg


PG_RETRY = ("40001", "40P01")  # serialization_failure, deadlock_detected: the unit is retried at once
PG_GONE = ("57P01", "57P02", "57P03")  # admin / crash shutdown, cannot connect now: the server is going or coming
PG_REFUSED = ("password authentication failed", "authentication failed", "does not exist", "no pg_hba.conf entry",
              "permission denied for database")  # the URL's user, password or database is wrong: the user's to fix


def sqlstate(exc: BaseException) -> str | None:
    return getattr(getattr(exc, "orig", None), "sqlstate", None)


def driver_reason(exc: BaseException) -> str:
    """The driver's first line of a database error (psycopg's ``connection failed: `` prefix dropped)."""
    orig = getattr(exc, "orig", None)
    text = str(orig if orig is not None else exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__).removeprefix("connection failed: ")

