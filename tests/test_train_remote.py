"""`marl train --eval remote`: a run's gauntlets as jobs of the league's queue, played by `marl worker`s (here the
library's worker loop in a thread), by the run itself at its end when no worker is attached, or later, after a run
that did not wait (--no-wait); on SQLite and on a real PostgreSQL. The games are the local rating worker's, seed by
seed, whoever plays them and whenever."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from collections import Counter
from pathlib import Path

import pytest
from cli_helpers import run
from sqlalchemy import select, update

from selfplay_cli.cli import main
from selfplay_cli.commands.train_view import describe_queue
from selfplay_cli.errors import MarlError
from selfplay_cli.evaluation.executors.base import GauntletJob, QueueStanding
from selfplay_cli.evaluation.executors.queue_workers import RemoteEvaluator, run_batch
from selfplay_cli.evaluation.jobs import play_leased
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.league.models import Game, GameSeat, Job, Match, Player
from selfplay_cli.league.store import League
from selfplay_cli.train.config import TrainConfig

KILL_POINTS = Path(__file__).with_name("kill_points.py")
RUN = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps",
       "2048", "--steps", "4096", "--eval-games", "4", "--eval-playoff", "4", "--seed", "3", "--run", "r", "--quiet"]
"""Three snapshot moments (s0, s2.05k, s4.1k) of two learners: three gauntlets, the last in full with a playoff."""
BATCH = run_batch("r")


def _record(league: League) -> Counter:
    """Every rating game in the league: its seed, length, and each seat's player (by name) and points; a multiset."""
    out: Counter = Counter()
    with league.session(readonly=True) as s:
        names = dict(s.execute(select(Player.id, Player.name)).all())
        games = s.execute(select(Game.id, Game.seed, Game.length).join(Match, Match.id == Game.match_id)
                          .where(Match.kind == "eval")).all()
        seats: dict[int, list] = {}
        for gid, _seat, pid, points in s.execute(select(GameSeat.game_id, GameSeat.seat, GameSeat.player_id,
                                                       GameSeat.points).order_by(GameSeat.seat)):
            seats.setdefault(gid, []).append((names[pid], points))
    for gid, seed, length in games:
        out[(seed, length, tuple(seats[gid]))] += 1
    return out


@pytest.fixture(scope="module")
def local_record(tmp_path_factory) -> Counter:
    """The rating games of the run with the default rating worker (a process beside training)."""
    home = tmp_path_factory.mktemp("local")
    assert main([*RUN, "--home", str(home)]) == 0
    with League.open(home) as league:
        record = _record(league)
    assert sum(record.values()) > 50
    return record


def _train_json(capsys, db_url: str, home: Path, *extra: str) -> dict:
    code, out, err = run(capsys, *RUN, "--eval", "remote", "--db", db_url, "--home", str(home), "--json", *extra)
    assert code == 0, err
    return json.loads(out)


@pytest.mark.slow
def test_workers_play_a_runs_gauntlets_and_the_games_are_the_local_workers(db_url, tmp_path, capsys, local_record):
    """A worker attached to the league plays every gauntlet of the run (the run plays none itself), in the order the
    snapshots were taken, and the ledger ends with the very games the default local worker stores."""
    home = tmp_path / "home"
    worker_league = League(db_url, home=home)
    reports = []
    worker = threading.Thread(target=lambda: reports.append(run_worker(worker_league, WorkerOptions(
        batches=(BATCH,), max_jobs=3, poll=0.05, beat=1.0, name="w1"))), daemon=True)
    worker.start()
    try:
        data = _train_json(capsys, db_url, home)
        worker.join(timeout=120)
        assert not worker.is_alive(), "the worker did not get the run's three gauntlets"
    finally:
        worker_league.close()
    assert data["rating"] == "remote" and data["rating_batch"] == BATCH
    assert data["rating_jobs_left"] == 0 and data["best"] is not None
    assert reports[0].done == 3 and reports[0].failed == 0
    with League(db_url, home=home) as league:
        jobs = league.queue.jobs(batch=BATCH)
        assert [(j.kind, j.state, j.worker) for j in jobs] == [("gauntlet", "done", "w1")] * 3
        assert [j.spec["snapshots"] for j in jobs] == [["r/s0-left", "r/s0-right"], ["r/s2.05k-left",
                                                       "r/s2.05k-right"], ["r/s4.1k-left", "r/s4.1k-right"]]
        assert [j.after for j in jobs] == [None, jobs[0].id, jobs[1].id]  # each waited for the one before it
        assert [j.spec["full"] for j in jobs] == [False, False, True] and jobs[2].spec["playoff"] == 4
        assert _record(league) == local_record
        assert data["rating_games"] == sum(local_record.values())


