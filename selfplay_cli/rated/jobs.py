"""Rating work on the league's queue (:mod:`selfplay_cli.league.queue`): playing a job of any kind, a leased one with
its heart beating, and seeing a queued batch through.

The kinds of job are :mod:`.games_jobs` (a few minutes of one match) and :mod:`.gauntlet_jobs` (a training run's
gauntlet of one snapshot moment); :data:`KINDS` finds each one's player. :func:`play_leased` plays one leased job
while a thread beats its heart, then finishes it (or fails it, with the error's first line, to be tried again after a
backoff). The worker (:mod:`selfplay_cli.work`) and :func:`see_through` both use it: a command that queued a batch
plays the batch's jobs that no worker has taken, and waits for those that workers play, so queued work is done even
with no worker attached.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..envs import UnknownEnvError
from ..errors import MarlError
from ..league.queue import BEAT_SECONDS, ENDED, SCAVENGE_SECONDS, JobRow
from ..league.store import League
from ..stats.sprt import LEVELS, categories, count_model
from . import games_jobs, gauntlet_jobs
from .played import Played

__all__ = ["KINDS", "JobLost", "Outcome", "play_job", "play_leased", "see_through", "sprt_verdict", "worker_name"]

KINDS: dict[str, Callable[..., Played]] = {games_jobs.GAMES: games_jobs.play,
                                           gauntlet_jobs.GAUNTLET: gauntlet_jobs.play}
"""The player of each kind of job: ``player(league, job, device=, parallel=, on_games=) -> Played``."""


class JobLost(Exception):
    """The job in play is no longer this worker's (cancelled, or taken over after its lease lapsed)."""


def worker_name(role: str = "worker") -> str:
    """``role@host:pid``: how a worker is listed."""
    return f"{role}@{socket.gethostname()}:{os.getpid()}"


def play_job(league: League, job: JobRow, *, device: str = "cpu", parallel: int = 1024,
             on_games: Callable[[int], None] | None = None) -> Played:
    """Play ``job`` in this process (nothing stored) by the player of its kind (:data:`KINDS`)."""
    player = KINDS.get(job.kind)
    if player is None:
        raise MarlError(f"job {job.id} is of kind {job.kind!r}, which this marl does not play: upgrade marl")
    return player(league, job, device=device, parallel=parallel, on_games=on_games)


class _Heart:
    """A thread that beats a worker's heart on the job it plays every ``beat`` seconds; ``lost`` is set when the job
    is no longer the worker's."""

    def __init__(self, league: League, worker_id: int, job_id: int, beat: float) -> None:
        self.league, self.worker_id, self.job_id, self.beat = league, worker_id, job_id, beat
        self.lost = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"heart-{job_id}", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.beat):
            try:
                if not self.league.worker_beat(self.worker_id, self.job_id):
                    self.lost.set()
                    return
            except Exception:  # the database away for a moment: the next beat tries again (the lease lapses late)
                continue

    def __enter__(self) -> _Heart:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


