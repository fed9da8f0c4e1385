"""What playing one queued job gave (:class:`Played`): the one type every kind of job returns; what a job's player
may be told (:class:`JobLost`) and given (:data:`See`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["JobLost", "Played", "See"]

See = Callable[..., list[Any]]
"""What a job's player is given to hand work on: ``see(batch, ids, on_games=..., on_change=...)`` sees the jobs
``ids`` of ``batch`` through (plays those no worker has taken, waits for the rest; their rows once all ended):
:func:`selfplay_cli.evaluation.jobs.see_through` of the league and device the job plays with."""


class JobLost(Exception):
    """The job in play is no longer this worker's (cancelled, or taken over after its lease lapsed)."""


@dataclass
class Played:
    """A job played: its games (league player ids per seat), the match they are filed as, and a summary."""

    games: list[Any]
    match_kind: str
    params: dict[str, Any]
    result: dict[str, Any]
    seconds: float
    played: int | None = None  # games played, where they are not ``games`` (a gauntlet stores its own as it plays)

    @property
    def count(self) -> int:
        return len(self.games) if self.played is None else self.played