@pytest.mark.slow
def test_the_final_wait_reports_each_gauntlet_as_it_finishes(tmp_path):
    """The run's three gauntlets, all owed at its end (no worker attached: the run plays them itself): each is
    reported (its snapshot event) as it finishes, while the wait goes on for the rest, and the wait's progress names
    only the snapshots still to be rated."""
    from selfplay_cli.train.loop import Trainer

    events: list[dict] = []
    cfg = TrainConfig(env="pong", run="r", steps=4096, games=16, snapshot_steps=2048, eval_games=4, eval_playoff=4,
                      seed=3, eval="remote", env_options={"points_to_win": 1})
    with League.open(tmp_path / "home") as league:
        league.roster.create_run("r", "pong", cfg.to_dict(), algo="ppo")
        report = Trainer(league, cfg, on_progress=events.append).train()
    assert report.rating_left == 0
    waiting = [i for i, e in enumerate(events) if e["event"] == "evaluating"]
    rated = [(i, tuple(r.name for r in e["records"])) for i, e in enumerate(events) if e["event"] == "snapshot"]
    assert [names for _, names in rated] == [("r/s0-left", "r/s0-right"), ("r/s2.05k-left", "r/s2.05k-right"),
                                             ("r/s4.1k-left", "r/s4.1k-right")]
    assert waiting and waiting[0] < rated[0][0]  # training had ended with all three owed
    assert [i for i, _ in rated[:2]] < [waiting[-1]] * 2  # the first two reported before the wait ended
    for i in waiting:  # the wait names what is still owed, no snapshot already reported
        done = {n for j, names in rated if j < i for n in names}
        assert events[i]["snapshots"] and not done & set(events[i]["snapshots"])
        assert events[i]["gauntlets"] == 3 - sum(j < i for j, _ in rated)


@pytest.mark.slow
def test_with_no_worker_attached_the_run_plays_its_gauntlets_itself(tmp_path, capsys, local_record):
    """No worker at all: the queued gauntlets are still played, by the run at its end (listed in the queue as the
    run's own process), with the same games."""
    home = tmp_path / "home"
    data = _train_json(capsys, f"sqlite:///{home / 'league.db'}", home)
    assert data["rating_jobs_left"] == 0 and data["best"] is not None
    with League.open(home) as league:
        jobs = league.queue.jobs(batch=BATCH)
        assert len(jobs) == 3 and {j.state for j in jobs} == {"done"}
        assert all(j.worker.startswith("train@") for j in jobs)
        assert _record(league) == local_record


@pytest.mark.slow
def test_no_wait_leaves_the_gauntlets_to_workers_and_the_ladder_fills_in_later(db_url, tmp_path, capsys,
                                                                                local_record):
    """--no-wait: the run ends with its three gauntlets queued (nothing rated, no best, said so); a worker that comes
    later plays them, in order, and the run's six snapshots are on the ladder, with the local worker's games."""
    home = tmp_path / "home"
    data = _train_json(capsys, db_url, home, "--no-wait")
    assert data["rating_jobs_left"] == 3 and data["best"] is None and data["rating_games"] == 0
    with League(db_url, home=home) as league:
        assert league.queue.job_counts(BATCH)["queued"] == 3
        assert _record(league) == Counter()
        report = run_worker(league, WorkerOptions(until_empty=True, poll=0.05, name="later"))
        assert (report.done, report.failed) == (3, 0)
        assert [j.worker for j in league.queue.jobs(batch=BATCH)] == ["later"] * 3
        assert _record(league) == local_record
    code, out, err = run(capsys, "league", "ladder", "--run", "r", "--db", db_url, "--home", str(home), "--json")
    assert code == 0, err
    rows = json.loads(out)
    rows = rows["rows"] if isinstance(rows, dict) else rows
    rated = {r["policy"] for r in rows if r.get("elo") is not None}
    assert {f"r/{n}-{side}" for n in ("s0", "s2.05k", "s4.1k") for side in ("left", "right")} <= rated


