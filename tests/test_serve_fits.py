"""``marl serve``'s background fits: while the first fit of a game runs its pages are a notice that reloads itself
(the fit held on an event here, not timed); a change of the league is refitted and shown; a fit that fails (a corrupt
row) is one line on the page and in the log while the server goes on answering; no thread outlives the app."""

from __future__ import annotations

import logging
import sqlite3
import threading
from pathlib import Path

import pytest
from cli_helpers import run_json
from league_helpers import record_plan

from selfplay_cli.league.store import League

pytest.importorskip("starlette", reason='marl serve needs its extra: pip install -e ".[serve]"')
from starlette.testclient import TestClient  # noqa: E402

from selfplay_cli.serve.app import create_app  # noqa: E402
from selfplay_cli.serve.fits import FitCache, fit_game  # noqa: E402
from selfplay_cli.serve.queries import Reader  # noqa: E402

DEADLINE = 120.0  # (seconds a test waits for a fit before it fails; none is timed)
REFRESH = '<meta http-equiv="refresh" content="3">'


@pytest.fixture
def home(tmp_path: Path) -> Path:
    home = tmp_path / "h"
    with League.open(home) as lg:
        lg.roster.ensure_bots("pong", ["a", "b", "c"])
        ids = {p.name: p.id for p in lg.roster.players("pong")}
        record_plan(lg, ids, [("a", "b", 12, 4), ("b", "c", 10, 6), ("a", "c", 14, 2)])  # 48 games
    return home


@pytest.fixture(autouse=True)
def no_thread_left():
    yield
    assert not [t for t in threading.enumerate() if t.name == "marl-serve-fits"]


def _ladder_shown(page: str, cli: list[dict]) -> None:
    for row in cli:
        assert f"{row['elo']:.1f}" in page and f"{row['ci_low']:.1f} .. {row['ci_high']:.1f}" in page, row["policy"]
        assert f"{row['wins']}-{row['draws']}-{row['losses']}" in page


@pytest.mark.slow
def test_pages_show_a_notice_while_the_first_fit_runs_then_its_figures(home: Path, capsys) -> None:
    started, release = threading.Event(), threading.Event()

    def held(reader: Reader, env: str, variant: str, games: int):
        started.set()
        assert release.wait(DEADLINE), "the test never released the fit"
        return fit_game(reader, env, variant, games)

    reader = Reader(home, None)
    fits = FitCache(reader, fit=held)
    try:
        with TestClient(create_app(reader, "x", fits), raise_server_exceptions=False) as client:
            try:
                assert started.wait(DEADLINE)
                for url in ["/ladder", "/matrix", "/player/1", "/player/1?vs=2"]:
                    r = client.get(url)
                    assert r.status_code == 200, url
                    assert "fitting the ratings of 48 games of pong" in r.text and "s ago)" in r.text, url
                    assert REFRESH in r.text, url
                health = client.get("/health").json()
                assert health["fitting"]["games"] == 48 and health["fitted"] == []
                assert client.get("/queue").status_code == 200 and client.get("/").status_code == 200
            finally:
                release.set()
            assert fits.wait(DEADLINE)
            cli = run_json(capsys, "league", "ladder", "--home", str(home), "--env", "pong")
            page = client.get("/ladder").text
            assert REFRESH not in page and "fitting the ratings" not in page
            assert "ratings as of " in page and ", 48 games (fitted in the background" in page
            _ladder_shown(page, cli)
            assert 'id="rating"' in client.get("/player/1").text
            assert client.get("/health").json()["fitted"][0]["games"] == 48
    finally:
        reader.close()


def test_a_change_of_the_league_is_refitted_and_shown(home: Path, capsys) -> None:
    reader = Reader(home, None)
    try:
        with TestClient(create_app(reader, "x"), raise_server_exceptions=False) as client:
            assert client.app.state.fits.wait(DEADLINE)
            before = client.get("/ladder").text
            assert ", 48 games (" in before
            with League.open(home) as lg:
                ids = {p.name: p.id for p in lg.roster.players("pong")}
                record_plan(lg, ids, [("c", "a", 16, 0)])  # c now beats a 16 times
            assert client.app.state.fits.wait(DEADLINE)
            page = client.get("/ladder").text
            assert ", 64 games (" in page
            cli = run_json(capsys, "league", "ladder", "--home", str(home), "--env", "pong")
            _ladder_shown(page, cli)
            assert page != before
    finally:
        reader.close()


def test_a_failing_fit_is_one_line_on_the_page_and_in_the_log_and_the_server_goes_on(home: Path, capsys,
                                                                                     caplog) -> None:
    con = sqlite3.connect(home / "league.db")
    con.execute("UPDATE game_seats SET points = 'garbage' WHERE game_id = 3")  # a corrupt row
    con.commit()
    con.close()
    reader = Reader(home, None)
    try:
        with caplog.at_level(logging.ERROR, logger="marl.serve"), \
                TestClient(create_app(reader, "x"), raise_server_exceptions=False) as client:
            assert client.app.state.fits.wait(DEADLINE)
            for url in ["/ladder", "/matrix", "/player/1"]:
                r = client.get(url)
                assert r.status_code == 200, url
                said = [line for line in r.text.splitlines() if 'id="fit-error"' in line]
                assert len(said) == 1 and "could not convert string to float: &#39;garbage&#39;" in said[0], url
                assert REFRESH not in r.text and "Traceback" not in r.text
            assert client.get("/").status_code == 200 and client.get("/queue").status_code == 200
            errors = client.get("/health").json()["errors"]
            assert len(errors) == 1 and "garbage" in errors[0]["error"]
            logged = [r.getMessage() for r in caplog.records if "fitting pong" in r.getMessage()]
            assert len(logged) == 1 and "\n" not in logged[0] and "garbage" in logged[0]
            # the row mended and a game more: the next fit shows the figures
            con = sqlite3.connect(home / "league.db")
            con.execute("UPDATE game_seats SET points = CASE seat WHEN 0 THEN 1.0 ELSE 0.0 END WHERE game_id = 3")
            con.commit()
            con.close()
            with League.open(home) as lg:
                ids = {p.name: p.id for p in lg.roster.players("pong")}
                record_plan(lg, ids, [("a", "b", 1, 0)])
            assert client.app.state.fits.wait(DEADLINE)
            page = client.get("/ladder").text
            assert 'id="fit-error"' not in page
            _ladder_shown(page, run_json(capsys, "league", "ladder", "--home", str(home), "--env", "pong"))
    finally:
        reader.close()
