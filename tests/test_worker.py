"""The rating worker beside `marl train`: it dies with its trainer, the run's lock names it, a dead or stalled one
is replaced at once, no gauntlet game is ever stored twice (a job played again after a kill leaves the ledger as an
uninterrupted run does), SIGTERM is honoured within seconds whatever the settings. (One command with one seed storing
the same gauntlet games twice over: test_gauntlet.py's test_the_rating_games_repeat_with_the_seed_whatever_the_timing,
whose two runs, one of them with this worker, store the very same games.)"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import procs
import pytest

from selfplay_cli.cli import main
from selfplay_cli.errors import MarlError
from selfplay_cli.evaluation.executors.base import GauntletJob, RatingWorkerError
from selfplay_cli.evaluation.executors.local import MAX_RESTARTS, Evaluator
from selfplay_cli.league import migrations
from selfplay_cli.league.store import League
from selfplay_cli.train import loop
from selfplay_cli.train.lock import claim, process_start

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SIGKILL, SIGSTOP and /proc")

KILL_POINTS = Path(__file__).with_name("kill_points.py")
MARKS = Path(__file__).with_name("marks.py")
FAST = ["--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps", "2048", "--quiet"]


def _env() -> dict[str, str]:
    return {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}


def _until(what, seconds: float) -> bool:
    """Whether ``what()`` came true within ``seconds`` (looked at every 50 ms)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not what():
        time.sleep(0.05)
    return bool(what())


def _lines(path: Path) -> int:
    """The lines written to ``path`` so far (0 before it exists)."""
    try:
        return path.read_text().count("\n")
    except FileNotFoundError:
        return 0


def _eval_games(db: Path) -> int:
    con = sqlite3.connect(db)
    try:
        return con.execute("select count(*) from games g join matches m on m.id = g.match_id "
                           "where m.kind = 'eval'").fetchone()[0]
    finally:
        con.close()


def _stored_any(db: Path) -> bool:
    """The ledger has a rating game (False while the database is still being created, or locked)."""
    try:
        return db.exists() and _eval_games(db) > 0
    except sqlite3.OperationalError:
        return False


# -- 1. the worker dies with its trainer ----------------------------------------------------------------------
@pytest.mark.slow
def test_the_rating_worker_dies_at_once_when_its_trainer_is_killed(tmp_path):
    """SIGKILL of `marl train` while its worker is in the middle of a gauntlet (64 games a matchup): the worker is
    gone, not playing on, and stores nothing more (it used to play on for minutes, then hang with init as parent).
    The run's lock named it. (How soon it goes, under two seconds, is measured by benchmarks/fault_matrix.py.)"""
    home = tmp_path / "h"
    trainer = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "train", "pong", *FAST, "--steps", "200000",
                                "--eval-games", "64", "--run", "r", "--home", str(home)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env())
    workers: list[int] = []
    try:
        # the worker has stored its first games: it is at work
        assert _until(lambda: _stored_any(home / "league.db") or trainer.poll() is not None, 240) \
            and trainer.poll() is None, "no rating game stored" if trainer.poll() is None else trainer.stderr.read()
        workers = procs.children(trainer.pid)
        assert len(workers) >= 1, "no rating worker found"
        lock = (home / "runs" / "r" / "lock").read_text()
        trainer.kill()
        trainer.wait(timeout=30)
        # a hang guard: a worker playing on lives for minutes
        assert _until(lambda: all(procs.gone(w) for w in workers), 30), "worker alive 30 s after its trainer died"
        # nothing of the run (a grandchild, say) is left to store a game: no process holds the league open
        assert not procs.holding(home / "league.db"), "a process still has the league open after the trainer died"
        named = json.loads(lock)
        assert named["trainer"][0] == trainer.pid and named["worker"][0] in workers
    finally:
        for pid in [trainer.pid, *workers, *procs.children(trainer.pid)]:  # (an orphan, where the fix is missing)
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


# -- 2. the run lock covers both processes ------------------------------------------------------------------
def _sleeper() -> subprocess.Popen:
    """A process that lives until it is killed (or this one ends, closing its stdin), answering each line it reads
    with the same line (:func:`_answers`)."""
    echo = "import sys\nfor line in sys.stdin: print(line, end='', flush=True)"
    return subprocess.Popen([sys.executable, "-c", echo], stdin=subprocess.PIPE, stdout=subprocess.PIPE)