@pytest.mark.slow
def test_local_no_wait_ends_with_training_and_leaves_the_rest_to_workers(tmp_path, capsys, local_record):
    """The default rating worker with --no-wait: the run ends as its training does, the worker stopped in the middle
    of whatever it played; the gauntlets it had not finished are on the league's queue, in order, and a worker that
    comes later plays them: the ledger ends with the very games the run would have waited for (a matchup stored
    before the stop counts once)."""
    home = tmp_path / "home"
    code, out, err = run(capsys, *RUN, "--no-wait", "--home", str(home), "--json")
    assert code == 0, err
    data = json.loads(out)
    left = data["rating_jobs_left"]
    assert left >= 1 and data["best"] is None  # the final gauntlet, submitted as training ended, is among them
    assert data["rating"] == "local" and data["rating_batch"] == BATCH
    with League.open(home) as league:
        jobs = league.queue.jobs(batch=BATCH)
        assert [j.state for j in jobs] == ["queued"] * left
        assert jobs[-1].spec["snapshots"] == ["r/s4.1k-left", "r/s4.1k-right"] and jobs[-1].spec["playoff"] == 4
        report = run_worker(league, WorkerOptions(until_empty=True, poll=0.05, name="later"))
        assert (report.done, report.failed) == (left, 0)
        assert _record(league) == local_record


@pytest.mark.slow
def test_ctrl_c_in_the_final_wait_leaves_the_rest_to_workers_and_keeps_the_run(tmp_path, capsys, local_record,
                                                                               ctrl_c_in_the_wait):
    """Ctrl-C once training is over stops the wait, not the run: it ends as a --no-wait run does (exit 0, its
    training finished and kept, the gauntlets not played on the league's queue, said so), and a worker that comes
    later plays them: the very games the run would have waited for. (A real SIGINT to this process, sent from the
    wait's first progress call. The worker process plays on meanwhile: on a busy machine it may have every game in
    by then, and the run then ends as one that waited. The --eval remote test below interrupts before any.)"""
    sent = ctrl_c_in_the_wait
    home = tmp_path / "home"
    code, out, err = run(capsys, *RUN, "--home", str(home), "--json")
    assert sent and code == 0, err
    data = json.loads(out)
    left = data["rating_jobs_left"]
    assert (data["best"] is None) == (left > 0) and data["rating_batch"] == (BATCH if left else None)
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"
        jobs = league.queue.jobs(batch=BATCH)
        assert [j.state for j in jobs] == ["queued"] * left
        if left:
            assert jobs[-1].spec["snapshots"] == ["r/s4.1k-left", "r/s4.1k-right"]
            report = run_worker(league, WorkerOptions(until_empty=True, poll=0.05, name="later"))
            assert (report.done, report.failed) == (left, 0)
        assert _record(league) == local_record


@pytest.mark.slow
def test_ctrl_c_while_the_run_plays_its_queued_gauntlets_gives_the_job_back(tmp_path, capsys, local_record,
                                                                           ctrl_c_in_the_wait):
    """--eval remote with no worker attached: the run plays its queued gauntlets itself at its end; Ctrl-C there
    (at its first look at the batch, before it plays any) gives the job in play back to the queue at once and the
    run ends as with --no-wait; a worker that comes later plays them, and the ledger ends with the local worker's
    games."""
    sent = ctrl_c_in_the_wait
    home = tmp_path / "home"
    data = _train_json(capsys, f"sqlite:///{home / 'league.db'}", home)
    assert sent
    assert data["rating_jobs_left"] == 3 and data["best"] is None and data["rating"] == "remote"
    left = 3
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"
        jobs = league.queue.jobs(batch=BATCH)
        assert [j.state for j in jobs] == ["queued"] * 3  # (none left leased to the run's process)
        report = run_worker(league, WorkerOptions(until_empty=True, poll=0.05, name="later"))
        assert (report.done, report.failed) == (left, 0)
        assert _record(league) == local_record


