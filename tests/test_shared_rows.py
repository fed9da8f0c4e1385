"""Rows another member of a shared league wrote (issue 49, sections 3 and 5): a queued job that no worker can play
fails as a job, never as the worker (a bot this marl does not know, a spec missing a key, counts past every bound, a
spec nested 5,000 deep), and a JSON value nested 5,000 deep or 10 MB large in any row makes that row unusable with one
line, never the command. On SQLite and on a real PostgreSQL."""

from __future__ import annotations

import json

import pytest
from cli_helpers import run, run_json
from sqlalchemy import text

from selfplay_cli.evaluation import jobs as jobs_module
from selfplay_cli.evaluation.games_jobs import GAMES, MAX_JOB_ROUNDS, games_jobs
from selfplay_cli.evaluation.jobs import MAX_ERROR, play_leased
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.league import bounded_json
from selfplay_cli.league.bounded_json import JSONBoundsError, Unreadable, UnreadableList, loads, read_column
from selfplay_cli.league.job_rows import TRIES_LIMIT, NewJob
from selfplay_cli.league.store import League, LeagueError

SHORT = {"points_to_win": 1}
DEEP = "[" * 5000 + "]" * 5000
HUGE = json.dumps({"x": "a" * 10_000_000})


def _league(url: str, home) -> League:
    lg = League(url, home=home)
    lg.roster.ensure_bots("pong", ["random", "cpu", "superbot"])  # superbot: a newer marl's bot, unknown to this one
    return lg


def _ids(lg: League) -> dict[str, int]:
    return {name: lg.roster.find_players(name, env="pong")[0].id for name in ("cpu", "random", "superbot")}


def _spec(ids: dict[str, int], **over) -> dict:
    spec = {"a": [ids["cpu"]], "b": ids["random"], "rounds": 1, "first_seed": 0, "match_kind": "match",
            "env_options": SHORT}
    spec.update(over)
    return spec


def _raw_json(lg: League, table: str, column: str, value: str, where: str = "", **params) -> None:
    """Write ``value`` as the stored JSON text of ``table.column`` behind marl's back, as another member's client may:
    an UPDATE when ``where`` is given, else an INSERT of a queued games job in batch ``bad``."""
    cast = "CAST(:v AS JSON)" if lg.is_postgres else ":v"
    with lg.engine.begin() as conn:
        if where:
            conn.execute(text(f"UPDATE {table} SET {column} = {cast} WHERE {where}"), {"v": value, **params})
        else:
            conn.execute(text(f"INSERT INTO jobs (batch, kind, env, spec, priority, state, tries, created_at) "
                              f"VALUES ('bad', 'games', 'pong', {cast}, 0, 'queued', 0, CURRENT_TIMESTAMP)"),
                         {"v": value})


# -- the bounded parser ------------------------------------------------------------------------------------------------
def test_the_parser_refuses_depth_and_size_before_parsing_and_reads_what_is_within():
    assert loads('{"a": [1, {"b": "[[[[[[[[[["}], "c": "\\"[{"}', max_bytes=100, max_depth=3) == {
        "a": [1, {"b": "[[[[[[[[[["}], "c": '"[{'}  # brackets inside strings, escaped quotes: not nesting
    with pytest.raises(JSONBoundsError, match="nested deeper than 32"):
        loads(DEEP, max_bytes=1 << 20)
    with pytest.raises(JSONBoundsError, match="nested deeper than 3 levels"):
        loads(b"[[[[1]]]]", max_bytes=100, max_depth=3)
    with pytest.raises(JSONBoundsError, match="10,000,009 bytes, over the 262,144"):
        loads(HUGE, max_bytes=262_144)
    with pytest.raises(JSONBoundsError, match="over the 10"):
        loads("\"\u00e9\u00e9\u00e9\u00e9\u00e9\u00e9\"", max_bytes=10)  # 8 characters, 14 bytes
    with pytest.raises(JSONBoundsError, match="not JSON"):
        loads('{"a": ', max_bytes=100)
    with pytest.raises(JSONBoundsError, match="not JSON"):
        loads('"' + '\\"' * 100_000, max_bytes=1 << 20)  # an unterminated string of escapes: one pass, then refused
    assert read_column(None, max_bytes=10, kind=dict) is None
    assert read_column("null", max_bytes=10, kind=dict) is None  # (SQLAlchemy stores None as JSON null)
    assert read_column({"k": 1}, max_bytes=10, kind=dict) == {"k": 1}  # parsed by a driver: its kind checked
    bad = read_column(DEEP, max_bytes=1 << 20, kind=dict)
    assert isinstance(bad, Unreadable) and bad == {} and "nested deeper" in bad.reason
    assert isinstance(read_column("[1]", max_bytes=10, kind=dict), Unreadable)  # not the column's kind
    assert isinstance(read_column("{}", max_bytes=10, kind=list), UnreadableList)
    assert isinstance(read_column(b"\xff\xfe", max_bytes=10, kind=dict), Unreadable)


