"""A league on PostgreSQL (the suite's own server, conftest's ``pg_server``): the URLs users type, the mistakes they
make (each one line, exit 2 or 4, nothing written), and a server restarted under a league that is writing."""

from __future__ import annotations

import json
import sys
import threading
import time

import pytest
from cli_helpers import run
from conftest import start_postgres, stop_postgres
from sqlalchemy import create_engine, event, inspect, text
from sqlalchemy.exc import DBAPIError

from selfplay_cli.league.store import GameResult, League, LeagueError, LeagueIOError

ENV = "pong"


def _socket_dir(pg_url: str) -> str:
    return pg_url.split("host=", 1)[1]


def _database(pg_url: str) -> str:
    return pg_url.split("@/", 1)[1].split("?", 1)[0]


def _tables(url: str) -> set[str]:
    engine = create_engine(url)
    with engine.connect() as conn:
        names = set(inspect(conn).get_table_names())
    engine.dispose()
    return names


def _one_line(code: int, out: str, err: str, exit_code: int) -> str:
    assert code == exit_code and out == "" and err.count("\n") == 1, (code, out, err)
    assert "Traceback" not in err
    return err


def _games(a: int, b: int, n: int, first_seed: int) -> list[GameResult]:
    return [GameResult(ENV, (a, b) if i % 2 else (b, a), seed=first_seed + i, scores=(1, 0), outcome=(1.0, 0.0),
                       length=10, truncated=False) for i in range(n)]


# -- the URLs a user types ---------------------------------------------------------------------------------------------