def _answers(p: subprocess.Popen) -> bool:
    """Whether ``p`` still runs: it answers a line. A process sent SIGKILL before this asks never answers (the kernel
    runs none of its code after the kill), so no time has to pass first for the answer to be sure."""
    try:
        p.stdin.write(b"?\n")
        p.stdin.flush()
    except BrokenPipeError:
        return False
    return p.stdout.readline() == b"?\n"


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_stale_lock_ends_the_old_runs_live_worker_and_only_it(tmp_path):
    run_dir = tmp_path / "runs" / "r"
    run_dir.mkdir(parents=True)
    lock = run_dir / "lock"
    worker, stranger = _sleeper(), _sleeper()
    try:
        # the trainer was killed, its worker lives on: taking the run over ends the worker, at once
        lock.write_text(json.dumps({"trainer": [_dead_pid(), None],
                                    "worker": [worker.pid, process_start(worker.pid)]}))
        claim(lock, "r")
        assert worker.wait(timeout=60) == -signal.SIGKILL
        assert json.loads(lock.read_text()) == {"trainer": [os.getpid(), process_start(os.getpid())]}
        # a pid given to another process since (another start time) is not the run's worker: left alone
        lock.write_text(json.dumps({"trainer": [_dead_pid(), None], "worker": [stranger.pid, "1"]}))
        claim(lock, "r")
        assert _answers(stranger)
        # a live trainer (the same process that wrote the lock) keeps its run
        lock.write_text(json.dumps({"trainer": [stranger.pid, process_start(stranger.pid)]}))
        with pytest.raises(MarlError, match=f"being trained by process {stranger.pid}"):
            claim(lock, "r")
        # ... but its pid, recycled by another process, does not
        lock.write_text(json.dumps({"trainer": [stranger.pid, "1"]}))
        claim(lock, "r")
        assert _answers(stranger)
    finally:
        for p in (worker, stranger):
            p.kill()
            p.communicate()


# -- 4. a dead or stalled worker is noticed at once and replaced ----------------------------------------------
@pytest.mark.slow
def test_a_dead_worker_is_noticed_by_poll_and_replaced_and_its_job_done(rated_league):
    league, snap = rated_league
    notes: list[str] = []
    with Evaluator(league, "cpu", background=True, note=notes.append) as ev:
        ev.submit(GauntletJob((snap.id,), 0, 2, 0))
        first = ev.worker_pid
        os.kill(first, signal.SIGKILL)
        deadline = time.time() + 60
        while time.time() < deadline and ev.restarts == 0:
            ev.poll()
            time.sleep(0.05)
        assert ev.restarts == 1 and ev.worker_pid != first
        assert "ended unexpectedly (killed by SIGKILL)" in notes[0] and "played again" in notes[0]
        (done,) = ev.wait()
        # s0 against random and cpu, 2 games each, and (the run's first moment) the two bots against each other
        assert done.job.snapshot_ids == (snap.id,) and done.games == 6 and done.error is None
    assert _eval_games(league.db_path) == 6


@pytest.mark.slow
def test_the_wait_hands_over_each_job_as_it_finishes(rated_league):
    """The final wait hands each finished job to ``on_wait`` at once, while the jobs after it are still owed (so
    the run reports each gauntlet as it comes), in order, and each once: none again in the list returned."""
    league, snap = rated_league
    jobs = [GauntletJob((snap.id,), seed, 2, 0) for seed in (0, 100, 200)]
    handed: list[tuple[GauntletJob, int]] = []  # each job handed over, and how many were still owed then
    with Evaluator(league, "cpu", background=True) as ev:
        for job in jobs:
            ev.submit(job)
        rest = ev.wait(on_wait=lambda done: handed.extend((d.job, ev.left) for d in done))
        assert ev.left == 0 and ev.pending == []
    assert rest == [] and [j for j, _ in handed] == jobs
    assert [left for _, left in handed] == [2, 1, 0]


def test_a_worker_that_keeps_dying_stops_the_run_as_an_internal_error(rated_league):
    league, snap = rated_league
    with Evaluator(league, "cpu", background=True, note=lambda line: None) as ev:
        ev.submit(GauntletJob((snap.id,), 0, 2, 0))
        with pytest.raises(RatingWorkerError, match=f"replaced {MAX_RESTARTS} times") as e:
            for _ in range(MAX_RESTARTS + 1):
                pid = ev.worker_pid
                os.kill(pid, signal.SIGKILL)
                assert _until(lambda pid=pid: procs.gone(pid), 60), f"worker {pid} alive 60 s after SIGKILL"
                ev.poll()
        assert not isinstance(e.value, MarlError)  # exit 5 (internal), not 2 (a user's mistake)