@pytest.mark.slow
def test_no_wait_says_the_ratings_are_still_coming(tmp_path, capsys):
    home = tmp_path / "home"
    code, out, err = run(capsys, *RUN, "--eval", "remote", "--no-wait", "--home", str(home))
    assert code == 0, err
    assert "0 rating games so far, 3 gauntlets still queued (through the league's queue" in out
    assert "r/s4.1k-left: not rated yet (its gauntlet is queued)" in out
    assert "ratings still coming: 3 gauntlets of this run" in out
    assert f"marl queue --batch {BATCH}" in out and "marl league ladder --run r" in out
    assert "best of r" not in out  # the playoff, which names it, is not played yet
    assert "no plot written" not in out  # (nothing is rated yet: the lines above say why)


@pytest.mark.slow
def test_a_run_killed_and_resumed_queues_no_gauntlet_twice(tmp_path, capsys):
    """Killed as its second moment's rows are committed (its gauntlet not queued yet; the first one queued): the
    resumed run finds the first gauntlet in the queue and queues the second and the rest once each, in order."""
    home = tmp_path / "home"
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
    child = subprocess.run([sys.executable, str(KILL_POINTS), "after-rows", str(home), *RUN, "--eval", "remote"],
                           capture_output=True, text=True, timeout=600, env=env)
    assert child.returncode == -signal.SIGKILL, child.stderr[-2000:]
    with League.open(home) as league:
        before = league.queue.jobs(batch=BATCH)
    assert [j.spec["snapshots"] for j in before] == [["r/s0-left", "r/s0-right"]]
    code, out, err = run(capsys, "train", "--resume", "r", "--home", str(home), "--json")
    assert code == 0, err
    with League.open(home) as league:
        jobs = league.queue.jobs(batch=BATCH)
    names = [tuple(j.spec["snapshots"]) for j in jobs]
    assert jobs[0].id == before[0].id and len(names) == len(set(names)) == 3
    assert names[1] == ("r/s2.05k-left", "r/s2.05k-right")
    assert [j.after for j in jobs] == [None, jobs[0].id, jobs[1].id] and {j.state for j in jobs} == {"done"}


# -- the evaluator on its own (a snapshot, the scripted players) -------------------------------------------------------
def test_a_gauntlet_already_queued_is_not_queued_again(rated_league):
    """A resumed session submits the gauntlets its run state still owes: those already in the batch are found by
    their snapshot ids and waited for, a new one waits for the last of them."""
    league, snap = rated_league
    first = RemoteEvaluator(league, "w", "cpu")
    first.submit(GauntletJob((snap.id,), 0, 2, 0))
    (queued,) = league.queue.jobs(batch=run_batch("w"))
    again = RemoteEvaluator(league, "w", "cpu")
    again.submit(GauntletJob((snap.id,), 0, 2, 0))
    again.submit(GauntletJob((snap.id, snap.id), 100, 2, 0))
    jobs = league.queue.jobs(batch=run_batch("w"))
    assert [j.id for j in jobs[:1]] == [queued.id] and len(jobs) == 2 and jobs[1].after == queued.id
    assert again.poll() == [] and len(again.pending) == 2


def test_the_wait_shows_which_worker_plays_and_a_dead_job_is_one_error(rated_league):
    """While a worker holds the run's gauntlet the wait names it (and this process plays nothing); a job that ended
    dead is raised as its error, in one line that says where to look."""
    league, snap = rated_league
    ev = RemoteEvaluator(league, "w", "cpu", poll_seconds=0.05)
    ev.submit(GauntletJob((snap.id,), 0, 2, 0))
    assert ev.queue_standing() == QueueStanding(left=1, workers=(), here=False, attached=0)
    wid = league.queue.add_worker("w9", "elsewhere", 1)
    job = league.queue.claim(wid)
    assert ev.queue_standing() == QueueStanding(left=1, workers=("w9",), here=False, attached=1)
    assert describe_queue(ev.queue_standing(), 0) == "1 gauntlet left in the queue, played by w9"
    seen: list[QueueStanding] = []
    finisher = threading.Timer(0.3, lambda: play_leased(league, wid, job))
    finisher.start()
    handed: list = []  # the jobs the wait hands over as they finish, the rest returned at its end
    rest = ev.wait(on_wait=lambda done: (handed.extend(done), seen.append(ev.queue_standing())))
    finisher.join()
    (done,) = handed + rest
    # s0 against random and cpu (2 games each), and at the run's first moment the two bots against each other
    assert done.games == 6 and ev.pending == [] and ev.games_played == 0  # all of it played by the worker
    assert seen and seen[0].workers == ("w9",)
    ev.submit(GauntletJob((snap.id, snap.id), 100, 2, 0))
    (jid,) = [j.id for j in league.queue.jobs(batch=run_batch("w"), states=["queued"])]
    with league.session() as s:
        s.execute(update(Job).where(Job.id == jid).values(state="dead", tries=5,
                                                           error="MarlError: s0: snapshot file missing"))
    with pytest.raises(MarlError, match=f"job {jid} .* failed on each of its 5 tries: MarlError: s0: snapshot file "
                                        f"missing \\(marl queue --batch run:w shows it\\)"):
        ev.poll()


