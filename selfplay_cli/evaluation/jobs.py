"""Rating work on the league's queue (:mod:`selfplay_cli.league.queue`): playing a job of any kind, a leased one with
its heart beating, and seeing a queued batch through.

The kinds of job are :mod:`.games_jobs` (a few minutes of one match) and :mod:`.gauntlet_jobs` (a training run's
gauntlet of one snapshot moment, and one matchup of it); :data:`KINDS` finds each one's player, :data:`CHECKS` the
check of its spec.
:func:`play_leased` plays one leased job while a thread beats its heart, then finishes it, or fails it with a short
line saying what failed: tried again after a backoff, dead after its tries; a spec its kind refuses, or one that
cannot be read, is dead at once. Whatever a job raises (a bot this marl does not know, a missing key, a recursion or
memory error) ends that job, never the worker; only Ctrl-C and SIGTERM stop it. The worker
(:mod:`selfplay_cli.evaluation.worker`) and :func:`see_through` both use it: a command that queued a batch plays the
batch's jobs that no worker has taken, and waits for those that workers play, so queued work is done even with no worker
attached.
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
from ..league.job_rows import BEAT_SECONDS, ENDED, SCAVENGE_SECONDS, JobRow
from ..league.store import League
from ..stats.sprt import LEVELS, categories, count_model
from . import games_jobs, gauntlet_jobs
from .job_spec import BadSpec
from .played import JobLost, Played

__all__ = ["CHECKS", "KINDS", "MAX_ERROR", "BadSpec", "JobLost", "Outcome", "check_job", "error_line", "play_job",
           "SHARING_ROLE", "play_leased", "see_through", "sprt_verdict", "worker_name"]

KINDS: dict[str, Callable[..., Played]] = {games_jobs.GAMES: games_jobs.play,
                                           gauntlet_jobs.GAUNTLET: gauntlet_jobs.play,
                                           gauntlet_jobs.MATCHUP: gauntlet_jobs.play_matchup}
"""The player of each kind of job: ``player(league, job, device=, parallel=, on_games=, see=) -> Played``
(``see``: :data:`~selfplay_cli.evaluation.played.See`, for a job that hands work on to other workers)."""
CHECKS: dict[str, Callable[[dict[str, Any]], None]] = {games_jobs.GAMES: games_jobs.check_spec,
                                                       gauntlet_jobs.GAUNTLET: gauntlet_jobs.check_spec,
                                                       gauntlet_jobs.MATCHUP: gauntlet_jobs.check_matchup_spec}
"""The check of each kind's spec: ``check(spec)`` raises :class:`BadSpec` saying what is wrong."""
SHARING_ROLE = "gauntlet"
"""How a worker that shares out a moment's matchups lists itself while it plays and waits for them
(``gauntlet@host:pid``: the same process as the worker holding the moment)."""
MAX_ERROR = 300
"""Characters of a failed job's error as its row keeps it (every member of a league reads it)."""


def worker_name(role: str = "worker") -> str:
    """``role@host:pid``: how a worker is listed."""
    return f"{role}@{socket.gethostname()}:{os.getpid()}"


def check_job(job: JobRow) -> None:
    """Refuse (:class:`BadSpec`) a job whose spec no worker can play: one that cannot be read (too large, nested too
    deep, not JSON), or one its kind's check refuses. A kind this marl does not know is left to :func:`play_job`
    (a newer marl's worker may play it)."""
    if job.bad_spec is not None:
        raise BadSpec(f"unreadable JSON ({job.bad_spec})")
    check = CHECKS.get(job.kind)
    if check is not None:
        check(job.spec)


def play_job(league: League, job: JobRow, *, device: str = "cpu", parallel: int = 1024,
             on_games: Callable[[int], None] | None = None) -> Played:
    """Play ``job`` in this process (nothing stored) by the player of its kind (:data:`KINDS`); its spec as
    :func:`check_job` passed it (:func:`play_leased` checks it before the job's heart starts)."""
    player = KINDS.get(job.kind)
    if player is None:
        raise MarlError(f"job {job.id} is of kind {job.kind!r}, which this marl does not play: upgrade marl")

    def see(batch: str, ids: Sequence[int], **kwargs: Any) -> list[JobRow]:  # (a moment's matchups: see gauntlet_jobs)
        return see_through(league, batch, device=device, parallel=parallel, ids=ids, role=SHARING_ROLE, **kwargs)

    return player(league, job, device=device, parallel=parallel, on_games=on_games, see=see)


