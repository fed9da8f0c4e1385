"""The work queue (league/queue.py) and the jobs it holds (rated/jobs.py), on SQLite and on a real PostgreSQL."""

from __future__ import annotations

import threading

import pytest
from sqlalchemy import func, select

from selfplay_cli.evaluation.games_jobs import GAMES, combine, games_jobs
from selfplay_cli.evaluation.jobs import play_job, play_leased, see_through
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.league.job_rows import NewJob, backoff
from selfplay_cli.league.models import Game, Match
from selfplay_cli.league.store import League

SHORT = {"points_to_win": 1}


@pytest.fixture
def league(db_url, tmp_path):
    lg = League(db_url, home=tmp_path / "home")
    lg.roster.ensure_bots("pong", ["random", "cpu"])
    yield lg
    lg.close()


def _bots(league):
    return league.roster.find_players("cpu", env="pong")[0], league.roster.find_players("random", env="pong")[0]


def _games(league) -> int:
    with league.session(readonly=True) as s:
        return int(s.execute(select(func.count()).select_from(Game)).scalar_one())


def _queue_match(league, games=40, job_rounds=4, batch="m1", first_seed=100):
    a, b = _bots(league)
    jobs = games_jobs(league, [a], b, games=games, first_seed=first_seed, match_kind="match", env_options=SHORT,
                      job_rounds=job_rounds)
    return league.queue.enqueue(batch, jobs)


def test_a_match_cut_into_jobs_plays_the_seeds_of_the_whole_match(league):
    """40 games of pong (20 seat-swapped pairs) in jobs of 4 rounds: 5 jobs on seeds 100..119, each seed twice; every
    job's games stored under its key in one match; the combined report is the one match's."""
    ids = _queue_match(league)
    assert len(ids) == 5
    jobs = league.queue.jobs(batch="m1")
    assert [j.spec["first_seed"] for j in jobs] == [100, 104, 108, 112, 116]
    assert all(j.spec["rounds"] == 4 and j.state == "queued" for j in jobs)
    report = run_worker(league, WorkerOptions(until_empty=True, poll=0.01))
    assert (report.done, report.failed, report.games) == (5, 0, 40)
    jobs = league.queue.jobs(batch="m1")
    assert {j.state for j in jobs} == {"done"}
    with league.session(readonly=True) as s:
        keys = sorted(s.execute(select(Match.work_key).where(Match.work_key.like("job:%"))).scalars())
        seeds = sorted(s.execute(select(Game.seed)).scalars())
        lengths = sum(s.execute(select(Game.length)).scalars())
    assert keys == sorted(f"job:{i}" for i in ids)
    assert seeds == sorted(list(range(100, 120)) * 2)
    merged = combine(jobs)
    assert merged is not None and merged.games == 40 and len(merged.round_points) == 20
    assert merged.wins + merged.draws + merged.losses == 40
    assert sum(merged.pentanomial) == 20
    assert merged.step_limit == 18_000  # pong's own limit, which `marl match --queue` states beside its truncated games
    # The same games as one local match on the same seeds (scripted players: the seeds decide everything).
    from selfplay_cli.evaluation.match import run_match
    from selfplay_cli.policies import ScriptedPolicy

    local = run_match(ScriptedPolicy("pong", "cpu", seed=0), ScriptedPolicy("pong", "random", seed=0), games=40,
                      first_seed=100, env_options=SHORT)
    assert local.round_points != [] and len(local.round_points) == len(merged.round_points)
    assert merged.game_steps == lengths > 40  # the jobs' steps, summed from their rows: the games' stored lengths


class _Clock:
    """The queue's clock, stopped: it moves when the test moves it (no sleeping, no race with a slow machine)."""

    def __init__(self) -> None:
        from selfplay_cli.league.models import utcnow

        self.now = utcnow()

    def __call__(self):
        return self.now

    def advance(self, seconds: float) -> None:
        from datetime import timedelta

        self.now += timedelta(seconds=seconds)


def _clock(league) -> _Clock:
    league.queue.clock = clock = _Clock()
    return clock


def test_a_job_finished_twice_counts_once(league):
    """Worker A's lease lapses, B takes the job over and stores it; A comes back and finishes too: nothing more is
    stored, and A learns it lost the job at its next heartbeat."""
    (jid,) = _queue_match(league, games=8, job_rounds=4)
    clock = _clock(league)
    wa, wb = league.queue.add_worker("a", "h", 1), league.queue.add_worker("b", "h", 2)
    ja = league.queue.claim(wa)
    assert ja is not None and ja.id == jid and ja.tries == 1
    assert league.queue.claim(wb) is None  # leased and alive: not for B
    clock.advance(0.19)
    assert league.queue.claim(wb, scavenge=0.2) is None  # A silent for 0.19 s < 0.2 s: still A's
    clock.advance(0.11)
    jb = league.queue.claim(wb, scavenge=0.2)  # A silent for 0.3 s > 0.2 s: the lease lapsed
    assert jb is not None and jb.id == jid and jb.tries == 2 and jb.worker == "b"
    assert league.queue.worker_beat(wa, jid) is False and league.queue.worker_beat(wb, jid) is True
    played = play_job(league, jb)
    assert league.queue.finish_job(jid, wb, games=played.games, match_kind="match", params=played.params,
                                   result=played.result, seconds=played.seconds)
    assert _games(league) == 8
    again = play_job(league, ja)
    assert again.games == played.games  # the same job plays the same games, whoever plays it
    assert not league.queue.finish_job(jid, wa, games=again.games, match_kind="match", params=again.params,
                                       result=again.result)
    assert _games(league) == 8
    (w_b,) = [w for w in league.queue.workers() if w.name == "b"]
    assert (w_b.jobs_done, w_b.games) == (1, 8)