def test_a_cancelled_gauntlet_leaves_its_snapshots_unrated_in_one_line(rated_league):
    league, snap = rated_league
    notes: list[str] = []
    ev = RemoteEvaluator(league, "w", "cpu", note=notes.append)
    ev.submit(GauntletJob((snap.id,), 0, 2, 0))
    assert league.queue.cancel_jobs(batch=run_batch("w")) == 1
    (done,) = ev.wait()
    assert done.games == 0 and ev.pending == []
    assert notes == [f"job {league.queue.jobs(batch=run_batch('w'))[0].id} (the gauntlet of w/s0) was cancelled in the "
                     "queue: those snapshots stay unrated"]


# -- the option -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("args", "needle"), [
    (["--eval", "cloud"], "--eval must be one of local, inline, remote, ray, not 'cloud'"),
    (["--eval", "inline", "--no-wait"], "--no-wait is for --eval local or remote"),
    (["--eval", "remote", "--eval-inline"], "--eval-inline is --eval inline: it cannot go with --eval remote"),
])
def test_bad_eval_options_are_one_line_and_start_nothing(args, needle, home, capsys):
    code, out, err = run(capsys, "train", "pong", *args)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1 and out == ""
    assert not (home / "runs").exists()


def test_a_config_of_an_earlier_release_keeps_its_inline_rating():
    """Runs saved before --eval (and config files written for them) say ``eval_inline``: true is --eval inline."""
    assert TrainConfig.from_dict({"env": "pong", "eval_inline": True}).eval == "inline"
    assert TrainConfig.from_dict({"env": "pong", "eval_inline": False}).eval == "local"
    assert "eval_inline" not in TrainConfig(env="pong", eval="remote").to_dict()
    with pytest.raises(MarlError, match="cannot go with eval = \"remote\""):
        TrainConfig.from_dict({"env": "pong", "eval_inline": True, "eval": "remote"})


def test_the_wait_at_the_end_says_how_many_gauntlets_are_left_and_who_plays_them(monkeypatch):
    """Without a terminal, the wait's line every 30 s names the gauntlets left and the workers holding them, or says
    the run plays them itself; the bar's text says the same."""
    import io

    from rich.console import Console

    import selfplay_cli.commands.train_view as train_view
    from selfplay_cli.train.progress import Standing

    buf = io.StringIO()
    monkeypatch.setattr(train_view, "err_console", Console(file=buf, width=400))
    now = [100.0]
    progress = train_view.TrainProgress(TrainConfig(env="pong", run="r", steps=1000), bar=False, lines=True,
                                        clock=lambda: now[0])
    standing = Standing(progress=1.0, steps=1000, episodes=4, playing=16, game_steps=10.0, time_limit=None,
                        snapshots=6, rated=2, newest=(), session_steps=1000, steps_per_second=100.0, remaining=None,
                        ended=True)
    for t, queued in ((31.0, QueueStanding(left=2, workers=("w1", "w2"), here=False, attached=3)),
                      (62.0, QueueStanding(left=1, workers=(), here=True, attached=0)),
                      (93.0, QueueStanding(left=1, workers=(), here=False, attached=1))):
        now[0] = 100.0 + t
        progress.update({"event": "evaluating", "snapshots": ["r/s1k-left", "r/s1k-right"], "games": 40,
                         "queue": queued, "standing": standing})
    lines = buf.getvalue().splitlines()
    assert len(lines) == 3
    assert "rating s1k-left, s1k-right (2 gauntlets left in the queue, played by w1, w2)" in lines[0]
    assert "(1 gauntlet left in the queue, played here: no worker takes it (40 games so far))" in lines[1]
    assert "(1 gauntlet left in the queue, waiting for one of 1 worker)" in lines[2]


