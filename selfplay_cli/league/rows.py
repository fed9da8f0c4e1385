"""The league's rows as its readers get them: a run (:class:`RunRow`, its status a :class:`RunStatus`) and a player
(:class:`PlayerRow`: a scripted player or a snapshot). Plain records, importing nothing of the league: every room
that reads a row (the roster that makes them, the blobs that a snapshot's bytes are, the rated play above) takes
them from here."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from enum import Enum
from typing import Any

__all__ = ["PlayerRow", "RunRow", "RunStatus"]


class RunStatus(str, Enum):
    """A training run's status. Each is the very word the ledger stores and JSON shows (a member equals its word,
    and prints as it), so leagues written before this type read the same."""

    RUNNING = "running"
    STOPPED = "stopped"
    """Stopped by Ctrl-C or SIGTERM: resumable."""
    FINISHED = "finished"
    FAILED = "failed"
    """Ended by an error, which a resume may get past."""
    ENDED = "ended"
    """A snapshot it needed was removed with ``marl checkpoint rm --force``: final, like ``finished``."""
    KILLED = "killed"
    INTERRUPTED = "interrupted"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class RunRow:
    """A training run. ``unusable``: why its ``config`` cannot be read (too large, nested too deep, not JSON), or
    None; such a run is listed but cannot be resumed."""

    id: int
    name: str
    env: str
    algo: str | None
    config: dict[str, Any]
    status: str
    created_at: datetime
    unusable: str | None = None


@dataclass(frozen=True)
class PlayerRow:
    """A bot or snapshot. ``elo`` / ``games`` are the online Elo and the number of games played. ``unusable``: why
    the row cannot be used (its ``meta`` cannot be read: too large, nested too deep, not JSON), or None; such a row is
    listed (its games are in the ledger) but never played."""

    id: int
    env: str
    kind: str
    name: str
    run: str | None
    step: int
    episode: int
    algo: str | None
    path: str | None
    sha256: str | None
    parent_id: int | None
    tags: tuple[str, ...]
    elo: float
    games: int
    removed: bool
    created_at: datetime
    meta: dict[str, Any] = field(default_factory=dict)
    unusable: str | None = None

    @property
    def full_name(self) -> str:
        """``run/name`` for a snapshot of a run, else the bare name (bots, run-less snapshots)."""
        return f"{self.run}/{self.name}" if self.run else self.name

    @property
    def is_bot(self) -> bool:
        """True for scripted bots."""
        return self.kind == "bot"
