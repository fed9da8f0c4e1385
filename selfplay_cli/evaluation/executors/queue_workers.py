"""A run's gauntlets on the league's workers (``marl train --eval remote``): each moment's gauntlet a job of the
league's work queue, played by ``marl worker`` processes on any machine, and by the run itself at its end when no
worker takes them (see :class:`RemoteEvaluator`). The same function plays a gauntlet wherever it is played
(:func:`selfplay_cli.evaluation.gauntlet_jobs.play_gauntlet_spec`), so it plays the local rating worker's matchups
(:mod:`.local`) on the same seeds; shared among several workers, a moment's matchups are played apart."""

from __future__ import annotations

import builtins
import sys
import time
from collections.abc import Callable
from typing import Any

from ...errors import MarlError, MarlIOError
from ...signals import signals_held
from .base import GauntletJob, JobDone, QueueStanding, RatingWorkerError

__all__ = ["UNTAKEN_SECONDS", "QueueStanding", "RemoteEvaluator", "run_batch"]

UNTAKEN_SECONDS = 60.0  # the run's end plays its owed gauntlets itself when the workers attached took none of them
# for this long (an idle worker looks at the queue every 10 s at most: they are busy with other work)


def run_batch(run: str) -> str:
    """The queue batch of a run's gauntlets (``--eval remote``): ``run:<run>``, as ``marl queue`` lists it."""
    return f"run:{run}"


