"""Rating games beside training: the gauntlet of each snapshot moment, played while the learners train on.

Training keeps the main process busy (acting and stepping the games on one core, the learners' updates on both);
the gauntlets (:func:`selfplay_cli.evaluation.gauntlet.rate_snapshots`) are played by one worker process of their own,
in the order the snapshots were taken, so the run does not stop for them and their results do not depend on
timing: the worker plays job after job, and each job picks the run's best from the games of the jobs before it,
exactly as an inline evaluation would. The worker writes the ledger itself (SQLite in WAL mode takes both writers);
the trainer only learns which jobs are done, and waits for the last one before it reports. The last job also plays
the run's playoff (:mod:`selfplay_cli.evaluation.playoff`): its best candidates meet until the best is separated.

Training ends with the worker behind (a moment's rating games take longer than a moment of training), and the
trainer's core idle. So where the final moment's gauntlet stands alone (it meets every earlier snapshot and picks no
best so far: :func:`~selfplay_cli.evaluation.gauntlet_plan.stands_alone`, a run with up to 24 earlier snapshots), a
second process, the helper, plays it on that core at once, beside the worker's backlog; the final job is held back
and handed to the worker once the helper is done, and finds its gauntlet stored (the same games: one batch, the
same seeds, in either process) and plays the playoff, after the moments ahead of it, as before. A helper that dies
hands the job to the worker as it stands (it plays what is missing); one that fails fails the run, as the worker's
job would.

``background=False`` plays each gauntlet in the calling process instead, when it is submitted (the same games).
:mod:`.queue_workers` (``marl train --eval remote``) puts them on the league's work queue instead, for ``marl worker``
processes on any machine, and plays them itself at the run's end if no worker takes them (the same games again: one
function plays a gauntlet wherever it is played, :func:`selfplay_cli.evaluation.gauntlet_jobs.play_gauntlet_spec`).

The worker leaves when told to, or when a job fails (the failure comes back as the job's error, raised in the
trainer in its class: a user's mistake, an I/O failure, or a bug). It dies with the trainer, at once, however the
trainer ends (:func:`die_with_parent`), so no orphan plays on. The trainer notices a worker that died as soon as
it next looks (every metrics line, every snapshot moment, every second of the final wait), and one that finished
no game for :data:`STALL_SECONDS` while it had a job (stopped with SIGSTOP, or stuck): it says so on stderr and
starts another, which plays the unfinished jobs again. That is safe because a job's stored work is idempotent
(:func:`selfplay_cli.evaluation.gauntlet.rate_snapshots`: a matchup is stored whole under a key, and a job played again
stores only what is missing, and makes the same choices). After :data:`MAX_RESTARTS` workers lost in a row the
run stops with an internal error (exit 5).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from ...errors import MarlError, MarlIOError
from ...signals import signals_held
from .base import GauntletJob, JobDone, RatingWorkerError

STALL_SECONDS = 300.0  # a worker that has a job and reports no finished game for this long is stuck (a stopped
# process, a game that never ends) and is replaced: a gauntlet's games all start at once, so one game's length
# (seconds in pong, under two minutes for the longest built-in game on a loaded machine) passes between reports
MAX_RESTARTS = 3  # workers replaced in a row (no job finished in between) before the run stops with an error
WATCH_SECONDS = 0.5  # how often a worker's watchdog looks for its parent (where the kernel does not watch)
_PR_SET_PDEATHSIG = 1  # prctl option (linux/prctl.h): the signal a process gets when its parent ends


def run_job(league: Any, job: GauntletJob, device: str, on_games: Any = None) -> JobDone:
    """Play one gauntlet in this process (as a worker of the league's queue plays it: the same spec, the same
    games)."""
    from ..gauntlet_jobs import play_gauntlet_spec

    games, seconds = play_gauntlet_spec(league, _spec(job), device=device, on_games=on_games)
    return JobDone(job, seconds, games)


def _spec(job: GauntletJob) -> dict[str, Any]:
    return {"snapshot_ids": list(job.snapshot_ids), "first_seed": job.first_seed, "games": job.games,
            "older": job.older, "full": job.full, "playoff": job.playoff, "precision": job.precision}


def die_with_parent(parent: int) -> None:
    """End this process the moment its parent (the trainer, pid ``parent``) ends, however it ends (SIGKILL
    included): nobody waits for its games then, and an orphan would play on for minutes, store them, and keep the
    terminal's output open. On Linux the kernel sends SIGKILL when the parent goes (``prctl(PR_SET_PDEATHSIG)``:
    strictly, when the parent's thread that started this process ends; the trainer starts its workers from its main
    thread); everywhere a watchdog thread checks the parent every :data:`WATCH_SECONDS` as well, and ends the
    process with SIGKILL (nothing runs on the way out: no queue feeder thread keeps it waiting)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):  # no libc to ask: the watchdog alone
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)

    def watch() -> None:
        while True:
            if os.getppid() != parent:
                os.kill(os.getpid(), signal.SIGKILL)
            time.sleep(WATCH_SECONDS)

    if os.getppid() != parent:  # gone before the kernel was asked
        os.kill(os.getpid(), signal.SIGKILL)
    threading.Thread(target=watch, name="marl-parent-watch", daemon=True).start()


