"""Where a training run's rating games are played (``marl train --eval``), behind one interface
(:class:`~.base.RatingExecutor`): :func:`open_executor` picks the one the run asked for."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .base import GauntletJob, JobDone, QueueStanding, RatingExecutor, RatingWorkerError

__all__ = ["EVAL_MODES", "GauntletJob", "JobDone", "QueueStanding", "RatingExecutor", "RatingWorkerError",
           "open_executor"]

EVAL_MODES = ("local", "inline", "remote", "ray")
"""``--eval``: a worker process beside training, the training process itself, the league's queue workers, queue
workers on Ray actors started for the run."""


def open_executor(league: Any, mode: str, run: str, device: str, *, games: int, wait: bool = True, actors: int = 1,
                  address: str = "", on_worker: Callable[[int], None] | None = None) -> RatingExecutor:
    """The run's rating games as ``mode`` (one of :data:`EVAL_MODES`) says: ``local`` (a process beside training,
    :mod:`.local`), ``inline`` (in the training process), ``remote`` (the league's workers, :mod:`.queue_workers`),
    ``ray`` (``actors`` queue workers on Ray actors at ``address``, started for the run, :mod:`.ray_actors`); with
    ``games`` 0 (``--eval-games 0``) an inline one that is never handed anything. ``wait``: the run's end waits for
    its gauntlets (``local``, ``remote``; else they are left on the league's queue for its workers).
    ``on_worker(pid)`` is told of a local worker process (the run's lock names it); Ray's actors end with the run's
    process by themselves."""
    if mode not in EVAL_MODES:
        raise ValueError(f"unknown rating executor {mode!r}: one of {', '.join(EVAL_MODES)}")
    if games and mode == "remote":
        from .queue_workers import RemoteEvaluator

        return RemoteEvaluator(league, run, device, wait=wait)
    if games and mode == "ray":
        from .ray_actors import RayEvaluator

        return RayEvaluator(league, run, device, actors=actors, address=address)
    from .local import Evaluator

    return Evaluator(league, device, background=bool(games) and mode == "local", on_worker=on_worker, run=run,
                     wait=wait)
