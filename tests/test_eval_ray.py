"""`marl train --eval ray`: a run's gauntlets played by queue workers on Ray actors started for the run (the league's
queue as --eval remote uses it): the games are --eval remote's, the actors are listed as the league's workers
(``ray@host:pid``), and they stop when the run's gauntlets are done or the run ends, a job in play given back to the
queue (the worker loop's ``stop()``). Ray itself is the suite's (the ``ray_local`` fixture), as a run finds it."""

from __future__ import annotations

import json
import threading
import time
from collections import Counter

import pytest
from cli_helpers import run
from sqlalchemy import select

from selfplay_cli.files import pid_alive
from selfplay_cli.league.models import Game, GameSeat, Match, Player
from selfplay_cli.league.store import League
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.evaluator import GauntletJob
from selfplay_cli.train.remote import RemoteEvaluator, run_batch
from selfplay_cli.work import WorkerOptions, run_worker

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
def test_a_run_that_ends_mid_gauntlet_gives_its_actors_job_back_at_once(ray_local, rated_league):
    """The run ends (Ctrl-C, an error) while its actor plays a long gauntlet: the actor's loop is told to stop, gives
    the job back to the queue at once (not counted as a try) and leaves, its worker row stopped, its process gone:
    nothing plays on after the run, and a resumed run's workers take the job at once."""
    from selfplay_cli.train.ray_eval import RayEvaluator

    league, snap = rated_league
    notes: list[str] = []
    ev = RayEvaluator(league, "w", "cpu", actors=1, note=notes.append)
    try:
        ev.submit(GauntletJob((snap.id,), 0, 2000, 0, full=True))  # minutes of games: still in play when stopped
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not league.jobs(batch=run_batch("w"), states=["leased"]):
            time.sleep(0.1)
        (job,) = league.jobs(batch=run_batch("w"))
        assert job.state == "leased" and job.worker.startswith("ray@")
        time.sleep(0.5)  # (games under way)
    finally:
        t0 = time.monotonic()
        ev.close()
        took = time.monotonic() - t0
    (job,) = league.jobs(batch=run_batch("w"))
    assert (job.state, job.tries) == ("queued", 0)
    (worker,) = league.workers()
    assert worker.stopped_at is not None and worker.holding == ()
    assert took < 10 and notes == []  # it left by itself: not killed
    assert _gone(worker.pid)


def test_a_worker_told_to_stop_gives_its_job_in_play_back_and_leaves(rated_league):
    """``run_worker(stop=...)``: asked before each claim and at each game of the job in play; once true the worker
    leaves, the job back in the queue at once (its try not counted), the worker stopped."""
    league, snap = rated_league
    RemoteEvaluator(league, "w", "cpu").submit(GauntletJob((snap.id,), 0, 200, 0, full=True))
    asked = []

    def stop() -> bool:
        asked.append(len(league.jobs(batch=run_batch("w"), states=["leased"])))
        return len(asked) > 3  # the claim, then two games of the job; the third game stops it

    report = run_worker(league, WorkerOptions(batches=(run_batch("w"),), poll=0.05, name="w1"), stop=stop)
    assert asked == [0, 1, 1, 1] and (report.done, report.failed, report.games) == (0, 0, 0)
    (job,) = league.jobs(batch=run_batch("w"))
    assert (job.state, job.tries) == ("queued", 0)
    assert [(w.name, w.stopped_at is not None) for w in league.workers()] == [("w1", True)]
    idle = threading.Event()
    idle.set()
    assert run_worker(league, WorkerOptions(name="w2"), stop=idle.is_set).done == 0  # stopped before any claim
    assert league.jobs(batch=run_batch("w"))[0].state == "queued"


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