def _error_kind(e: BaseException) -> str:
    """How the trainer reports a failed job: ``usage`` for a user's mistake (exit 2), ``io`` for a file or disk the
    system refused (exit 4), ``internal`` for a bug (exit 5)."""
    if isinstance(e, (MarlIOError, OSError)):
        return "io"
    return "usage" if isinstance(e, MarlError) else "internal"


def _worker(url: str, home: str | None, device: str, jobs: Any, done: Any, parent: int,
            games: tuple[str, ...] = ()) -> None:
    """The worker process: jobs in order until told to stop (None) or a job fails; it dies with its parent.
    ``games``: the games of your own the trainer may import (those its user named), admitted here too."""
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the trainer's to handle; it stops the worker

    import torch

    from ...envs import admit
    from ...league.store import League

    for game in games:
        admit(game)
    torch.set_num_threads(1)
    league = League(url, home=home)
    try:
        while True:
            job = jobs.get()
            if job is None:
                return
            try:
                done.put(run_job(league, job, device, on_games=lambda n: done.put(("games", n))))
            except Exception as e:  # reported to the trainer, which raises it there as one line
                done.put(JobDone(job, 0.0, 0, error=f"{type(e).__name__}: {e}" if not isinstance(e, MarlError)
                                 else str(e), error_kind=_error_kind(e)))
                return
    finally:
        league.close()


