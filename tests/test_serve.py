"""``marl serve`` without a browser: every page over a hand-written league shows the CLI's own figures; hostile names,
tags, notes and errors show as text; a replay reaches only a file the league registered inside its videos folder; bad
query parameters are 4xx pages; the server cannot write and leaves the league file as it was."""

from __future__ import annotations

import json
import os
import sqlite3
from pathlib import Path

import pytest
from cli_helpers import run, run_json
from league_helpers import record_plan

from selfplay_cli.league.queue import NewJob
from selfplay_cli.league.store import League

pytest.importorskip("starlette", reason='marl serve needs its extra: pip install -e ".[serve]"')
from starlette.testclient import TestClient  # noqa: E402

from selfplay_cli.serve.app import create_app  # noqa: E402
from selfplay_cli.serve.queries import Reader  # noqa: E402

SCRIPT = "<script>alert(1)</script>"
IMG = '"><img src=x onerror=alert(1)>'
PAGES = ["/", "/ladder", "/matrix", "/matches", "/queue", "/replays", "/replay/1", "/player/1", "/player/1?vs=2",
         "/ladder?sort=elo&order=asc", "/ladder?q=a", "/ladder?kind=bot", "/matches?kind=match"]


@pytest.fixture
def league_home(tmp_path: Path) -> Path:
    """Three scripted players of pong with games chosen by hand, a queued job, one recording; then hostile rows
    written as another user of a shared league could (straight into the database)."""
    home = tmp_path / "h"
    with League.open(home) as lg:
        lg.roster.ensure_bots("pong", ["a", "b", "c"])
        ids = {p.name: p.id for p in lg.roster.players("pong")}
        record_plan(lg, ids, [("a", "b", 12, 4), ("b", "c", 10, 6), ("a", "c", 14, 2)])
        lg.roster.tag(ids["a"], "champ")
        lg.queue.enqueue("batch-1", [NewJob("games", "pong", {"x": 1})])
        (home / "videos").mkdir()
        (home / "videos" / "a-vs-b.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x00" * 64)
        lg.videos.register(env="pong", path=home / "videos" / "a-vs-b.mp4", fmt="mp4", players=[ids["a"], ids["b"]],
                           seed=0, length=10)
        lg.videos.register(env="pong", path=home / "videos" / "a-vs-b.mp4", fmt="mp4", players=[ids["a"]],
                           seed=1, length=10)
    con = sqlite3.connect(home / "league.db")
    con.execute("UPDATE players SET name = ?, meta = ? WHERE name = 'c'", (SCRIPT, json.dumps({"note": IMG})))
    con.execute("UPDATE tags SET tag = ?", (f"q'uote{IMG}",))
    con.execute("UPDATE jobs SET error = ?, batch = ?", (SCRIPT, f"b{IMG}"))
    con.execute("UPDATE videos SET path = '/etc/passwd' WHERE id = 2")  # a row tampered with
    con.commit()
    con.close()
    return home


@pytest.fixture
def client(league_home: Path):
    reader = Reader(league_home, None)
    with TestClient(create_app(reader, str(league_home)), raise_server_exceptions=False) as c:
        assert c.app.state.fits.wait(120), "the background fit did not finish in time"  # (a deadline, polled)
        yield c
    reader.close()


def test_every_page_loads_and_shows_the_cli_ladder(client: TestClient, league_home: Path, capsys) -> None:
    for url in PAGES:
        r = client.get(url)
        assert r.status_code == 200, (url, r.text[:500])
        assert "script-src 'none'" in r.headers["content-security-policy"]
    assert '<td class="num">48</td>' in client.get("/matches").text  # the games the ledger holds of the one match
    cli = run_json(capsys, "league", "ladder", "--home", str(league_home), "--env", "pong")
    page = client.get("/ladder").text
    for row in cli:  # each row's Elo, interval, games and record as the CLI's JSON gives them
        assert f"{row['elo']:.1f}" in page and f"{row['ci_low']:.1f} .. {row['ci_high']:.1f}" in page
        assert f"{row['wins']}-{row['draws']}-{row['losses']}" in page
    reader = Reader(league_home, None)
    try:
        assert reader.ladder("pong", "").records == cli  # the very records of `marl league ladder --json`
        matrix = run_json(capsys, "league", "matrix", "--home", str(league_home), "--env", "pong")
        assert reader.matrix("pong", "", 10, None, 8, "points").to_json() == {k: v for k, v in matrix.items()
                                                                            if k != "png"}
        predict = run_json(capsys, "league", "predict", "a", "b", "--env", "pong", "--home", str(league_home))
        a, b = (next(p for p in reader.league.roster.players("pong") if p.name == n) for n in "ab")
        assert reader.predict("pong", "", a, b) == predict
        queue = run_json(capsys, "queue", "--home", str(league_home))
        assert reader.queue(None, None, 20) == queue
    finally:
        reader.close()
    assert f"{100 * predict['score']:.1f}%" in client.get(f"/player/{a.id}?vs={b.id}").text


