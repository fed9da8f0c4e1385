"""The worker loop: lease a job, play it while a heart beats, store it, again; wait (backing off) when the queue is
empty, and keep going through a database that went away for a while.

A job that fails, for whatever reason (a bot this marl does not know, a spec its kind refuses, an error of any kind in
its play), is that job's failure: it counts a try (a refused spec ends it at once) and the worker takes the next.

Stopping: Ctrl-C or SIGTERM gives the job in play back to the queue at once (it is not counted as a try) and the
worker leaves (exit 130 or 143), and so does ``stop()`` turning true (a worker run by another program: ``marl train
--eval ray``'s actors, :mod:`selfplay_cli.evaluation.executors.ray_actors`); SIGKILL leaves the job leased until its
lease lapses (``scavenge``), when another worker takes it. A database that cannot be reached stops nothing: the worker
says so once and tries again with a growing wait; games played while it was away are stored when it is back (the job's
key keeps them from counting twice if another worker took the job meanwhile).

A worker that starts while its database cannot be reached (:func:`reach_league`) waits for it the same way, said
once, but for a bounded time: a worker started with its database server (a machine booting, a service restarted)
goes to work when the server is up; one given a server that never comes leaves with one line (exit 4).
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import MarlIOError
from ..league.job_rows import BACKOFF_SECONDS, BEAT_SECONDS, REACH_SECONDS, SCAVENGE_SECONDS, JobRow
from ..league.store import League, LeagueUnreachable
from .jobs import Outcome, play_leased, worker_name

__all__ = ["Leaving", "WorkerOptions", "WorkerReport", "reach_league", "run_worker"]

_IDLE_MAX = 2.0  # the longest wait between two looks at an empty queue (a claim is one cheap query)
_AWAY_FIRST = 1.0  # the first wait before another try of a database that cannot be reached (doubling each time)
_AWAY_MAX = 30.0  # the longest wait between two tries of a database that cannot be reached


@dataclass(frozen=True)
class WorkerOptions:
    """How a worker works: which batches (None: all), how many jobs before it leaves (None: no limit), whether it
    leaves when the queue is empty (``until_empty``), its heartbeat and the lease it lets lapse, where networks run,
    the first wait of a job that failed before it is tried again (``backoff``, doubling with each failure)."""

    batches: tuple[str, ...] | None = None
    max_jobs: int | None = None
    until_empty: bool = False
    beat: float = BEAT_SECONDS
    scavenge: float = SCAVENGE_SECONDS
    device: str = "cpu"
    parallel: int = 1024
    name: str | None = None
    poll: float = 1.0
    backoff: float = BACKOFF_SECONDS


class _Stopped(BaseException):
    """``stop()`` said so while a job was in play: raised from its games' reports, past the job's own error handling
    (as Ctrl-C is), to the worker loop, which gives the job back."""


@dataclass
class WorkerReport:
    """What a worker did: jobs done (stored by it), counted (finished by another first), failed, lost; games."""

    worker_id: int
    name: str
    done: int = 0
    counted: int = 0
    failed: int = 0
    lost: int = 0
    games: int = 0
    seconds: float = 0.0
    outcomes: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"worker_id": self.worker_id, "name": self.name, "done": self.done, "counted": self.counted,
                "failed": self.failed, "lost": self.lost, "games": self.games, "seconds": round(self.seconds, 3),
                "games_per_second": round(self.games / self.seconds, 2) if self.seconds > 0 else None,
                "jobs": self.outcomes}


@dataclass(frozen=True)
class Leaving:
    """How a worker left: the job it had in play (None: it was idle) and the jobs the league took back from it
    (None: the league could not be reached; their leases lapse instead)."""

    in_play: JobRow | None
    given_back: tuple[int, ...] | None

    def describe(self) -> str:
        """What became of the job in play, in words (``no job was in play`` when idle)."""
        if self.in_play is None:
            return "no job was in play"
        j = self.in_play
        what = f"job {j.id} ({j.batch}, {j.kind})"
        if self.given_back is None:
            return (f"{what} was in play; the league could not be reached: it goes back to the queue when its lease "
                    "lapses")
        if j.id in self.given_back:
            return f"{what}, in play, went back to the queue"
        return f"{what} was in play but no longer leased to this worker (cancelled or taken over): nothing given back"


def _retrying(fn: Callable[[], Any], say: Callable[[str], None], what: str) -> Any:
    """``fn()``, tried again with a growing wait while the database cannot be reached (said once)."""
    wait, said = _AWAY_FIRST, False
    while True:
        try:
            return fn()
        except MarlIOError as exc:
            if not said:
                say(f"{what}: {exc}; trying again until it is back")
                said = True
            time.sleep(wait)
            wait = min(wait * 2, _AWAY_MAX)


def reach_league(open_league: Callable[[], League], say: Callable[[str], None], wait_for: float = REACH_SECONDS, *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> League:
    """``open_league()`` at a worker's start, tried again while its database server cannot be reached
    (:class:`~selfplay_cli.league.store.LeagueUnreachable`) with a running worker's growing wait (1 s, doubling, at
    most 30 s), for up to ``wait_for`` seconds by ``clock`` (said once through ``say``); after that, one
    :class:`LeagueUnreachable` (exit 4). Anything else (a refused user, a missing driver, a full disk) is raised at
    once: waiting cures none of them. ``clock`` and ``sleep`` are what a test replaces."""
    wait, deadline = _AWAY_FIRST, None
    while True:
        try:
            return open_league()
        except LeagueUnreachable as exc:
            if wait_for <= 0:
                raise
            now = clock()
            if deadline is None:
                deadline = now + wait_for
                say(f"league database {exc.where} unreachable, retrying for up to {wait_for:g} s ({exc.reason})")
            if now >= deadline:
                raise LeagueUnreachable(f"league database {exc.where} unreachable for {wait_for:g} s at the worker's "
                                        f"start (--wait-db): {exc.reason}", exc.where, exc.reason) from None
            sleep(min(wait, deadline - now))
            wait = min(wait * 2, _AWAY_MAX)


def run_worker(league: League, options: WorkerOptions, *, say: Callable[[str], None] = lambda _: None,
               on_job: Callable[[Outcome], None] | None = None,
               on_games: Callable[[int], None] | None = None,
               stop: Callable[[], bool] | None = None,
               on_leave: Callable[[Leaving], None] | None = None) -> WorkerReport:
    """Work the queue of ``league`` as ``options`` say (see the module docstring); what was done. ``stop()`` is asked
    before each claim, at each look at an empty queue and at each game report of the job in play: once it is true
    the worker leaves, the job in play given back to the queue at once. ``on_leave`` is told how it left, however
    it left (Ctrl-C and SIGTERM too, before they go on): the job in play, if any, and what was given back."""
    stopped = stop or (lambda: False)

    def counted(n: int) -> None:
        if stopped():
            raise _Stopped
        if on_games is not None:
            on_games(n)

    name = options.name or worker_name()
    wid = _retrying(lambda: league.queue.add_worker(name, socket.gethostname(), os.getpid(), serves=options.batches),
                    say,
                    "league unreachable")
    report = WorkerReport(wid, name)
    idle = options.poll
    job: JobRow | None = None
    try:
        while (options.max_jobs is None or report.done + report.counted + report.failed < options.max_jobs) \
                and not stopped():
            job = _retrying(lambda: league.queue.claim(wid, batches=options.batches, scavenge=options.scavenge), say,
                            "league unreachable")
            if job is None:
                if options.until_empty and not _retrying(lambda: _open_work(league, options), say,
                                                          "league unreachable"):
                    break
                time.sleep(idle)
                idle = min(idle * 1.5, _IDLE_MAX)
                _retrying(lambda: league.queue.worker_beat(wid), say, "league unreachable")
                continue
            idle = options.poll
            try:
                out = play_leased(league, wid, job, beat=options.beat, device=options.device,
                                  parallel=options.parallel, on_games=counted, base_backoff=options.backoff,
                                  retry=lambda fn: _retrying(fn, say, "league unreachable"))
            except _Stopped:
                break
            job = None
            _count(report, out)
            if on_job is not None:
                on_job(out)
    finally:  # Ctrl-C, SIGTERM, an error: the job in play goes back to the queue now, not when its lease lapses
        back: tuple[int, ...] | None = None
        with contextlib.suppress(Exception):  # (the database away: the lease lapses instead)
            back = league.queue.stop_worker(wid, give_back=True)
        if on_leave is not None:
            on_leave(Leaving(job, back))
    return report


def _open_work(league: League, options: WorkerOptions) -> bool:
    """Whether the batches this worker serves still have jobs not ended (queued, waiting, or leased by others)."""
    return any(counts["queued"] + counts["leased"] > 0 for batch, counts in league.queue.batches()
               if options.batches is None or batch in options.batches)


def _count(report: WorkerReport, out: Outcome) -> None:
    if out.state == "done":
        report.done += 1
        report.games += out.games
        report.seconds += out.seconds
    elif out.state == "counted":
        report.counted += 1
    elif out.state == "failed":
        report.failed += 1
    else:
        report.lost += 1
    report.outcomes.append({"job": out.job.id, "batch": out.job.batch, "state": out.state, "games": out.games,
                            "seconds": round(out.seconds, 3), "error": out.error})