class RemoteEvaluator:
    """Gauntlet jobs put on the league's work queue (``--eval remote``), for ``marl worker`` processes on any machine.

    Each moment's gauntlet is one job of the run's batch (:func:`run_batch`), chained after the one before it, so the
    workers play them in the order the snapshots were taken and each picks the run's best from the games of the jobs
    before it, as the local worker does. The worker that takes a moment shares its matchups with the other workers
    of the batch, each a job of its own (:mod:`selfplay_cli.evaluation.gauntlet_jobs`): a moment's independent matchups
    go to whoever is free. A resumed run finds a moment's job already queued (by its
    snapshot ids) and waits for that one instead of queueing it twice.

    :meth:`poll` reports the jobs done, so the run's progress and ladder fill in as their games arrive. :meth:`wait`
    (the run's end) waits for the jobs still owed; while no worker is attached (none whose heart beat within
    ``alive_within`` seconds), or none took any of them for ``untaken`` seconds (the workers attached are busy with
    other batches, or serve only those), this process plays them itself (:func:`~selfplay_cli.evaluation.jobs.
    see_through`, beside any worker that takes a share), so the work is done with no worker at all. With
    ``wait=False`` (``--no-wait``) it returns at once and leaves them to the workers. A job that ends dead (it failed
    on every try) raises its error; one cancelled in the queue (``marl queue cancel``) leaves its snapshots unrated,
    said in one line.
    """

    def __init__(self, league: Any, run: str, device: str, *, wait: bool = True, alive_within: float | None = None,
                 untaken: float = UNTAKEN_SECONDS, poll_seconds: float = 1.0, scavenge: float | None = None,
                 note: Callable[[str], None] | None = None) -> None:
        from ...league.job_rows import SCAVENGE_SECONDS

        self.league, self.device, self.wait_for = league, device, wait
        self.batch = run_batch(run)
        self.alive_within = SCAVENGE_SECONDS if alive_within is None else alive_within
        self.scavenge = SCAVENGE_SECONDS if scavenge is None else scavenge
        self.untaken, self.poll_seconds = untaken, poll_seconds
        self.pending: list[GauntletJob] = []
        self.games_played = 0  # games this process played of the run's jobs (none while workers play them)
        self.queued = True
        self.here = False  # this process is playing the owed jobs itself
        self._ids: dict[GauntletJob, int] = {}
        self._last: int | None = None  # the job the next one waits for
        self._note = note or (lambda line: print(line, file=sys.stderr, flush=True))
        self._ticked = 0.0

    @property
    def left(self) -> int:
        """Gauntlets submitted and not done yet (as the last :meth:`poll` found them)."""
        return len(self.pending)

    def submit(self, job: GauntletJob) -> None:
        """Queue ``job`` after the run's previous gauntlet, unless the batch already holds it (a resumed run)."""
        from ..gauntlet_jobs import GAUNTLET, gauntlet_job

        mine = [j for j in self.league.queue.jobs(batch=self.batch) if j.kind == GAUNTLET]  # (not their matchups' jobs)
        found = [j for j in mine if j.state != "dead"
                 and [int(i) for i in j.spec.get("snapshot_ids", ())] == list(job.snapshot_ids)]
        if found:
            jid = found[-1].id
        else:
            after = self._last if self._last is not None else (mine[-1].id if mine else None)
            new = gauntlet_job(self.league, job.snapshot_ids, first_seed=job.first_seed, games=job.games,
                               older=job.older, full=job.full, playoff=job.playoff, precision=job.precision)
            (jid,) = self.league.queue.enqueue(self.batch, [new], chain=True, after=after)
        self._ids[job], self._last = jid, jid
        self.pending.append(job)

    def poll(self) -> list[JobDone]:
        """The jobs done since the last call, in the order they were asked for; a dead one raises its error."""
        if not self.pending:
            return []
        rows = {r.id: r for r in self.league.queue.jobs(ids=list(self._ids.values()))}
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

    def wait(self, on_wait: Callable[[list[JobDone]], None] | None = None) -> list[JobDone]:
        """Block until every submitted job is done (``wait``), playing them here while no worker is attached;
        ``on_wait(done)`` is called about every second meanwhile, with the jobs finished since
        (:meth:`.base.RatingExecutor.wait`); the rest are returned. With ``wait=False``: the jobs done now."""
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

    def leave(self) -> list[JobDone]:
        """The jobs done by now; the rest stay in the league's queue, where they already are (one this process was
        playing itself went back to it as the Ctrl-C stopped the play: :func:`~..jobs.see_through`)."""
        return self.poll()

    def _held(self) -> bool:
        """A worker holds one of the run's jobs now, its heart beating on it (a silent one's lease lapses)."""
        from ...league.models import utcnow

        now = utcnow()
        return any(r.state == "leased" and r.beat_at is not None and (now - r.beat_at).total_seconds() < self.scavenge
                   for r in self.league.queue.jobs(ids=list(self._ids.values())))

    def serving(self) -> list[str]:
        """The workers attached to the league that take the run's jobs now: not stopped, heart beaten within
        ``alive_within`` seconds (this process, playing them itself, left out)."""
        return [w.name for w in self.league.queue.workers(alive_within=self.alive_within, taking=self.batch)
                if not self._is_me(w.name)]

    @staticmethod
    def _is_me(name: str) -> bool:
        from ..jobs import worker_name

        return name == worker_name("train")

    def _play_here(self, on_wait: Any) -> None:
        """Play the batch's queued jobs in this process, and wait for those that workers hold, until all have ended
        (a worker that attaches meanwhile takes its share)."""
        from ..jobs import see_through

        def played(n: int) -> None:  # (in the middle of a job: the queue is not read here, see _tick)
            self.games_played += n
            self._tick(on_wait, look=False)

        self.here = True
        try:
            see_through(self.league, self.batch, device=self.device, scavenge=self.scavenge, role="train",
                        on_games=played, on_change=lambda jobs: bool(self._tick(on_wait, force=True)))
        finally:
            self.here = False

    def _tick(self, on_wait: Callable[[list[JobDone]], None] | None, force: bool = False, look: bool = True) -> None:
        """``on_wait(done)``, at most about once a second unless ``force``, with the jobs the queue says are done since
        the last look (:meth:`poll`; none when not to ``look``: in the middle of a job this process plays, where a
        dead job's error raised would pass for that job's failure)."""
        now = time.monotonic()
        if on_wait is not None and (force or now - self._ticked >= 1.0):
            self._ticked = now
            with signals_held():  # (a Ctrl-C waits until the jobs the poll took are handed over)
                on_wait(self.poll() if look else [])

    def queue_standing(self) -> QueueStanding:
        """Where the run's owed gauntlets stand now (for the wait's display)."""
        from ...league.job_rows import ENDED

        rows = self.league.queue.jobs(ids=list(self._ids.values())) if self._ids else []
        left = [r for r in rows if r.state not in ENDED]
        from ..jobs import SHARING_ROLE

        playing = self.league.queue.jobs(batch=self.batch, states=["leased"]) if left else []  # (its matchups' too)
        who = sorted({r.worker for r in playing if r.worker and not self._is_me(r.worker)
                      and not r.worker.startswith(f"{SHARING_ROLE}@")})  # (the moment's worker, named already)
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