def test_names_tags_notes_and_errors_show_as_text(client: TestClient) -> None:
    for url in ["/ladder", "/matrix", "/player/3", "/player/1?vs=3", "/queue", "/replays", "/matches"]:
        html = client.get(url).text
        assert SCRIPT not in html and "<img src=x" not in html, url
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in client.get("/ladder").text
    player = client.get("/player/3").text
    assert "&#34;&gt;&lt;img src=x onerror=alert(1)&gt;" in player  # the note
    assert "q&#39;uote&#34;&gt;&lt;img" in client.get("/player/1").text  # the tag
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in client.get("/queue").text  # a job's error


@pytest.mark.parametrize("url", ["/video/..%2F..%2Fetc%2Fpasswd", "/video/%2e%2e%2fleague.db", "/video/%2Fetc%2Fpasswd",
                                 "/video/2", "/replay/../league.db", "/video/-1", "/video/999", "/video/1.0",
                                 "/static/../league.db", "/static/%2e%2e/%2e%2e/league/store.py"])
def test_a_replay_reaches_only_a_registered_file_inside_the_videos_folder(client: TestClient, url: str) -> None:
    r = client.get(url)
    assert r.status_code == 404, (url, r.status_code)
    assert "root:" not in r.text and "SQLite format" not in r.text


def test_a_registered_video_plays_with_range_requests(client: TestClient, league_home: Path) -> None:
    whole = (league_home / "videos" / "a-vs-b.mp4").read_bytes()
    r = client.get("/video/1")
    assert r.status_code == 200 and r.content == whole and r.headers["content-type"] == "video/mp4"
    part = client.get("/video/1", headers={"Range": "bytes=4-11"})
    assert part.status_code == 206 and part.content == whole[4:12]
    assert '<video id="video" controls' in client.get("/replay/1").text
    assert "not in the league" in client.get("/replay/2").text  # the tampered row: no player for it


def test_a_symlink_out_of_the_videos_folder_is_not_followed(league_home: Path, tmp_path: Path) -> None:
    secret = tmp_path / "secret.mp4"
    secret.write_bytes(b"secret")
    (league_home / "videos" / "link.mp4").symlink_to(secret)
    with League.open(league_home) as lg:
        row = lg.videos.register(env="pong", path=league_home / "videos" / "link.mp4", fmt="mp4", players=[1],
                                 seed=0, length=1)
    assert row is None  # (resolved outside the folder: not the league's)
    con = sqlite3.connect(league_home / "league.db")
    con.execute("INSERT INTO videos (env, path, format, players, seed, length, meta, created_at) "
                "VALUES ('pong', 'link.mp4', 'mp4', '[1]', 0, 1, '{}', '2026-01-01')")
    con.commit()
    con.close()
    reader = Reader(league_home, None)
    try:
        with TestClient(create_app(reader, "x"), raise_server_exceptions=False) as c:
            r = c.get("/video/3")
            assert r.status_code == 404 and b"secret" not in r.content
    finally:
        reader.close()


BAD = [("/ladder?env=nope", 404), ("/ladder?sort=nonsense", 400), ("/ladder?order=up", 400), ("/ladder?kind=x", 400),
       ("/ladder?run=nope", 404), ("/ladder?variant=%7B%22x%22%3A1%7D", 404), ("/ladder?q=" + "x" * 300, 400),
       ("/matrix?top=-1", 400), ("/matrix?top=abc", 400), ("/matrix?top=1e9", 400), ("/matrix?payoff=x", 400),
       ("/matrix?min_games=0", 400), ("/matches?page=-1", 400), ("/matches?page=0", 400), ("/matches?kind=x", 400),
       ("/matches?env=nope", 404), ("/queue?state=x", 400), ("/queue?last=-5", 400), ("/queue?batch=nope", 404),
       ("/player/999", 404), ("/player/abc", 404), ("/player/1?vs=999", 404), ("/player/1?vs=x", 400),
       ("/player/1?games=0", 400), ("/player/99999999999999999999999", 404), ("/curves", 404),
       ("/curves?run=nope", 404), ("/replay/abc", 404), ("/nowhere", 404), ("/ladder?q=%00", 400)]


