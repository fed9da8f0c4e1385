"""Rating games beside training: the gauntlet of each snapshot moment, played while the learners train on.

Training keeps the main process busy (acting and stepping the games on one core, the learners' updates on both);
the gauntlets (:func:`selfplay_cli.rated.gauntlet.rate_snapshots`) are played by one worker process of their own,
in the order the snapshots were taken, so the run does not stop for them and their results do not depend on
timing: the worker plays job after job, and each job picks the run's best from the games of the jobs before it,
exactly as an inline evaluation would. The worker writes the ledger itself (SQLite in WAL mode takes both writers);
the trainer only learns which jobs are done, and waits for the last one before it reports. The last job also plays
the run's playoff (:mod:`selfplay_cli.rated.playoff`): its best candidates meet until the best is separated.

``background=False`` plays each gauntlet in the calling process instead, when it is submitted (the same games).

The worker leaves when told to, when a job fails (the failure comes back as the job's error) or when the training
process is gone (killed with SIGKILL: it checks its parent every second).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import MarlError

FINAL_BOT_GAMES = 4  # a run's final snapshots play this many times --eval-games against each scripted player (32
# at the default 8): the run's summary reports their scores against the bots, and each score's interval
FINAL_OLDER = 24  # a run's final snapshots meet this many of its earlier snapshots (all of a default run's), spread
# over the run: is the final stronger than the whole history, and where does it lose what it had (self-play's
# rock-paper-scissors shows between snapshots far apart, which the ratings alone do not predict)
PLAYOFF_SEEDS = 5_000  # a final job's playoff seeds start this far above its gauntlet's (which take a few dozen)


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


def run_job(league: Any, job: GauntletJob, device: str, on_games: Any = None) -> JobDone:
    """Play one gauntlet in this process."""
    from ..envs import get_env
    from ..rated.gauntlet import GauntletConfig, rate_snapshots
    from ..results import Rules

    t0 = time.perf_counter()
    # games in a round of two players: a seat-swapped pair, or one game where each plays only its own side
    per = 1 if Rules.of(get_env(league.get_player(job.snapshot_ids[0]).env)).sides_differ else 2
    n = max(job.games // per, 1)
    cfg = GauntletConfig(pairs=n, clear_pairs=n if job.full else 1, max_pairs=n,
                         older=max(job.older, FINAL_OLDER) if job.full else job.older,
                         bot_pairs=max(n, FINAL_BOT_GAMES * job.games // per) if job.full else 0)
    matchups = rate_snapshots(league, job.snapshot_ids, first_seed=job.first_seed, config=cfg, device=device,
                              on_games=on_games)
    games = sum(m.games for m in matchups)
    if job.playoff:
        from ..rated.playoff import PlayoffConfig, playoff

        games += playoff(league, job.snapshot_ids, first_seed=job.first_seed + PLAYOFF_SEEDS,
                         config=PlayoffConfig(max_games=job.playoff), device=device, on_games=on_games)
    return JobDone(job, time.perf_counter() - t0, games)


def _worker(url: str, home: str | None, device: str, jobs: Any, done: Any, parent: int) -> None:
    """The worker process: jobs in order until told to stop (None), a job fails, or the parent is gone."""
    import signal

    import torch

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the trainer's to handle; it stops the worker

    from ..league.store import League

    torch.set_num_threads(1)
    league = League(url, home=home)
    try:
        while True:
            try:
                job = jobs.get(timeout=1.0)
            except queue.Empty:
                if os.getppid() != parent:
                    return  # the trainer was killed: nobody waits for these games
                continue
            if job is None:
                return
            try:
                done.put(run_job(league, job, device, on_games=lambda n: done.put(("games", n))))
            except Exception as e:  # reported to the trainer, which raises it there as one line
                done.put(JobDone(job, 0.0, 0, error=f"{type(e).__name__}: {e}" if not isinstance(e, MarlError)
                                 else str(e)))
                return
    finally:
        league.close()


class Evaluator:
    """Gauntlet jobs, played in a worker process (``background``) or inline; see the module docstring."""

    def __init__(self, league: Any, device: str, background: bool = True) -> None:
        self.league, self.device, self.background = league, device, background
        self.pending: list[GauntletJob] = []
        self.games_played = 0  # games the worker reported since the last poll
        self._done: list[JobDone] = []
        self._proc: Any = None
        if background:
            ctx = mp.get_context("spawn")  # no fork: the trainer holds threads, a database engine and torch state
            self._jobs, self._results = ctx.Queue(), ctx.Queue()
            home = None if league.home is None else str(Path(league.home))
            self._proc = ctx.Process(target=_worker, name="marl-rating",
                                     args=(league.url.render_as_string(hide_password=False), home, device,
                                           self._jobs, self._results, os.getpid()), daemon=True)
            self._proc.start()

    def submit(self, job: GauntletJob) -> None:
        self.pending.append(job)
        if self.background:
            self._jobs.put(job)
        else:
            self._done.append(run_job(self.league, job, self.device, on_games=self._count))

    def _count(self, n: int) -> None:
        self.games_played += n

    def poll(self) -> list[JobDone]:
        """The jobs finished since the last call (never blocks). A failed job raises its error."""
        if self.background:
            while True:
                try:
                    item = self._results.get_nowait()
                except queue.Empty:
                    break
                self._take(item)
        return self._finish()

    def wait(self, on_wait: Any = None) -> list[JobDone]:
        """Block until every submitted job is done; ``on_wait()`` is called about every second meanwhile."""
        if self.background:
            while len(self._done) < len(self.pending) and not any(d.error for d in self._done):
                try:
                    self._take(self._results.get(timeout=1.0))
                except queue.Empty:
                    if not self._proc.is_alive():
                        try:  # it may have said why just before it left
                            self._take(self._results.get(timeout=2.0))
                        except queue.Empty:
                            raise MarlError(f"the rating worker process ended unexpectedly (exit code "
                                            f"{self._proc.exitcode})") from None
                if on_wait is not None:
                    on_wait()
        return self._finish()

    def _take(self, item: Any) -> None:
        if isinstance(item, tuple):
            self.games_played += int(item[1])
        else:
            self._done.append(item)

    def _finish(self) -> list[JobDone]:
        out, self._done = self._done, []
        for d in out:
            if d.error is not None:
                raise MarlError(f"rating games failed: {d.error}")
            self.pending.remove(d.job)
        return out

    def close(self) -> None:
        """Stop the worker (a job in progress is abandoned; its finished matchups are in the ledger)."""
        if self._proc is not None:
            if self._proc.is_alive():
                self._jobs.put(None)
                self._proc.join(timeout=5)
            if self._proc.is_alive():
                self._proc.terminate()
                self._proc.join(timeout=5)
            self._jobs.close()
            self._results.close()
            self._proc = None

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
