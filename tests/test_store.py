"""Tests for selfplay_cli.league.store: schema, CRUD, name resolution, the game ledger, online Elo,
SQLite concurrency (two writer processes) and crash consistency (SIGKILL mid-run)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import random
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
import traceback
from pathlib import Path

import numpy as np
import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import create_engine, inspect, select, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import OperationalError

from selfplay_cli.errors import MarlError
from selfplay_cli.league import migrations, store
from selfplay_cli.league import url as league_url
from selfplay_cli.league.job_rows import NewJob
from selfplay_cli.league.models import Base, Player
from selfplay_cli.league.store import (
    GameResult,
    League,
    LeagueError,
    PlayerRow,
)
from selfplay_cli.stats.elo import elo_update

ENV = "pong"
OLD_LEAGUE = Path(__file__).parent / "data" / "league_before_variants.db"


@pytest.fixture
def league(tmp_path: Path, db_url: str) -> League:
    """A fresh league, once on SQLite and once on PostgreSQL (conftest's ``db_url``), its home under ``tmp_path``."""
    lg = League.open(home=tmp_path / "league", url=db_url)
    yield lg
    lg.close()


@pytest.fixture
def sqlite_league(tmp_path: Path) -> League:
    """A fresh league in the default place, SQLite (the tests of what only SQLite has: pragmas, locks, files)."""
    lg = League.open(home=tmp_path / "league")
    yield lg
    lg.close()


def _sql(url: str, query: str, **params: object) -> list[tuple]:
    """Run one SQL statement on the database at ``url`` outside marl (committed); its rows, if any."""
    engine = create_engine(url)
    try:
        with engine.begin() as conn:
            result = conn.execute(text(query), params)
            return [tuple(r) for r in result] if result.returns_rows else []
    finally:
        engine.dispose()


def _one_line(exc: pytest.ExceptionInfo[BaseException]) -> str:
    msg = str(exc.value)
    assert msg and "\n" not in msg, msg
    assert isinstance(exc.value, MarlError)
    return msg


def _game(a: int, b: int, score_a: float, seed: int = 0, env: str = ENV, actions: bytes | None = None) -> GameResult:
    scores = {1.0: (21, 10), 0.5: (15, 15), 0.0: (10, 21)}[score_a]
    return GameResult(env=env, players=(a, b), seed=seed, scores=scores, outcome=(score_a, 1.0 - score_a),
                      length=100 + seed, truncated=score_a == 0.5, actions=actions)


def _snap(lg: League, name: str, run: str | None = "r1", env: str = ENV, **kw: object) -> PlayerRow:
    return lg.roster.add_snapshot(env=env, run=run, name=name, path=f"/snaps/{run}/{name}.pt", sha256="0" * 64, **kw)


# --------------------------------------------------------------------------------------------------
# Schema, version, pragmas
# --------------------------------------------------------------------------------------------------


LEAGUE_TABLES = {"meta", "runs", "players", "tags", "matches", "games", "game_seats", "blobs", "workers", "jobs",
                 "seed_ranges", "videos", "alembic_version"}


def test_a_new_league_is_at_the_newest_revision(db_url: str) -> None:
    with League(db_url) as lg:
        assert lg.schema_revision() == migrations.head() == "0005"
    engine = create_engine(db_url)
    with engine.connect() as conn:
        assert set(inspect(conn).get_table_names()) == LEAGUE_TABLES
    engine.dispose()
    assert _sql(db_url, "SELECT version_num FROM alembic_version") == [("0005",)]
    # meta.schema_version stays above what a release from before Alembic reads (2): such a release refuses the league
    assert _sql(db_url, "SELECT value FROM meta WHERE key = 'schema_version'") == [("3",)]
    with League(db_url) as lg2:  # re-opening an existing league keeps it
        assert lg2.schema_revision() == "0005"


def _schema(url: str) -> dict[str, object]:
    """Everything a database says of its league tables: columns (type, nullable), keys, indexes (with partial
    ``WHERE``), unique constraints, foreign keys."""
    engine = create_engine(url)
    out: dict[str, object] = {}
    with engine.connect() as conn:
        insp = inspect(conn)
        for t in sorted(set(insp.get_table_names()) - {"alembic_version"}):
            out[t] = {
                "columns": [(c["name"], str(c["type"]), c["nullable"]) for c in insp.get_columns(t)],
                "pk": insp.get_pk_constraint(t)["constrained_columns"],
                "fks": sorted((tuple(f["constrained_columns"]), f["referred_table"], tuple(f["referred_columns"]),
                               str(f.get("options"))) for f in insp.get_foreign_keys(t)),
                "indexes": sorted((i["name"], tuple(i["column_names"]), bool(i["unique"]),
                                   str(sorted((k, str(v)) for k, v in (i.get("dialect_options") or {}).items())))
                                  for i in insp.get_indexes(t)),
                "uniques": sorted((u["name"] or "", tuple(u["column_names"])) for u in insp.get_unique_constraints(t)),
            }
    engine.dispose()
    return out


def test_the_revisions_make_the_schema_create_all_makes(db_url: str, pg_url: str, tmp_path: Path) -> None:
    """Run from nothing, the Alembic revisions give the very schema of the models (the one a new league gets):
    Alembic's own comparison finds nothing to change, and every column, key and index (the partial unique one and
    the work keys' among them) reads back the same."""
    other = pg_url if db_url.startswith("postgresql") else f"sqlite:///{tmp_path / 'by_create_all.db'}"
    League(other).close()  # create_all, stamped
    engine = create_engine(db_url)
    with engine.begin() as conn:
        assert migrations.upgrade(conn, None) == ["0002", "0003", "0004", "0005"]
    with engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
    engine.dispose()
    migrated, created = _schema(db_url), _schema(other)
    assert "uq_players_env_name_no_run" in str(migrated["players"]) and "run_id IS NULL" in str(migrated["players"])
    assert "uq_matches_work_key" in str(migrated["matches"])
    assert migrated == created
    assert _sql(db_url, "SELECT version_num FROM alembic_version") == [("0005",)]


def test_the_revisions_marl_knows_are_the_versions_folder() -> None:
    """``REVISIONS`` (read without Alembic) is the chain Alembic reads from ``versions/``, oldest first."""
    chain = [sc.revision for sc in migrations.scripts().walk_revisions()][::-1]
    assert tuple(chain) == migrations.REVISIONS and migrations.head() == migrations.scripts().get_current_head()


def test_opening_an_up_to_date_league_does_not_import_alembic(tmp_path: Path) -> None:
    """Every command opens the league: one that is up to date costs a row read, not Alembic's import."""
    url = f"sqlite:///{tmp_path / 'league.db'}"
    League(url).close()
    code = f"import sys; from selfplay_cli.league.store import League; League({url!r}).close(); " \
           "print('alembic' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "False", out.stderr


def _make_legacy(url: str, version: int) -> None:
    """Turn the league at ``url`` into one the last release before Alembic wrote: no queue tables, no Alembic table,
    ``meta.schema_version`` = ``version`` (1: no work keys either; 3: a development build's, with the queue tables)."""
    _sql(url, "DROP TABLE videos")  # (no release before Alembic had these)
    _sql(url, "DROP TABLE seed_ranges")
    for table in ("jobs", "workers", "blobs", "alembic_version")[(3 if version == 3 else 0):]:
        _sql(url, f"DROP TABLE {table}")
    if version == 1:
        _sql(url, "DROP INDEX uq_matches_work_key")
        _sql(url, "ALTER TABLE matches DROP COLUMN work_key")
    _sql(url, "UPDATE meta SET value = :v WHERE key = 'schema_version'", v=str(version))


@pytest.mark.parametrize("legacy", [1, 2, 3])
def test_a_league_of_the_previous_release_is_upgraded_in_place_once(db_url: str, pg_url: str, tmp_path: Path,
                                                                     legacy: int) -> None:
    with League(db_url) as lg:
        lg.roster.ensure_bots(ENV, ["a", "b"])
        a, b = (p.id for p in lg.roster.players())
        lg.ledger.record_games(lg.ledger.create_match(ENV, "match"), [_game(a, b, 1.0, 1), _game(b, a, 0.5, 2)])
        before = {p.id: (p.elo, p.games) for p in lg.roster.players()}
    _make_legacy(db_url, legacy)
    notes: list[str] = []
    with League(db_url, readonly=True, note=notes.append) as lg:  # a command that only reads reads it as it is
        assert lg.schema_revision() == f"legacy {legacy}"
        assert {p.id: (p.elo, p.games) for p in lg.roster.players()} == before and lg.ledger.count_games() == 2
    assert notes == [] and ("alembic_version",) not in _tables(db_url)
    with League(db_url, note=notes.append) as lg:  # a command that writes upgrades it, and says so once
        assert lg.schema_revision() == "0005"
        assert {p.id: (p.elo, p.games) for p in lg.roster.players()} == before and lg.ledger.count_games() == 2
        lg.ledger.create_match_with_games(ENV, "eval", {}, [_game(a, b, 1.0, 3)], key="k")  # what the upgrade brought
        assert set(lg.ledger.keyed_matches("k")) == {"k"} and lg.ledger.count_games() == 3
    where = str(tmp_path / "league.db") if db_url.startswith("sqlite") else make_url(db_url).render_as_string()
    brought = {1: "match work keys; snapshot blobs, work queue; seed ranges; videos",
               2: "snapshot blobs, work queue; seed ranges; videos", 3: "seed ranges; videos"}[legacy]
    assert notes == [f"marl: upgraded league database {where} from schema {legacy} to 0005 ({brought})"]
    with League(db_url, note=notes.append):
        pass
    assert len(notes) == 1
    other = pg_url if db_url.startswith("postgresql") else f"sqlite:///{tmp_path / 'new.db'}"
    League(other).close()
    assert _schema(db_url) == _schema(other)  # the upgraded league is a new league's schema
    assert _sql(db_url, "SELECT value FROM meta WHERE key = 'schema_version'") == [("3",)]


def test_a_league_of_revision_0003_gets_its_seed_ranges(db_url: str, pg_url: str, tmp_path: Path) -> None:
    """The release before seed ranges (Alembic's 0003, jobs queued in it) is upgraded by the first command that
    writes, in one line; its queued jobs stay, and the schema is a new league's."""
    with League(db_url) as lg:
        lg.roster.ensure_bots(ENV, ["a", "b"])
        lg.queue.enqueue("b1", [NewJob("games", ENV, {"x": 1})])
    _sql(db_url, "DROP TABLE videos")
    _sql(db_url, "DROP TABLE seed_ranges")
    _sql(db_url, "UPDATE alembic_version SET version_num = '0003'")
    notes: list[str] = []
    with League(db_url, note=notes.append) as lg:
        assert lg.schema_revision() == "0005" and [j.batch for j in lg.queue.jobs()] == ["b1"]
    where = str(tmp_path / "league.db") if db_url.startswith("sqlite") else make_url(db_url).render_as_string()
    assert notes == [f"marl: upgraded league database {where} from schema 0003 to 0005 (seed ranges; videos)"]
    other = pg_url if db_url.startswith("postgresql") else f"sqlite:///{tmp_path / 'new.db'}"
    League(other).close()
    assert _schema(db_url) == _schema(other)


def _tables(url: str) -> list[tuple[str]]:
    engine = create_engine(url)
    with engine.connect() as conn:
        names = [(t,) for t in inspect(conn).get_table_names()]
    engine.dispose()
    return names


def test_the_league_file_of_the_previous_release_upgrades(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A real league file written by an older release (schema 1, ``tests/data``), through the CLI: a command that
    reads reads it as it is and changes nothing; the first command that writes upgrades it, in one line on stderr."""
    from cli_helpers import run

    home = tmp_path / "h"
    home.mkdir()
    shutil.copy(OLD_LEAGUE, home / "league.db")
    code, out, err = run(capsys, "league", "ladder", "--home", str(home), "--env", "pong", "--bootstrap", "0", "--json")
    assert code == 0 and err == "" and json.loads(out)
    assert (home / "league.db").read_bytes() == OLD_LEAGUE.read_bytes()
    match = ("match", "cpu", "random", "--env", "pong", "--env-option", "points_to_win=1", "--games", "2", "-q",
             "--home", str(home), "--json")
    code, out, err = run(capsys, *match)
    assert code == 0 and json.loads(out)["games"] == 2, err
    assert err == (f"marl: upgraded league database {(home / 'league.db').resolve()} from schema 1 to 0005 "
                   "(match work keys; snapshot blobs, work queue; seed ranges; videos)\n")
    code, out, err = run(capsys, *match)
    assert code == 0 and err == ""  # once
    with League.open(home, readonly=True) as lg:
        assert lg.schema_revision() == "0005" and lg.ledger.count_games("pong") == 12 + 4  # 12 pong games before
    engine = create_engine(f"sqlite:///{home / 'league.db'}")
    with engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
    engine.dispose()


@pytest.mark.parametrize("what", ["revision", "legacy"])
def test_a_league_of_a_newer_marl_is_refused(db_url: str, what: str) -> None:
    League(db_url).close()
    if what == "revision":
        _sql(db_url, "UPDATE alembic_version SET version_num = '0099'")
    else:
        _sql(db_url, "DROP TABLE alembic_version")
        _sql(db_url, "UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    for readonly in (False, True):
        with pytest.raises(LeagueError) as exc:
            League(db_url, readonly=readonly)
        msg = _one_line(exc)
        assert f"was written by a newer marl (schema {'0099' if what == 'revision' else '99'}); upgrade marl" in msg
    if what == "revision":
        assert _sql(db_url, "SELECT version_num FROM alembic_version") == [("0099",)]  # nothing written


def test_a_league_without_a_valid_version_is_refused(db_url: str) -> None:
    League(db_url).close()
    _sql(db_url, "DROP TABLE alembic_version")
    _sql(db_url, "UPDATE meta SET value = '0' WHERE key = 'schema_version'")
    with pytest.raises(LeagueError, match="has no valid schema version") as exc:
        League(db_url)
    _one_line(exc)


def _open_at_once(url: str, start: object, out: str, ready: object) -> None:
    """Child process: say it is ``ready`` (its imports done), open the league at ``url`` when ``start`` is set; write
    the lines it said."""
    notes: list[str] = []
    ready.release()  # type: ignore[attr-defined]
    start.wait(60)  # type: ignore[attr-defined]
    try:
        League(url, note=notes.append).close()
    except BaseException:
        notes.append("error: " + traceback.format_exc())
    Path(out).write_text(json.dumps(notes))


@pytest.mark.slow
@pytest.mark.parametrize("old", [False, True])
def test_two_processes_opening_a_new_or_old_league_at_once(db_url: str, tmp_path: Path, old: bool) -> None:
    """The opening transactions are serialised: one creates (or upgrades) the league, the other finds it done."""
    if old:
        League(db_url).close()
        _make_legacy(db_url, 2)
    ctx = mp.get_context("spawn")
    start, ready = ctx.Event(), ctx.Semaphore(0)
    outs = [tmp_path / f"open{i}.json" for i in range(3)]
    procs = [ctx.Process(target=_open_at_once, args=(db_url, start, str(o), ready)) for o in outs]
    for p in procs:
        p.start()
    for _ in procs:  # all three at the start line (spawn imports marl first)
        assert ready.acquire(timeout=120)
    start.set()
    for p in procs:
        p.join(60)
    notes = [json.loads(o.read_text()) for o in outs]
    assert not any(n.startswith("error") for said in notes for n in said), notes
    assert sum(len(said) for said in notes) == (1 if old else 0), notes
    assert _sql(db_url, "SELECT version_num FROM alembic_version") == [("0005",)]
    assert _sql(db_url, "SELECT count(*) FROM meta WHERE key = 'schema_version'") == [(1,)]
    assert set(_tables(db_url)) == {(t,) for t in LEAGUE_TABLES}


def test_a_database_that_is_not_a_league_is_refused_and_left_alone(db_url: str) -> None:
    _sql(db_url, "CREATE TABLE stuff (x INTEGER)")
    for readonly in (False, True):
        with pytest.raises(LeagueError) as exc:
            League(db_url, readonly=readonly)
        assert "is not a marl league database (it holds other tables: stuff)" in _one_line(exc)
    assert _tables(db_url) == [("stuff",)]


def test_corrupt_database_or_url_is_refused(tmp_path: Path) -> None:
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"this is not sqlite at all" * 100)
    with pytest.raises(LeagueError) as exc:
        League(f"sqlite:///{junk}")
    assert str(junk) in _one_line(exc)
    with pytest.raises(LeagueError):
        League("not a url at all")


def test_sqlite_pragmas_wal(sqlite_league: League) -> None:
    league = sqlite_league
    with league.session() as s:
        assert s.execute(text("PRAGMA journal_mode")).scalar() == "wal"
        assert s.execute(text("PRAGMA busy_timeout")).scalar() == 30000
        assert s.execute(text("PRAGMA foreign_keys")).scalar() == 1
        assert s.execute(text("PRAGMA synchronous")).scalar() == 1  # NORMAL
    con = sqlite3.connect(league.db_path)  # WAL is persistent: a plain connection sees it too
    assert con.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    con.close()


def test_write_sessions_begin_immediate(sqlite_league: League) -> None:
    """SQLite: a write session takes the write lock at BEGIN; readers are never blocked by it (WAL)."""
    league = sqlite_league
    other = League(f"sqlite:///{league.db_path}", busy_timeout=0.1)
    try:
        with league.session() as s:
            s.execute(select(Player.id)).all()  # a read only, but the transaction is IMMEDIATE
            with other.session(readonly=True) as r:  # deferred read transaction: fine
                assert r.execute(select(Player.id)).all() == []
            with pytest.raises(OperationalError, match="locked"), other.session() as w:
                w.execute(select(Player.id)).all()  # cannot even BEGIN IMMEDIATE
    finally:
        other.close()


def test_open_defaults_from_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MARL_HOME", raising=False)
    monkeypatch.delenv("MARL_DB", raising=False)
    with League.open() as lg:
        assert lg.home == (tmp_path / "league").resolve() and lg.db_path.name == "league.db"
    monkeypatch.setenv("MARL_HOME", str(tmp_path / "envhome"))
    with League.open() as lg:
        assert lg.home == (tmp_path / "envhome").resolve()
        assert (tmp_path / "envhome" / "league.db").exists()
    monkeypatch.setenv("MARL_DB", f"sqlite:///{tmp_path / 'elsewhere' / 'x.db'}")
    with League.open() as lg:  # the URL wins; home is still the resolved home
        assert lg.db_path == tmp_path / "elsewhere" / "x.db" and lg.home == (tmp_path / "envhome").resolve()
    with League.open(url="sqlite://") as lg:  # any URL works, e.g. in-memory SQLite
        lg.roster.ensure_bots(ENV, ["random"])
        assert [p.name for p in lg.roster.players()] == ["random"]


# --------------------------------------------------------------------------------------------------
# Runs, bots, snapshots, tags, name resolution
# --------------------------------------------------------------------------------------------------


def test_runs_crud(league: League) -> None:
    r = league.roster.create_run("r1", ENV, {"lr": 3e-4, "net": [64, 64]}, algo="ppo")
    assert (r.name, r.env, r.algo, r.config, r.status) == ("r1", ENV, "ppo", {"lr": 3e-4, "net": [64, 64]}, "running")
    assert r.created_at.tzinfo is not None
    with pytest.raises(LeagueError) as exc:
        league.roster.create_run("r1", ENV, {})
    assert "already exists" in _one_line(exc)
    league.roster.create_run("r2", "other_env", {})
    league.roster.set_run_status("r1", "finished")
    assert league.roster.get_run("r1").status == "finished"
    assert league.roster.get_run("nope") is None
    assert [x.name for x in league.roster.list_runs()] == ["r1", "r2"]
    assert [x.name for x in league.roster.list_runs(env=ENV)] == ["r1"]
    with pytest.raises(LeagueError):
        league.roster.set_run_status("nope", "killed")
    league.roster.set_run_status("r1", store.RunStatus.STOPPED)  # stored as its word, read back equal to it
    assert league.roster.get_run("r1").status == "stopped" == store.RunStatus.STOPPED
    with pytest.raises(LeagueError, match="unknown run status 'paused': one of running, stopped, finished"):
        league.roster.set_run_status("r1", "paused")  # the docstring's promise: a status is one of RunStatus's words
    assert league.roster.get_run("r1").status == "stopped"
    with pytest.raises(LeagueError):
        league.roster.create_run("a/b", ENV, {})


def test_bots_and_snapshots(league: League) -> None:
    league.roster.ensure_bots(ENV, ["random", "chaser"])
    league.roster.ensure_bots(ENV, ["chaser", "random"])  # idempotent
    league.roster.ensure_bots("other_env", ["random"])
    bots = league.roster.players(env=ENV, kind="bot")
    assert [(b.name, b.kind, b.run, b.full_name, b.elo, b.games) for b in bots] == [
        ("random", "bot", None, "random", 1000.0, 0), ("chaser", "bot", None, "chaser", 1000.0, 0)]
    assert len(league.roster.players(kind="bot")) == 3

    league.roster.create_run("r1", ENV, {})
    league.roster.create_run("r2", ENV, {})
    s1 = _snap(league, "ep90", step=9000, episode=90, algo="ppo", meta={"note": "x"})
    assert (s1.full_name, s1.step, s1.episode, s1.algo, s1.meta, s1.kind) == ("r1/ep90", 9000, 90, "ppo", {"note": "x"},
                                                                              "snapshot")
    with pytest.raises(LeagueError) as exc:
        _snap(league, "ep90")
    assert "already exists" in _one_line(exc)
    s2 = _snap(league, "ep90", run="r2", parent_id=s1.id)
    assert s2.parent_id == s1.id and s2.full_name == "r2/ep90"
    loose = _snap(league, "imported", run=None)
    assert loose.full_name == "imported" and loose.run is None
    with pytest.raises(LeagueError):
        _snap(league, "imported", run=None)
    with pytest.raises(LeagueError):
        _snap(league, "x", run="no_such_run")
    with pytest.raises(LeagueError):
        _snap(league, "x", run="r1", env="other_env")  # r1 trains pong
    with pytest.raises(LeagueError):
        _snap(league, "x", parent_id=12345)
    assert league.roster.get_player(s1.id) == s1
    with pytest.raises(LeagueError) as exc:
        league.roster.get_player(12345)
    _one_line(exc)
    assert [p.id for p in league.roster.players(env=ENV, kind="snapshot")] == [s1.id, s2.id, loose.id]
    assert league.roster.latest(env=ENV) == loose
    assert league.roster.latest(run="r1") == s1
    assert league.roster.latest(env="other_env") is None


def test_find_players(league: League) -> None:
    league.roster.ensure_bots(ENV, ["random"])
    league.roster.create_run("r1", ENV, {})
    league.roster.create_run("r2", ENV, {})
    a = _snap(league, "ep90")
    b = _snap(league, "ep90", run="r2")
    c = _snap(league, "ep100")
    bot = league.roster.players(kind="bot")[0]
    league.roster.tag(c.id, "champion")

    def ids(name: str, **kw: object) -> list[int]:
        return [p.id for p in league.roster.find_players(name, **kw)]

    assert ids("ep90") == [a.id, b.id]  # ambiguous: both candidates
    assert ids("r1/ep90") == [a.id]
    assert ids("r2/ep90") == [b.id]
    assert ids("champion") == [c.id]
    assert ids(str(c.id)) == [c.id]
    assert ids("random") == [bot.id]
    assert ids("ep100", env="other_env") == []
    assert ids("nothing") == [] and ids("r3/ep90") == []
    assert league.roster.find_players("champion")[0].tags == ("champion",)


def test_exploitability_is_filed_in_the_row_exact_replaced_lower_bound_only_by_a_tighter_one(
        sqlite_league: League) -> None:
    lg = sqlite_league
    lg.roster.create_run("r1", ENV, {})
    p = _snap(lg, "s1", meta={"league_role": "main"})
    lg.roster.set_exploitability(p.id, {"kind": "exact", "value": 0.3, "nash_conv": 0.6})
    lg.roster.set_exploitability(p.id, {"kind": "exact", "value": 0.2,
                                        "nash_conv": 0.4})  # a newer exact figure replaces
    lg.roster.set_exploitability(p.id, {"kind": "lower_bound", "value": 0.1, "low": 0.05, "high": 0.15, "by": "x/s1"})
    lg.roster.set_exploitability(p.id, {"kind": "lower_bound", "value": 0.2, "low": 0.01,
                                        "high": 0.4})  # looser: kept out
    row = lg.roster.get_player(p.id)
    book = row.meta["exploitability"]
    assert row.meta["league_role"] == "main"
    assert (book["exact"]["value"], book["exact"]["nash_conv"]) == (0.2, 0.4)
    assert (book["lower_bound"]["low"], book["lower_bound"]["by"]) == (0.05, "x/s1")
    lg.roster.set_exploitability(p.id, {"kind": "lower_bound", "value": 0.12, "low": 0.08, "high": 0.16})
    assert lg.roster.get_player(p.id).meta["exploitability"]["lower_bound"]["low"] == 0.08
    for bad in ({"kind": "guess", "value": 0.1}, {"kind": "exact", "value": float("nan")}):
        with pytest.raises(LeagueError) as exc:
            lg.roster.set_exploitability(p.id, bad)
        _one_line(exc)
    with pytest.raises(LeagueError):
        lg.roster.set_exploitability(10**6, {"kind": "exact", "value": 0.1})


def test_tags(league: League) -> None:
    league.roster.ensure_bots(ENV, ["random"])
    league.roster.create_run("r1", ENV, {})
    a, b = _snap(league, "ep1"), _snap(league, "ep2")
    league.roster.tag(a.id, "best_so_far")
    league.roster.tag(a.id, "gold")
    assert league.roster.get_player(a.id).tags == ("best_so_far", "gold")
    league.roster.tag(b.id, "gold")  # re-tagging moves the tag
    assert league.roster.get_player(a.id).tags == ("best_so_far",)
    assert league.roster.get_player(b.id).tags == ("gold",)
    for bad in ("random", "latest", "123", "a/b", ""):
        with pytest.raises(LeagueError) as exc:
            league.roster.tag(a.id, bad)
        _one_line(exc)
    with pytest.raises(LeagueError):
        league.roster.tag(999, "x")


def test_remove_snapshot_keeps_games(league: League) -> None:
    league.roster.ensure_bots(ENV, ["random"])
    league.roster.create_run("r1", ENV, {})
    snap, other = _snap(league, "ep90"), _snap(league, "ep91")
    bot = league.roster.players(kind="bot")[0]
    league.roster.tag(snap.id, "gold")
    m = league.ledger.create_match(ENV, "match")
    ids = league.ledger.record_games(m, [_game(snap.id, bot.id, 1.0, 1), _game(bot.id, snap.id, 0.5, 2)])
    removed = league.roster.remove_snapshot(snap.id)
    assert removed.removed and removed.path == "/snaps/r1/ep90.pt" and removed.tags == ("gold",)
    after = league.roster.get_player(snap.id)
    assert after.removed and after.tags == () and after.games == 2
    assert [p.id for p in league.roster.players(kind="snapshot")] == [other.id]
    assert [p.id for p in league.roster.players(kind="snapshot", include_removed=True)] == [snap.id, other.id]
    assert league.roster.find_players("ep90") == [] and league.roster.find_players("gold") == []
    assert [p.id for p in league.roster.find_players("ep90", include_removed=True)] == [snap.id]
    assert league.roster.latest() == league.roster.get_player(other.id)
    table = league.ledger.games()
    assert table.game_id.tolist() == ids and snap.id in table.player_ids()
    assert league.ledger.pair_counts(snap.id, bot.id) == (1, 1, 0)
    with league.session(readonly=True) as s:
        assert s.execute(text("SELECT count(*) FROM game_seats WHERE player_id = :p"), {"p": snap.id}).all() == [(2,)]
    with pytest.raises(LeagueError):
        league.roster.remove_snapshot(snap.id)  # already removed
    with pytest.raises(LeagueError):
        league.roster.remove_snapshot(bot.id)  # bots are not snapshots
    league.ledger.record_games(m, [_game(snap.id, bot.id, 0.0)])  # the ledger stays append-only and usable


# --------------------------------------------------------------------------------------------------
# The ledger and the online Elo
# --------------------------------------------------------------------------------------------------


def test_record_games_online_elo_hand_computed(league: League) -> None:
    league.roster.ensure_bots(ENV, ["a", "b"])
    a, b = (p.id for p in league.roster.players())
    m = league.ledger.create_match(ENV, "match", {"games": 3})
    league.ledger.record_games(m, [_game(a, b, 1.0)])  # equal players, A wins: +-K/2
    assert (league.roster.get_player(a).elo, league.roster.get_player(b).elo) == (1008.0, 992.0)
    # Draw at 1008 vs 992: E_A = 1 / (1 + 10^(-16/400)) = 0.5230095873, delta = 16 (0.5 - E_A) = -0.3681533968.
    league.ledger.record_games(m, [_game(a, b, 0.5)])
    ra, rb = league.roster.get_player(a).elo, league.roster.get_player(b).elo
    assert ra == pytest.approx(1007.6318466032, abs=1e-9) and rb == pytest.approx(992.3681533968, abs=1e-9)
    # B wins from seat 0, then A wins from seat 1, within one batch: applied in game order.
    league.ledger.record_games(m, [_game(b, a, 1.0), _game(b, a, 0.0)])
    rb2, ra2 = elo_update(rb, ra, 1.0)
    rb3, ra3 = elo_update(rb2, ra2, 0.0)
    assert (league.roster.get_player(a).elo, league.roster.get_player(b).elo) == (ra3, rb3)
    assert league.roster.get_player(a).games == league.roster.get_player(b).games == 4
    assert league.ledger.pair_counts(a, b) == (2, 1, 1) and league.ledger.pair_counts(b, a) == (1, 1, 2)

    league.elo_k = 32.0
    league.ledger.record_games(m, [_game(a, b, 1.0)])
    assert league.roster.get_player(a).elo == elo_update(ra3, rb3, 1.0, k=32.0)[0]


def test_record_games_is_atomic_and_validated(league: League) -> None:
    league.roster.ensure_bots(ENV, ["a", "b"])
    league.roster.ensure_bots("other_env", ["c"])
    a, b, c = (p.id for p in league.roster.players())
    m = league.ledger.create_match(ENV, "tournament")
    bad_batches = [
        [_game(a, b, 1.0), _game(a, 999, 1.0)],  # unknown player in the last game
        [_game(a, b, 1.0), _game(a, c, 1.0)],  # player of another env
        [_game(a, b, 1.0, env="other_env")],  # env differs from the match
        [GameResult(ENV, (a, b), 0, (1, 0), (1.0, 1.0), 5, False)],  # outcome does not sum to 1
        [GameResult(ENV, (a, b), 0, (1,), (1.0, 0.0), 5, False)],  # scores per seat missing
    ]
    for batch in bad_batches:
        with pytest.raises(LeagueError) as exc:
            league.ledger.record_games(m, batch)
        _one_line(exc)
    with pytest.raises(LeagueError):
        league.ledger.record_games(12345, [_game(a, b, 1.0)])
    with pytest.raises(LeagueError):
        league.ledger.create_match(ENV, "friendly")
    row = league.roster.get_player(a)
    assert league.ledger.count_games() == 0 and row.elo == 1000.0 and row.games == 0
    assert league.ledger.record_games(m, []) == []


def test_games_table(league: League) -> None:
    league.roster.ensure_bots(ENV, ["a", "b", "c"])
    league.roster.ensure_bots("other_env", ["z"])
    a, b, c, z = (p.id for p in league.roster.players())
    m = league.ledger.create_match(ENV, "match")
    ids = league.ledger.record_games(m, [_game(a, b, 1.0, 7, actions=b"\x01\x02"), _game(c, a, 0.5, 8), _game(b, c,
                                                                                                              0.0, 9)])
    three_seats = GameResult(ENV, (a, b, c), 10, (3, 2, 1), (1.0, 0.0, 0.0), 50, False)
    self_play = _game(a, a, 1.0, 11)
    extra = league.ledger.record_games(m, [three_seats, self_play])
    m2 = league.ledger.create_match("other_env", "eval")
    league.ledger.record_games(m2, [GameResult("other_env", (z,), 1, (5,), (1.0,), 10, False)])
    assert league.ledger.count_games() == 6 and league.ledger.count_games(ENV) == 5

    t = league.ledger.games(env=ENV)
    assert len(t) == 3  # only 2-seat games between two different players
    assert t.game_id.tolist() == ids and t.match_id.tolist() == [m] * 3
    assert t.player_a.tolist() == [a, c, b] and t.player_b.tolist() == [b, a, c]
    assert t.score_a.tolist() == [1.0, 0.5, 0.0]
    assert t.seed.tolist() == [7, 8, 9] and t.length.tolist() == [107, 108, 109]
    assert t.truncated.tolist() == [False, True, False]
    assert t.player_ids().tolist() == [a, b, c] and t.game_id.dtype == np.int64
    pop, ia, ib = t.indexed()
    assert (pop[ia] == t.player_a).all() and (pop[ib] == t.player_b).all()
    assert league.ledger.games(players=[a, b]).game_id.tolist() == [ids[0]]
    assert league.ledger.games(players=[a], any_seat=True).game_id.tolist() == ids[:2]
    assert len(league.ledger.games(env="nope")) == 0 and league.ledger.games(env="nope").player_ids().size == 0
    # Elo ignores the 3-seat and the self-play game, the game counters do not.
    assert league.roster.get_player(a).games == 4 and league.roster.get_player(c).games == 3
    assert extra == [ids[-1] + 1, ids[-1] + 2]


def test_recompute_online_elo_reproduces_stored_values(league: League) -> None:
    league.roster.ensure_bots(ENV, ["a", "b", "c", "d"])
    league.roster.ensure_bots("other_env", ["x", "y"])
    ids = [p.id for p in league.roster.players(env=ENV)]
    x, y = (p.id for p in league.roster.players(env="other_env"))
    rng = random.Random(3)
    m = league.ledger.create_match(ENV, "tournament")
    mo = league.ledger.create_match("other_env", "match")
    for _ in range(8):
        batch = [_game(*rng.sample(ids, 2), rng.choice([0.0, 0.5, 1.0]), seed=rng.randrange(10**6)) for _ in range(15)]
        league.ledger.record_games(m, batch)
        league.ledger.record_games(mo, [_game(x, y, rng.choice([0.0, 1.0]), env="other_env")])
    stored = {p.id: (p.elo, p.games) for p in league.roster.players()}
    assert len({e for e, _ in stored.values()}) > 2
    with league.session() as s:  # scramble the cached ratings
        for p in s.scalars(select(Player)):
            p.elo, p.games = 1234.5, 77
    league.ledger.recompute_online_elo(env=ENV)
    assert {p.id: (p.elo, p.games) for p in league.roster.players(env=ENV)} == {i: stored[i] for i in ids}
    assert league.roster.get_player(x).elo == 1234.5  # other envs untouched
    league.ledger.recompute_online_elo()
    assert {p.id: (p.elo, p.games) for p in league.roster.players()} == stored


# --------------------------------------------------------------------------------------------------
# Concurrency and crash consistency (real processes, spawn context)
# --------------------------------------------------------------------------------------------------


def _writer(url: str, match_id: int, players: list[int], n_games: int, batch: int, seed: int, start: object,
            out: str, pause: float = 0.0, ready: object = None) -> None:
    """Child process: record ``n_games`` games in batches (forever if n_games < 0), report the ids.

    ``pause`` seconds between batches stand in for playing the next batch of games. ``ready`` (an Event) is set
    once the league is open, then ``start`` is waited for.
    """
    result: dict[str, object] = {}
    try:
        lg = League(url)
        if ready is not None:
            ready.set()  # type: ignore[attr-defined]
        start.wait(60)  # type: ignore[attr-defined]
        rng = random.Random(seed)
        ids: list[int] = []
        blob = os.urandom(4096)
        done = 0
        while n_games < 0 or done < n_games:
            games = [_game(*rng.sample(players, 2), rng.choice([0.0, 0.5, 1.0]), seed=rng.randrange(10**6),
                           actions=blob) for _ in range(batch)]
            ids += lg.ledger.record_games(match_id, games)
            done += batch
            time.sleep(pause)
        result = {"ids": ids, "retries": lg.lock_retries}
        lg.close()
    except BaseException:
        result = {"error": traceback.format_exc()}
        raise
    finally:
        Path(out).write_text(json.dumps(result))


def _setup_league(url: str) -> tuple[int, list[int]]:
    with League(url) as lg:
        lg.roster.ensure_bots(ENV, ["a", "b", "c", "d"])
        players = [p.id for p in lg.roster.players()]
        match_id = lg.ledger.create_match(ENV, "tournament")
        return match_id, players


def _count_games(url: str) -> int:
    return _sql(url, "SELECT count(*) FROM games")[0][0]


@pytest.mark.slow
def test_two_processes_write_concurrently(tmp_path: Path, db_url: str) -> None:
    url = db_url
    match_id, players = _setup_league(url)
    ctx = mp.get_context("spawn")
    start = ctx.Event()
    outs = [tmp_path / f"w{i}.json" for i in range(2)]
    ready = [ctx.Event() for _ in range(2)]
    procs = [ctx.Process(target=_writer, args=(url, match_id, players, 300, 10, i, start, str(outs[i]), 0.005,
                                               ready[i])) for i in range(2)]
    for p in procs:
        p.start()
    assert all(r.wait(120) for r in ready), "a writer never opened the league"  # both connected: release together
    start.set()
    for p in procs:
        p.join(60)
    results = [json.loads(o.read_text()) for o in outs]
    for p, r in zip(procs, results, strict=True):
        assert "error" not in r, r.get("error")
        assert p.exitcode == 0
    ids = results[0]["ids"] + results[1]["ids"]
    assert len(ids) == len(set(ids)) == 600
    # The writers really ran at the same time: their batches interleave in the ledger.
    first, second = results[0]["ids"], results[1]["ids"]
    assert min(first) < max(second) and min(second) < max(first)
    with League(url) as lg:
        assert lg.ledger.count_games() == 600
        assert sorted(lg.ledger.games().game_id.tolist()) == sorted(ids)
        assert sum(p.games for p in lg.roster.players()) == 1200
        stored = {p.id: p.elo for p in lg.roster.players()}
        lg.ledger.recompute_online_elo()  # online updates were serialized in game-id order
        assert {p.id: p.elo for p in lg.roster.players()} == stored
    # SQLite: BEGIN IMMEDIATE + busy_timeout suffice; PostgreSQL: the players' rows are locked in one order, so the
    # writers never deadlock. The retry is only a safety net.
    assert results[0]["retries"] == results[1]["retries"] == 0


@pytest.mark.slow
def test_sigkill_mid_run_leaves_consistent_ledger(tmp_path: Path, db_url: str) -> None:
    if sys.platform == "win32":  # pragma: no cover
        pytest.skip("SIGKILL is POSIX")
    url = db_url
    match_id, players = _setup_league(url)
    ctx = mp.get_context("spawn")
    start = ctx.Event()
    start.set()
    proc = ctx.Process(target=_writer, args=(url, match_id, players, -1, 10, 1, start, str(tmp_path / "k.json")))
    proc.start()
    deadline = time.monotonic() + 30
    count = 0
    while count < 200 and time.monotonic() < deadline:
        time.sleep(0.02)
        count = _count_games(url)
    assert count >= 200, "writer made no progress"
    os.kill(proc.pid, signal.SIGKILL)  # (wherever it is: mid-transaction, between two)
    proc.join(10)
    assert proc.exitcode == -signal.SIGKILL

    with League(url) as lg, lg.session(readonly=True) as s:
        if lg.is_sqlite:
            assert s.execute(text("PRAGMA integrity_check")).scalar() == "ok"
        n = s.execute(text("SELECT count(*) FROM games")).scalar()
        assert n >= 200 and n % 10 == 0  # whole batches only
        incomplete = s.execute(text(
            "SELECT count(*) FROM games g WHERE g.n_seats != "
            "(SELECT count(*) FROM game_seats x WHERE x.game_id = g.id)")).scalar()
        orphans = s.execute(text(
            "SELECT count(*) FROM game_seats x LEFT JOIN games g ON g.id = x.game_id WHERE g.id IS NULL")).scalar()
        assert incomplete == 0 and orphans == 0
        assert s.execute(text("SELECT sum(games) FROM players")).scalar() == 2 * n  # Elo cache in step
        if lg.is_sqlite:
            assert s.execute(text("PRAGMA foreign_key_check")).all() == []
    with League(url) as lg:
        stored = {p.id: p.elo for p in lg.roster.players()}
        lg.ledger.recompute_online_elo()
        assert {p.id: p.elo for p in lg.roster.players()} == stored
        lg.ledger.record_games(match_id, [_game(players[0], players[1], 1.0)])  # still writable
        assert lg.ledger.count_games() == n + 1


# --------------------------------------------------------------------------------------------------
# SQLite on a network file system
# --------------------------------------------------------------------------------------------------


def _mountinfo(tmp_path: Path) -> str:
    """A /proc/self/mountinfo of a machine whose ``tmp_path/nfs`` is NFS (with a local disk mounted inside it),
    ``tmp_path/my share`` SMB and ``tmp_path/remote`` sshfs."""
    for d in ("nfs/local", "nfsx", "my share", "remote"):
        (tmp_path / d).mkdir(parents=True)
    t = str(tmp_path.resolve())
    return "\n".join([
        "22 1 8:1 / / rw,relatime shared:1 - ext4 /dev/sda1 rw",
        f"40 22 0:50 / {t}/nfs rw,relatime shared:30 - nfs4 server:/export rw,vers=4.2",
        f"41 40 8:2 / {t}/nfs/local rw,relatime - xfs /dev/sdb1 rw",
        f"42 22 0:51 / {t}/my\\040share rw,relatime shared:31 master:2 - cifs //nas/share rw",
        f"43 22 0:52 / {t}/remote rw,nosuid - fuse.sshfs me@host:/data rw,user_id=0",
        "garbage line",
    ])


def test_network_filesystem_is_told_by_the_longest_mount_point(tmp_path: Path) -> None:
    info = _mountinfo(tmp_path)
    nfs = league_url.network_filesystem
    assert nfs(tmp_path / "nfs", info) == "nfs4"
    assert nfs(tmp_path / "nfs" / "not" / "made" / "yet", info) == "nfs4"  # a league home still to be created
    assert nfs(tmp_path / "nfs" / "local", info) is None  # a local disk mounted inside the NFS share
    assert nfs(tmp_path / "nfsx", info) is None  # a neighbour whose name starts the same is not inside it
    assert nfs(tmp_path / "my share", info) == "cifs"  # mountinfo writes a space as \040
    assert nfs(tmp_path / "remote", info) == "fuse.sshfs"
    assert nfs(tmp_path, info) is None
    (tmp_path / "link").symlink_to(tmp_path / "remote")
    assert nfs(tmp_path / "link", info) == "fuse.sshfs"  # symlinks followed
    assert nfs(tmp_path, "") is None


def test_a_sqlite_league_on_a_network_file_system_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    from cli_helpers import run

    info = _mountinfo(tmp_path)
    home = tmp_path / "nfs" / "league"
    League.open(home).close()  # made before the share was mounted over it, say
    monkeypatch.setattr(league_url, "_read_mountinfo", lambda: info)
    monkeypatch.delenv(league_url.ALLOW_NETWORK_SQLITE, raising=False)
    before = (home / "league.db").read_bytes()
    for args in (("league", "ladder"), ("checkpoint", "list"), ("elo", "fit")):
        code, out, err = run(capsys, *args, "--home", str(home))
        assert code == 2 and out == "" and err.count("\n") == 1, (args, code, err)
        assert f"{home.resolve() / 'league.db'} is on a network file system (nfs4)" in err
        assert "use a PostgreSQL league" in err and "MARL_ALLOW_NETWORK_SQLITE=1" in err
    assert (home / "league.db").read_bytes() == before
    with pytest.raises(LeagueError, match="network file system"):
        League.open(tmp_path / "remote" / "new")
    assert not (tmp_path / "remote" / "new").exists()  # refused before anything is made
    monkeypatch.setenv(league_url.ALLOW_NETWORK_SQLITE, "1")  # the user knows better
    code, _, err = run(capsys, "checkpoint", "list", "--home", str(home))
    assert code == 0, err