def test_bad_query_parameters_get_a_4xx_page_never_a_traceback(client: TestClient) -> None:
    for url, status in BAD:
        r = client.get(url)
        assert r.status_code == status, (url, r.status_code, r.text[:300])
        assert "Traceback" not in r.text and 'class="error"' in r.text, url


def test_the_server_cannot_write_and_leaves_the_league_file_as_it_was(league_home: Path, client: TestClient) -> None:
    db = league_home / "league.db"
    before = (db.read_bytes(), os.stat(db).st_mtime_ns)
    for url in PAGES + [u for u, _ in BAD]:
        client.get(url)
    reader = Reader(league_home, None)
    try:
        with pytest.raises(Exception, match="readonly|read-only|attempt to write"), \
                reader.league.engine.begin() as conn:
            conn.exec_driver_sql("UPDATE players SET elo = 0")
        assert reader.league.read_only_connection
    finally:
        reader.close()
    assert (db.read_bytes(), os.stat(db).st_mtime_ns) == before
    # (mode=ro cannot remove the WAL's index and empty log that SQLite makes for readers; nothing is in them)
    assert {p.name for p in league_home.iterdir()} <= {"league.db", "videos", "league.db-wal", "league.db-shm"}
    wal = league_home / "league.db-wal"
    assert not wal.exists() or wal.stat().st_size == 0


def test_the_command_refuses_what_it_cannot_serve(tmp_path: Path, capsys, league_home: Path) -> None:
    code, out, err = run(capsys, "serve", "--home", str(tmp_path / "none"))
    assert code == 2 and err.count("\n") == 1 and "no league at" in err and not (tmp_path / "none").exists()
    code, out, err = run(capsys, "serve", "--db", f"sqlite:///{tmp_path / 'missing.db'}")
    assert code == 2 and err.count("\n") == 1 and not (tmp_path / "missing.db").exists()
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        code, out, err = run(capsys, "serve", "--home", str(league_home), "--port", str(port))
    assert code == 2 and err == f"marl: error: port {port} on 127.0.0.1 is in use: pick another with --port (or " \
                                "--port 0 for a free one)\n"


def test_marl_help_imports_no_web_library() -> None:
    import subprocess
    import sys

    code = "import sys; from selfplay_cli.cli import main; main(['--help']); " \
           "print(sorted(m for m in ('starlette', 'uvicorn', 'jinja2', 'torch') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stderr


def test_a_match_with_an_sprt_shows_its_llr_and_decision_from_its_stored_games(league_home: Path) -> None:
    """A match stored as `marl match --sprt` stores it (its players by name, its SPRT's settings): the matches page,
    unfiltered, shows its games and the LLR of those games, paired by seed, as the SPRT computes it; A won every game
    of 12 seat-swapped pairs against H0 = 0 / H1 = 100 Elo, so the test has accepted H1."""
    from selfplay_cli.results import GameResult
    from selfplay_cli.stats.sprt import SPRT, round_counts

    settings = {"elo0": 0.0, "elo1": 100.0, "alpha": 0.05, "beta": 0.05}
    with League.open(league_home) as lg:
        ids = {p.name: p.id for p in lg.roster.players("pong")}
        games = [GameResult(env="pong", players=(ids["a"], ids["b"]) if k % 2 == 0 else (ids["b"], ids["a"]),
                            seed=k // 2, scores=(21.0, 0.0) if k % 2 == 0 else (0.0, 21.0),
                            outcome=(1.0, 0.0) if k % 2 == 0 else (0.0, 1.0), length=100, truncated=False)
                 for k in range(24)]
        mid = lg.ledger.create_match("pong", "match", {"a": "a", "b": "b", "games": 100, "sprt": settings})
        lg.ledger.record_games(mid, games)
    counts, model = round_counts([[1.0, 1.0]] * 12, True)
    test = SPRT(**settings)
    llr = test.llr(counts, model=model)
    assert test.decide(llr) == "H1"
    reader = Reader(league_home, None)
    try:
        with TestClient(create_app(reader, str(league_home))) as client:
            page = client.get("/matches").text
    finally:
        reader.close()
    row = page[page.index(f'<td class="num">{mid}</td>'):]
    row = row[:row.index("</tr>")]
    assert '<td class="num">24</td>' in row and f"LLR {llr:.2f}" in row and "<b>H1</b>" in row


