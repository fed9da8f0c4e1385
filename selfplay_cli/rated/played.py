"""What playing one queued job gave (:class:`Played`): the one type every kind of job returns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Played"]


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