def test_a_failing_job_backs_off_then_dies_with_its_error(league):
    a, b = _bots(league)
    (jid,) = league.queue.enqueue("bad", [NewJob(GAMES, "pong", {"a": [a.id], "b": 999_999, "rounds": 1,
                                                                 "first_seed": 0,
                                                                 "match_kind": "match"}, max_tries=2)])
    clock = _clock(league)
    w = league.queue.add_worker("w", "h", 1)
    job = league.queue.claim(w)
    out = play_leased(league, w, job, base_backoff=0.2)
    assert out.state == "failed" and "999999" in (out.error or "")
    (row,) = league.queue.jobs(ids=[jid])
    assert row.state == "queued" and row.not_before is not None and row.error
    assert league.queue.claim(w) is None  # waiting out its backoff
    clock.advance(0.19)
    assert league.queue.claim(w) is None  # (0.2 s)
    clock.advance(0.02)
    job = league.queue.claim(w)
    assert job is not None and job.tries == 2
    out = play_leased(league, w, job, base_backoff=0.2)
    (row,) = league.queue.jobs(ids=[jid])
    assert row.state == "dead" and "999999" in row.error and row.tries == 2
    assert league.queue.claim(w) is None
    assert [backoff(t) for t in (1, 2, 3, 10)] == [10.0, 20.0, 40.0, 600.0]


def test_silent_workers_kill_a_job_after_its_tries(league):
    a, b = _bots(league)
    (jid,) = league.queue.enqueue("x", [NewJob(GAMES, "pong", {"a": [a.id], "b": b.id, "rounds": 1, "first_seed": 0,
                                                               "match_kind": "match"}, max_tries=1)])
    clock = _clock(league)
    w = league.queue.add_worker("w", "h", 1)
    assert league.queue.claim(w).id == jid
    clock.advance(0.15)
    assert league.queue.claim(w, scavenge=0.1) is None
    (row,) = league.queue.jobs(ids=[jid])
    assert row.state == "dead" and "silent" in row.error


def test_jobs_wait_for_the_job_they_come_after(league):
    a, b = _bots(league)
    spec = {"a": [a.id], "b": b.id, "rounds": 1, "first_seed": 0, "match_kind": "match"}
    first, second = league.queue.enqueue("chain", [NewJob(GAMES, "pong", spec), NewJob(GAMES, "pong", spec)],
                                         chain=True)
    w1, w2 = league.queue.add_worker("1", "h", 1), league.queue.add_worker("2", "h", 2)
    assert league.queue.claim(w1).id == first
    assert league.queue.claim(w2) is None  # the second waits for the first
    league.queue.cancel_jobs(ids=[first])
    assert league.queue.claim(w2).id == second  # an ended job (cancelled too) releases the next


def test_cancel_stops_a_job_in_play_and_stores_nothing(league):
    (jid,) = _queue_match(league, games=8, job_rounds=4)
    w = league.queue.add_worker("w", "h", 1)
    job = league.queue.claim(w)
    assert league.queue.cancel_jobs(batch="m1") == 1
    assert league.queue.worker_beat(w, jid) is False
    played = play_job(league, job)
    assert not league.queue.finish_job(jid, w, games=played.games, match_kind="match", params=played.params)
    assert _games(league) == 0 and league.queue.job_counts("m1")["cancelled"] == 1


def test_a_stopped_worker_gives_its_job_back_untried(league):
    (jid,) = _queue_match(league, games=8, job_rounds=4)
    w = league.queue.add_worker("w", "h", 1)
    assert league.queue.claim(w).tries == 1
    league.queue.stop_worker(w)
    (row,) = league.queue.jobs(ids=[jid])
    assert (row.state, row.tries) == ("queued", 0)


def test_the_command_that_queued_a_batch_plays_it_with_the_workers(league, db_url):
    """see_through plays the jobs no worker takes; a worker (another League, a thread) plays the others; every job
    is played once."""
    _queue_match(league, games=64, job_rounds=2, batch="t")  # 16 jobs
    other = League(db_url, home=league.home)
    stop = threading.Event()
    helper = threading.Thread(target=lambda: run_worker(other, WorkerOptions(batches=("t",), until_empty=True,
                                                                             poll=0.01, name="helper")))
    helper.start()
    jobs = see_through(league, "t", poll=0.01)
    helper.join(timeout=60)
    stop.set()
    other.close()
    assert {j.state for j in jobs} == {"done"} and len(jobs) == 16
    assert _games(league) == 64
    by = {j.worker for j in jobs}
    assert by <= {"helper"} | {j.worker for j in jobs if j.worker and j.worker.startswith("marl@")}
