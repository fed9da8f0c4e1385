"""The work queue's records as their readers get them, and its timings and limits.

A job to queue (:class:`NewJob`), a job as stored (:class:`JobRow`) and a worker (:class:`WorkerRow`); the job states
(:data:`JOB_STATES`, :data:`ENDED`); how often a worker's heart beats (:data:`BEAT_SECONDS`), when a silent lease
lapses (:data:`SCAVENGE_SECONDS`), how long a worker that starts waits for its server (:data:`REACH_SECONDS`), the
leases a job may have (:data:`MAX_TRIES`, :data:`TRIES_LIMIT`, :func:`max_tries_of`) and the wait after a failure
(:func:`backoff`). Plain records and rules, no database: the queue that stores them is
:mod:`selfplay_cli.league.queue`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from selfplay_cli.league.models import utcnow
from selfplay_cli.league.seeds import SeedClaim

__all__ = ["BACKOFF_SECONDS", "BEAT_SECONDS", "ENDED", "JOB_STATES", "MAX_TRIES", "SCAVENGE_SECONDS", "TRIES_LIMIT",
           "JobRow", "NewJob", "WorkerRow", "max_tries_of"]

JOB_STATES = ("queued", "leased", "done", "dead", "cancelled")
ENDED = frozenset({"done", "dead", "cancelled"})
BEAT_SECONDS = 120.0
"""How often a worker beats its heart on the job it plays (fishtest's 120 s)."""
SCAVENGE_SECONDS = 360.0
"""A leased job whose heart has not beaten for this long goes back to the queue (fishtest's 360 s)."""
REACH_SECONDS = 60.0
"""How long a worker that starts while its database server cannot be reached waits for it (``marl worker
--wait-db``): the time a running command waits for a lost server."""
MAX_TRIES = 5
"""Leases of one job before a failure (or a silent worker) marks it dead."""
TRIES_LIMIT = 20
"""The most leases a job may ask for (``max_tries``): past it, a job that fails everywhere would hold workers for days
of backoff (its waits double up to 10 minutes)."""
BACKOFF_SECONDS = 10.0
"""A job that failed waits this long before it is leased again, doubling with each failure (at most 10 minutes)."""
_BACKOFF_CAP = 600.0


@dataclass(frozen=True)
class NewJob:
    """A job to queue: its ``kind`` (what plays it), the game, and the ``spec`` its kind reads. ``max_tries``: leases
    before it is marked dead."""

    kind: str
    env: str
    spec: dict[str, Any]
    priority: int = 0
    max_tries: int = MAX_TRIES
    claim: SeedClaim | None = None
    """The seeds its games are played on, taken with it (:mod:`selfplay_cli.league.seeds`), or None."""


@dataclass(frozen=True)
class JobRow:
    """A job as stored (see :class:`~selfplay_cli.league.models.Job`); ``worker``: the name of the worker that
    holds or held it."""

    id: int
    batch: str
    kind: str
    env: str
    spec: dict[str, Any]
    priority: int
    state: str
    after: int | None
    tries: int
    worker_id: int | None
    worker: str | None
    leased_at: datetime | None
    beat_at: datetime | None
    not_before: datetime | None
    error: str | None
    result: dict[str, Any] | None
    created_at: datetime
    finished_at: datetime | None

    bad_spec: str | None = None
    """Why the stored spec cannot be read (too large, nested too deep, not JSON), or None: such a job is marked dead
    with it when a worker takes it."""

    @property
    def max_tries(self) -> int:
        return max_tries_of(self.spec)

    def to_json(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in ("id", "batch", "kind", "env", "state", "after", "tries", "worker",
                                             "error", "result", "priority")}
        if out["error"] is None and self.bad_spec is not None:
            out["error"] = f"bad job spec: unreadable JSON ({self.bad_spec})"
        for k in ("leased_at", "beat_at", "not_before", "created_at", "finished_at"):
            v = getattr(self, k)
            out[k] = v.isoformat() if v is not None else None
        return out


@dataclass(frozen=True)
class WorkerRow:
    """A worker as stored, with the jobs it holds now."""

    id: int
    name: str
    host: str
    pid: int
    started_at: datetime
    beat_at: datetime
    stopped_at: datetime | None
    jobs_done: int
    games: int
    seconds: float
    serves: tuple[str, ...] | None = None  # the batches it takes jobs from (None: all)
    holding: tuple[int, ...] = field(default=())

    def takes(self, batch: str) -> bool:
        """Whether it takes jobs of ``batch``."""
        return self.serves is None or batch in self.serves

    @property
    def games_per_second(self) -> float | None:
        return self.games / self.seconds if self.seconds > 0 else None

    def alive(self, within: float = SCAVENGE_SECONDS, now: datetime | None = None) -> bool:
        """Not stopped, and its heart beat within ``within`` seconds."""
        now = now or utcnow()
        return self.stopped_at is None and (now - self.beat_at).total_seconds() <= within

    def status(self, now: datetime | None = None) -> str:
        """``stopped``, ``alive`` (its heart beat within :data:`SCAVENGE_SECONDS`) or ``silent`` (its job goes to
        the next worker): what ``marl queue`` and ``marl serve`` say of it."""
        return "stopped" if self.stopped_at is not None else "alive" if self.alive(SCAVENGE_SECONDS, now) else "silent"

    def to_json(self) -> dict[str, Any]:
        gps = self.games_per_second
        return {"id": self.id, "name": self.name, "host": self.host, "pid": self.pid,
                "started_at": self.started_at.isoformat(), "beat_at": self.beat_at.isoformat(),
                "stopped_at": self.stopped_at.isoformat() if self.stopped_at else None, "jobs_done": self.jobs_done,
                "games": self.games, "seconds": round(self.seconds, 3),
                "serves": list(self.serves) if self.serves is not None else None,
                "games_per_second": round(gps, 2) if gps is not None else None, "holding": list(self.holding)}


def max_tries_of(spec: Any) -> int:
    """The leases a job's ``spec`` allows (``max_tries``; :data:`MAX_TRIES` when it says none), never more than
    :data:`TRIES_LIMIT`; a value that is not a whole number reads as the default (its kind's check refuses it)."""
    n = spec.get("max_tries", MAX_TRIES) if isinstance(spec, dict) else MAX_TRIES
    if not isinstance(n, int) or isinstance(n, bool):
        n = MAX_TRIES
    return min(max(n, 1), TRIES_LIMIT)



def backoff(tries: int, base: float = BACKOFF_SECONDS) -> float:
    """Seconds a job that failed on its ``tries``-th lease waits: ``base``, doubling per failure, at most 10 min."""
    return min(base * 2.0 ** max(tries - 1, 0), _BACKOFF_CAP)

