"""`marl train --eval ray`: a run's gauntlets played by queue workers on Ray actors started for the run (the league's
queue as --eval remote uses it): the games are --eval remote's, the actors are listed as the league's workers
(``ray@host:pid``), and they stop when the run's gauntlets are done or the run ends, a job in play given back to the
queue (the worker loop's ``stop()``). Ray itself is the suite's (the ``ray_local`` fixture), as a run finds it."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter

import procs
import pytest
from cli_helpers import run
from sqlalchemy import select

from selfplay_cli.evaluation.executors.base import GauntletJob
from selfplay_cli.evaluation.executors.queue_workers import RemoteEvaluator, run_batch
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.files import pid_alive
from selfplay_cli.league.models import Game, GameSeat, Match, Player
from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.lock import same_process

RUN = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps",
       "2048", "--steps", "4096", "--eval-games", "2", "--eval-playoff", "2", "--seed", "3", "--run", "r", "--json"]
"""Three snapshot moments (s0, s2.05k, s4.1k) of two learners: three gauntlets, the last in full with a playoff."""
GAUNTLET_KEYS = ("snapshots", "final", "rating_games", "rating_batch", "rating_jobs_left", "best")
"""What a run's report says of its gauntlets (the rest is timing, and who played them)."""


def _record(league: League) -> Counter:
    """Every rating game in the league: its seed, length, and each seat's player (by name) and points; a multiset."""
    with league.session(readonly=True) as s:
        names = dict(s.execute(select(Player.id, Player.name)).all())
        games = s.execute(select(Game.id, Game.seed, Game.length).join(Match, Match.id == Game.match_id)
                          .where(Match.kind == "eval")).all()
        seats: dict[int, list] = {}
        for gid, pid, points in s.execute(select(GameSeat.game_id, GameSeat.player_id, GameSeat.points)
                                          .order_by(GameSeat.seat)):
            seats.setdefault(gid, []).append((names[pid], points))
    return Counter((seed, length, tuple(seats[gid])) for gid, seed, length in games)


def _gone(pid: int, within: float = 10.0) -> bool:
    """Whether process ``pid`` (a Ray actor of this machine) has ended within ``within`` seconds."""
    deadline = time.monotonic() + within
    while pid_alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    return not pid_alive(pid)


@pytest.mark.slow
def test_a_runs_gauntlets_are_played_on_its_ray_actors_with_the_remote_runs_games(ray_local, tmp_path, capsys):
    """--eval ray: every gauntlet is played by the run's Ray actor (a worker of the league named ray@host:pid; the run
    plays none itself), stdout is the JSON alone, and the ledger and the report's gauntlet content are --eval
    remote's. When the run returns its actor has stopped: its worker row says so and its process is gone."""
    code, out, err = run(capsys, *RUN, "--eval", "ray", "--home", str(tmp_path / "ray"))
    assert code == 0, err
    data = json.loads(out)
    code, out, err = run(capsys, *RUN, "--eval", "remote", "--home", str(tmp_path / "remote"))
    assert code == 0, err
    remote = json.loads(out)
    assert data["rating"] == "ray" and data["rating_batch"] == run_batch("r") and data["best"] is not None
    assert {k: data[k] for k in GAUNTLET_KEYS} == {k: remote[k] for k in GAUNTLET_KEYS}
    code, out, err = run(capsys, "queue", "--home", str(tmp_path / "ray"), "--json")
    assert code == 0, err
    queue = json.loads(out)
    (worker,) = queue["workers"]
    assert worker["name"].startswith("ray@") and worker["status"] == "stopped" and worker["jobs_done"] == 3
    assert [(j["state"], j["worker"]) for j in queue["jobs"]] == [("done", worker["name"])] * 3
    assert worker["games"] == data["rating_games"] > 0
    assert _gone(worker["pid"])
    with League.open(tmp_path / "ray") as ray_league, League.open(tmp_path / "remote") as remote_league:
        assert _record(ray_league) == _record(remote_league)