def error_line(exc: BaseException, private: dict[str, str] | None = None) -> str:
    """What failed, in one short line for a job's row: the error's kind and its first line, cut at
    :data:`MAX_ERROR` characters. A job's row is read by every member of a shared league: the folders of this
    machine in ``private`` (a path: the name shown instead, such as ``$MARL_HOME``) are not shown."""
    try:
        quoted = isinstance(exc, KeyError) and type(exc).__str__ is KeyError.__str__ and len(exc.args) == 1
        first = (str(exc.args[0]) if quoted else str(exc)).strip()  # (a KeyError's own str is its key's repr)
        first = (first.splitlines() or [""])[0]
    except Exception:  # (an error whose message itself fails)
        first = ""
    for path, name in sorted((private or {}).items(), key=lambda kv: -len(kv[0])):  # (the longest first)
        if len(path) > 1:
            first = first.replace(path, name)
    line = f"{type(exc).__name__}: {first}" if first else type(exc).__name__
    return line if len(line) <= MAX_ERROR else line[:MAX_ERROR - 3] + "..."


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
                if not self.league.queue.worker_beat(self.worker_id, self.job_id):
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
    """Play a job this worker leased while its heart beats, then store it
    (:meth:`~selfplay_cli.league.queue.Queue.finish_job`), or put it back as failed with a short line saying what failed
    (:func:`error_line`), whatever the error (a recursion or memory error too): tried again after a backoff, dead after
    its tries. A spec that cannot be played (:func:`check_job`) makes the job dead at once, with ``bad job spec: ...``.
    ``retry`` runs each write (a worker tries again while the database is away, so games played are not played again). A
    :class:`KeyboardInterrupt` (Ctrl-C, SIGTERM) and any other ``BaseException`` propagate: the caller gives the job
    back."""
    from ..errors import MarlIOError
    from ..files import cache_home

    kwargs = {} if base_backoff is None else {"base_backoff": base_backoff}
    private = {str(league.home): "$MARL_HOME", str(cache_home()): "$MARL_CACHE", os.path.expanduser("~"): "~"}

    def failed(exc: BaseException, final: bool = False) -> Outcome:
        usage = isinstance(exc, MarlError | UnknownEnvError)  # (a game not here, or not named here: the job's fault)
        kind = "io" if isinstance(exc, MarlIOError | OSError) else "usage" if usage else "internal"
        error = f"bad job spec: {exc}"[:MAX_ERROR] if final else error_line(exc, private)
        state = retry(lambda: league.queue.fail_job(job.id, worker_id, error, final=final, **kwargs))
        return Outcome(job, "failed", error=error, error_kind=kind, extra={"state": state})

    try:
        check_job(job)
    except BadSpec as exc:
        return failed(exc, final=True)
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
        except Exception as exc:  # (RecursionError and MemoryError are Exceptions: they end the job, not the worker)
            return failed(exc)
    try:
        stored = retry(lambda: league.queue.finish_job(job.id, worker_id, games=played.games,
                                                       match_kind=played.match_kind,
                                                       params=played.params, result=played.result,
                                                       seconds=played.seconds,
                                                       played=played.count))
    except MarlIOError:  # (the database away, and no retry here: the lease lapses, another worker plays it)
        raise
    except Exception as exc:  # games or a result the league refuses: the job failed, the worker goes on
        return failed(exc)
    return Outcome(job, "done" if stored else "counted", games=played.count, seconds=played.seconds)


def see_through(league: League, batch: str, *, device: str = "cpu", parallel: int = 1024, play: bool = True,
                beat: float = BEAT_SECONDS, scavenge: float = SCAVENGE_SECONDS, poll: float = 0.5,
                on_games: Callable[[int], None] | None = None,
                on_change: Callable[[list[JobRow]], bool] | None = None, role: str = "marl",
                ids: Sequence[int] | None = None) -> list[JobRow]:
    """See a queued batch (its jobs with ``ids``, when given) through: play its jobs that no worker has taken
    (``play``), wait for those that workers play, until every job has ended; the batch's jobs then.
    ``on_change(jobs)`` is called at every look at the batch (before each job this process plays, and each ``poll``
    seconds while it waits: a progress display follows it); when it returns True the batch's remaining jobs are
    cancelled (a decided SPRT) and this returns. Ctrl-C gives a job in play back to the queue."""
    worker_id = league.queue.add_worker(worker_name(role), socket.gethostname(), os.getpid(), serves=[batch]) if play \
        else None
    try:
        while True:
            jobs = league.queue.jobs(batch=batch, ids=ids)
            if on_change is not None and on_change(jobs):
                league.queue.cancel_jobs(batch=batch, ids=ids)
                return league.queue.jobs(batch=batch, ids=ids)
            if all(j.state in ENDED for j in jobs):
                return jobs
            job = league.queue.claim(worker_id, batches=[batch], scavenge=scavenge, ids=ids) \
                if worker_id is not None else None
            if job is None:
                time.sleep(poll)
                if worker_id is not None:
                    league.queue.worker_beat(worker_id)
                continue
            play_leased(league, worker_id, job, beat=beat, device=device, parallel=parallel,  # type: ignore[arg-type]
                        on_games=on_games)
    finally:
        if worker_id is not None:
            league.queue.stop_worker(worker_id)


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