def test_a_resumed_run_takes_wait_or_no_wait_for_its_session(tmp_path):
    """Whether this session's end waits for the workers is the session's to say (--wait/--no-wait with --resume);
    who rates the run is the run's configuration, kept."""
    from selfplay_cli.train.needs import resumable
    from selfplay_cli.train.settings import resumed_config

    with League.open(tmp_path / "h") as league:
        for name, mode in (("a", "remote"), ("b", "inline")):
            league.roster.create_run(name, "pong", TrainConfig(env="pong", run=name, eval=mode).to_dict(), algo="ppo")
        assert resumed_config(league, resumable(league, "a"), {"resume", "eval_wait"}, wait=False).eval_wait is False
        assert resumed_config(league, resumable(league, "a"), {"resume"}).eval_wait is True
        with pytest.raises(MarlError, match="--no-wait is for --eval local or remote"):
            resumed_config(league, resumable(league, "b"), {"resume", "eval_wait"}, wait=False)
        with pytest.raises(MarlError, match="--eval cannot change it"):
            resumed_config(league, resumable(league, "a"), {"resume", "eval"})


def test_work_no_attached_worker_takes_is_played_by_the_run(rated_league):
    """A worker is attached (its heart beats) but never takes the run's gauntlet (busy with other work, or serving
    other batches): after ``untaken`` seconds the run's end plays it itself, and says so while it does."""
    from selfplay_cli.league.job_rows import NewJob

    league, snap = rated_league
    busy = league.queue.add_worker("busy", "elsewhere", 1)
    league.queue.enqueue("other", [NewJob(kind="games", env="pong", spec={})])
    assert league.queue.claim(busy, batches=["other"]) is not None  # busy with another batch's job
    ev = RemoteEvaluator(league, "w", "cpu", untaken=0.5, poll_seconds=0.05)
    ev.submit(GauntletJob((snap.id,), 0, 2, 0))
    seen: list[QueueStanding] = []

    handed: list = []

    def looked(done: list) -> None:
        handed.extend(done)
        league.queue.worker_beat(busy)
        seen.append(ev.queue_standing())

    out: list = []
    waiting = threading.Thread(target=lambda: out.append(ev.wait(on_wait=looked)), daemon=True)
    waiting.start()
    waiting.join(timeout=60)
    assert out, "the run waited on for a worker that never took its gauntlet"
    (done,) = handed + out[0]
    assert done.games == 6 and ev.games_played == 6  # s0 against each bot, and the bots against each other
    (job,) = league.queue.jobs(batch=run_batch("w"))
    assert job.state == "done" and job.worker.startswith("train@")
    assert seen[0] == QueueStanding(left=1, workers=(), here=False, attached=1)
    assert any(s.here for s in seen)


# -- a moment's matchups shared among the workers ---------------------------------------------------------------------
def _claim_matchup(league: League, worker: int):
    """The first ``matchup`` job this worker can lease, once the moment's worker has queued them (waited for by
    looking again, at most a minute)."""
    import time

    from selfplay_cli.evaluation.gauntlet_jobs import MATCHUP

    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        job = league.queue.claim(worker, kinds=[MATCHUP])
        if job is not None:
            return job
        time.sleep(0.02)
    raise AssertionError("the moment's worker queued no matchup")


def _seeds(league: League, match_id: int) -> list[int]:
    with league.session(readonly=True) as s:
        return sorted(s.execute(select(Game.seed).where(Game.match_id == match_id)).scalars())


