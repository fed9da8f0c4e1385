"""Rating games beside training: the gauntlet of each snapshot moment, played while the learners train on.

Training keeps the main process busy (acting and stepping the games on one core, the learners' updates on both);
the gauntlets (:func:`selfplay_cli.rated.gauntlet.rate_snapshots`) are played by one worker process of their own,
in the order the snapshots were taken, so the run does not stop for them and their results do not depend on
timing: the worker plays job after job, and each job picks the run's best from the games of the jobs before it,
exactly as an inline evaluation would. The worker writes the ledger itself (SQLite in WAL mode takes both writers);
the trainer only learns which jobs are done, and waits for the last one before it reports. The last job also plays
the run's playoff (:mod:`selfplay_cli.rated.playoff`): its best candidates meet until the best is separated.

``background=False`` plays each gauntlet in the calling process instead, when it is submitted (the same games).
:class:`RemoteEvaluator` (``marl train --eval remote``) puts them on the league's work queue instead, for ``marl
worker`` processes on any machine, and plays them itself at the run's end if no worker is attached (the same games
again: one function plays a gauntlet wherever it is played, :func:`selfplay_cli.rated.gauntlet_jobs.
play_gauntlet_spec`).

The worker leaves when told to, or when a job fails (the failure comes back as the job's error, raised in the
trainer in its class: a user's mistake, an I/O failure, or a bug). It dies with the trainer, at once, however the
trainer ends (:func:`die_with_parent`), so no orphan plays on. The trainer notices a worker that died as soon as
it next looks (every metrics line, every snapshot moment, every second of the final wait), and one that finished
no game for :data:`STALL_SECONDS` while it had a job (stopped with SIGSTOP, or stuck): it says so on stderr and
starts another, which plays the unfinished jobs again. That is safe because a job's stored work is idempotent
(:func:`selfplay_cli.rated.gauntlet.rate_snapshots`: a matchup is stored whole under a key, and a job played again
stores only what is missing, and makes the same choices). After :data:`MAX_RESTARTS` workers lost in a row the
run stops with an internal error (exit 5).
"""

from __future__ import annotations

import builtins
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import MarlError, MarlIOError

STALL_SECONDS = 300.0  # a worker that has a job and reports no finished game for this long is stuck (a stopped
# process, a game that never ends) and is replaced: a gauntlet's games all start at once, so one game's length
# (seconds in pong, under two minutes for the longest built-in game on a loaded machine) passes between reports
MAX_RESTARTS = 3  # workers replaced in a row (no job finished in between) before the run stops with an error
WATCH_SECONDS = 0.5  # how often a worker's watchdog looks for its parent (where the kernel does not watch)
_PR_SET_PDEATHSIG = 1  # prctl option (linux/prctl.h): the signal a process gets when its parent ends


@dataclass(frozen=True)
class GauntletJob:
    """The snapshots of one moment to rate, and how."""

    snapshot_ids: tuple[int, ...]
    first_seed: int
    games: int  # games per opponent (seat-swapped pairs, or single games where each plays only its own side)
    older: int
    full: bool = False  # every opponent gets ``games``, even where the lineage's result is already clear
    playoff: int = 0  # after the gauntlet, the run's best candidates meet, up to this many games a pair (the final)


@dataclass(frozen=True)
class JobDone:
    """A finished job: how long it took and how many games it played, or why it failed."""

    job: GauntletJob
    seconds: float
    games: int
    error: str | None = None
    error_kind: str = "usage"  # a failed job's class: usage (exit 2), io (4) or internal (5)


def run_job(league: Any, job: GauntletJob, device: str, on_games: Any = None) -> JobDone:
    """Play one gauntlet in this process (as a worker of the league's queue plays it: the same spec, the same
    games)."""
    from ..rated.gauntlet_jobs import play_gauntlet_spec

    games, seconds = play_gauntlet_spec(league, _spec(job), device=device, on_games=on_games)
    return JobDone(job, seconds, games)


def _spec(job: GauntletJob) -> dict[str, Any]:
    return {"snapshot_ids": list(job.snapshot_ids), "first_seed": job.first_seed, "games": job.games,
            "older": job.older, "full": job.full, "playoff": job.playoff}


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


def _worker(url: str, home: str | None, device: str, jobs: Any, done: Any, parent: int) -> None:
    """The worker process: jobs in order until told to stop (None) or a job fails; it dies with its parent."""
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the trainer's to handle; it stops the worker

    import torch

    from ..league.store import League

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


class RatingWorkerError(RuntimeError):
    """The rating worker kept dying, or a job failed on a bug: an internal error (exit 5), not the user's."""


