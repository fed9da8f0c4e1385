"""The work queue: rating games as jobs that any number of workers, on any machine, lease from the league.

This is fishtest's pull model, kept in the league's own database (the one source of truth): a command that has games
to play (a tournament, an SPRT, the games a gate still needs, a run's gauntlets) queues them as jobs of a few minutes
each, in a ``batch``; ``marl worker`` processes anywhere lease one job at a time, beat a heart on it while they play,
and store its games together with the job's end in one transaction.

* **Queuing** (:meth:`Queue.enqueue`) writes a batch's jobs in one transaction, each with the seeds its games are
  played on (:mod:`selfplay_cli.league.seeds`): a pair's seeds are taken under a unique key, so the same games queued
  twice, by one user or two at the same moment, are queued once (the second command joins the first's jobs).
* **Leasing** (:meth:`Queue.claim`) takes the first job by priority then age that is queued (and past its backoff),
  or leased by a worker whose heart has not beaten on it for ``scavenge`` seconds (fishtest's 360 s): the job goes
  back to the pool by being taken again. On PostgreSQL the row is taken with ``FOR UPDATE SKIP LOCKED``, so workers
  never wait for each other's claims; on SQLite the unit of work holds the write lock (``BEGIN IMMEDIATE``). A job
  can wait for another (``after``: a run's gauntlets are played in order).
* **Finishing** (:meth:`Queue.finish_job`) stores the job's games as the match keyed ``job:<id>`` and marks the job
  done in one transaction, with the job's row locked: a job finished twice (a worker thought dead that comes back
  after another took its job) stores its games once; the second finish stores nothing.
* **Failing** (:meth:`Queue.fail_job`) puts the job back with a growing wait (backoff), or, after ``max_tries``
  leases (at most :data:`TRIES_LIMIT`), marks it ``dead`` with its error; a job that cannot be played at all (a spec
  its kind refuses, or one that cannot be read) is marked dead at once (``final``). A job leased that many times whose
  workers all went silent is marked dead too, when the next claim finds it lapsed.
* **Cancelling** (:meth:`Queue.cancel_jobs`) ends queued and leased jobs (a decided SPRT's remaining batches); a
  worker holding one learns it at its next heartbeat and stops, and a finish of a cancelled job stores nothing.

Times are the workers' own clocks in UTC; a lease lapses after minutes, so clocks a few seconds apart do not matter.
The queue's records (jobs, workers) and its timings and limits are :mod:`selfplay_cli.league.job_rows`'.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import and_, bindparam, exists, func, inspect, or_, select, text, update
from sqlalchemy.orm import Session, aliased

from selfplay_cli.league.bounded_json import JSONBoundsError, check_value, say_unusable, unreadable
from selfplay_cli.league.db import Database, Part
from selfplay_cli.league.failures import LeagueError
from selfplay_cli.league.job_rows import (
    BACKOFF_SECONDS,
    ENDED,
    JOB_STATES,
    MAX_TRIES,
    SCAVENGE_SECONDS,
    TRIES_LIMIT,
    JobRow,
    NewJob,
    WorkerRow,
    backoff,
    max_tries_of,
)
from selfplay_cli.league.ledger import Ledger
from selfplay_cli.league.models import SPEC_BYTES, Job, Worker, utcnow
from selfplay_cli.league.seeds import Pair, Seeds
from selfplay_cli.results import GameResult

__all__ = ["Queue"]


def _job_row(j: Job, worker: str | None) -> JobRow:
    bad_result = unreadable(j.result)
    if bad_result is not None:
        say_unusable(f"job {j.id}", "result", bad_result, "its summary is left out")
    return JobRow(id=j.id, batch=j.batch, kind=j.kind, env=j.env, spec=dict(j.spec or {}), priority=j.priority,
                  state=j.state, after=j.after, tries=j.tries, worker_id=j.worker_id, worker=worker,
                  leased_at=j.leased_at, beat_at=j.beat_at, not_before=j.not_before, error=j.error,
                  result=dict(j.result) if j.result is not None and bad_result is None else None,
                  created_at=j.created_at, finished_at=j.finished_at, bad_spec=unreadable(j.spec))


def _worker_row(w: Worker, holding: tuple[int, ...] = ()) -> WorkerRow:
    return WorkerRow(id=w.id, name=w.name, host=w.host, pid=w.pid, started_at=w.started_at, beat_at=w.beat_at,
                     stopped_at=w.stopped_at, jobs_done=w.jobs_done, games=int(w.games), seconds=float(w.seconds),
                     serves=tuple(w.serves) if w.serves is not None else None, holding=holding)


def _lazy_commit(s: Session, sqlite: bool) -> None:
    """On PostgreSQL, let this transaction's commit return before its WAL reaches the disk (``synchronous_commit =
    off``, for this transaction only): a lease or a heartbeat lost in a server crash costs nothing (the job is leased
    again, and its games still count once), and the next durable commit (a job's games) flushes it anyway. It halves
    the time a lease takes."""
    if not sqlite:
        s.execute(text("SET LOCAL synchronous_commit = off"))


@functools.lru_cache(maxsize=16)
def _claim_query(by_batch: bool, by_kind: bool, sqlite: bool, by_id: bool = False) -> Any:
    """The next job to lease (see :meth:`Queue.claim`), built once: with bound ``now`` and ``lapsed`` (and
    ``batches``, ``kinds``, ``ids``)."""
    before = aliased(Job)
    now, lapsed = bindparam("now"), bindparam("lapsed")
    ready = or_(Job.after.is_(None), exists().where(before.id == Job.after, before.state.in_(tuple(ENDED))))
    takeable = or_(and_(Job.state == "queued", or_(Job.not_before.is_(None), Job.not_before <= now)),
                   and_(Job.state == "leased", Job.beat_at < lapsed))
    q = select(Job.__table__).where(takeable, ready).order_by(Job.priority.desc(), Job.id).limit(1)
    if by_batch:
        q = q.where(Job.batch.in_(bindparam("batches", expanding=True)))
    if by_kind:
        q = q.where(Job.kind.in_(bindparam("kinds", expanding=True)))
    if by_id:
        q = q.where(Job.id.in_(bindparam("ids", expanding=True)))
    if not sqlite:  # workers never wait for each other's claims
        q = q.with_for_update(skip_locked=True, of=Job.__table__)
    return q


def _check_new_job(nj: NewJob) -> None:
    """Refuse, in one line, a job no reader would take: ``max_tries`` out of 1..:data:`TRIES_LIMIT`, a spec that is
    not a JSON object within the bounds its column is read with, a kind or game name too long for its column."""
    n = nj.max_tries
    if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= TRIES_LIMIT:
        raise LeagueError(f"a job's max_tries must be a whole number from 1 to {TRIES_LIMIT}, not {n!r}")
    if not isinstance(nj.spec, dict):
        raise LeagueError(f"a job's spec must be a table of settings, not {type(nj.spec).__name__}")
    if not nj.kind or len(nj.kind) > 32 or not nj.env or len(nj.env) > 100:
        raise LeagueError("a job's kind (1 to 32 characters) and game (1 to 100) must be named")
    try:
        check_value(nj.spec, max_bytes=SPEC_BYTES, what=f"the spec of a {nj.kind} job")
    except JSONBoundsError as exc:
        raise LeagueError(str(exc)) from None



class Queue(Part):
    """The work queue of a league (a part of :class:`~selfplay_cli.league.store.League`; see the module docstring).

    ``clock``: what "now" is to the queue (leases, heartbeats, backoffs, who is alive), UTC; a test moves it on
    instead of sleeping."""

    def __init__(self, db: Database, ledger: Ledger, seeds: Seeds) -> None:
        super().__init__(db)
        self.ledger, self.seeds = ledger, seeds
        self.clock: Callable[[], datetime] = utcnow

    def _has_queue(self) -> bool:
        """Whether the database has the queue's tables: always once a command that writes has opened it; a league from
        before the queue, opened only to read, has none (and so an empty queue)."""
        if not self.db.readonly:
            return True
        known = getattr(self, "_queue_tables", None)
        if known is None:
            known = self._queue_tables = inspect(self.db.engine).has_table("jobs")
        return bool(known)

    # -- workers

    def add_worker(self, name: str, host: str, pid: int, serves: Sequence[str] | None = None) -> int:
        """Register a worker that takes jobs of the batches it ``serves`` (None: of every batch); its id."""

        def work(s: Session) -> int:
            w = Worker(name=name[:200], host=host[:200], pid=int(pid), serves=list(serves) if serves else None)
            s.add(w)
            s.flush()
            return w.id

        return self._unit(work)

    def worker_beat(self, worker_id: int, job_id: int | None = None) -> bool:
        """Beat ``worker_id``'s heart (and its lease on ``job_id``). False when the job is no longer this worker's to
        play: cancelled, dead, done by another, or taken by another after this worker's lease lapsed."""

        def work(s: Session) -> bool:
            _lazy_commit(s, self.db.is_sqlite)
            now = self.clock()
            s.execute(update(Worker).where(Worker.id == worker_id).values(beat_at=now))
            if job_id is None:
                return True
            hit = s.execute(update(Job).where(Job.id == job_id, Job.worker_id == worker_id, Job.state == "leased")
                            .values(beat_at=now))
            return bool(hit.rowcount)  # type: ignore[attr-defined]

        return self._unit(work)

    def stop_worker(self, worker_id: int, give_back: bool = True) -> tuple[int, ...]:
        """Mark a worker stopped; with ``give_back``, the jobs it still holds go back to the queue at once (not
        counted as a try): their ids."""

        def work(s: Session) -> tuple[int, ...]:
            now = self.clock()
            s.execute(update(Worker).where(Worker.id == worker_id).values(stopped_at=now, beat_at=now))
            back: list[int] = []
            if give_back:
                for j in s.execute(select(Job).where(Job.worker_id == worker_id, Job.state == "leased")).scalars():
                    j.state, j.tries, j.leased_at, j.beat_at = "queued", max(j.tries - 1, 0), None, None
                    back.append(int(j.id))
            return tuple(back)

        return self._unit(work)

    def workers(self, alive_within: float | None = None, taking: str | None = None) -> list[WorkerRow]:
        """Every worker (or those whose heart beat within ``alive_within`` seconds and that have not stopped; that
        take jobs of batch ``taking``), with the jobs each holds."""

        if not self._has_queue():
            return []

        def work(s: Session) -> list[WorkerRow]:
            q = select(Worker).order_by(Worker.id)
            if alive_within is not None:
                since = self.clock() - timedelta(seconds=alive_within)
                q = q.where(Worker.stopped_at.is_(None), Worker.beat_at >= since)
            held: dict[int, list[int]] = {}
            for jid, wid in s.execute(select(Job.id, Job.worker_id).where(Job.state == "leased").order_by(Job.id)):
                held.setdefault(int(wid), []).append(int(jid))
            rows = [_worker_row(w, tuple(held.get(w.id, ()))) for w in s.execute(q).scalars()]
            return [w for w in rows if taking is None or w.takes(taking)]

        return self._read(work)

    # -- jobs

    def enqueue(self, batch: str, jobs: Sequence[NewJob], *, chain: bool = False, after: int | None = None,
                seen: Mapping[Pair, int] | None = None) -> list[int]:
        """Queue ``jobs`` in ``batch`` in one transaction; their ids, in order. ``chain``: each job waits for the one
        before it (the first for ``after``, when given). The seeds the jobs claim (:attr:`NewJob.claim`) are taken
        with them, each pair's after the ``seq`` the look they were planned from found (``seen``): when another
        command took seeds of one of the pairs since, nothing is queued
        (:class:`~selfplay_cli.league.seeds.SeedsTaken`)."""
        if not batch or len(batch) > 200:
            raise LeagueError(f"a batch name must have 1 to 200 characters, not {len(batch)}")
        for nj in jobs:
            _check_new_job(nj)

        def work(s: Session) -> list[int]:
            ids: list[int] = []
            prev = after
            for nj in jobs:
                spec = dict(nj.spec)
                if nj.max_tries != MAX_TRIES:
                    spec["max_tries"] = int(nj.max_tries)
                j = Job(batch=batch, kind=nj.kind, env=nj.env, spec=spec, priority=int(nj.priority), state="queued",
                        after=prev)
                s.add(j)
                s.flush()
                ids.append(j.id)
                if chain:
                    prev = j.id
            claimed = [(nj.claim, i) for nj, i in zip(jobs, ids, strict=True) if nj.claim is not None]
            self.seeds.write_ranges(s, [c for c, _ in claimed], seen or {}, batch,
                               [i for _, i in claimed])
            return ids

        return self.seeds.taking(work)

    def claim(self, worker_id: int, *, batches: Sequence[str] | None = None, kinds: Sequence[str] | None = None,
              scavenge: float = SCAVENGE_SECONDS, ids: Sequence[int] | None = None) -> JobRow | None:
        """Lease the next job for ``worker_id`` (of ``batches`` / ``kinds`` / with ``ids`` only, when given), or None
        if none is ready. A job leased as many times as it may be whose lease lapsed again is marked dead when it
        comes up."""

        def work(s: Session) -> JobRow | None:
            _lazy_commit(s, self.db.is_sqlite)
            now = self.clock()
            lapsed = now - timedelta(seconds=scavenge)
            params: dict[str, Any] = {"now": now, "lapsed": lapsed}
            if batches is not None:
                params["batches"] = list(batches)
            if kinds is not None:
                params["kinds"] = list(kinds)
            if ids is not None:
                params["ids"] = [int(i) for i in ids]
            q = _claim_query(batches is not None, kinds is not None, self.db.is_sqlite,
                             ids is not None)
            jobs = Job.__table__
            while True:  # (Core statements: the ORM's bookkeeping would double the time a lease takes)
                j = s.execute(q, params).first()
                if j is None:
                    return None
                if j.state == "queued" or j.tries < max_tries_of(j.spec):
                    break
                s.execute(jobs.update().where(jobs.c.id == j.id).values(  # silent on every lease it may have
                    state="dead", finished_at=now,
                    error=f"its worker went silent (no heartbeat for {scavenge:g} s) on each of its {j.tries} leases"))
            s.execute(jobs.update().where(jobs.c.id == j.id).values(state="leased", worker_id=worker_id, leased_at=now,
                                                                    beat_at=now, tries=j.tries + 1))
            name = s.execute(Worker.__table__.update().where(Worker.__table__.c.id == worker_id).values(beat_at=now)
                             .returning(Worker.__table__.c.name)).scalar()
            return replace(_job_row(j, name), state="leased", worker_id=worker_id, leased_at=now, beat_at=now,
                           tries=j.tries + 1)

        return self._unit(work)

    def finish_job(self, job_id: int, worker_id: int, *, games: Sequence[GameResult] = (), match_kind: str = "match",
                   params: dict[str, Any] | None = None, result: dict[str, Any] | None = None,
                   seconds: float = 0.0, played: int | None = None) -> bool:
        """End a job: store its ``games`` (player ids per seat) as the match keyed ``job:<id>`` and mark it done, in one
        transaction with the job's row locked. False, and nothing stored, when the job was cancelled, marked dead, or
        finished before (by another worker that took it after this one's lease lapsed): it counts once. ``played``:
        the games the worker played, where the job stored its own as it went (default: ``len(games)``)."""
        from selfplay_cli.league.ledger import _check_games, _match_params

        games = list(games)
        pids = _check_games(games)

        def work(s: Session) -> bool:
            jobs, workers = Job.__table__, Worker.__table__
            q = select(jobs.c.state, jobs.c.env, jobs.c.batch).where(jobs.c.id == job_id)
            if not self.db.is_sqlite:
                q = q.with_for_update()
            j = s.execute(q).first()
            if j is None:
                raise LeagueError(f"no job with id {job_id}")
            if j.state in ENDED:
                return False
            out = dict(result or {})
            if games:
                mp = _match_params(j.env, match_kind, {**(params or {}), "job": job_id, "batch": j.batch})
                # (a job not ended has stored no games: they go in with its end, and its row is locked)
                match_id, ids = self.ledger.store_match(s, j.env, match_kind, mp, games, pids,
                                                  f"job:{job_id}", look=False)
                out.update(match_id=match_id, games_stored=len(ids))
            now = self.clock()
            s.execute(jobs.update().where(jobs.c.id == job_id).values(state="done", result=out, finished_at=now,
                                                                      worker_id=worker_id, error=None))
            s.execute(workers.update().where(workers.c.id == worker_id).values(
                beat_at=now, jobs_done=workers.c.jobs_done + 1,
                games=workers.c.games + (len(games) if played is None else int(played)),
                seconds=workers.c.seconds + float(seconds)))
            return True

        return self._unit(work)

    def fail_job(self, job_id: int, worker_id: int, error: str, *, base_backoff: float = BACKOFF_SECONDS,
                 final: bool = False) -> str:
        """A job that ``worker_id`` could not play: back to the queue after :func:`backoff`, or ``dead`` with
        ``error`` once it was leased ``max_tries`` times, or at once when ``final`` (a job no worker can play: a spec
        its kind refuses). Its new state (unchanged when it was not this worker's)."""

        def work(s: Session) -> str:
            j = s.get(Job, job_id)
            if j is None:
                raise LeagueError(f"no job with id {job_id}")
            if j.state != "leased" or j.worker_id != worker_id:
                return j.state
            now = self.clock()
            j.error = error[:2000]
            if final or j.tries >= max_tries_of(j.spec):
                j.state, j.finished_at = "dead", now
            else:
                j.state, j.not_before = "queued", now + timedelta(seconds=backoff(j.tries, base_backoff))
                j.leased_at = j.beat_at = None
            return j.state

        return self._unit(work)

    def cancel_jobs(self, *, batch: str | None = None, ids: Sequence[int] | None = None) -> int:
        """Cancel the queued and leased jobs of ``batch`` and/or with ``ids``; how many were cancelled."""
        if batch is None and ids is None:
            raise LeagueError("say which jobs to cancel (a batch or job ids)")

        def work(s: Session) -> int:
            q = update(Job).where(Job.state.in_(("queued", "leased")))
            if batch is not None:
                q = q.where(Job.batch == batch)
            if ids is not None:
                q = q.where(Job.id.in_([int(i) for i in ids]))
            hit = s.execute(q.values(state="cancelled", finished_at=self.clock()))
            return int(hit.rowcount)  # type: ignore[attr-defined]

        return self._unit(work)

    def jobs(self, *, batch: str | None = None, ids: Sequence[int] | None = None, states: Sequence[str] | None = None,
             limit: int | None = None) -> list[JobRow]:
        """Jobs (of ``batch``, with ``ids``, in ``states``), newest last; the last ``limit`` of them when given."""

        if not self._has_queue():
            return []

        def work(s: Session) -> list[JobRow]:
            q = select(Job, Worker.name).outerjoin(Worker, Worker.id == Job.worker_id)
            if batch is not None:
                q = q.where(Job.batch == batch)
            if ids is not None:
                q = q.where(Job.id.in_([int(i) for i in ids]))
            if states is not None:
                q = q.where(Job.state.in_(list(states)))
            q = q.order_by(Job.id.desc())
            if limit is not None:
                q = q.limit(int(limit))
            rows = [_job_row(j, name) for j, name in s.execute(q)]
            return rows[::-1]

        return self._read(work)

    def job_counts(self, batch: str | None = None) -> dict[str, int]:
        """How many jobs (of ``batch``) are in each state (every state listed, zeros included)."""

        if not self._has_queue():
            return dict.fromkeys(JOB_STATES, 0)

        def work(s: Session) -> dict[str, int]:
            q = select(Job.state, func.count()).group_by(Job.state)
            if batch is not None:
                q = q.where(Job.batch == batch)
            counts = dict.fromkeys(JOB_STATES, 0)
            counts.update({str(k): int(n) for k, n in s.execute(q)})
            return counts

        return self._read(work)

    def batches(self) -> list[tuple[str, dict[str, int]]]:
        """Every batch with its job counts by state, oldest first."""

        if not self._has_queue():
            return []

        def work(s: Session) -> list[tuple[str, dict[str, int]]]:
            q = select(Job.batch, Job.state, func.count(), func.min(Job.id)).group_by(Job.batch, Job.state)
            out: dict[str, dict[str, int]] = {}
            first: dict[str, int] = {}
            for b, st, n, lo in s.execute(q):
                out.setdefault(b, dict.fromkeys(JOB_STATES, 0))[st] = int(n)
                first[b] = min(first.get(b, lo), lo)
            return sorted(out.items(), key=lambda kv: first[kv[0]])

        return self._read(work)