# -- 3. poison jobs ----------------------------------------------------------------------------------------------------
def test_poison_jobs_die_with_their_reasons_and_the_worker_plays_the_good_one(db_url, tmp_path, capsys, monkeypatch):
    """A bot this marl does not know (a valid spec: its tries are counted, then it is dead), a spec missing a key,
    rounds=1e8 with max_tries=1e6, a spec 5,000 deep (each dead at once, "bad job spec"), then a good job: `marl
    worker --until-empty` exits 0, every bad job is dead with a short error saying what failed, the good one is
    played; `marl queue` and `marl queue --json` show them, before and after."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.delenv("MARL_DB", raising=False)
    home = tmp_path / "h"
    lg = _league(db_url, home)
    ids = _ids(lg)
    (unknown,) = lg.queue.enqueue("bad", [NewJob(GAMES, "pong", _spec(ids, b=ids["superbot"]), max_tries=1)])
    spec = _spec(ids)
    del spec["rounds"]
    _raw_json(lg, "jobs", "spec", json.dumps(spec))
    _raw_json(lg, "jobs", "spec", json.dumps(_spec(ids, rounds=10**8, max_tries=10**6)))
    _raw_json(lg, "jobs", "spec", DEEP)
    (good,) = lg.queue.enqueue("good", [NewJob(GAMES, "pong", _spec(ids, first_seed=7))])
    missing, unbounded, deep = unknown + 1, unknown + 2, unknown + 3
    assert good == deep + 1

    before = {j["id"]: j for j in run_json(capsys, "queue", "--db", db_url, "--home", str(home))["jobs"]}
    assert {j["state"] for j in before.values()} == {"queued"}
    assert before[deep]["error"] == "bad job spec: unreadable JSON (nested deeper than 32 levels)"

    code, out, err = run(capsys, "worker", "--db", db_url, "--home", str(home), "--until-empty", "--json")
    assert code == 0, err
    report = json.loads(out)
    assert (report["done"], report["failed"], report["games"]) == (1, 4, 2)

    after = {j["id"]: j for j in run_json(capsys, "queue", "--db", db_url, "--home", str(home))["jobs"]}
    assert after[good]["state"] == "done" and after[good]["error"] is None
    for jid in (unknown, missing, unbounded, deep):
        assert after[jid]["state"] == "dead" and after[jid]["tries"] == 1, after[jid]
        assert 0 < len(after[jid]["error"]) <= MAX_ERROR and "\n" not in after[jid]["error"]
    assert "superbot" in after[unknown]["error"] and not after[unknown]["error"].startswith("bad job spec")
    assert after[missing]["error"] == "bad job spec: rounds is missing"
    assert after[unbounded]["error"].startswith("bad job spec: rounds must be from 1 to")
    assert after[deep]["error"] == "bad job spec: unreadable JSON (nested deeper than 32 levels)"

    code, out, err = run(capsys, "queue", "--db", db_url, "--home", str(home))
    assert code == 0 and err == "", err
    assert "bad job spec: rounds is missing" in out and "superbot" in out
    lg.close()


def test_a_job_that_fails_everywhere_counts_its_tries_then_dies(tmp_path):
    """A bot this marl does not know: the job fails on each lease (a try each, waiting its backoff in between) and is
    dead after its max_tries, its error kept; the worker leaves when the queue is empty, having played the good
    job."""
    lg = _league(f"sqlite:///{tmp_path / 'league.db'}", tmp_path / "h")
    ids = _ids(lg)
    (jid,) = lg.queue.enqueue("bad", [NewJob(GAMES, "pong", _spec(ids, b=ids["superbot"]), max_tries=3)])
    (good,) = lg.queue.enqueue("good", [NewJob(GAMES, "pong", _spec(ids))])
    report = run_worker(lg, WorkerOptions(until_empty=True, poll=0.01, backoff=0.01))
    assert (report.done, report.failed) == (1, 3)
    (row,) = lg.queue.jobs(ids=[jid])
    assert (row.state, row.tries) == ("dead", 3) and "superbot" in row.error
    assert lg.queue.jobs(ids=[good])[0].state == "done"
    lg.close()


@pytest.mark.parametrize("error", [RecursionError, MemoryError, KeyError, AttributeError, ZeroDivisionError])
def test_any_error_of_a_job_ends_that_job_and_not_the_worker(tmp_path, monkeypatch, error):
    """Whatever a job raises (RecursionError and MemoryError too) is one failed try of that job, with a short line of
    what failed; the worker goes on with the next job."""
    lg = _league(f"sqlite:///{tmp_path / 'league.db'}", tmp_path / "h")
    ids = _ids(lg)

    def poison(league, job, **kwargs):
        if job.spec["first_seed"] == 0:
            raise error("x" * 5000)
        return played(league, job, **kwargs)

    played = jobs_module.KINDS[GAMES]
    monkeypatch.setitem(jobs_module.KINDS, GAMES, poison)
    (bad,) = lg.queue.enqueue("bad", [NewJob(GAMES, "pong", _spec(ids), max_tries=1)])
    (good,) = lg.queue.enqueue("good", [NewJob(GAMES, "pong", _spec(ids, first_seed=5))])
    report = run_worker(lg, WorkerOptions(until_empty=True, poll=0.01))
    assert (report.done, report.failed) == (1, 1)
    (row,) = lg.queue.jobs(ids=[bad])
    assert row.state == "dead" and row.error.startswith(error.__name__) and len(row.error) <= MAX_ERROR
    assert lg.queue.jobs(ids=[good])[0].state == "done"
    lg.close()


@pytest.mark.parametrize("stop", [KeyboardInterrupt, SystemExit])
def test_ctrl_c_in_a_job_still_stops_the_worker_and_gives_the_job_back_untried(tmp_path, monkeypatch, stop):
    lg = _league(f"sqlite:///{tmp_path / 'league.db'}", tmp_path / "h")
    ids = _ids(lg)

    def interrupted(*_args, **_kwargs):
        raise stop

    monkeypatch.setitem(jobs_module.KINDS, GAMES, interrupted)
    (jid,) = lg.queue.enqueue("k", [NewJob(GAMES, "pong", _spec(ids))])
    with pytest.raises(stop):
        run_worker(lg, WorkerOptions(until_empty=True, poll=0.01))
    (row,) = lg.queue.jobs(ids=[jid])
    assert (row.state, row.tries, row.error) == ("queued", 0, None)
    lg.close()


def test_specs_are_checked_when_marl_queues_them(tmp_path):
    """What a worker would refuse is refused when the job is made, in one line: rounds past the bound, max_tries past
    its limit, a spec nested too deep for its column."""
    lg = _league(f"sqlite:///{tmp_path / 'league.db'}", tmp_path / "h")
    ids = _ids(lg)
    cpu, rnd = lg.roster.get_player(ids["cpu"]), lg.roster.get_player(ids["random"])
    with pytest.raises(LeagueError, match=f"max_tries must be a whole number from 1 to {TRIES_LIMIT}"):
        lg.queue.enqueue("x", [NewJob(GAMES, "pong", _spec(ids), max_tries=10**6)])
    with pytest.raises(LeagueError, match="nested deeper than 32"):
        lg.queue.enqueue("x", [NewJob(GAMES, "pong", {**_spec(ids), "params": json.loads("[" * 40 + "]" * 40)})])
    with pytest.raises(LeagueError, match="over the 262,144"):
        lg.queue.enqueue("x", [NewJob(GAMES, "pong", {**_spec(ids), "params": {"x": "a" * 300_000}})])
    with pytest.raises(jobs_module.BadSpec, match="rounds must be from 1 to"):
        games_jobs(lg, [cpu], rnd, games=2 * (MAX_JOB_ROUNDS + 1), first_seed=0, match_kind="match",
                   env_options=SHORT, job_rounds=MAX_JOB_ROUNDS + 1)
    assert lg.queue.jobs() == []
    lg.close()


def test_a_spec_its_kind_refuses_is_dead_at_once_in_a_command_playing_its_own_batch(tmp_path):
    """play_leased (also what `marl match --queue` uses to play its own batch) marks such a job dead on its first
    lease, whatever its max_tries."""
    lg = _league(f"sqlite:///{tmp_path / 'league.db'}", tmp_path / "h")
    ids = _ids(lg)
    _raw_json(lg, "jobs", "spec", json.dumps(_spec(ids, a="cpu", max_tries=5)))
    w = lg.queue.add_worker("w", "h", 1)
    out = play_leased(lg, w, lg.queue.claim(w), base_backoff=0.01)
    assert out.state == "failed" and out.extra["state"] == "dead" and out.error.startswith("bad job spec: a must be")
    lg.close()


# -- 5. JSON values in players.meta, runs.config, matches.params -------------------------------------------------------
def _snapshots(db_url: str, tmp_path, n: int = 3) -> tuple[League, list[int]]:
    from selfplay_cli.cli import main
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    home = tmp_path / "h"
    arch = Arch(hidden=(8,))
    for i in range(n):
        meta = SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="w", name=f"s{i}", algo="ppo",
                            step=i, env_options=SHORT)
        save_snapshot(tmp_path / f"s{i}.safetensors", build_network((8, 6), 3, arch, seed=i), meta)
        assert main(["checkpoint", "import", str(tmp_path / f"s{i}.safetensors"), "--db", db_url, "--home",
                     str(home)]) == 0
    assert main(["league", "tournament", *(f"w/s{i}" for i in range(n)), "cpu", "--env", "pong", "--games-per-pair",
                 "2", "--db", db_url, "--home", str(home), "--quiet"]) == 0
    lg = League(db_url, home=home)
    return lg, [p.id for p in lg.roster.players("pong", kind="snapshot")]


@pytest.mark.slow
def test_rows_whose_json_cannot_be_read_are_one_line_each_never_the_command(db_url, tmp_path, capsys, monkeypatch):
    """players.meta 5,000 deep and 10 MB, a run's config 5,000 deep, a match's params 5,000 deep: the ladder, the
    checkpoint list, another snapshot's page and the matrix exit 0, each bad row said in one line on stderr; a bad
    row is never played (`marl match` refuses it in one line), a bad run never resumed."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.delenv("MARL_DB", raising=False)
    lg, (deep, huge, fine) = _snapshots(db_url, tmp_path)
    _raw_json(lg, "players", "meta", DEEP, where="id = :i", i=deep)
    _raw_json(lg, "players", "meta", HUGE, where="id = :i", i=huge)
    _raw_json(lg, "runs", "config", DEEP, where="name = 'w'")
    with lg.engine.connect() as conn:
        last_match = conn.execute(text("SELECT max(id) FROM matches")).scalar_one()
    _raw_json(lg, "matches", "params", DEEP, where="id = :i", i=last_match)
    where = ["--db", db_url, "--home", str(tmp_path / "h")]
    said = {}
    for args in (["league", "ladder", "--env", "pong"], ["checkpoint", "list"], ["checkpoint", "show", "w/s2"],
                 ["league", "matrix", "--env", "pong"], ["league", "ladder", "--env", "pong", "--json"],
                 ["league", "ladder", "--run", "w"]):
        code, out, err = run(capsys, *args, *where)
        assert code == 0, (args, err)
        lines = said[" ".join(args)] = err.splitlines()
        assert all(line.startswith("marl: warning: ") and "cannot be read" in line for line in lines), (args, err)
        assert len(lines) == len(set(lines)), (args, err)  # each row once
        for row in (f"player {deep} ", f"player {huge} ", f"match {last_match}:", "run "):
            assert sum(row in line for line in lines) <= 1, (args, err)
        if args[-1] == "--json":
            json.loads(out)
        if args[1] == "show":
            assert "w/s2" in out
    lines = said["checkpoint list"]
    assert sum(f"player {deep} " in line and "nested deeper than 32" in line for line in lines) == 1
    assert sum(f"player {huge} " in line and "10,000,0" in line for line in lines) == 1
    assert any(f"match {last_match}: its params cannot be read" in line for line in said["league ladder --env pong"])
    assert any(line.startswith("marl: warning: run ") and "its config cannot be read" in line
               for line in said["league ladder --run w"])
    code, out, err = run(capsys, "match", "w/s0", "cpu", "--games", "2", *where)
    assert code == 2 and err.splitlines()[-1].startswith("marl: error: w/s0: its row in the league cannot be read")
    assert bounded_json.unreadable(lg.roster.get_player(deep).meta) is None and lg.roster.get_player(deep).unusable
    code, out, err = run(capsys, "train", "--resume", "w", *where)
    assert code == 2 and err.splitlines()[-1] == ("marl: error: run 'w': its configuration in the league cannot be "
                                                  "read (nested deeper than 32 levels): start a new run"), err
    lg.close()