class Evaluator:
    """Gauntlet jobs, played in a worker process (``background``) or inline; see the module docstring.

    ``on_worker(pid)`` is told of every worker process started (the run's lock records it); ``note(line)`` says
    on stderr that a worker died or stalled and was replaced."""

    def __init__(self, league: Any, device: str, background: bool = True,
                 on_worker: Callable[[int], None] | None = None, note: Callable[[str], None] | None = None,
                 stall_seconds: float | None = None) -> None:
        self.league, self.device, self.background = league, device, background
        self.pending: list[GauntletJob] = []
        self.games_played = 0  # games the worker reported since the last poll
        self.restarts = 0  # workers started to replace one that died or stalled
        self.stall_seconds = STALL_SECONDS if stall_seconds is None else stall_seconds
        self._on_worker = on_worker
        self._note = note or (lambda line: print(line, file=sys.stderr, flush=True))
        self._done: list[JobDone] = []
        self._proc: Any = None
        self._failures = 0  # workers lost since a job last finished
        self._progress = time.monotonic()  # when the worker last reported a game or a job
        if background:
            self._start()

    def _start(self) -> None:
        """Start a worker on fresh queues (a killed worker may have died holding a lock of the old ones) and hand
        it every unfinished job, in order."""
        ctx = mp.get_context("spawn")  # no fork: the trainer holds threads, a database engine and torch state
        self._jobs, self._results = ctx.Queue(), ctx.Queue()
        home = None if self.league.home is None else str(Path(self.league.home))
        self._proc = ctx.Process(target=_worker, name="marl-rating",
                                 args=(self.league.url.render_as_string(hide_password=False), home, self.device,
                                       self._jobs, self._results, os.getpid()), daemon=True)
        self._proc.start()
        self._progress = time.monotonic()
        for job in self.pending:
            self._jobs.put(job)
        if self._on_worker is not None:
            self._on_worker(self._proc.pid)

    @property
    def worker_pid(self) -> int | None:
        """The live worker's process id (None inline)."""
        return None if self._proc is None else self._proc.pid

    def submit(self, job: GauntletJob) -> None:
        if not self.pending:
            self._progress = time.monotonic()  # an idle worker was not stalled: the clock starts with its work
        self.pending.append(job)
        if self.background:
            self._jobs.put(job)
        else:
            self._done.append(run_job(self.league, job, self.device, on_games=self._count))

    def _count(self, n: int) -> None:
        self.games_played += n

    def queue_standing(self) -> None:
        """Nothing of a local worker's is in the league's queue (see :meth:`RemoteEvaluator.queue_standing`)."""
        return None

    def poll(self) -> list[JobDone]:
        """The jobs finished since the last call (never blocks, beyond replacing a worker that died or stalled). A
        failed job raises its error."""
        if self.background:
            self._drain()
            self._check()
        return self._finish()

    def wait(self, on_wait: Any = None) -> list[JobDone]:
        """Block until every submitted job is done; ``on_wait()`` is called about every second meanwhile."""
        if self.background:
            while len(self._done) < len(self.pending) and not any(d.error for d in self._done):
                try:
                    self._take(self._results.get(timeout=1.0))
                except queue.Empty:
                    self._check()
                if on_wait is not None:
                    on_wait()
        return self._finish()

    def _drain(self) -> None:
        while True:
            try:
                item = self._results.get_nowait()
            except queue.Empty:
                return
            self._take(item)

    def _check(self) -> None:
        """Replace a worker that died (a job it owed is played again: a job's stored matchups count once, see
        :func:`selfplay_cli.rated.gauntlet.rate_snapshots`), or that reported nothing for :attr:`stall_seconds`
        while it had a job; raise :class:`RatingWorkerError` once :data:`MAX_RESTARTS` workers in a row were lost."""
        if any(d.error for d in self._done):
            return  # a job failed: its error, not a restart
        if self._proc.is_alive():
            waited = time.monotonic() - self._progress
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
        self._discard_queues()
        self.restarts += 1
        self._start()

    def _take(self, item: Any) -> None:
        self._progress = time.monotonic()
        if isinstance(item, tuple):
            self.games_played += int(item[1])
        else:
            self._failures = 0
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
            self.pending.remove(d.job)
        return out

    def _discard_queues(self) -> None:
        for q in (self._jobs, self._results):
            q.cancel_join_thread()  # nothing flushed to a reader that is gone
            q.close()

    def close(self) -> None:
        """Stop the worker: at once when it is in the middle of a job (the job is abandoned; its stored matchups
        count once when it is played again on resume), else after it has read the stop."""
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


# -- the league's workers (--eval remote) ----------------------------------------------------------------------------
_COORDINATORS = ("train@", "marl@")  # names of commands that play their own batch's jobs (see_through), not others'