@pytest.mark.slow
def test_a_runs_ray_actors_hand_their_job_back_whenever_they_end(ray_local, rated_league, capsys):
    """A long gauntlet's job, held by an actor of a killed session of the run: the new session takes it back at once
    (the run's lock says that actor is dead) and its actor plays it. That actor is killed mid-job: said in one line,
    the job back in the queue at once, another actor started, which takes it. The run ends while that one plays:
    its loop is told to stop, gives the job back (not counted as a try) and leaves, its worker row stopped, its
    process gone: nothing plays on after the run, and the next session's actors take the job at once. Ray's news of
    the dead actor is on stderr: stdout is the JSON's under --json."""
    from selfplay_cli.evaluation.executors.ray_actors import RayEvaluator

    league, snap = rated_league
    batch = run_batch("w")
    job = GauntletJob((snap.id,), 0, 2000, 0, full=True)  # minutes of games: still in play when stopped
    RemoteEvaluator(league, "w", "cpu").submit(job)
    dead = league.queue.add_worker("ray@elsewhere:1", "elsewhere", 1, serves=[batch])
    assert league.queue.claim(dead) is not None

    def held_by_another(than: set[str]) -> str:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            ev.poll()
            (row,) = league.queue.jobs(batch=batch)
            if row.state == "leased" and row.worker not in than:
                return row.worker
            time.sleep(0.1)
        raise AssertionError(f"the job stayed with {than}")

    notes: list[str] = []
    ev = RayEvaluator(league, "w", "cpu", actors=1, note=notes.append)
    try:
        ev.submit(job)  # found in the queue, taken back from the dead actor at once (not in minutes)
        first = held_by_another({"ray@elsewhere:1"})
        assert first.startswith("ray@") and notes == []
        os.kill(int(first.rsplit(":", 1)[1]), signal.SIGKILL)
        second = held_by_another({"ray@elsewhere:1", first})
        assert second.startswith("ray@")
        assert len(notes) == 1 and notes[0].startswith("a rating actor of this run ended (")
        assert notes[0].endswith("its gauntlet went back to the queue and another is started")
        # the job is the second actor's (its row says so): its loop went from the claim straight into playing it,
        # and meets the stop at its first finished game
    finally:
        ev.close()
    (row,) = league.queue.jobs(batch=batch)
    assert (row.state, row.tries) == ("queued", 0)
    workers = {w.name: w for w in league.queue.workers()}
    assert list(workers) == ["ray@elsewhere:1", first, second]
    assert all(w.stopped_at is not None and w.holding == () for w in workers.values())
    assert len(notes) == 1  # the second left by itself: not killed (that is said, after the stop time)
    assert _gone(workers[second].pid)
    out, err = capsys.readouterr()
    assert "A worker died or was killed" in err and out == ""



@pytest.mark.slow
def test_ctrl_c_in_the_final_wait_stops_the_actors_and_keeps_the_run(ray_local, tmp_path, capsys, ctrl_c_in_the_wait):
    """--eval ray: Ctrl-C once training is over stops the wait, not the run. It ends as with --no-wait (exit 0, its
    training finished and kept), its actor stopped and gone, each gauntlet done or back on the league's queue (none
    left leased to the stopped actor); a worker that comes later plays the rest, and the ledger ends as an --eval
    remote run's. (A real SIGINT to this process from the wait's first progress call: the actor may have played some
    gauntlets by then, or none.)"""
    code, out, err = run(capsys, *RUN, "--eval", "ray", "--home", str(tmp_path / "ray"))
    assert ctrl_c_in_the_wait and code == 0, err
    data = json.loads(out)
    left = data["rating_jobs_left"]
    assert data["rating"] == "ray" and 0 <= left <= 3 and (data["best"] is None) == (left > 0)
    code, out, err = run(capsys, *RUN, "--eval", "remote", "--home", str(tmp_path / "remote"))
    assert code == 0, err
    with League.open(tmp_path / "ray") as league, League.open(tmp_path / "remote") as remote:
        assert league.roster.get_run("r").status == "finished"
        states = [j.state for j in league.queue.jobs(batch=run_batch("r"))]
        assert len(states) == 3 and states.count("queued") == left and states.count("done") == 3 - left
        for actor in league.queue.workers(taking=run_batch("r")):  # (one that had not joined the queue yet: none)
            assert actor.name.startswith("ray@") and actor.stopped_at is not None and not actor.holding
            assert _gone(actor.pid)
        report = run_worker(league, WorkerOptions(until_empty=True, poll=0.05, name="later"))
        assert (report.done, report.failed) == (left, 0)
        assert _record(league) == _record(remote)


@pytest.mark.slow
def test_a_run_that_ends_before_its_actors_have_started_stops_them_at_once(ray_local, rated_league):
    """Ctrl-C as the run begins: its actor, still starting, is told to stop all the same and leaves as soon as it is
    up (a cancelled call once kept it waiting, and the run with it, until the kill after the stop time). The stop
    time is long here (a loaded machine took 16 s and more to start an actor): an actor that waits for it is killed,
    and says so, however fast the machine."""
    from selfplay_cli.evaluation.executors.ray_actors import RayEvaluator

    league, _ = rated_league
    notes: list[str] = []
    ev = RayEvaluator(league, "w", "cpu", actors=2, note=notes.append, stop_seconds=300.0)
    ev.close()
    assert notes == []  # each left on its own: none was killed
    workers = league.queue.workers()
    assert len(workers) == 2 and all(w.stopped_at is not None and _gone(w.pid) for w in workers)

