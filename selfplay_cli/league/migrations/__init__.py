"""The league's schema, versioned with Alembic: which revision a database is at, and bringing it to the newest.

The revisions live in ``versions/`` (one file each, ``revision`` ids ``"0002"``, ``"0003"``, ...: the baseline is
``"0002"`` because it is the schema the last release before Alembic called version 2). They are run from here, inside
the transaction that opens the league, with no ``alembic.ini`` and no ``env.py``: :func:`upgrade` applies each
revision's ``upgrade()`` through :class:`alembic.operations.Operations` and records it in Alembic's own
``alembic_version`` table. A new league is made by ``create_all`` of the models and stamped with the newest revision
(:func:`stamp_head`); a test checks that the two ways give the same schema, on SQLite and PostgreSQL.

Leagues written before Alembic have no ``alembic_version`` table; their ``meta.schema_version`` (1, 2, or 3 for a
league written by a development build of the queue) says where they stand (:func:`legacy_revision`). A league
Alembic manages keeps ``meta.schema_version`` at :data:`ALEMBIC_MARK` so that a release from before Alembic refuses
it, in its own one line, as newer than itself.

A change to the models is a new file in ``versions/`` (``revision`` the next number, ``down_revision`` the last one,
a first docstring line that says what it brings: the upgrade line quotes it) and its id at the end of
:data:`REVISIONS`; ``tests/test_store.py`` checks that the revisions, run from nothing, give the models' schema.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Connection, inspect

if TYPE_CHECKING:
    from alembic.script import ScriptDirectory

__all__ = ["ALEMBIC_MARK", "REVISIONS", "current", "head", "known", "legacy_revision", "stamp_head", "summary",
           "upgrade"]

REVISIONS = ("0002", "0003", "0004", "0005")
"""Every revision in ``versions/``, oldest first (a test checks this against Alembic's own reading of the folder).
Kept here so that opening a league that is up to date reads one row and imports nothing of Alembic (~0.1 s that every
command would pay); Alembic is imported only to create, stamp or upgrade."""

ALEMBIC_MARK = 3
"""``meta.schema_version`` of every league whose schema Alembic keeps: one more than the newest version (2) a release
from before Alembic knows, so such a release says the league is newer than itself and asks to be upgraded."""

_LEGACY = {2: "0002", 3: "0003"}
"""The revision that a pre-Alembic ``meta.schema_version`` stands for (1 is 2 without the work keys: see
:func:`legacy_revision`)."""


@cache
def scripts() -> ScriptDirectory:
    """Alembic's view of the revisions (the package folder is the script location; its ``versions/`` the scripts)."""
    from alembic.script import ScriptDirectory

    return ScriptDirectory(str(Path(__file__).parent))


def head() -> str:
    """The newest revision this code knows."""
    return REVISIONS[-1]


def known(revision: str) -> bool:
    """True if ``revision`` is one of this code's (False: a newer marl wrote it)."""
    return revision in REVISIONS


def current(conn: Connection) -> str | None:
    """The revision stored in the database (None: no ``alembic_version`` table, a league from before Alembic)."""
    if "alembic_version" not in inspect(conn).get_table_names():
        return None
    return conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalar()


def legacy_revision(conn: Connection, version: int) -> str:
    """Bring a pre-Alembic league of ``meta.schema_version`` ``version`` (1, 2 or 3) to the revision it stands for,
    and return that revision (not yet stamped). Version 1 lacks ``matches.work_key`` and its unique index, which
    version 2 added; they are added here. ``KeyError`` for a version that is not one of these."""
    if version == 1:
        if "work_key" not in {c["name"] for c in inspect(conn).get_columns("matches")}:
            conn.exec_driver_sql("ALTER TABLE matches ADD COLUMN work_key VARCHAR(200)")
        if "uq_matches_work_key" not in {i["name"] for i in inspect(conn).get_indexes("matches")}:
            conn.exec_driver_sql("CREATE UNIQUE INDEX uq_matches_work_key ON matches (work_key)")
        return _LEGACY[2]
    return _LEGACY[version]


def stamp_head(conn: Connection) -> None:
    """Record the newest revision in the database (whose tables ``create_all`` just made)."""
    from alembic.runtime.migration import MigrationContext

    MigrationContext.configure(conn).stamp(scripts(), "heads")


def upgrade(conn: Connection, start: str | None) -> list[str]:
    """Apply every revision after ``start`` (None: from nothing) up to :func:`head`, in order, inside the caller's
    transaction, recording each in ``alembic_version`` as it goes; the revisions applied."""
    from alembic.operations import Operations
    from alembic.runtime.migration import MigrationContext

    ctx = MigrationContext.configure(conn)
    if start is not None and ctx.get_current_revision() != start:
        ctx.stamp(scripts(), start)  # a league from before Alembic: where it stands
    steps = list(reversed(list(scripts().iterate_revisions("heads", start or "base"))))
    for script in steps:
        with Operations.context(ctx):
            assert script.module is not None
            script.module.upgrade()
        ctx.stamp(scripts(), script.revision)
    return [s.revision for s in steps]


def summary(revisions: list[str]) -> str:
    """What ``revisions`` bring, from the first line of each one's docstring (``"snapshot blobs, work queue"``)."""
    return "; ".join((scripts().get_revision(r).doc or r).strip() for r in revisions)
