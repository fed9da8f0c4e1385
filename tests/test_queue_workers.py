"""Workers on the queue as users run them: `marl worker` processes killed mid-lease, many workers at once, an SPRT
decided across workers, `marl queue`; on SQLite and on a real PostgreSQL."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter

import pytest
from cli_helpers import run, run_json
from sqlalchemy import select

from selfplay_cli.evaluation.games_jobs import games_jobs
from selfplay_cli.evaluation.jobs import play_job
from selfplay_cli.evaluation.match import SPRTSettings, run_match
from selfplay_cli.evaluation.queued import queue_match
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.league.models import Game, GameSeat
from selfplay_cli.league.store import League

SHORT = {"points_to_win": 1}


def _league(url, home):
    lg = League(url, home=home)
    lg.roster.ensure_bots("pong", ["random", "cpu"])
    return lg


def _bots(league):
    return league.roster.find_players("cpu", env="pong")[0], league.roster.find_players("random", env="pong")[0]


def _stored(league) -> list[tuple[int, int]]:
    """Every stored game as (seed, cpu's seat): two games of one seed differ by the seat."""
    cpu, _ = _bots(league)
    with league.session(readonly=True) as s:
        q = select(Game.seed, GameSeat.seat).join(GameSeat, GameSeat.game_id == Game.id).where(
            GameSeat.player_id == cpu.id)
        return [(int(a), int(b)) for a, b in s.execute(q)]


def _worker(url: str, home, *args: str) -> subprocess.Popen:
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    return subprocess.Popen([sys.executable, "-m", "selfplay_cli", "worker", "--db", url, "--home", str(home),
                             "--quiet", *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait(pred, timeout: float = 60.0, every: float = 0.02) -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, "timed out"
        time.sleep(every)


@pytest.mark.slow
def test_a_worker_killed_mid_lease_its_job_played_again_once_and_counted_once(db_url, tmp_path):
    """kill -9 of a `marl worker` while it plays a job: nothing of the job is stored; the lease lapses, a second worker
    plays it again (its second try) and stores it once; every seed's pair of games is there exactly once."""
    league = _league(db_url, tmp_path / "h")
    cpu, rnd = _bots(league)
    (jid,) = league.queue.enqueue("k", games_jobs(league, [cpu], rnd, games=3000, first_seed=0, match_kind="match",
                                                  env_options=SHORT, job_rounds=1500))
    first = _worker(db_url, tmp_path / "h", "--beat", "0.2", "--scavenge", "1")
    _wait(lambda: league.queue.jobs(ids=[jid])[0].state == "leased")
    os.kill(first.pid, signal.SIGKILL)
    first.wait()
    assert league.queue.jobs(ids=[jid])[0].state == "leased" and _stored(league) == []
    second = _worker(db_url, tmp_path / "h", "--beat", "0.2", "--scavenge", "1", "--until-empty", "--json")
    out, err = second.communicate(timeout=180)
    assert second.returncode == 0, err
    report = json.loads(out)
    assert report["done"] == 1 and report["games"] == 3000
    (job,) = league.queue.jobs(ids=[jid])
    assert job.state == "done" and job.tries == 2 and job.worker.startswith("worker@")
    games = _stored(league)
    assert len(games) == 3000 and Counter(games) == Counter((s, k) for s in range(1500) for k in (0, 1))
    league.close()


@pytest.mark.slow
def test_many_workers_at_once_play_every_job_once(db_url, tmp_path):
    """Eight workers (threads, each with its own connection to the league) on 48 small jobs: every job done once by
    one worker, every game stored once, no lock error anywhere."""
    league = _league(db_url, tmp_path / "h")
    cpu, rnd = _bots(league)
    league.queue.enqueue("many", games_jobs(league, [cpu], rnd, games=192, first_seed=0, match_kind="tournament",
                                            env_options=SHORT, job_rounds=2))
    reports, errors = [], []

    def work(i: int) -> None:
        lg = League(db_url, home=tmp_path / "h")
        try:
            reports.append(run_worker(lg, WorkerOptions(until_empty=True, poll=0.01, name=f"w{i}")))
        except Exception as exc:  # any lock error fails the test
            errors.append(exc)
        finally:
            lg.close()

    threads = [threading.Thread(target=work, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert errors == []
    assert sum(r.done for r in reports) == 48 and sum(r.failed + r.lost + r.counted for r in reports) == 0
    assert sum(r.games for r in reports) == 192
    jobs = league.queue.jobs(batch="many")
    assert {j.state for j in jobs} == {"done"} and all(j.tries == 1 for j in jobs)
    games = _stored(league)
    assert Counter(games) == Counter((s, k) for s in range(96) for k in (0, 1))
    league.close()


def test_an_sprt_decided_across_two_workers_cancels_its_remaining_jobs(db_url, tmp_path):
    """cpu against random under an SPRT, queued in jobs of 2 pairs, played by two workers while the command only
    waits: the verdict falls on the pair a single match stops at; the jobs after it are cancelled; the games stored
    are those of the jobs done, once each."""
    league = _league(db_url, tmp_path / "h")
    cpu, rnd = _bots(league)
    settings = SPRTSettings(elo0=0, elo1=400, alpha=0.05, beta=0.05)
    queued = queue_match(league, [cpu], rnd, games=400, first_seed=0, env_options=SHORT, sprt=settings, job_rounds=2)
    stop = threading.Event()
    reports = []

    def work(i: int) -> None:
        lg = League(db_url, home=tmp_path / "h")
        try:
            reports.append(run_worker(lg, WorkerOptions(batches=(queued.batch,), until_empty=True, poll=0.01,
                                                        name=f"w{i}")))
        finally:
            lg.close()

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    report = queued.see_through(play=False, poll=0.01)
    for t in threads:
        t.join(timeout=120)
    stop.set()
    from selfplay_cli.policies import ScriptedPolicy

    local = run_match(ScriptedPolicy("pong", "cpu"), ScriptedPolicy("pong", "random"), games=400, first_seed=0,
                      env_options=SHORT, sprt=settings)
    assert report.sprt["decision"] == local.sprt["decision"] == "H1"
    assert report.sprt["pairs"] == local.sprt["pairs"]
    jobs = league.queue.jobs(batch=queued.batch)
    counts = Counter(j.state for j in jobs)
    assert counts["queued"] == counts["leased"] == counts["dead"] == 0
    assert counts["cancelled"] >= 90 and counts["done"] >= -(-local.sprt["pairs"] // 2)
    assert {j.worker for j in jobs if j.state == "done"} <= {"w0", "w1"}
    done_games = sum(j.result["games"] for j in jobs if j.state == "done")
    games = _stored(league)
    assert len(games) == done_games == len(set(games))
    league.close()


def test_marl_queue_shows_and_cancels(tmp_path, capsys, monkeypatch):
    home = tmp_path / "h"
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.delenv("MARL_DB", raising=False)
    code, out, err = run(capsys, "league", "tournament", "cpu", "random", "--env", "pong", "--env-option",
                         "points_to_win=1", "--games-per-pair", "300", "--queue", "--no-wait", "--home", str(home))
    assert code == 0, err
    assert "queued 300 games of 1 pairs as batch tournament:pong:" in out
    shown = run_json(capsys, "queue", "--home", str(home))
    (batch,) = shown["batches"]
    assert (batch["queued"], batch["done"]) == (3, 0) and shown["workers"] == []
    code, out, err = run(capsys, "queue", "cancel", str(shown["jobs"][0]["id"]), "--home", str(home))
    assert code == 0 and "cancelled 1 job" in out
    code, out, err = run(capsys, "worker", "--home", str(home), "--until-empty", "--quiet")
    assert code == 0, err
    shown = run_json(capsys, "queue", "--home", str(home))
    (batch,) = shown["batches"]
    assert (batch["queued"], batch["done"], batch["cancelled"]) == (0, 2, 1)
    (w,) = shown["workers"]
    assert w["jobs_done"] == 2 and w["games"] == 172 and w["status"] == "stopped"
    code, out, err = run(capsys, "queue", "cancel", "999", "--home", str(home))
    assert code == 2 and err.count("\n") == 1 and "no job 999" in err
    code, out, err = run(capsys, "queue", "--state", "nope", "--home", str(home))
    assert code == 2 and err.count("\n") == 1


def test_a_worker_refuses_a_league_that_is_not_on_this_machine(tmp_path, capsys):
    code, out, err = run(capsys, "worker", "--db", f"sqlite:///{tmp_path}/elsewhere/league.db", "--until-empty")
    assert code == 2 and err.count("\n") == 1 and "PostgreSQL" in err
    assert not (tmp_path / "elsewhere").exists()
    code, out, err = run(capsys, "worker", "--home", str(tmp_path / "none"), "--until-empty")
    assert code == 2 and err.count("\n") == 1 and not (tmp_path / "none").exists()


@pytest.mark.slow
def test_a_worker_with_only_the_url_plays_network_snapshots_from_the_league(db_url, tmp_path):
    """Two network snapshots registered in home H; a worker with another, empty home (another machine) fetches their
    files from the league by sha256 into its cache and plays the queued match: the games equal the ones played in
    H from the files."""
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    home = tmp_path / "h"
    league = _league(db_url, home)
    league.roster.create_run("r", "pong", {}, algo="ppo")
    arch = Arch(hidden=(16, 16))
    rows = []
    for i in (1, 2):
        path = home / "snapshots" / "r" / f"s{i}.safetensors"
        path.parent.mkdir(parents=True, exist_ok=True)
        save_snapshot(path, build_network((8, 6), 3, arch, seed=i), SnapshotMeta(
            env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="r", name=f"s{i}", algo="ppo", step=i))
        rows.append(league.roster.add_snapshot(env="pong", run="r", name=f"s{i}", path=str(path.relative_to(home)),
                                               step=i))
    jobs = games_jobs(league, [rows[0]], rows[1], games=8, first_seed=7, match_kind="match", env_options=SHORT,
                      job_rounds=2)
    league.queue.enqueue("far", jobs)
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "MARL_CACHE": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", "worker", "--db", db_url, "--home",
                          str(tmp_path / "elsewhere"), "--until-empty", "--json"], env=env, capture_output=True,
                         text=True, timeout=180)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["done"] == 2
    assert len(list((tmp_path / "cache").rglob("*.safetensors"))) == 2  # fetched, cached
    assert not (tmp_path / "elsewhere" / "snapshots").exists()
    here = [g for job in league.queue.jobs(batch="far") for g in play_job(league, job).games]  # from H's files
    with league.session(readonly=True) as s:
        stored = sorted((int(g.seed), int(g.length)) for g in s.execute(select(Game)).scalars())
    assert len(stored) == 8 and stored == sorted((r.seed, r.length) for r in here)
    league.close()


def _network_league(url: str, home, players: int) -> League:
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    league = _league(url, home)
    league.roster.create_run("r", "pong", {}, algo="ppo")
    arch = Arch(hidden=(16, 16))
    for i in range(players):
        path = home / "snapshots" / "r" / f"s{i}.safetensors"
        path.parent.mkdir(parents=True, exist_ok=True)
        save_snapshot(path, build_network((8, 6), 3, arch, seed=i + 1), SnapshotMeta(
            env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="r", name=f"s{i}", algo="ppo", step=i + 1))
        league.roster.add_snapshot(env="pong", run="r", name=f"s{i}", path=str(path.relative_to(home)), step=i + 1)
    return league


@pytest.mark.slow
def test_a_tournament_goes_on_through_a_postgresql_restart(pg_url, pg_restart, tmp_path):
    """`marl league tournament` (not queued) with PostgreSQL stopped for 1.5 s and started again mid-way: it waits for
    the server and ends with exit 0, every pair with its games, none twice (it ended with an internal error, exit 5,
    15 of 28 pairs unplayed, before)."""
    home = tmp_path / "h"
    league = _network_league(pg_url, home, 4)
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "league", "tournament", "--run", "r",
                             "--games-per-pair", "30", "--env-option", "points_to_win=2", "--db", pg_url, "--home",
                             str(home), "--json"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait(lambda: league.ledger.count_games("pong") > 0, timeout=120)
    league.close()
    pg_restart(down=1.5)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert err.count("unreachable") == 1  # the restart came mid-way: waited for, said once
    league = League(pg_url, home=home)
    with league.session(readonly=True) as s:
        seats = s.execute(select(GameSeat.game_id, GameSeat.seat, GameSeat.player_id, Game.seed)
                          .join(Game, Game.id == GameSeat.game_id)).all()
    games: dict[int, dict] = {}
    for gid, seat, pid, seed in seats:
        games.setdefault(gid, {"seed": seed})[seat] = pid
    per_pair = Counter(frozenset((g[0], g[1])) for g in games.values())
    assert len(per_pair) == 6 and set(per_pair.values()) == {30}
    assert len({(g["seed"], g[0], g[1]) for g in games.values()}) == len(games) == 180  # no game twice
    league.close()


@pytest.mark.slow
def test_a_training_run_and_its_worker_go_on_through_a_postgresql_restart(pg_url, pg_restart, tmp_path):
    """`marl train --eval remote` on a PostgreSQL league with a `marl worker` playing its gauntlets, and the server
    stopped for 3 s (longer than either pauses between two looks at it) and started again after the run's first
    snapshots: each says once that the league is unreachable, waits for it and goes on; the run finishes with every
    snapshot registered and rated, the worker's jobs all done."""
    home = tmp_path / "h"
    league = League(pg_url, home=home)
    worker = _worker(pg_url, tmp_path / "elsewhere", "--beat", "0.5", "--batch", "run:r", "--name", "far")
    _wait(lambda: any(w.name == "far" for w in league.queue.workers()), timeout=60, every=0.05)
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "train", "pong", "--agents", "2", "--games", "16",
                             "--env-option", "points_to_win=1", "--snapshot-steps", "2048", "--steps", "8192",
                             "--eval-games", "4", "--eval-playoff", "0", "--eval", "remote", "--run", "r", "--quiet",
                             "--json", "--db", pg_url, "--home", str(home)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    _wait(lambda: len(league.roster.players("pong", kind="snapshot")) >= 4, timeout=180, every=0.05)
    league.close()
    pg_restart(down=3.0)
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    assert err.count("unreachable") == 1
    worker.send_signal(signal.SIGTERM)  # the run is over: the worker (it serves the run's batch) is let go
    w_out, w_err = worker.communicate(timeout=60)
    assert worker.returncode == 143, w_err
    assert w_err.count("unreachable") == 1
    report = json.loads(out)
    league = League(pg_url, home=home)
    snaps = league.roster.players("pong", kind="snapshot")
    assert league.roster.get_run("r").status == "finished" and report["rating_jobs_left"] == 0
    assert len(snaps) == len(report["snapshots"]) == 10  # s0 and every 2,048 steps to 8,192, both paddles
    jobs = league.queue.jobs(batch="run:r")
    assert [j.state for j in jobs] == ["done"] * 5
    assert "far" in {j.worker for j in jobs} <= {"far", f"train@{socket.gethostname()}:{proc.pid}"}
    with league.session(readonly=True) as s:
        rated = set(s.execute(select(GameSeat.player_id).distinct()).scalars())
    assert {p.id for p in snaps} <= rated  # every snapshot played its gauntlet
    league.close()


def _ctrl_c(*_args, **_kwargs):
    raise KeyboardInterrupt


def test_an_idle_worker_stopped_by_ctrl_c_says_no_job_was_in_play(tmp_path, capsys, monkeypatch):
    """Issue 48: an idle worker stopped by Ctrl-C said 'the job in play went back to the queue'."""
    import types

    from selfplay_cli.evaluation import worker as worker_module

    home = tmp_path / "h"
    League.open(home=home).close()
    monkeypatch.delenv("MARL_DB", raising=False)
    monkeypatch.setattr(worker_module, "time", types.SimpleNamespace(sleep=_ctrl_c))  # Ctrl-C while it waits idle
    code, out, err = run(capsys, "worker", "--home", str(home), "--quiet")
    assert code == 130 and err.count("\n") == 1, err
    assert "went back" not in err and "no job was in play" in err, err


def test_a_worker_stopped_by_ctrl_c_in_play_names_the_job_it_gave_back(tmp_path, capsys, monkeypatch):
    from selfplay_cli.evaluation import worker as worker_module

    home = tmp_path / "h"
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.delenv("MARL_DB", raising=False)
    code, _, err = run(capsys, "league", "tournament", "cpu", "random", "--env", "pong", "--env-option",
                       "points_to_win=1", "--games-per-pair", "100", "--queue", "--no-wait", "--home", str(home))
    assert code == 0, err
    (job,) = run_json(capsys, "queue", "--home", str(home))["jobs"]
    monkeypatch.setattr(worker_module, "play_leased", _ctrl_c)  # Ctrl-C while the leased job plays
    code, out, err = run(capsys, "worker", "--home", str(home), "--quiet")
    assert code == 130 and err.count("\n") == 1, err
    assert f"job {job['id']}" in err and "went back to the queue" in err, err
    (back,) = run_json(capsys, "queue", "--home", str(home))["jobs"]
    assert back["id"] == job["id"] and back["state"] == "queued" and back["tries"] == 0  # it did, not counted


# --- issue 49: a worker started while its PostgreSQL server is down waits for it, bounded ---


class _Clock:
    """A clock that the waits of :func:`reach_league` move (no real waiting), with ``then(n, fn)``: ``fn()`` at the
    n-th wait."""

    def __init__(self) -> None:
        self.now, self.waits, self.at = 1000.0, [], {}

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.waits.append(seconds)
        self.now += seconds
        if len(self.waits) in self.at:
            self.at[len(self.waits)]()


def test_a_worker_starting_while_postgresql_is_down_retries_until_it_is_up(pg_server, pg_url, tmp_path):
    """Issue 49: `marl worker` with PostgreSQL down exited 4 at once. Now it retries as a running worker does
    (1 s, doubling), said once, and goes to work with the server up: here after its third wait."""
    from conftest import start_postgres, stop_postgres

    from selfplay_cli.evaluation.worker import reach_league

    League(pg_url, home=tmp_path / "h").close()  # a league there
    said, clock = [], _Clock()
    stop_postgres(pg_server)
    try:
        clock.at[3] = lambda: start_postgres(pg_server)
        league = reach_league(lambda: League.open(home=tmp_path / "h", url=pg_url), said.append, 60.0, clock=clock,
                              sleep=clock.sleep)
    finally:
        if not pg_server.get_postmaster_info().is_running():
            start_postgres(pg_server)
    try:
        assert league.queue.batches() == [] and league.queue.add_worker("w", "here", 1) > 0  # the league, reached
    finally:
        league.close()
    assert clock.waits == [1.0, 2.0, 4.0]
    assert len(said) == 1 and said[0].startswith("league database postgresql+psycopg://")
    assert "unreachable, retrying for up to 60 s" in said[0]


def test_a_worker_whose_postgresql_never_comes_leaves_after_its_wait_in_one_line(pg_server, pg_url, tmp_path):
    from conftest import start_postgres, stop_postgres

    from selfplay_cli.evaluation.worker import reach_league
    from selfplay_cli.league.store import LeagueUnreachable

    said, clock, tries = [], _Clock(), []

    def open_it():
        tries.append(clock())
        return League.open(home=tmp_path / "h", url=pg_url)

    stop_postgres(pg_server)
    try:
        with pytest.raises(LeagueUnreachable) as failed:
            reach_league(open_it, said.append, 60.0, clock=clock, sleep=clock.sleep)
        with pytest.raises(LeagueUnreachable, match="cannot reach league database"):  # --wait-db 0: at once
            reach_league(open_it, said.append, 0.0, clock=clock, sleep=clock.sleep)
    finally:
        start_postgres(pg_server)
    assert clock.waits == [1.0, 2.0, 4.0, 8.0, 16.0, 29.0] and tries[-2] - tries[0] == 60.0  # the last wait cut
    assert len(said) == 1 and "unreachable for 60 s at the worker's start" in str(failed.value)
    assert "\n" not in str(failed.value) and failed.value.exit_code == 4


@pytest.mark.slow
def test_marl_worker_started_before_its_postgresql_goes_to_work_when_it_comes(pg_server, pg_url, tmp_path):
    """The command as a user runs it: started while the server is down, it says so once and waits; the server
    started when it has said so, it works (an empty queue here: --until-empty leaves, exit 0). With a server that
    does not come within --wait-db, one more line and exit 4."""
    from conftest import start_postgres, stop_postgres

    League(pg_url, home=tmp_path / "h").close()
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    stop_postgres(pg_server)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "worker", "--db", pg_url, "--until-empty",
                                 "--wait-db", "600", "--json"], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        first = proc.stderr.readline()  # it has tried, failed, and waits
        assert "unreachable, retrying for up to 600 s" in first, first
        start_postgres(pg_server)
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0 and "unreachable" not in err, err
        assert json.loads(out)["done"] == 0
        stop_postgres(pg_server)
        gave_up = subprocess.run([sys.executable, "-m", "selfplay_cli", "worker", "--db", pg_url, "--wait-db", "1"],
                                 env=env, capture_output=True, text=True, timeout=300)
    finally:
        if not pg_server.get_postmaster_info().is_running():
            start_postgres(pg_server)
    lines = gave_up.stderr.splitlines()
    assert gave_up.returncode == 4 and len(lines) == 2 and "Traceback" not in gave_up.stderr, gave_up.stderr
    assert "retrying for up to 1 s" in lines[0] and "unreachable for 1 s at the worker's start (--wait-db)" in lines[1]