class Evaluator:
    """Gauntlet jobs, played in a worker process (``background``) or inline; see the module docstring.

    ``on_worker(pid)`` is told of every worker process started (the run's lock records it); ``note(line)`` says
    on stderr that a worker died or stalled and was replaced; ``clock()`` is the time a stall is measured in
    (seconds; a test moves it on instead of sleeping)."""

    def __init__(self, league: Any, device: str, background: bool = True,
                 on_worker: Callable[[int], None] | None = None, note: Callable[[str], None] | None = None,
                 stall_seconds: float | None = None, clock: Callable[[], float] = time.monotonic, *,
                 run: str = "", wait: bool = True) -> None:
        self._clock = clock
        self.league, self.device, self.background = league, device, background
        self.run, self.wait_for = run, wait
        self.pending: list[GauntletJob] = []
        self.games_played = 0  # games the worker reported since the last poll
        self.queued = False
        self.restarts = 0  # workers started to replace one that died or stalled
        self.stall_seconds = STALL_SECONDS if stall_seconds is None else stall_seconds
        self._on_worker = on_worker
        self._note = note or (lambda line: print(line, file=sys.stderr, flush=True))
        self._done: list[JobDone] = []
        self._proc: Any = None
        self._helper: Any = None  # the process playing the final gauntlet beside the worker's backlog
        self._helper_job: GauntletJob | None = None  # what it plays (the final job without its playoff)
        self._helper_jobs: Any = None  # its queue of jobs
        self._held: list[GauntletJob] = []  # jobs kept from the worker until the helper is done, in order
        self._extra: dict[GauntletJob, float] = {}  # a held job's seconds already spent by the helper
        self._failures = 0  # workers lost since a job last finished
        self._progress = self._clock()  # when the worker last reported a game or a job
        if background:
            self._start()

    def _start(self) -> None:
        """Start a worker on fresh queues (a killed worker may have died holding a lock of the old ones) and hand
        it every unfinished job, in order."""
        from ...envs.loading import admitted

        ctx = mp.get_context("spawn")  # no fork: the trainer holds threads, a database engine and torch state
        self._jobs, self._results = ctx.Queue(), ctx.Queue()
        home = None if self.league.home is None else str(Path(self.league.home))
        self._proc = ctx.Process(target=_worker, name="marl-rating",
                                 args=(self.league.url.render_as_string(hide_password=False), home, self.device,
                                       self._jobs, self._results, os.getpid(), admitted()), daemon=True)
        self._proc.start()
        self._progress = self._clock()
        for job in self.pending:
            if job not in self._held:
                self._jobs.put(job)
        if self._on_worker is not None:
            self._on_worker(self._proc.pid)

    @property
    def left(self) -> int:
        """Gauntlets submitted and not finished yet (as far as this process has heard)."""
        return len(self.pending) - len(self._done)

    @property
    def worker_pid(self) -> int | None:
        """The live worker's process id (None inline)."""
        return None if self._proc is None else self._proc.pid

    def submit(self, job: GauntletJob) -> None:
        if not self.pending:
            self._progress = self._clock()  # an idle worker was not stalled: the clock starts with its work
        self.pending.append(job)
        if self.background:
            if self._held or self._ahead(job):
                self._held.append(job)
            else:
                self._jobs.put(job)
        else:
            self._done.append(run_job(self.league, job, self.device, on_games=self._count))

    def _count(self, n: int) -> None:
        self.games_played += n

    def _ahead(self, job: GauntletJob) -> bool:
        """Start the helper on ``job``'s gauntlet if it is the run's final one, jobs are still ahead of it and it stands
        alone (see the module docstring); whether it did."""
        from ..gauntlet_jobs import stands_alone_spec

        if not (job.full and self.wait_for and self.left > 1 and self._helper is None
                and stands_alone_spec(self.league, _spec(job))):
            return False
        from ...envs.loading import admitted

        ctx = mp.get_context("spawn")
        jobs = ctx.Queue()
        home = None if self.league.home is None else str(Path(self.league.home))
        self._helper = ctx.Process(target=_worker, name="marl-rating-final",
                                   args=(self.league.url.render_as_string(hide_password=False), home, self.device,
                                         jobs, self._results, os.getpid(), admitted()), daemon=True)
        self._helper.start()
        self._helper_job = replace(job, playoff=0)
        jobs.put(self._helper_job)
        jobs.put(None)  # (it leaves once the gauntlet is played)
        self._helper_jobs = jobs  # (kept until it is done: a queue dropped here is gone before the child reads it)
        return True

    def _release(self, seconds: float = 0.0) -> None:
        """The helper is done (or gone): the held jobs go to the worker, in order; the final one's count includes
        the helper's ``seconds``."""
        helper, self._helper, self._helper_job = self._helper, None, None
        if helper is not None:
            helper.join(timeout=5)
            if helper.is_alive():
                helper.kill()
                helper.join(timeout=5)
            self._close_helper_jobs()
        if self._held:
            self._extra[self._held[0]] = seconds
        for job in self._held:
            self._jobs.put(job)
        self._held = []

    def _close_helper_jobs(self) -> None:
        self._helper_jobs.cancel_join_thread()
        self._helper_jobs.close()
        self._helper_jobs = None

    def _stop_helper(self) -> None:
        """End the helper now (the worker is replaced, or the run stops): its gauntlet goes to the worker with the
        other held jobs (it stores what is missing)."""
        if self._helper is not None:
            if self._helper.is_alive():
                self._helper.kill()
            self._helper.join(timeout=5)
            self._helper, self._helper_job = None, None
            self._close_helper_jobs()
        self._held = []  # (a new worker is handed every pending job; :meth:`close` hands none)

    def queue_standing(self) -> None:
        """Nothing of a local worker's is in the league's queue (see :meth:`.remote.RemoteEvaluator.queue_standing`).
        """
        return None

    def poll(self) -> list[JobDone]:
        """The jobs finished since the last call (never blocks, beyond replacing a worker that died or stalled). A
        failed job raises its error."""
        if self.background:
            self._drain()
            self._check()
        return self._finish()

    def wait(self, on_wait: Callable[[list[JobDone]], None] | None = None) -> list[JobDone]:
        """Block until every submitted job is done; ``on_wait(done)`` is called about every second meanwhile, with
        the jobs finished since (:meth:`.base.RatingExecutor.wait`); the rest are returned. With ``wait=False``
        (``--no-wait``): the jobs done by now; the worker stops, and the rest are left to the league's workers
        (:meth:`_leave`)."""
        if self.background and not self.wait_for:
            self._drain()
            self._check()
            return self.leave()
        if self.background:
            while len(self._done) < len(self.pending) and not any(d.error for d in self._done):
                try:
                    self._take(self._results.get(timeout=1.0))
                except queue.Empty:
                    self._check()
                if on_wait is not None:
                    with signals_held():  # (a Ctrl-C waits until the jobs taken from here are handed over)
                        on_wait(self._finish())  # (a failed job raises its error here)
        return self._finish()

    def leave(self) -> list[JobDone] | None:
        """The jobs done by now; the worker stops and the rest go on the league's queue (:meth:`_leave`). None
        inline: every job was played as it was submitted, so there is nothing to leave."""
        if not self.background:
            return None
        self._drain()
        done = self._finish()
        self._leave()
        return done

    def _leave(self) -> None:
        """Stop the worker (a job in the middle is abandoned: its matchups stored so far count once) and put the
        jobs it had not finished on the league's work queue, in order, as ``--eval remote`` queues them (the same
        specs: a ``marl worker`` plays the same games, storing only what is missing)."""
        if not self.pending:
            return
        from .queue_workers import RemoteEvaluator

        self.close()
        remote = RemoteEvaluator(self.league, self.run, self.device, wait=False, note=self._note)
        for job in self.pending:
            remote.submit(job)
        self.queued = True

    def _drain(self) -> None:
        while True:
            try:
                item = self._results.get_nowait()
            except queue.Empty:
                return
            self._take(item)

    def _check(self) -> None:
        """Replace a worker that died (a job it owed is played again: a job's stored matchups count once, see
        :func:`selfplay_cli.evaluation.gauntlet.rate_snapshots`), or that reported nothing for :attr:`stall_seconds`
        while it had a job; raise :class:`RatingWorkerError` once :data:`MAX_RESTARTS` workers in a row were lost."""
        if any(d.error for d in self._done):
            return  # a job failed: its error, not a restart
        if self._helper is not None and not self._helper.is_alive():
            self._drain()  # (what it said before it left: its gauntlet done)
            if self._helper is not None:  # it died without finishing: the worker plays what is missing
                self._note(f"the final gauntlet's helper (process {self._helper.pid}) ended unexpectedly "
                           f"({_exit(self._helper.exitcode)}); the rating worker plays what it left")
                self._release()
        if self._proc.is_alive():
            waited = self._clock() - self._progress
            if not self.pending or waited < self.stall_seconds:
                return
            why = (f"the rating worker (process {self._proc.pid}) finished no game for {waited:.0f} s "
                   f"(stopped, or stuck in a game); replacing it")
            self._proc.kill()
            self._proc.join(timeout=10)
        else:
            self._drain()  # what it said just before it left (a job it finished, or why it failed)
            if any(d.error for d in self._done) or (not self.pending and self._proc.exitcode == 0):
                return
            why = f"the rating worker (process {self._proc.pid}) ended unexpectedly ({_exit(self._proc.exitcode)})"
        self._failures += 1
        if self._failures > MAX_RESTARTS:
            raise RatingWorkerError(f"{why}; it was replaced {MAX_RESTARTS} times and lost each time, so the run "
                                    f"stops (continue it with marl train --resume once the cause is gone)")
        self._note(f"{why}; its unfinished gauntlet is played again, and the games it stored count once")
        self._stop_helper()  # (it reports on the queues replaced here: the new worker plays its gauntlet too)
        self._discard_queues()
        self.restarts += 1
        self._start()

    def _take(self, item: Any) -> None:
        self._progress = self._clock()
        if isinstance(item, tuple):
            self.games_played += int(item[1])
        elif self._helper_job is not None and item.job == self._helper_job and item.error is None:
            self._release(item.seconds)  # the final gauntlet is stored: its job goes to the worker (the playoff)
        else:
            self._failures = 0
            if item.job in self._extra:
                item = replace(item, seconds=item.seconds + self._extra.pop(item.job))
            self._done.append(item)

    def _finish(self) -> list[JobDone]:
        out, self._done = self._done, []
        for d in out:
            if d.error is not None:
                message = f"rating games failed: {d.error}"
                if d.error_kind == "io":
                    raise MarlIOError(message)
                if d.error_kind == "internal":
                    raise RatingWorkerError(message)
                raise MarlError(message)
            if d.job in self.pending:  # (the helper's failed job is not one of them: its error was raised above)
                self.pending.remove(d.job)
        return out

    def _discard_queues(self) -> None:
        for q in (self._jobs, self._results):
            q.cancel_join_thread()  # nothing flushed to a reader that is gone
            q.close()

    def close(self) -> None:
        """Stop the worker: at once when it is in the middle of a job (the job is abandoned; its stored matchups
        count once when it is played again on resume), else after it has read the stop."""
        self._stop_helper()
        if self._proc is not None:
            if self._proc.is_alive():
                if self.pending:
                    self._proc.kill()
                else:
                    self._jobs.put(None)
                self._proc.join(timeout=5)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(timeout=5)
            self._discard_queues()
            self._proc = None

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _exit(code: int | None) -> str:
    """A worker's exit code as words."""
    if code is not None and code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"