class _Clock:
    """A stall's clock that moves only when the test moves it."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.mark.slow
def test_a_stopped_worker_is_reported_and_replaced(rated_league):
    league, snap = rated_league
    notes: list[str] = []
    clock = _Clock()
    with Evaluator(league, "cpu", background=True, note=notes.append, stall_seconds=3.0, clock=clock) as ev:
        ev.submit(GauntletJob((snap.id,), 0, 2, 0))
        stopped = ev.worker_pid
        os.kill(stopped, signal.SIGSTOP)
        assert _until(lambda: procs.stopped(stopped), 60), "the worker did not stop"  # (every thread of it)
        ev.poll()  # (what it said before it stopped: it says nothing more)
        clock.now += 2.9
        ev.poll()
        assert ev.restarts == 0 and notes == []  # not before its stall time
        clock.now += 0.2
        ev.poll()
        assert ev.restarts == 1
        assert f"(process {stopped}) finished no game for 3 s" in notes[0] and "replacing it" in notes[0]
        assert procs.gone(stopped)
        ev.stall_seconds = 300.0  # the new worker's start-up (spawn, torch) is no stall
        (done,) = ev.wait()
        assert done.games == 6  # s0 against each bot, and the bots against each other
    assert _eval_games(league.db_path) == 6


def test_an_idle_worker_given_work_is_not_taken_for_stalled(rated_league):
    league, snap = rated_league
    notes: list[str] = []
    clock = _Clock()
    with Evaluator(league, "cpu", background=True, note=notes.append, stall_seconds=2.0, clock=clock) as ev:
        clock.now += 2.5  # nothing to do for longer than the stall time
        ev.poll()
        ev.submit(GauntletJob((snap.id,), 0, 2, 0))
        ev.poll()
        assert ev.restarts == 0 and notes == []


# -- 5. the final gauntlet, on the trainer's idle core beside the worker's backlog -------------------------
def _three_moments(home: Path, tmp_path: Path) -> tuple[League, list[GauntletJob]]:
    """A league with three one-snapshot moments of run w (small untrained networks) and the scripted players; the
    jobs of their gauntlets, the last the run's final (a playoff of up to 8 games a pair)."""
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    arch = Arch(hidden=(16,))
    for k in range(3):
        meta = SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="w", name=f"s{k}",
                            algo="ppo", step=k, env_options={"points_to_win": 1})
        save_snapshot(tmp_path / f"s{k}.safetensors", build_network((8, 6), 3, arch, seed=k + 1), meta)
        assert main(["checkpoint", "import", str(tmp_path / f"s{k}.safetensors"), "--home", str(home)]) == 0
    league = League.open(home)
    league.roster.ensure_bots("pong", ["random", "cpu"])
    ids = [p.id for p in league.roster.players("pong", kind="snapshot")]
    return league, [GauntletJob((ids[0],), 0, 2, 1), GauntletJob((ids[1],), 100, 2, 1),
                    GauntletJob((ids[2],), 200, 2, 1, full=True, playoff=8)]


def _games_of(db: Path) -> list[tuple]:
    """Every stored game by its match's work key, seed, players and points (comparable across leagues)."""
    con = sqlite3.connect(db)
    rows = con.execute("select m.work_key, g.seed, g.length, group_concat(p.name || ':' || s.points, ' ') from games g "
                       "join matches m on m.id = g.match_id join game_seats s on s.game_id = g.id join players p on "
                       "p.id = s.player_id group by g.id order by m.work_key, g.seed").fetchall()
    con.close()
    return rows


@pytest.mark.slow
def test_the_final_gauntlet_is_played_beside_the_backlog_and_is_the_same_games(tmp_path):
    """Submitted while the worker still owes two moments, the final gauntlet (it meets every earlier snapshot, so it
    chooses nothing from their games) starts at once in a helper process; the final job is handed to the worker
    after it, finds its gauntlet stored and plays the playoff. Every game, playoff included, is the one a run whose
    gauntlets are played inline, one after the other, stores; the jobs come back in order, the final counting the
    gauntlet's games."""
    league, jobs = _three_moments(tmp_path / "h", tmp_path)
    with Evaluator(league, "cpu", background=True) as ev:
        for job in jobs[:2]:
            ev.submit(job)
        ev.submit(jobs[2])
        assert ev._helper is not None and ev._helper.is_alive()  # at once, beside the backlog
        done = ev.wait()
        assert ev._helper is None and ev.left == 0
    assert [d.job for d in done] == jobs
    league.close()
    inline, inline_jobs = _three_moments(tmp_path / "i", tmp_path)
    with Evaluator(inline, "cpu", background=False) as ev:
        for job in inline_jobs:
            ev.submit(job)
        alone = ev.wait()
        assert ev._helper is None  # (inline: every job as it comes)
    inline.close()
    assert [d.games for d in done] == [d.games for d in alone] and done[2].games > done[1].games
    games = _games_of(tmp_path / "h" / "league.db")
    assert games == _games_of(tmp_path / "i" / "league.db")
    assert any(k.startswith("gauntlet/3/") for k, *_ in games)  # (the final moment's, by its snapshot's id)