UNTAKEN_SECONDS = 60.0  # the run's end plays its owed gauntlets itself when the workers attached took none of them
# for this long (an idle worker looks at the queue every 10 s at most: they are busy with other work)


def run_batch(run: str) -> str:
    """The queue batch of a run's gauntlets (``--eval remote``): ``run:<run>``, as ``marl queue`` lists it."""
    return f"run:{run}"


@dataclass(frozen=True)
class QueueStanding:
    """Where a run's queued gauntlets stand: how many are not played yet, the workers playing them now (by name),
    whether this process plays them itself (no worker attached), and how many workers the league has attached."""

    left: int
    workers: tuple[str, ...]
    here: bool
    attached: int


class RemoteEvaluator:
    """Gauntlet jobs put on the league's work queue (``--eval remote``), for ``marl worker`` processes on any machine.

    Each moment's gauntlet is one job of the run's batch (:func:`run_batch`), chained after the one before it, so the
    workers play them in the order the snapshots were taken and each picks the run's best from the games of the jobs
    before it, as the local worker does: the same games. A resumed run finds a moment's job already queued (by its
    snapshot ids) and waits for that one instead of queueing it twice.

    :meth:`poll` reports the jobs done, so the run's progress and ladder fill in as their games arrive. :meth:`wait`
    (the run's end) waits for the jobs still owed; while no worker is attached (none whose heart beat within
    ``alive_within`` seconds), or none took any of them for ``untaken`` seconds (the workers attached are busy with
    other batches, or serve only those), this process plays them itself (:func:`~selfplay_cli.rated.jobs.
    see_through`, beside any worker that takes a share), so the work is done with no worker at all. With
    ``wait=False`` (``--no-wait``) it returns at once and leaves them to the workers. A job that ends dead (it failed
    on every try) raises its error; one cancelled in the queue (``marl queue cancel``) leaves its snapshots unrated,
    said in one line.
    """

    def __init__(self, league: Any, run: str, device: str, *, wait: bool = True, alive_within: float | None = None,
                 untaken: float = UNTAKEN_SECONDS, poll_seconds: float = 1.0, scavenge: float | None = None,
                 note: Callable[[str], None] | None = None) -> None:
        from ..league.queue import SCAVENGE_SECONDS

        self.league, self.device, self.wait_for = league, device, wait
        self.batch = run_batch(run)
        self.alive_within = SCAVENGE_SECONDS if alive_within is None else alive_within
        self.scavenge = SCAVENGE_SECONDS if scavenge is None else scavenge
        self.untaken, self.poll_seconds = untaken, poll_seconds
        self.pending: list[GauntletJob] = []
        self.games_played = 0  # games this process played of the run's jobs (none while workers play them)
        self.restarts = 0  # (no process of its own to replace)
        self.worker_pid: int | None = None
        self.here = False  # this process is playing the owed jobs itself
        self._ids: dict[GauntletJob, int] = {}
        self._last: int | None = None  # the job the next one waits for
        self._note = note or (lambda line: print(line, file=sys.stderr, flush=True))
        self._ticked = 0.0

    def submit(self, job: GauntletJob) -> None:
        """Queue ``job`` after the run's previous gauntlet, unless the batch already holds it (a resumed run)."""
        from ..rated.gauntlet_jobs import GAUNTLET, gauntlet_job

        mine = self.league.jobs(batch=self.batch)
        found = [j for j in mine if j.kind == GAUNTLET and j.state != "dead"
                 and [int(i) for i in j.spec.get("snapshot_ids", ())] == list(job.snapshot_ids)]
        if found:
            jid = found[-1].id
        else:
            after = self._last if self._last is not None else (mine[-1].id if mine else None)
            new = gauntlet_job(self.league, job.snapshot_ids, first_seed=job.first_seed, games=job.games,
                               older=job.older, full=job.full, playoff=job.playoff)
            (jid,) = self.league.enqueue(self.batch, [new], chain=True, after=after)
        self._ids[job], self._last = jid, jid
        self.pending.append(job)

    def poll(self) -> list[JobDone]:
        """The jobs done since the last call, in the order they were asked for; a dead one raises its error."""
        if not self.pending:
            return []
        rows = {r.id: r for r in self.league.jobs(ids=list(self._ids.values()))}
        out = []
        for job in self.pending:
            row = rows[self._ids[job]]
            if row.state == "done":
                result = row.result or {}
                out.append(JobDone(job, float(result.get("seconds", 0.0)), int(result.get("games", 0))))
            elif row.state == "cancelled":
                self._note(f"job {row.id} (the gauntlet of {_names(row)}) was cancelled in the queue: those "
                           "snapshots stay unrated")
                out.append(JobDone(job, 0.0, 0))
            elif row.state == "dead":
                raise _dead(row)
        for d in out:
            self.pending.remove(d.job)
            del self._ids[d.job]
        return out

    def wait(self, on_wait: Any = None) -> list[JobDone]:
        """Block until every submitted job is done (``wait``), playing them here while no worker is attached;
        ``on_wait()`` is called about every second meanwhile. With ``wait=False``: the jobs done now."""
        done = self.poll()
        taken = time.monotonic()  # when a worker last held or finished one of the run's jobs
        while self.wait_for and self.pending:
            if self._held():
                taken = time.monotonic()
            if not self.serving() or time.monotonic() - taken > self.untaken:
                self._play_here(on_wait)
            else:
                self._tick(on_wait, force=True)
                time.sleep(self.poll_seconds)
            finished = self.poll()
            if finished:
                taken = time.monotonic()
            done += finished
        return done

    def _held(self) -> bool:
        """A worker holds one of the run's jobs now, its heart beating on it (a silent one's lease lapses)."""
        from ..league.models import utcnow

        now = utcnow()
        return any(r.state == "leased" and r.beat_at is not None and (now - r.beat_at).total_seconds() < self.scavenge
                   for r in self.league.jobs(ids=list(self._ids.values())))

    def serving(self) -> list[str]:
        """The workers attached to the league now: not stopped, heart beaten within ``alive_within`` seconds (the
        commands that play only their own batch's jobs left out)."""
        return [w.name for w in self.league.workers(alive_within=self.alive_within)
                if not w.name.startswith(_COORDINATORS)]

    def _play_here(self, on_wait: Any) -> None:
        """Play the batch's queued jobs in this process, and wait for those that workers hold, until all have ended
        (a worker that attaches meanwhile takes its share)."""
        from ..rated.jobs import see_through

        def played(n: int) -> None:
            self.games_played += n
            self._tick(on_wait)

        self.here = True
        try:
            see_through(self.league, self.batch, device=self.device, scavenge=self.scavenge, role="train",
                        on_games=played, on_change=lambda jobs: bool(self._tick(on_wait, force=True)))
        finally:
            self.here = False

    def _tick(self, on_wait: Any, force: bool = False) -> None:
        """``on_wait()``, at most about once a second unless ``force``."""
        now = time.monotonic()
        if on_wait is not None and (force or now - self._ticked >= 1.0):
            self._ticked = now
            on_wait()

    def queue_standing(self) -> QueueStanding:
        """Where the run's owed gauntlets stand now (for the wait's display)."""
        from ..league.queue import ENDED

        rows = self.league.jobs(ids=list(self._ids.values())) if self._ids else []
        left = [r for r in rows if r.state not in ENDED]
        who = sorted({r.worker for r in left if r.state == "leased" and r.worker
                      and not r.worker.startswith(_COORDINATORS)})
        return QueueStanding(left=len(left), workers=tuple(who), here=self.here, attached=len(self.serving()))

    def close(self) -> None:
        """Nothing to stop: the jobs not done stay queued for the workers (a resumed run finds them)."""

    def __enter__(self) -> RemoteEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _names(row: Any) -> str:
    names = row.spec.get("snapshots") or [str(i) for i in row.spec.get("snapshot_ids", ())]
    return ", ".join(names)