@dataclass
class Outcome:
    """What became of one leased job: ``done`` (stored now), ``counted`` (finished before by another: not stored
    again), ``lost`` (cancelled or taken over while in play), or ``failed`` (with ``error``)."""

    job: JobRow
    state: str
    games: int = 0
    seconds: float = 0.0
    error: str | None = None
    error_kind: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def play_leased(league: League, worker_id: int, job: JobRow, *, beat: float = BEAT_SECONDS, device: str = "cpu",
                parallel: int = 1024, on_games: Callable[[int], None] | None = None,
                base_backoff: float | None = None, retry: Callable[[Callable[[], Any]], Any] = lambda fn: fn()
                ) -> Outcome:
    """Play a job this worker leased while its heart beats, then store it (:meth:`League.finish_job`), or put it back
    as failed with its error's first line; ``retry`` runs each write (a worker tries again while the database is
    away, so games played are not played again). A :class:`KeyboardInterrupt` (Ctrl-C, SIGTERM) propagates: the
    caller gives the job back."""
    from ..errors import MarlIOError

    with _Heart(league, worker_id, job.id, beat) as heart:
        def counted(n: int) -> None:
            if heart.lost.is_set():
                raise JobLost
            if on_games is not None:
                on_games(n)

        try:
            played = play_job(league, job, device=device, parallel=parallel, on_games=counted)
        except JobLost:
            return Outcome(job, "lost")
        except (MarlError, OSError, ValueError, RuntimeError, UnknownEnvError) as exc:
            # (UnknownEnvError: a game this machine does not have or will not import, e.g. a job naming a module
            # nobody here named: the job's failure, not the worker's)
            kind = "io" if isinstance(exc, MarlIOError | OSError) else "usage" if isinstance(exc, MarlError | \
                UnknownEnvError) else "internal"
            line = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            kwargs = {} if base_backoff is None else {"base_backoff": base_backoff}
            error = f"{type(exc).__name__}: {line}"
            state = retry(lambda: league.fail_job(job.id, worker_id, error, **kwargs))
            return Outcome(job, "failed", error=line, error_kind=kind, extra={"state": state})
    stored = retry(lambda: league.finish_job(job.id, worker_id, games=played.games, match_kind=played.match_kind,
                                             params=played.params, result=played.result, seconds=played.seconds,
                                             played=played.count))
    return Outcome(job, "done" if stored else "counted", games=played.count, seconds=played.seconds)


def see_through(league: League, batch: str, *, device: str = "cpu", parallel: int = 1024, play: bool = True,
                beat: float = BEAT_SECONDS, scavenge: float = SCAVENGE_SECONDS, poll: float = 0.5,
                on_games: Callable[[int], None] | None = None,
                on_change: Callable[[list[JobRow]], bool] | None = None, role: str = "marl") -> list[JobRow]:
    """See a queued batch through: play its jobs that no worker has taken (``play``), wait for those that workers
    play, until every job has ended; the batch's jobs then. ``on_change(jobs)`` is called at every look at the batch
    (before each job this process plays, and each ``poll`` seconds while it waits: a progress display follows it);
    when it returns True the batch's remaining jobs are cancelled (a decided SPRT) and this returns. Ctrl-C gives a
    job in play back to the queue."""
    worker_id = league.add_worker(worker_name(role), socket.gethostname(), os.getpid(), serves=[batch]) if play \
        else None
    try:
        while True:
            jobs = league.jobs(batch=batch)
            if on_change is not None and on_change(jobs):
                league.cancel_jobs(batch=batch)
                return league.jobs(batch=batch)
            if all(j.state in ENDED for j in jobs):
                return jobs
            job = league.claim(worker_id, batches=[batch], scavenge=scavenge) if worker_id is not None else None
            if job is None:
                time.sleep(poll)
                if worker_id is not None:
                    league.worker_beat(worker_id)
                continue
            play_leased(league, worker_id, job, beat=beat, device=device, parallel=parallel,  # type: ignore[arg-type]
                        on_games=on_games)
    finally:
        if worker_id is not None:
            league.stop_worker(worker_id)


def sprt_verdict(jobs: Sequence[JobRow], test: Any, paired: bool) -> tuple[float, str | None, int]:
    """The SPRT over the done jobs' rounds in order, up to the first job not done: the LLR, the decision (None while
    undecided) and the rounds it counted. Rounds are checked one by one, so the decision falls where a single
    match playing them in order would have stopped."""
    rounds: list[list[float]] = []
    for j in sorted(jobs, key=lambda j: int(j.spec.get("round", 0))):
        if j.state != "done" or not j.result:
            break
        rounds += j.result["round_points"]
    llr, decision, n = 0.0, None, 0
    model = count_model(rounds, paired)
    counts = [0] * {"categorical": LEVELS, "pentanomial": 5, "trinomial": 3}[model]
    for pts in rounds:
        n += 1
        for k in categories(pts, model):
            counts[k] += 1
        llr = test.llr(counts, model)
        decision = test.decide(llr)
        if decision is not None:
            break
    return llr, decision, n
