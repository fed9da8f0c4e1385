"""``marl worker``: a process on any machine that leases rating jobs from a league's queue, plays them through
:mod:`selfplay_cli.rated` and stores their games (:mod:`.worker`)."""

from .worker import Leaving, WorkerOptions, WorkerReport, reach_league, run_worker

__all__ = ["Leaving", "WorkerOptions", "WorkerReport", "reach_league", "run_worker"]
