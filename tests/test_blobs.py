"""Snapshots reachable from anywhere: the league keeps each snapshot file's bytes by their sha256, and a League opened
from the database URL alone (another home, or none) plays any snapshot from them, checked by hash, cached locally,
never trusted by name. Every test runs on SQLite and on PostgreSQL (``db_url``)."""

from __future__ import annotations

import hashlib
import http.server
import json
import shutil
import threading
from functools import partial
from pathlib import Path

import pytest
from cli_helpers import run
from sqlalchemy import event, func, select, text

from selfplay_cli.evaluation.match import run_match
from selfplay_cli.league.models import Blob
from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.players.files import blob_cache_file, check_legacy_file, snapshot_relpath
from selfplay_cli.players.load import load_player
from selfplay_cli.policies.network import Arch, SnapshotError, build_network
from selfplay_cli.policies.snapshot_format import MAX_FILE_BYTES, SnapshotMeta, file_sha256, save_snapshot

SHORT = {"points_to_win": 1}


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch) -> Path:
    """This machine's cache of fetched snapshot files, empty for each test."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("MARL_CACHE", str(folder))
    return folder


def save(home: Path, name: str, seed: int, run: str = "r") -> str:
    """A small pong snapshot file of run ``run`` in ``home``; its path relative to the home."""
    rel = snapshot_relpath(run, name)
    arch = Arch(hidden=(16,))
    save_snapshot(home / rel, build_network((8, 6), 3, arch, seed=seed),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, algo="ppo", run=run, name=name,
                               step=1000 * seed))
    return rel


def trained(db_url: str, home: Path, names=("s1", "s2")) -> League:
    """League A: run ``r`` with one snapshot per name, registered as training registers them (files in ``home``)."""
    league = League.open(home, url=db_url)
    league.roster.create_run("r", "pong", {})
    league.roster.add_snapshots([dict(env="pong", run="r", name=n, path=save(home, n, seed=i + 1), step=1000 * (i + 1),
                                      algo="ppo") for i, n in enumerate(names)])
    league.roster.ensure_bots("pong", ["cpu"])
    return league


def results(league: League, name: str) -> list[tuple]:
    """Four short games of snapshot ``r/name`` against the cpu bot, as (seed, scores, outcome, length)."""
    row, cpu = league.roster.find_players(f"r/{name}")[0], league.roster.find_players("cpu")[0]
    rep = run_match(load_player(league, row, seed=7), load_player(league, cpu), games=4, first_seed=3,
                    env_options=SHORT)
    return [(r.seed, tuple(r.scores), tuple(r.outcome), r.length) for r in rep.results]


def blob_count(league: League) -> int:
    with league.session(readonly=True) as s:
        return s.execute(select(func.count()).select_from(Blob)).scalar_one()


def execute(league: League, sql: str, **params) -> None:
    with league.session() as s:
        s.execute(text(sql), params)


def one_line(exc: BaseException) -> str:
    message = str(exc)
    assert "\n" not in message
    return message


# ---------------------------------------------------------------------------------------------------------------


def test_a_snapshot_is_played_from_the_database_alone_with_the_files_results(db_url, tmp_path, cache):
    home = tmp_path / "home"
    a = trained(db_url, home)
    row = a.roster.find_players("r/s1")[0]
    data = (home / row.path).read_bytes()
    assert row.sha256 == hashlib.sha256(data).hexdigest()
    assert a.blobs.blob_bytes(row.sha256, limit=MAX_FILE_BYTES) == data  # stored with the row, keyed by the file's hash
    from_file = results(a, "s1")
    assert not cache.exists()  # the home's file was played: nothing fetched
    elsewhere = League.open(tmp_path / "other-machine", url=db_url)  # another, empty home
    assert not (tmp_path / "other-machine" / row.path).exists()
    assert results(elsewhere, "s1") == from_file
    cached = blob_cache_file(row.sha256)
    assert cached == cache / "blobs" / row.sha256[:2] / f"{row.sha256}.safetensors"
    assert cached.read_bytes() == data
    homeless = League(db_url)
    homeless.home = None  # (a SQLite URL's league defaults to the file's folder; none at all here)
    assert results(homeless, "s1") == from_file
    for league in (a, elsewhere, homeless):
        league.close()


def test_the_cli_plays_a_snapshot_with_only_the_database_url(db_url, tmp_path, capsys):
    home = tmp_path / "home"
    trained(db_url, home).close()
    empty = tmp_path / "empty"
    code, out, err = run(capsys, "match", "r/s1", "cpu", "--games", "2", "--env-option", "points_to_win=1",
                         "--db", db_url, "--home", str(empty), "--json")
    assert code == 0, err
    assert json.loads(out)["games"] == 2
    assert not (empty / "snapshots").exists()
    with League.open(home, url=db_url) as league:
        assert league.ledger.count_games("pong") == 2


def test_a_blob_altered_in_the_database_is_refused_in_one_line(db_url, tmp_path, capsys):
    home = tmp_path / "home"
    a = trained(db_url, home)
    s1, s2 = a.roster.find_players("r/s1")[0], a.roster.find_players("r/s2")[0]
    execute(a, "update blobs set data = :data where sha256 = :sha", data=(home / s2.path).read_bytes(), sha=s1.sha256)
    elsewhere = League.open(tmp_path / "elsewhere", url=db_url)
    with pytest.raises(LeagueError) as e:
        load_player(elsewhere, s1)
    assert s1.sha256 in one_line(e.value) and "altered" in str(e.value) and "r/s1" in str(e.value)
    assert not blob_cache_file(s1.sha256).exists()  # nothing cached
    assert load_player(a, s1).id == "r/s1"  # the home's file is still played where it is
    elsewhere.close()
    a.close()
    code, _, err = run(capsys, "match", "r/s1", "cpu", "--games", "2", "--db", db_url, "--home",
                       str(tmp_path / "elsewhere"))
    assert code != 0 and err.count("\n") == 1 and s1.sha256 in err and "Traceback" not in err


def test_a_tampered_cache_file_is_fetched_again(db_url, tmp_path):
    home = tmp_path / "home"
    a = trained(db_url, home)
    from_file = results(a, "s1")
    s1, s2 = a.roster.find_players("r/s1")[0], a.roster.find_players("r/s2")[0]
    elsewhere = League.open(tmp_path / "elsewhere", url=db_url)
    load_player(elsewhere, s1)
    cached = blob_cache_file(s1.sha256)
    shutil.copyfile(home / s2.path, cached)  # a valid snapshot, but another one, under s1's name
    assert results(elsewhere, "s1") == from_file
    assert file_sha256(cached) == s1.sha256
    cached.write_bytes(b"garbage")
    assert load_player(elsewhere, s1).id == "r/s1" and file_sha256(cached) == s1.sha256
    elsewhere.close()
    a.close()


def test_a_snapshot_whose_blob_is_not_in_the_league_is_refused_in_one_line(db_url, tmp_path):
    home = tmp_path / "home"
    a = trained(db_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    execute(a, "delete from blobs")
    with League.open(tmp_path / "elsewhere", url=db_url) as elsewhere, pytest.raises(LeagueError) as e:
        load_player(elsewhere, s1)
    assert "r/s1" in one_line(e.value) and "marl checkpoint push" in str(e.value) and s1.sha256 in str(e.value)
    a.close()


def test_registration_stores_the_blob_in_the_same_transaction_as_the_row(db_url, tmp_path):
    home = tmp_path / "home"
    a = trained(db_url, home, names=("s1",))
    assert blob_count(a) == 1
    rel = save(home, "s9", seed=9)
    with pytest.raises(LeagueError, match="already exists"):  # the second row fails: nothing of the unit is kept
        a.roster.add_snapshots([dict(env="pong", run="r", name="s9", path=rel), dict(env="pong", run="r", name="s1",
                                                                               path=rel)])
    assert blob_count(a) == 1 and not a.blobs.has_blobs([file_sha256(home / rel)])
    row = a.roster.add_snapshot(env="pong", run="r", name="s9", path=rel)
    assert a.blobs.has_blobs([row.sha256, "0" * 64]) == {row.sha256}
    a.close()


def test_put_blob_is_idempotent_and_two_writers_racing_both_succeed(db_url, tmp_path):
    from selfplay_cli.league.blobs import store_blob

    a, b = League(db_url), League(db_url)
    data = b"the same bytes"
    sha = hashlib.sha256(data).hexdigest()
    done: list[str] = []
    reached = threading.Event()
    event.listen(b.engine, "before_cursor_execute", lambda *_: reached.set())  # B at the database
    with a.session() as s:  # A stores the blob and has not committed yet when B stores it too
        assert store_blob(s, sha, data)
        writer = threading.Thread(target=lambda: done.append(b.blobs.put_blob(data)))
        writer.start()
        assert reached.wait(30)
        assert not done  # B cannot be through while A's transaction holds the row (or SQLite's write lock)
    writer.join(30)
    assert done == [sha] and blob_count(a) == 1
    assert a.blobs.put_blob(data) == sha and blob_count(a) == 1
    path = tmp_path / "f"
    path.write_bytes(b"other bytes")
    assert a.blobs.put_blob(path) == file_sha256(path) and blob_count(a) == 2
    assert a.blobs.blob_bytes(file_sha256(path), limit=MAX_FILE_BYTES) == b"other bytes"
    a.close()
    b.close()


def test_blobs_kept_at_a_file_url_or_an_http_url_are_read_and_checked(db_url, tmp_path, monkeypatch):
    home = tmp_path / "home"
    a = trained(db_url, home)
    s1, s2 = a.roster.find_players("r/s1")[0], a.roster.find_players("r/s2")[0]
    shared = tmp_path / "shared disk"
    shared.mkdir()
    for row in (s1, s2):
        shutil.copyfile(home / row.path, shared / row.sha256)
    execute(a, "update blobs set data = NULL, url = :url where sha256 = :sha",
            url=(shared / s1.sha256).as_uri(), sha=s1.sha256)
    handler = partial(http.server.SimpleHTTPRequestHandler, directory=str(shared))
    handler.log_message = lambda *args: None  # type: ignore[attr-defined]
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    monkeypatch.setenv("MARL_BLOB_LOCATIONS", f"{shared.as_uri()} http://127.0.0.1:{server.server_address[1]}/")
    try:
        execute(a, "update blobs set data = NULL, url = :url where sha256 = :sha",
                url=f"http://127.0.0.1:{server.server_address[1]}/{s2.sha256}", sha=s2.sha256)
        elsewhere = League.open(tmp_path / "elsewhere", url=db_url)
        assert load_player(elsewhere, s1).id == "r/s1" and load_player(elsewhere, s2).id == "r/s2"
        assert blob_cache_file(s2.sha256).read_bytes() == (home / s2.path).read_bytes()
        shutil.copyfile(home / s1.path, shared / s2.sha256)  # the server now serves s1's bytes under s2's hash
        with pytest.raises(LeagueError) as e:
            elsewhere.blobs.blob_bytes(s2.sha256, limit=MAX_FILE_BYTES)
        assert s2.sha256 in one_line(e.value) and "altered" in str(e.value)
        (shared / s1.sha256).unlink()
        blob_cache_file(s1.sha256).unlink()
        with pytest.raises(LeagueError) as e:
            load_player(elsewhere, s1)
        assert s1.sha256 in one_line(e.value) and "cannot read" in str(e.value)
        elsewhere.close()
    finally:
        server.shutdown()
    a.close()


def legacy(db_url: str, home: Path) -> tuple[League, dict]:
    """A league made before blobs existed, with the rows of an older marl: no blobs; ``s2`` holds the weights'
    checksum as its sha256 (and in its meta), as trained rows did before sha256 meant the file."""
    from selfplay_cli.policies.snapshot_reader import read_meta

    a = trained(db_url, home, names=("s1", "s2", "s3"))
    execute(a, "delete from blobs")
    s2 = a.roster.find_players("r/s2")[0]
    checksum = read_meta(home / s2.path).weights_sha256
    with a.session() as s:
        from selfplay_cli.league.models import Player

        p = s.get(Player, s2.id)
        p.sha256, p.meta = checksum, {"weights_sha256": checksum}
    return a, {p.name: p for p in a.roster.players(kind="snapshot")}


def test_ensure_blobs_backfills_a_league_made_before_blobs(db_url, tmp_path):
    home = tmp_path / "home"
    a, rows = legacy(db_url, home)
    (home / rows["s3"].path).unlink()  # s3's file is not on this machine
    elsewhere = League.open(tmp_path / "elsewhere", url=db_url)
    with pytest.raises(LeagueError, match="not in the league"):
        load_player(elsewhere, rows["s1"])
    report = a.blobs.ensure_blobs(a.roster.players(kind="snapshot") + a.roster.players(kind="bot"),
                                  check_legacy=check_legacy_file)
    assert report.stored == ["r/s1", "r/s2"] and report.missing == ["r/s3"] and report.present == []
    assert report.stored_bytes == sum((home / rows[n].path).stat().st_size for n in ("s1", "s2"))
    s2 = a.roster.find_players("r/s2")[0]
    assert s2.sha256 == file_sha256(home / s2.path) != rows["s2"].sha256  # the row now names its file
    assert s2.meta["weights_sha256"] == rows["s2"].sha256
    for name in ("s1", "s2"):
        row = elsewhere.roster.find_players(f"r/{name}")[0]
        assert load_player(elsewhere, row).id == f"r/{name}"
        assert blob_cache_file(row.sha256).read_bytes() == (home / row.path).read_bytes()
    again = a.blobs.ensure_blobs(a.roster.players(kind="snapshot"), check_legacy=check_legacy_file)
    assert again.stored == [] and again.present == ["r/s1", "r/s2"] and again.missing == ["r/s3"]
    elsewhere.close()
    a.close()


def test_ensure_blobs_refuses_a_file_that_is_not_the_rows(db_url, tmp_path):
    home = tmp_path / "home"
    a, rows = legacy(db_url, home)
    shutil.copyfile(home / rows["s1"].path, home / rows["s2"].path)  # the legacy row's file replaced
    shutil.copyfile(home / rows["s1"].path, home / rows["s3"].path)  # and a modern row's
    report = a.blobs.ensure_blobs(a.roster.players(kind="snapshot"), check_legacy=check_legacy_file)
    assert report.stored == ["r/s1"] and report.refused == ["r/s2", "r/s3"]
    assert "not the snapshot r/s2" in report.reasons["r/s2"] and "is not the" in report.reasons["r/s3"]
    assert a.roster.find_players("r/s2")[0].sha256 == rows["s2"].sha256  # unchanged
    assert a.blobs.has_blobs([rows["s1"].sha256]) and blob_count(a) == 1
    assert a.blobs.ensure_blobs([rows["s2"]]).refused == ["r/s2"]  # a legacy row is stored only through its check
    a.close()


def test_checkpoint_push_backfills_and_reports(db_url, tmp_path, capsys):
    home = tmp_path / "home"
    a, rows = legacy(db_url, home)
    a.close()
    where = ("--db", db_url, "--home", str(home))
    code, _, err = run(capsys, "checkpoint", "push", *where)
    assert code == 2 and err.count("\n") == 1 and "--all" in err
    code, out, err = run(capsys, "checkpoint", "push", "r/s1", *where)
    assert (code, out) == (0, f"stored 1 snapshot file in the league ({(home / rows['s1'].path).stat().st_size:,} "
                              "bytes); 0 there already\n"), err
    (home / rows["s3"].path).unlink()
    code, out, _ = run(capsys, "checkpoint", "push", "--all", *where, "--json")
    report = json.loads(out)
    assert code == 1 and report["stored"] == 1 and report["already_there"] == 1 and report["missing"] == ["r/s3"]
    assert report["stored_bytes"] == (home / rows["s2"].path).stat().st_size
    code, out, _ = run(capsys, "checkpoint", "push", "--all", *where)
    assert code == 1 and "stored 0 snapshot files in the league (0 bytes); 2 there already" in out
    assert "not on this machine, not in the league: r/s3" in out
    with League.open(tmp_path / "elsewhere", url=db_url) as elsewhere:
        assert load_player(elsewhere, elsewhere.roster.find_players("r/s2")[0]).id == "r/s2"
        elsewhere.roster.remove_snapshot(rows["s3"].id)  # a removed snapshot is played nowhere: --all leaves it out
    code, out, _ = run(capsys, "checkpoint", "push", "--all", *where)
    assert (code, out) == (0, "stored 0 snapshot files in the league (0 bytes); 2 there already\n")


def test_a_swapped_file_in_the_home_is_refused_not_replaced_by_the_blob(db_url, tmp_path):
    home = tmp_path / "home"
    a = trained(db_url, home)
    s1, s2 = a.roster.find_players("r/s1")[0], a.roster.find_players("r/s2")[0]
    shutil.copyfile(home / s2.path, home / s1.path)
    with pytest.raises(SnapshotError, match="not the snapshot r/s1"):
        load_player(a, s1)
    a.close()


def test_a_league_can_keep_its_blobs_in_a_shared_folder(db_url, tmp_path, capsys, monkeypatch):
    home, shared = tmp_path / "home", tmp_path / "shared disk"
    shared.mkdir()
    monkeypatch.setenv("MARL_BLOB_LOCATIONS", shared.as_uri())
    a = trained(db_url, home, names=("s1",))  # stored in the database, the default
    assert a.blobs.blob_location() is None
    for bad, why in (("http://host/blobs", "file://"), ("file://relative", "file://"),
                     ((tmp_path / "absent").as_uri(), "not a folder")):
        with pytest.raises(LeagueError, match=why):
            a.blobs.set_blob_location(bad)
    assert a.blobs.set_blob_location(shared.as_uri()) == shared.as_uri() == a.blobs.blob_location()
    row = a.roster.add_snapshot(env="pong", run="r", name="s2", path=save(home, "s2", seed=2))
    assert (shared / row.sha256).read_bytes() == (home / row.path).read_bytes()
    with a.session(readonly=True) as s:
        stored = s.execute(select(Blob.url, Blob.data, Blob.size).where(Blob.sha256 == row.sha256)).one()
    assert stored == ((shared / row.sha256).as_uri(), None, (home / row.path).stat().st_size)
    elsewhere = League.open(tmp_path / "elsewhere", url=db_url)
    assert results(elsewhere, "s2") == results(a, "s2")
    assert load_player(elsewhere, elsewhere.roster.find_players("r/s1")[0]).id == "r/s1"  # (still in the database)
    elsewhere.close()
    execute(a, "delete from blobs")
    a.close()
    where = ("--db", db_url, "--home", str(home))
    code, out, err = run(capsys, "checkpoint", "push", "--to", "db", *where, "--json")
    assert (code, json.loads(out)) == (0, {"blob_url": None}), err
    code, out, err = run(capsys, "checkpoint", "push", "--all", "--to", str(shared), *where)
    assert code == 2 and err.count("\n") == 1 and "file://" in err
    code, out, err = run(capsys, "checkpoint", "push", "--all", "--to", shared.as_uri(), *where)
    assert code == 0 and out.splitlines()[0] == f"the league keeps its snapshot files in {shared.as_uri()} from now on"
    assert "stored 2 snapshot files" in out
    with League.open(home, url=db_url) as league:
        s1 = league.roster.find_players("r/s1")[0]
        stored = league.blobs.blob_bytes(s1.sha256, limit=MAX_FILE_BYTES)
        assert stored == (shared / s1.sha256).read_bytes() == (home / s1.path).read_bytes()


def test_show_and_export_work_with_only_the_database_url(db_url, tmp_path, capsys):
    home = tmp_path / "home"
    trained(db_url, home, names=("s1",)).close()
    where = ("--db", db_url, "--home", str(tmp_path / "elsewhere"))
    code, out, err = run(capsys, "checkpoint", "show", "r/s1", *where, "--json")
    assert code == 0 and json.loads(out)["file"]["name"] == "s1", err
    code, _, err = run(capsys, "checkpoint", "export", "r/s1", str(tmp_path / "out.safetensors"), *where)
    assert code == 0, err
    from selfplay_cli.policies.snapshot_reader import read_snapshot

    assert read_snapshot(tmp_path / "out.safetensors").meta.name == "s1"