def _dead(row: Any) -> Exception:
    """A dead job's error, raised in its class (as the local worker's): the worker's line starts with its type."""
    error = row.error or "no error recorded"
    message = (f"rating games failed: job {row.id} (the gauntlet of {_names(row)}) failed on each of its "
               f"{row.tries} tries: {error} (marl queue --batch {row.batch} shows it)")
    kind = error.split(":", 1)[0]
    cls = getattr(builtins, kind, None)
    if kind.endswith("IOError") or isinstance(cls, type) and issubclass(cls, OSError):
        return MarlIOError(message)
    if kind in _subclass_names(MarlError):
        return MarlError(message)
    return RatingWorkerError(message)


def _subclass_names(cls: type) -> set[str]:
    return {cls.__name__}.union(*(_subclass_names(c) for c in cls.__subclasses__()))


def make_evaluator(league: Any, cfg: Any, device: str, on_worker: Callable[[int], None] | None = None
                   ) -> Evaluator | RemoteEvaluator:
    """The run's rating worker as ``cfg.eval`` says: ``local`` (a process beside training), ``inline`` (in the
    training process), ``remote`` (the league's workers); none plays anything with ``--eval-games 0``."""
    if cfg.eval_games and cfg.eval == "remote":
        return RemoteEvaluator(league, cfg.run, device, wait=cfg.eval_wait)
    return Evaluator(league, device, background=bool(cfg.eval_games) and cfg.eval == "local", on_worker=on_worker)