def test_a_league_on_postgresql_is_served_read_only(pg_url: str, tmp_path: Path, capsys) -> None:
    """The same pages over a league on PostgreSQL: the ladder is the CLI's (its records, through the URL), and the
    server's connection refuses a write (``default_transaction_read_only``), so no page can change the league."""
    home = tmp_path / "h"
    with League(pg_url, home=home) as lg:
        lg.roster.ensure_bots("pong", ["a", "b", "c"])
        ids = {p.name: p.id for p in lg.roster.players("pong")}
        record_plan(lg, ids, [("a", "b", 12, 4), ("b", "c", 10, 6), ("a", "c", 14, 2)])
    reader = Reader(home, pg_url)
    try:
        with TestClient(create_app(reader, str(home))) as client:
            assert client.app.state.fits.wait(120), "the background fit did not finish in time"
            for url in ("/", "/ladder", "/matrix", "/matches", "/queue", "/player/1", "/player/1?vs=2"):
                assert client.get(url).status_code == 200, url
            page = client.get("/ladder").text
        cli = run_json(capsys, "league", "ladder", "--db", pg_url, "--home", str(home), "--env", "pong")
        assert reader.ladder("pong", "").records == cli
        for row in cli:
            assert f"{row['elo']:.1f}" in page and f"{row['wins']}-{row['draws']}-{row['losses']}" in page
        with pytest.raises(Exception, match="read-only transaction"), reader.league.engine.begin() as conn:
            conn.exec_driver_sql("UPDATE players SET name = 'x'")
    finally:
        reader.close()
    with League(pg_url, home=home) as lg:
        assert sorted(p.name for p in lg.roster.players("pong")) == ["a", "b", "c"]


def test_a_runs_exploitability_curve_shows_what_was_filed_and_a_hostile_value_is_left_out(tmp_path: Path) -> None:
    """A run whose snapshots have exploitabilities filed (as marl exploit files them) gets their curve on its page,
    each point's figure as filed; a value another member wrote straight into a row (not a number) is one point left
    out, never a failed page."""
    home = tmp_path / "h"
    with League.open(home) as lg:
        lg.roster.ensure_bots("pong", ["random"])
        rows = lg.roster.add_snapshots([dict(env="pong", run="r", name=f"s{k}", path=f"snapshots/r/s{k}.safetensors",
                                             sha256=f"{k + 1:064x}", step=1000 * k, algo="ppo") for k in range(3)],
                                       run_config={})
        ids = {p.name: p.id for p in lg.roster.players("pong")}
        record_plan(lg, ids, [("s0", "random", 5, 3), ("s1", "random", 6, 2), ("s2", "random", 7, 1),
                              ("s1", "s0", 5, 3), ("s2", "s1", 5, 3)])
        lg.roster.set_exploitability(rows[0].id, {"kind": "exact", "value": 0.4583})
        lg.roster.set_exploitability(rows[1].id, {"kind": "exact", "value": 0.1234})
        lg.roster.set_exploitability(rows[2].id, {"kind": "exact", "value": 0.0567})
    con = sqlite3.connect(home / "league.db")
    meta = json.dumps({"exploitability": {"exact": {"kind": "exact", "value": "lots"}}})
    con.execute("UPDATE players SET meta = ? WHERE id = ?", (meta, rows[2].id))
    con.commit()
    con.close()
    reader = Reader(home, None)
    try:
        with TestClient(create_app(reader, str(home))) as client:
            assert client.app.state.fits.wait(120), "the background fit did not finish in time"
            r = client.get("/curves?run=r")
    finally:
        reader.close()
    assert r.status_code == 200 and "exploit-chart" in r.text
    assert "r/s0: 0.4583" in r.text and "r/s1: 0.1234" in r.text and "lots" not in r.text


def test_a_filed_exploitability_that_is_not_a_number_is_no_figure() -> None:
    """What the ladder (CLI and pages) shows of a row's exploitability: as filed where it is a finite number, nothing
    where another member wrote something else, and a lower bound's interval only where both ends are numbers."""
    from selfplay_cli.ratings.ladder import shown_exploitability

    good = {"kind": "lower_bound", "value": 0.2, "low": 0.1, "high": 0.3}
    assert shown_exploitability({"exploitability": {"lower_bound": good}}) == good
    assert shown_exploitability({"exploitability": {"exact": {"value": 0.05}, "lower_bound": good}}) == \
        {"value": 0.05, "kind": "exact"}
    for bad in ("lots", None, float("nan"), float("inf"), True, [1]):
        assert shown_exploitability({"exploitability": {"exact": {"value": bad}}}) is None
    assert shown_exploitability({"exploitability": {"exact": {"value": "x"}, "lower_bound": good}}) == good
    assert shown_exploitability({"exploitability": "x"}) is None and shown_exploitability({}) is None
    assert shown_exploitability({"exploitability": {"lower_bound": {**good, "low": "<b>"}}}) == \
        {"kind": "lower_bound", "value": 0.2, "high": 0.3}