@pytest.mark.slow
def test_a_moments_matchups_go_to_whoever_is_free(rated_league, tmp_path):
    """Issue 49: with --eval remote a moment's gauntlet was one job: one worker played it while the others sat idle.
    Now the worker that leases a moment queues its matchups as jobs of their own when another worker of the batch is
    free: the free one takes one, the moment's worker plays the rest and waits for it, and the moment ends with all
    of its games stored once, on the seeds and under the keys the whole moment plays them."""
    import shutil

    from selfplay_cli.evaluation.gauntlet_jobs import MATCHUP

    league, snap = rated_league
    ev = RemoteEvaluator(league, "w", "cpu")
    ev.submit(GauntletJob((snap.id,), 0, 2, 0))
    whole_home = tmp_path / "whole"
    shutil.copytree(league.home, whole_home)  # the same league, to play the moment whole for comparison
    mover = league.queue.add_worker("mover", "here", 1)
    free = league.queue.add_worker("free", "elsewhere", 2)  # attached, heart beating, holding nothing
    moment = league.queue.claim(mover, kinds=["gauntlet"])
    outcome: list = []
    playing = threading.Thread(target=lambda: outcome.append(play_leased(league, mover, moment)), daemon=True)
    playing.start()
    taken = _claim_matchup(league, free)
    assert taken.batch == run_batch("w") and taken.after is None  # not chained: whoever is free takes it
    assert play_leased(league, free, taken).state == "done"
    playing.join(timeout=120)
    assert outcome and outcome[0].state == "done", outcome
    jobs = league.queue.jobs(batch=run_batch("w"))
    matchups = [j for j in jobs if j.kind == MATCHUP]
    # s0 against random and cpu, and at the run's first moment the two bots against each other
    assert len(matchups) == 3 and {j.state for j in jobs} == {"done"}
    assert sorted(tuple(j.spec["snapshots"]) for j in matchups) == [("random", "cpu"), ("w/s0", "cpu"),
                                                                     ("w/s0", "random")]
    by = Counter(j.worker for j in matchups)
    assert by["free"] == 1 and sum(n for w, n in by.items() if w.startswith("gauntlet@")) == 2, by
    (done,) = ev.poll()
    assert done.games == 6  # the moment counts every game of its matchups, whoever played them
    split = league.ledger.keyed_matches("gauntlet/")
    with League.open(whole_home) as alone:  # the same moment played whole by one worker
        only = alone.queue.add_worker("only", "here", 3)
        job = alone.queue.claim(only, kinds=["gauntlet"])
        assert play_leased(alone, only, job).state == "done"
        assert [j.kind for j in alone.queue.jobs(batch=run_batch("w"))] == ["gauntlet"]  # nobody free: played whole
        whole = alone.ledger.keyed_matches("gauntlet/")
        seeds = {k: _seeds(alone, mid) for k, (mid, _) in whole.items()}
    assert set(split) == set(whole) and len(split) == 3  # the same matchups, stored once each, under the same keys
    assert {k: _seeds(league, mid) for k, (mid, _) in split.items()} == seeds


def test_a_moment_played_again_queues_none_of_its_matchups_twice(rated_league):
    """A moment's worker that died after queueing its matchups: the moment's next worker finds them queued (or
    stored) and queues nothing twice; a matchup spec a worker cannot play is refused, in one line."""
    from selfplay_cli.evaluation.gauntlet_jobs import _config, check_matchup_spec, queue_matchups
    from selfplay_cli.evaluation.gauntlet_plan import plan_moment
    from selfplay_cli.evaluation.job_spec import BadSpec

    league, snap = rated_league
    RemoteEvaluator(league, "w", "cpu").submit(GauntletJob((snap.id,), 0, 2, 0))
    first = league.queue.add_worker("first", "here", 1)
    job = league.queue.claim(first, kinds=["gauntlet"])
    cfg = _config(league, job.spec)

    def queued() -> list[int]:  # (each time planned anew, as a worker that takes the moment over plans it)
        return queue_matchups(league, job, plan_moment(league, job.spec["snapshot_ids"], cfg.older), cfg)

    ids = queued()
    assert len(ids) == 3 and queued() == ids
    one = league.queue.claim(first, kinds=["matchup"])
    assert play_leased(league, first, one).state == "done"
    assert sorted(queued()) == sorted(i for i in ids if i != one.id)  # stored: not again
    spec = dict(one.spec)
    check_matchup_spec(spec)
    for key, bad, needle in (("precision", 1.5, "precision must be a number from 0 up to"),
                             ("a", "evilmod:env", "a must be a whole number"),
                             ("snapshot_ids", [], "snapshot_ids must be a list of 1 to")):
        with pytest.raises(BadSpec, match=needle):
            check_matchup_spec({**spec, key: bad})
