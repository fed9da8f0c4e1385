"""The league home: its default folder (:data:`DEFAULT_HOME`), the database file in it (:data:`DB_FILENAME`) and the
folder of snapshot files (:data:`SNAPSHOTS`); and the homes this process created (:data:`NEW_HOMES`, which
:meth:`~selfplay_cli.league.db.Database.open` fills), which a refused command removes while they hold nothing of
anyone's (:func:`undo_new_homes`), so that it leaves no ``./league`` behind."""

from __future__ import annotations

import sqlite3
from pathlib import Path

__all__ = ["DB_FILENAME", "DEFAULT_HOME", "NEW_HOMES", "SNAPSHOTS", "forget_new_homes", "undo_new_homes"]

SNAPSHOTS = "snapshots"
"""The folder of the league home that holds every snapshot file (``snapshots/<run>/<name>.safetensors``)."""

DEFAULT_HOME = "./league"
DB_FILENAME = "league.db"
NEW_HOMES: list[Path] = []  # league homes this process created (undo_new_homes: a refused command leaves none)


def forget_new_homes() -> None:
    """Start a command afresh: the homes earlier commands of this process created are theirs (tests run many)."""
    NEW_HOMES.clear()


def undo_new_homes() -> list[Path]:
    """Remove the league homes this process created that hold nothing of anyone's: only the database's own files
    (``league.db`` and its journal) with no run, snapshot, match or job in it (the scripted players a command may have
    entered are not anyone's). What a refused command calls, so that it leaves no ``./league`` behind; a home with
    anything else in it is left as it is. The homes removed."""
    removed = []
    database_files = {DB_FILENAME, DB_FILENAME + "-wal", DB_FILENAME + "-shm", DB_FILENAME + "-journal"}
    while NEW_HOMES:
        home = NEW_HOMES.pop()
        try:
            if not home.is_dir() or home.is_symlink() or not {p.name for p in home.iterdir()} <= database_files:
                continue
            db = home / DB_FILENAME
            if db.exists():
                con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
                try:
                    tables = {r[0] for r in con.execute("select name from sqlite_master where type = 'table'")}
                    if any(con.execute(f"select 1 from {t} limit 1").fetchone() is not None
                           for t in ("runs", "matches", "games", "jobs", "tags", "blobs", "workers") if t in tables):
                        continue
                    if "players" in tables and con.execute(
                            "select 1 from players where kind != 'bot' limit 1").fetchone() is not None:
                        continue
                finally:
                    con.close()
            for name in database_files:
                (home / name).unlink(missing_ok=True)
            home.rmdir()
            removed.append(home)
        except (OSError, sqlite3.Error):
            continue
    return removed