@pytest.mark.slow
def test_a_helper_that_dies_leaves_its_gauntlet_to_the_worker(tmp_path):
    """The helper killed as it starts: the trainer says so in one line, the worker plays the final gauntlet after
    the backlog (what the helper stored counts once), then the playoff: the same games as an undisturbed run."""
    league, jobs = _three_moments(tmp_path / "h", tmp_path)
    notes: list[str] = []
    with Evaluator(league, "cpu", background=True, note=notes.append) as ev:
        for job in jobs:
            ev.submit(job)
        helper = ev._helper.pid
        os.kill(helper, signal.SIGKILL)
        done = ev.wait()
        assert ev.restarts == 0
    league.close()
    assert [d.job for d in done] == jobs
    assert len(notes) == 1 and f"helper (process {helper}) ended unexpectedly (killed by SIGKILL)" in notes[0]
    other, other_jobs = _three_moments(tmp_path / "o", tmp_path)
    with Evaluator(other, "cpu", background=True) as ev:
        for job in other_jobs:
            ev.submit(job)
        ev.wait()
    other.close()
    assert _games_of(tmp_path / "h" / "league.db") == _games_of(tmp_path / "o" / "league.db")


# -- 3. no game is ever counted twice -------------------------------------------------------------------------
def _gauntlet_record(home: Path, seeds: range) -> dict[tuple[str, str], list[tuple]]:
    """The gauntlet games whose matchup starts in ``seeds``: per (a, b) of the matchup, each game's seed and its
    seats' players and points, sorted."""
    con = sqlite3.connect(home / "league.db")
    out: dict[tuple[str, str], list[tuple]] = defaultdict(list)
    for params, gid, seed in con.execute("select m.params, g.id, g.seed from games g join matches m "
                                         "on m.id = g.match_id where m.kind = 'eval' order by g.id"):
        p = json.loads(params)
        if int(p["first_seed"]) in seeds:
            seats = con.execute("select p.name, s.points from game_seats s join players p on p.id = s.player_id "
                                "where s.game_id = ? order by s.seat", (gid,)).fetchall()
            out[(p["a"], p["b"])].append((seed, *seats))
    con.close()
    return {k: sorted(v) for k, v in out.items()}


@pytest.mark.slow
def test_a_job_cut_by_a_kill_is_stored_as_an_uninterrupted_run_stores_it(tmp_path, capsys):
    """The worker is killed (and its trainer with it) as it stores the second moment's gauntlet; `marl train
    --resume` plays that job again: every matchup of the moment ends with exactly the games, seeds and results of
    an uninterrupted run of the same command (none stored twice, none missing, none different)."""
    args = ["train", "pong", *FAST, "--steps", "4096", "--eval-games", "4", "--eval-playoff", "0", "--run", "r"]
    assert main([*args, "--home", str(tmp_path / "whole")]) == 0
    killed = tmp_path / "killed"
    child = subprocess.run([sys.executable, str(KILL_POINTS), "worker-mid-job", str(killed), *args],
                           capture_output=True, text=True, timeout=600, env=_env())
    assert child.returncode == -signal.SIGKILL, child.stderr[-2000:]
    second = range(10_020_000, 10_030_000)  # (two learners: the first moment took two snapshots)
    cut = _gauntlet_record(killed, second)
    assert sum(map(len, cut.values())) > 0, "the kill came before the moment's first games were stored"
    assert main(["train", "--resume", "r", "--home", str(killed), "--json"]) == 0, capsys.readouterr().err
    whole, resumed = _gauntlet_record(tmp_path / "whole", second), _gauntlet_record(killed, second)
    assert Counter({k: len(v) for k, v in resumed.items()}) == Counter({k: len(v) for k, v in whole.items()})
    assert resumed == whole
    first = range(10_000_000, 10_020_000)  # the first moment's gauntlet, finished before the kill
    assert _gauntlet_record(killed, first) == _gauntlet_record(tmp_path / "whole", first)


