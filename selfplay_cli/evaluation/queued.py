"""A match played through the league's work queue: cut into jobs (:func:`~selfplay_cli.evaluation.jobs.games_jobs`),
played by whichever workers are attached and by the command itself (:func:`~selfplay_cli.evaluation.jobs.see_through`),
and reported as one match. Under an SPRT the verdict is taken over the jobs' rounds in order, round by round, as a
single match would take it, and the batch's remaining jobs are cancelled once it is decided."""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime, timezone
from typing import Any

from ..errors import MarlError
from ..league.job_rows import JobRow
from ..league.seeds import Pair
from ..league.store import League, PlayerRow
from ..stats.sprt import SPRT
from .games_jobs import JOB_ROUNDS, combine, games_jobs
from .jobs import see_through, sprt_verdict
from .match import MatchReport, SPRTSettings
from .seeds import Settled

__all__ = ["QueuedMatch", "batch_name", "dead_jobs_error", "queue_match"]


_BATCHES = itertools.count(1)


def batch_name(kind: str, *parts: str) -> str:
    """A batch's name: ``kind:part:...:YYYYmmddTHHMMSS-PID``, readable in ``marl queue``; a process's later batches
    end in ``-PID-N`` (N = 2, 3, ...), so two of one process in one second are two batches."""
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S")
    n = next(_BATCHES)
    tail = f"{stamp}-{os.getpid()}" + (f"-{n}" if n > 1 else "")
    return ":".join([kind, *parts])[:200 - len(tail) - 1] + ":" + tail


class QueuedMatch:
    """A match queued as jobs in ``batch`` (see the module docstring)."""

    def __init__(self, league: League, batch: str, *, sprt: SPRTSettings | None = None,
                 confidence: float = 0.95) -> None:
        self.league, self.batch, self.confidence = league, batch, confidence
        self.settings = sprt
        self.test = SPRT(elo0=sprt.elo0, elo1=sprt.elo1, alpha=sprt.alpha, beta=sprt.beta) if sprt else None
        self.verdict: tuple[float, str | None, int] = (0.0, None, 0)
        self._done: frozenset[int] | None = None  # the jobs the verdict was taken over

    def decided(self, jobs: list[JobRow]) -> bool:
        """Whether the SPRT is decided over the jobs done so far (always False without one); taken again only when
        another job is done."""
        if self.test is None or not jobs:
            return False
        done = frozenset(j.id for j in jobs if j.state == "done")
        if done != self._done:
            paired = next((bool(j.result["paired"]) for j in jobs if j.result), True)
            self.verdict, self._done = sprt_verdict(jobs, self.test, paired), done
        return self.verdict[1] is not None

    def see_through(self, *, device: str = "cpu", parallel: int = 1024, play: bool = True,
                    on_jobs: Callable[[list[JobRow]], None] | None = None, poll: float = 0.5) -> MatchReport:
        """Play and wait until every job has ended (or the SPRT is decided); the one report of the games."""

        def changed(jobs: list[JobRow]) -> bool:
            if on_jobs is not None:
                on_jobs(jobs)
            return self.decided(jobs)

        start = time.perf_counter()
        jobs = see_through(self.league, self.batch, device=device, parallel=parallel, play=play, on_change=changed,
                           poll=poll)
        self.decided(jobs)
        out = self.report(jobs)
        out.seconds = time.perf_counter() - start  # the wall time, whoever played (games/s: of them all)
        return out

    def report(self, jobs: Sequence[JobRow]) -> MatchReport:
        """The report of the done jobs (an SPRT's verdict with it); a :class:`MarlError` when none is done."""
        dead = dead_jobs_error(jobs)
        out = combine(jobs, confidence=self.confidence)
        if out is None:
            raise dead or MarlError(f"no job of {self.batch} was played")
        if self.settings is not None and self.test is not None:
            llr, decision, rounds = self.verdict
            s = self.settings
            out.sprt = {"elo0": s.elo0, "elo1": s.elo1, "alpha": s.alpha, "beta": s.beta, "llr": round(llr, 4),
                        "lower": round(self.test.lower, 4), "upper": round(self.test.upper, 4),
                        "decision": decision, "pairs": rounds, "batch": self.batch}
            if not out.paired:
                out.sprt["model"] = "trinomial"
        return out


def queue_match(league: League, rows_a: Sequence[PlayerRow], row_b: PlayerRow, *, games: int, first_seed: int,
                match_kind: str = "match", env_options: dict[str, Any] | None = None, team_name: str | None = None,
                sprt: SPRTSettings | None = None, confidence: float = 0.95, job_rounds: int = JOB_ROUNDS,
                device: str = "cpu", params: dict[str, Any] | None = None, seeds: Settled | None = None,
                seen: Mapping[Pair, int] | None = None) -> QueuedMatch:
    """Queue a match of ``games`` games from ``first_seed`` as jobs of ``job_rounds`` rounds in a new batch; with
    ``seeds`` (what :func:`~selfplay_cli.evaluation.seeds.settle` decided, from a look that found ``seen``) the jobs
    take their seeds as they are queued."""
    who = team_name or rows_a[0].full_name
    batch = batch_name("sprt" if sprt else match_kind, f"{who}-vs-{row_b.full_name}")
    extra = {**(params or {}), **({"sprt": vars(sprt).copy()} if sprt else {})}
    jobs = games_jobs(league, rows_a, row_b, games=games, first_seed=first_seed, match_kind=match_kind,
                      env_options=env_options, params=extra, team_name=team_name, job_rounds=job_rounds,
                      device=device, seeds=seeds)
    league.queue.enqueue(batch, jobs, seen=seen)
    return QueuedMatch(league, batch, sprt=sprt, confidence=confidence)


def dead_jobs_error(jobs: Sequence[JobRow]) -> MarlError | None:
    """The error of a batch some of whose jobs died (their games are missing), naming the first job's error."""
    dead = [j for j in jobs if j.state == "dead"]
    if not dead:
        return None
    return MarlError(f"{len(dead)} job{'s' * (len(dead) != 1)} of {dead[0].batch} failed every try (job {dead[0].id}: "
                     f"{dead[0].error}); marl queue --batch {dead[0].batch} --state dead lists them")