def test_a_jobs_error_line_shows_no_folder_of_the_workers_machine(tmp_path):
    """A job's error is read by every member: the worker's home, cache and user folder are shown by name, a
    KeyError's message without its quotes, and the line is cut at MAX_ERROR."""
    from selfplay_cli.evaluation.jobs import error_line

    home, cache = tmp_path / "home", tmp_path / "home-cache"
    private = {str(home): "$MARL_HOME", str(cache): "$MARL_CACHE", str(tmp_path): "~"}
    exc = LeagueError(f"r/s1 (no file at {home}/snapshots/r/s1.safetensors), cached at {cache}/blobs, in {tmp_path}")
    assert error_line(exc, private) == ("LeagueError: r/s1 (no file at $MARL_HOME/snapshots/r/s1.safetensors), "
                                        "cached at $MARL_CACHE/blobs, in ~")
    assert error_line(KeyError("pong has no scripted player 'superbot'")) == (
        "KeyError: pong has no scripted player 'superbot'")
    assert len(error_line(ValueError("x" * 1000))) == MAX_ERROR
    from selfplay_cli.envs import GameNotAdmittedError

    admitted = GameNotAdmittedError("evilmod:env")  # (a KeyError whose own str is its message)
    assert error_line(admitted) == f"GameNotAdmittedError: {admitted}" and "is not imported" in str(admitted)