def test_a_matchup_is_stored_once_whatever_the_number_of_writers(tmp_path):
    """The unique work key: the same unit stored twice (two workers, or one played again) keeps the first."""
    from selfplay_cli.results import GameResult

    league = League.open(tmp_path / "h")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    a, b = (p.id for p in league.roster.players("pong", kind="bot"))
    games = [GameResult("pong", (a, b), seed=i, scores=(1, 0), outcome=(1.0, 0.0), length=5, truncated=False)
             for i in range(3)]
    first, ids = league.ledger.create_match_with_games("pong", "eval", {"gauntlet": True}, games,
                                                       key="gauntlet/7/0/1/2")
    again, none = league.ledger.create_match_with_games("pong", "eval", {"gauntlet": True}, games,
                                                        key="gauntlet/7/0/1/2")
    assert (again, none, len(ids)) == (first, [], 3) and league.ledger.count_games("pong") == 3
    assert set(league.ledger.keyed_matches("gauntlet/7/")) == {"gauntlet/7/0/1/2"}
    assert not league.ledger.keyed_matches("gauntlet/70")
    league.close()


def test_a_league_of_schema_1_gets_its_work_keys(tmp_path):
    """An existing league (schema 1: no work keys) is migrated when a command that writes opens it."""
    League.open(tmp_path / "h").close()
    con = sqlite3.connect(tmp_path / "h" / "league.db")
    newer = ("seed_ranges", "jobs", "workers", "blobs", "videos", "alembic_version")  # (none before Alembic)
    for table in newer:
        con.execute(f"drop table {table}")
    con.execute("drop index uq_matches_work_key")
    con.execute("alter table matches drop column work_key")
    con.execute("update meta set value = '1' where key = 'schema_version'")
    con.commit()
    con.close()
    with League.open(tmp_path / "h", readonly=True) as league:  # a command that only reads reads it as it is
        assert league.schema_revision() == "legacy 1" and league.ledger.count_games("pong") == 0
    with League.open(tmp_path / "h") as league:
        assert league.schema_revision() == migrations.head()
        league.roster.ensure_bots("pong", ["random"])
        league.ledger.create_match_with_games("pong", "eval", {}, [], key="k")
        assert set(league.ledger.keyed_matches("k")) == {"k"}


# -- 5. SIGTERM within seconds, whatever the settings --------------------------------------------------------
@pytest.mark.slow
def test_sigterm_stops_a_run_within_seconds_even_in_an_endless_update(tmp_path):
    """update_epochs = 1e9: the learners' updates (two, in threads) would run for hours; SIGTERM stops the run with
    exit 143 and status stopped (how soon, under five seconds, is measured by benchmarks/fault_matrix.py)."""
    home = tmp_path / "h"
    config = tmp_path / "endless.toml"
    config.write_text("[ppo]\nupdate_epochs = 1_000_000_000\n")
    marks = tmp_path / "marks"  # a line each time a learner begins an update (tests/marks.py)
    proc = subprocess.Popen([sys.executable, str(MARKS), str(marks), "train", "pong", *FAST, "--steps", "100000",
                             "--eval-games", "0", "--config", str(config), "--run", "r", "--home", str(home)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        # both learners in their first update (its rollout, 2,048 steps of 16 games, takes well under a second)
        assert _until(lambda: _lines(marks) >= 2 or proc.poll() is not None, 120) and proc.poll() is None, \
            proc.communicate()[1][-1000:] if proc.poll() is not None else "no update began"
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)  # the update alone would run for hours
    finally:
        proc.kill()
    assert proc.returncode == 143, (proc.returncode, err[-1000:])
    assert "stopped r at step" in err and "Traceback" not in err
    assert _lines(marks) == 2  # the stop came in the learners' first update: no other began
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "stopped"


def test_a_stopped_run_leaves_no_stop_standing_for_later_learning(tmp_path, monkeypatch):
    """A run that ends on an error tells its learners' threads to stop; once they have, later learning in the same
    process (a test after it, a second run) updates in full again: an update is not cut short by an old stop."""
    from selfplay_cli.algos.ppo import PPOConfig
    from selfplay_cli.signals import stop_requested
    from selfplay_cli.train.config import TrainConfig

    league = League.open(tmp_path / "league")
    cfg = TrainConfig(env="pong", steps=4096, games=16, eval_games=0, run="t", env_options={"points_to_win": 1},
                      ppo=PPOConfig(rollout_steps=32, minibatches=2, update_epochs=1))
    league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
    seen = []

    def broken(self):
        seen.append(stop_requested())
        raise RuntimeError("broken")

    monkeypatch.setattr(loop.Trainer, "_train", broken)
    with pytest.raises(RuntimeError, match="broken"):
        loop.Trainer(league, cfg).train()
    assert seen == [False] and not stop_requested()
    league.close()
