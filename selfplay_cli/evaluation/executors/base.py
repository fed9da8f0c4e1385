"""The one interface a training run's rating games are played through, wherever they are played: a local worker
process beside training or the training process itself (:mod:`.local`), the league's work queue for ``marl worker``
processes on any machine (:mod:`.queue_workers`), or queue workers on Ray actors started for the run
(:mod:`.ray_actors`). :func:`selfplay_cli.evaluation.executors.open_executor` picks one as ``marl train --eval``
says; the trainer knows only :class:`RatingExecutor`.

Each of them plays a moment's gauntlet by the same function (:func:`selfplay_cli.evaluation.gauntlet_jobs
.play_gauntlet_spec`), on the same seeds, so where the games are played changes when they arrive, never what they
are."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

__all__ = ["GauntletJob", "JobDone", "QueueStanding", "RatingExecutor", "RatingWorkerError"]


@dataclass(frozen=True)
class GauntletJob:
    """The snapshots of one moment to rate, and how."""

    snapshot_ids: tuple[int, ...]
    first_seed: int
    games: int  # games per opponent (seat-swapped pairs, or single games where each plays only its own side)
    older: int
    full: bool = False  # the run's final moment: it meets every earlier snapshot (up to 24) and plays the bots longer
    playoff: int = 0  # after the gauntlet, the run's best candidates meet, up to this many games a pair (the final)
    precision: float = 0.0  # a matchup (bots too) plays the games an even record needs to predict a 200-game match
    # within this many score points (up to 4 times ``games``; 0: ``games`` exactly)


@dataclass(frozen=True)
class JobDone:
    """A finished job: how long it took and how many games it played, or why it failed."""

    job: GauntletJob
    seconds: float
    games: int
    error: str | None = None
    error_kind: str = "usage"  # a failed job's class: usage (exit 2), io (4) or internal (5)


@dataclass(frozen=True)
class QueueStanding:
    """Where a run's queued gauntlets stand: how many are not played yet, the workers playing them now (by name),
    whether this process plays them itself (no worker attached), and how many workers the league has attached."""

    left: int
    workers: tuple[str, ...]
    here: bool
    attached: int


class RatingWorkerError(RuntimeError):
    """The rating worker kept dying, or a job failed on a bug: an internal error (exit 5), not the user's."""


class RatingExecutor(Protocol):
    """How a run hands its moments' gauntlets out and hears that they are done: submit a job as each snapshot moment
    is taken, poll between updates (never blocks), wait at the run's end; a failed job raises its error in its
    class (a user's mistake, an I/O failure, or :class:`RatingWorkerError`)."""

    games_played: int
    """Rating games this process played or heard of since the last :meth:`poll` (the run's progress line)."""
    queued: bool
    """Whether the gauntlets are jobs of the league's queue (where they stand takes a read of the database)."""

    @property
    def left(self) -> int:
        """Gauntlets submitted and not done yet."""
        ...

    def submit(self, job: GauntletJob) -> None:
        """Hand out one moment's gauntlet, after the ones before it."""
        ...

    def poll(self) -> list[JobDone]:
        """The jobs done since the last call, in the order they were submitted."""
        ...

    def wait(self, on_wait: Callable[[list[JobDone]], None] | None = None) -> list[JobDone]:
        """Block until every submitted job is done (or handed to others, where the executor may leave them);
        ``on_wait(done)`` about every second meanwhile, with the jobs done since it was last called (in the order they
        were submitted; often none), so each can be reported as it finishes. Each finished job is handed over once:
        to ``on_wait``, or in the list returned (the rest)."""
        ...

    def leave(self) -> list[JobDone] | None:
        """Stop waiting (Ctrl-C during the run's final wait): the jobs done by now, the rest left on the league's
        queue for ``marl worker`` as ``--no-wait`` leaves them; None where they cannot be left (played inline)."""
        ...

    def queue_standing(self) -> QueueStanding | None:
        """Where the run's gauntlets stand in the league's queue (None: they are not in the queue)."""
        ...

    def close(self) -> None:
        """Stop what the executor started (its worker process, its actors); jobs in the queue stay there."""
        ...

    def __enter__(self) -> RatingExecutor: ...

    def __exit__(self, *exc: object) -> None: ...