def test_a_plain_postgresql_url_means_psycopg_3(pg_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    """SQLAlchemy reads ``postgresql://`` as psycopg2, which marl does not bring: marl reads it as psycopg 3."""
    for scheme in ("postgresql", "postgres"):
        plain = pg_url.replace("postgresql+psycopg://", f"{scheme}://")
        with League(plain) as lg:
            assert lg.url.drivername == "postgresql+psycopg" and lg.is_postgres and not lg.is_sqlite
            lg.roster.ensure_bots(ENV, ["random"])
    code, out, err = run(capsys, "checkpoint", "list", "--db", pg_url.replace("+psycopg", ""), "--json")
    assert code == 0 and out.strip() == "[]", err


def test_every_command_takes_the_url_from_marl_db(pg_url: str, tmp_path, monkeypatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A match played and read back through the CLI, the league in PostgreSQL (``MARL_DB``), nothing in the home
    but what is a file."""
    monkeypatch.setenv("MARL_DB", pg_url)
    monkeypatch.setenv("MARL_HOME", str(tmp_path / "home"))
    code, _, err = run(capsys, "match", "cpu", "random", "--env", "pong", "--games", "4", "--env-option",
                       "points_to_win=1", "--quiet")
    assert code == 0, err
    code, out, err = run(capsys, "league", "ladder", "--env", "pong", "--env-option", "points_to_win=1", "--json")
    assert code == 0, err
    assert sorted(r["policy"] for r in json.loads(out)) == ["cpu", "random"]
    assert not (tmp_path / "home" / "league.db").exists()
    with League(pg_url, readonly=True) as lg:
        assert lg.ledger.count_games("pong") == 4


def test_a_read_only_league_cannot_write_even_by_hand(pg_url: str) -> None:
    """A unit of work of a command that only reads runs in a READ ONLY transaction on PostgreSQL."""
    League(pg_url).close()
    with League(pg_url, readonly=True) as lg, pytest.raises(DBAPIError, match="read-only transaction"), \
            lg.session(readonly=True) as s:
        s.execute(text("INSERT INTO meta (key, value) VALUES ('x', 'y')"))
    assert ("x",) not in {tuple(r) for r in create_engine(pg_url).connect().execute(text("SELECT key FROM meta"))}


# -- mistakes: one line, exit 2 or 4, nothing written -----------------------------------------------------------------


def test_a_url_that_cannot_be_reached_is_exit_4(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    for url in (f"postgresql+psycopg://postgres@/league?host={tmp_path / 'no-server-here'}",
                "postgresql://postgres@127.0.0.1:1/league?connect_timeout=3"):
        for args in (("league", "ladder"), ("checkpoint", "list"), ("checkpoint", "tag", "x", "y")):
            err = _one_line(*run(capsys, *args, "--db", url), exit_code=4)
            assert err.startswith("marl: I/O error: cannot reach league database postgresql+psycopg://postgres@"), err


def test_wrong_credentials_or_database_are_exit_2(pg_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    sock = _socket_dir(pg_url)
    for url, words in ((f"postgresql://nobody@/{_database(pg_url)}?host={sock}", 'role "nobody" does not exist'),
                       (f"postgresql://postgres@/no_such_db?host={sock}", 'database "no_such_db" does not exist')):
        for args in (("league", "ladder"), ("checkpoint", "list"), ("elo", "fit")):
            err = _one_line(*run(capsys, *args, "--db", url), exit_code=2)
            assert err.startswith("marl: error: cannot open league database ") and words in err, err
    assert _tables(pg_url) == set()


def test_a_database_that_is_not_a_league_is_exit_2(pg_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    engine = create_engine(pg_url)
    with engine.begin() as conn:
        conn.execute(text("CREATE TABLE customers (id INTEGER PRIMARY KEY)"))
    engine.dispose()
    for args in (("league", "ladder"), ("checkpoint", "list"), ("checkpoint", "tag", "x", "y")):
        err = _one_line(*run(capsys, *args, "--db", pg_url), exit_code=2)
        assert "is not a marl league database (it holds other tables: customers)" in err
    assert _tables(pg_url) == {"customers"}


def test_a_missing_driver_says_what_to_install(pg_url: str, monkeypatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "psycopg", None)  # as if psycopg were not installed
    for url in (pg_url, pg_url.replace("+psycopg", "")):
        err = _one_line(*run(capsys, "league", "ladder", "--db", url), exit_code=2)
        assert 'no driver (pip install "selfplay-cli[postgres]")' in err, err


def test_a_league_of_a_newer_marl_is_exit_2(pg_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    League(pg_url).close()
    engine = create_engine(pg_url)
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = '0042'"))
    engine.dispose()
    for args in (("league", "ladder"), ("checkpoint", "list"), ("checkpoint", "tag", "x", "y")):
        err = _one_line(*run(capsys, *args, "--db", pg_url), exit_code=2)
        assert err.endswith("was written by a newer marl (schema 0042); upgrade marl\n"), err


# -- the server restarted under a league that writes -------------------------------------------------------------------


@pytest.mark.slow
def test_writes_go_on_across_a_server_restart(pg_server, pg_url: str, pg_restart) -> None:
    """The server is stopped (every connection cut) for 3 s while a league writes batch after batch: the writes wait
    for it, say so once, and go on; every batch is stored once, none is lost, and the Elo cache matches the ledger.
    Each batch is a unit of work with its key, as every unit marl writes under a server that may go away is (a
    gauntlet's matchup, a queued job): a stop that cuts a COMMIT off leaves it unknown whether the batch is stored,
    and only a keyed unit may then be done again (it counts once). An unkeyed write cut there is refused instead
    (test_a_write_whose_commit_is_cut_off_is_not_retried): the stop lands in one now and then under load."""
    notes: list[str] = []
    lg = League(pg_url, note=notes.append)
    lg.roster.ensure_bots(ENV, ["a", "b", "c"])
    a, b, c = (p.id for p in lg.roster.players())
    written = threading.Event()
    times: dict[str, float] = {}

    def restart() -> None:
        written.wait(30)
        times["stop"] = time.monotonic()
        stop_postgres(pg_server)
        time.sleep(3.0)
        times["start"] = time.monotonic()
        start_postgres(pg_server)
        times["up"] = time.monotonic()

    thread = threading.Thread(target=restart)
    thread.start()
    ids: list[int] = []
    stamps: list[float] = []
    batches = 0
    deadline = time.monotonic() + 60
    while (not times.get("up") or stamps[-1] < times["up"] + 1.0) and time.monotonic() < deadline:
        ids += lg.ledger.create_match_with_games(ENV, "tournament", None, _games(a if batches % 2 else c, b, 10,
                                                                                 10 * batches),
                                                 key=f"restart-batch-{batches}")[1]
        stamps.append(time.monotonic())
        batches += 1
        if batches == 20:
            written.set()
        time.sleep(0.01)
    thread.join(30)
    assert "up" in times and stamps[-1] > times["up"], "the writes never went on after the restart"
    assert len(ids) == len(set(ids)) >= 10 * (batches - 1)  # (a batch done again after a cut COMMIT: stored once)
    assert lg.ledger.count_games() == 10 * batches
    assert sorted(lg.ledger.games().seed.tolist()) == list(range(10 * batches))  # every batch once, none lost
    stored = {p.id: (p.elo, p.games) for p in lg.roster.players()}
    assert sum(g for _, g in stored.values()) == 20 * batches
    lg.ledger.recompute_online_elo()
    assert {p.id: (p.elo, p.games) for p in lg.roster.players()} == stored
    assert len(notes) == 1 and "unreachable, retrying" in notes[0], notes
    gap = max(t1 - t0 for t0, t1 in zip(stamps, stamps[1:], strict=False))
    after = min(t for t in stamps if t > times["up"]) - times["up"]
    print(f"\nrestart: {batches} batches of 10 games, server down {times['start'] - times['stop']:.1f} s "
          f"(+{times['up'] - times['start']:.1f} s to start), longest wait of a write {gap:.1f} s, first write "
          f"{after:.2f} s after the server was up, {lg.reconnects} reconnect tries")
    lg.close()


def test_a_server_that_stays_away_ends_the_command_with_exit_4(pg_server, pg_url: str, pg_restart) -> None:
    notes: list[str] = []
    lg = League(pg_url, note=notes.append, reconnect_for=1.5)
    lg.roster.ensure_bots(ENV, ["a", "b"])
    a, b = (p.id for p in lg.roster.players())
    match = lg.ledger.create_match(ENV, "match")
    stop_postgres(pg_server)
    try:
        began = time.monotonic()
        with pytest.raises(LeagueIOError) as exc:
            lg.ledger.record_games(match, _games(a, b, 4, 0))
        waited = time.monotonic() - began
    finally:
        start_postgres(pg_server)
    msg = str(exc.value)
    assert exc.value.exit_code == 4 and "\n" not in msg and "unreachable for 2 s" in msg, msg
    assert waited >= 1.5  # it retried for its reconnect time before it gave up
    assert len(notes) == 1 and "unreachable, retrying for up to 2 s" in notes[0]
    assert lg.ledger.count_games() == 0  # nothing half-written; the league works again
    lg.ledger.record_games(match, _games(a, b, 4, 0))
    assert lg.ledger.count_games() == 4
    lg.close()


def test_a_league_error_is_not_mistaken_for_a_lost_server(pg_url: str) -> None:
    """A unique clash or a bad name is an error at once, not a wait for the server."""
    with League(pg_url, reconnect_for=30) as lg:
        lg.roster.create_run("r", ENV, {})
        began = time.monotonic()
        with pytest.raises(LeagueError, match="already exists"):
            lg.roster.create_run("r", ENV, {})
        assert time.monotonic() - began < 5 and lg.reconnects == 0


def test_a_new_empty_database_reads_as_an_empty_league(pg_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    """A database just made for the league (createdb): the commands that only read see an empty league, as they do
    a home without one, and create nothing there; the first command that writes makes the league."""
    code, out, err = run(capsys, "checkpoint", "list", "--db", pg_url, "--json")
    assert code == 0 and json.loads(out) == [], err
    err = _one_line(*run(capsys, "league", "ladder", "--db", pg_url), exit_code=2)
    assert "no rated games yet" in err
    assert _tables(pg_url) == set()
    assert run(capsys, "checkpoint", "tag", "x", "y", "--db", pg_url)[0] == 2  # no snapshot x: but the league is made
    assert "alembic_version" in _tables(pg_url)


def test_a_write_whose_commit_is_cut_off_is_not_retried(pg_url: str) -> None:
    """The connection dies as COMMIT goes out: whether it was stored cannot be known from here, so the unit is not
    played again (it could count twice); one line, exit 4. (Here the server had not committed it: nothing stored.)"""
    lg = League(pg_url, reconnect_for=30)
    lg.roster.ensure_bots(ENV, ["a", "b"])
    a, b = (p.id for p in lg.roster.players())
    match = lg.ledger.create_match(ENV, "match")
    killer = create_engine(pg_url)

    def cut(session) -> None:  # the server drops this very connection just before COMMIT is sent
        pid = session.connection().exec_driver_sql("SELECT pg_backend_pid()").scalar()
        with killer.begin() as conn:
            conn.execute(text("SELECT pg_terminate_backend(:pid)"), {"pid": pid})

    event.listen(lg._sessions, "before_commit", cut)
    with pytest.raises(LeagueIOError) as exc:
        lg.ledger.record_games(match, _games(a, b, 4, 0))
    event.remove(lg._sessions, "before_commit", cut)
    killer.dispose()
    msg = str(exc.value)
    assert "\n" not in msg and "while committing" in msg and "may or may not be stored" in msg, msg
    assert lg.reconnects == 0 and lg.ledger.count_games() == 0
    lg.ledger.record_games(match, _games(a, b, 4, 0))  # the league goes on
    assert lg.ledger.count_games() == 4
    lg.close()


def test_a_keyed_write_whose_commit_is_cut_off_is_done_again_once(pg_url: str) -> None:
    """A unit keyed by its work key (a gauntlet's matchup, a job's games) is safe to do twice: retried after the cut,
    its games are stored once."""
    notes: list[str] = []
    lg = League(pg_url, reconnect_for=30, note=notes.append)
    lg.roster.ensure_bots(ENV, ["a", "b"])
    a, b = (p.id for p in lg.roster.players())
    killer = create_engine(pg_url)
    cuts: list[int] = []

    def cut(session) -> None:
        if not cuts:
            cuts.append(session.connection().exec_driver_sql("SELECT pg_backend_pid()").scalar())
            with killer.begin() as conn:
                conn.execute(text("SELECT pg_terminate_backend(:pid)"), {"pid": cuts[0]})

    event.listen(lg._sessions, "before_commit", cut)
    match, ids = lg.ledger.create_match_with_games(ENV, "eval", {}, _games(a, b, 4, 0), key="gauntlet/r/1")
    event.remove(lg._sessions, "before_commit", cut)
    killer.dispose()
    assert len(cuts) == 1 and len(ids) == 4 and lg.reconnects == 1 and len(notes) == 1
    assert lg.ledger.count_games() == 4 and set(lg.ledger.keyed_matches("gauntlet/r/")) == {"gauntlet/r/1"}
    lg.close()