def _descendants(root: int) -> list[tuple[int, str | None]]:
    """Every process descended from ``root`` now, each with its start time (to end only those, later)."""
    return [(p.pid, p.start) for p in procs.descendants(root)]


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_a_trainer_killed_with_sigkill_takes_its_ray_actors_with_it(tmp_path):
    """kill -9 of a training process that started Ray itself: its rating actor (not detached: owned by the driver)
    ends with it within seconds, rather than play on for a run nobody trains."""
    home = tmp_path / "home"
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
    env.pop("RAY_ADDRESS", None)
    trainer = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *RUN[:-1], "--steps", "50000000", "--eval",
                                "ray", "--home", str(home), "--quiet"], env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    ray_processes: list[tuple[int, str | None]] = []
    try:
        deadline, workers = time.monotonic() + 90, []
        while time.monotonic() < deadline and not workers and trainer.poll() is None:
            time.sleep(0.5)
            with contextlib.suppress(LeagueError), League.open(home, readonly=True) as league:  # (none yet, or
                workers = [w for w in league.queue.workers() if w.name.startswith("ray@")]  # its tables being made)
        assert workers, trainer.stderr.read().decode()[-2000:] if trainer.poll() is not None else "no actor"
        ray_processes = _descendants(trainer.pid)
        assert workers[0].pid in {pid for pid, _ in ray_processes}
        trainer.send_signal(signal.SIGKILL)
        trainer.wait(timeout=10)
        assert _gone(workers[0].pid, within=20), "the rating actor plays on after its trainer was killed"
    finally:
        if trainer.poll() is None:
            trainer.kill()
            trainer.wait()
        trainer.stderr.close()
        for pid, start in ray_processes:  # what Ray itself leaves behind a killed driver (idle agents): ended here
            if same_process(pid, start):
                os.kill(pid, signal.SIGKILL)


def test_a_worker_told_to_stop_gives_its_job_in_play_back_and_leaves(rated_league):
    """``run_worker(stop=...)``: asked before each claim and at each game of the job in play; once true the worker
    leaves, the job back in the queue at once (its try not counted), the worker stopped."""
    league, snap = rated_league
    RemoteEvaluator(league, "w", "cpu").submit(GauntletJob((snap.id,), 0, 200, 0, full=True))
    asked = []

    def stop() -> bool:
        asked.append(len(league.queue.jobs(batch=run_batch("w"), states=["leased"])))
        return len(asked) > 3  # the claim, then two games of the job; the third game stops it

    report = run_worker(league, WorkerOptions(batches=(run_batch("w"),), poll=0.05, name="w1"), stop=stop)
    assert asked == [0, 1, 1, 1] and (report.done, report.failed, report.games) == (0, 0, 0)
    (job,) = league.queue.jobs(batch=run_batch("w"))
    assert (job.state, job.tries) == ("queued", 0)
    assert [(w.name, w.stopped_at is not None) for w in league.queue.workers()] == [("w1", True)]
    idle = threading.Event()
    idle.set()
    assert run_worker(league, WorkerOptions(name="w2"), stop=idle.is_set).done == 0  # stopped before any claim
    assert league.queue.jobs(batch=run_batch("w"))[0].state == "queued"


# -- the option -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("args", "needle"), [
    (["--eval", "ray", "--eval-actors", "0"], "--eval-actors must be at least 1, not 0"),
    (["--eval-actors", "2"], "--eval-actors is for --eval ray (queue workers on Ray actors), not --eval local"),
    (["--eval", "ray", "--no-wait"], "with --eval ray its Ray actors, which end with it, play every gauntlet"),
])
def test_bad_eval_actors_options_are_one_line_and_start_nothing(args, needle, home, capsys):
    code, out, err = run(capsys, "train", "pong", *args)
    assert code == 2 and needle in err and out == ""
    assert not (home / "runs").exists()


def test_eval_actors_is_checked_and_saved_with_the_run():
    """At least 1 (a config file is checked as the option is), and kept in the run's configuration."""
    from selfplay_cli.errors import MarlError

    cfg = TrainConfig(env="pong", eval="ray", eval_actors=3)
    assert TrainConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))).eval_actors == 3
    assert TrainConfig.from_dict({"env": "pong"}).eval_actors == 1  # a run saved before the setting
    with pytest.raises(MarlError, match="--eval-actors must be at least 1, not 0"):
        TrainConfig(env="pong", eval="ray", eval_actors=0)

