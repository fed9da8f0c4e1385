"""The recordings the league holds: ``league.videos``, the mp4s and gifs ``marl record`` made under the league home's
``videos/`` folder, registered by their path there (relative), the players they show seat by seat and the stored game
they replay, if any.

A row is only a claim: in a shared league anyone may have written it. :meth:`Videos.file` is the one way to the file
a row names: a relative path of plain parts under ``<home>/videos``, resolved with symlinks followed and still inside
that folder, and a regular file there; anything else is None. ``marl serve`` plays those files and no other."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path, PurePosixPath
from typing import Any

from sqlalchemy import inspect, select
from sqlalchemy.orm import Session

from selfplay_cli.league.bounded_json import unreadable
from selfplay_cli.league.db import Part
from selfplay_cli.league.models import Video

__all__ = ["VIDEOS", "VideoRow", "Videos"]

VIDEOS = "videos"
"""The folder of the league home that holds the recordings (``<home>/videos``)."""


@dataclass(frozen=True)
class VideoRow:
    """A registered recording: ``path`` relative to ``<home>/videos``; ``players`` the ids seat by seat (an
    unreadable list reads as none)."""

    id: int
    env: str
    path: str
    format: str
    players: tuple[int, ...]
    game_id: int | None
    seed: int
    length: int
    created_at: datetime
    meta: dict[str, Any] = field(default_factory=dict)


def _row(v: Video) -> VideoRow:
    players = v.players if isinstance(v.players, list) and not unreadable(v.players) else []
    meta = v.meta if isinstance(v.meta, dict) and not unreadable(v.meta) else {}
    return VideoRow(id=v.id, env=v.env, path=v.path, format=v.format,
                    players=tuple(int(p) for p in players if isinstance(p, int) and not isinstance(p, bool)),
                    game_id=v.game_id, seed=int(v.seed), length=int(v.length), created_at=v.created_at, meta=meta)


def _plain_parts(path: str) -> tuple[str, ...] | None:
    """The parts of a relative ``/``-separated path, each a plain name; None for anything else (absolute, ``..``,
    ``.``, empty parts, a backslash or a NUL)."""
    if not isinstance(path, str) or not path or "\\" in path or "\0" in path:
        return None
    pure = PurePosixPath(path)
    if pure.is_absolute() or path.startswith("/"):
        return None
    parts = path.split("/")
    if any(p in ("", ".", "..") for p in parts):
        return None
    return tuple(parts)


class Videos(Part):
    """``league.videos``: the recordings registered in the league (see the module docstring). A league of an
    earlier schema read without an upgrade (a command that only reads never upgrades) has no recordings."""

    def held(self) -> bool:
        """Whether the league has the table of recordings (schema revision 0005 or later)."""
        return self._read(lambda s: inspect(s.connection()).has_table(Video.__tablename__))

    def folder(self) -> Path | None:
        """``<home>/videos`` (None for a league without a home)."""
        return None if self.db.home is None else self.db.home / VIDEOS

    def relative(self, path: Path) -> str | None:
        """``path`` as a row stores it (relative to ``<home>/videos``), or None where it lies outside that folder
        (a recording written elsewhere with ``--out`` is not the league's)."""
        folder = self.folder()
        if folder is None:
            return None
        try:
            rel = Path(path).resolve().relative_to(folder.resolve())
        except ValueError:
            return None
        text = rel.as_posix()
        return text if _plain_parts(text) is not None else None

    def register(self, *, env: str, path: Path, fmt: str, players: list[int], seed: int, length: int,
                 game_id: int | None = None, meta: dict[str, Any] | None = None) -> VideoRow | None:
        """Register the recording at ``path`` (inside ``<home>/videos``; None and nothing stored otherwise)."""
        rel = self.relative(path)
        if rel is None:
            return None

        def work(s: Session) -> VideoRow:
            v = Video(env=env, path=rel, format=fmt, players=[int(p) for p in players], game_id=game_id,
                      seed=int(seed), length=int(length), meta=dict(meta or {}))
            s.add(v)
            s.flush()
            return _row(v)

        return self._unit(work)

    def list(self, env: str | None = None, player_id: int | None = None) -> list[VideoRow]:
        """The registered recordings, newest first: of ``env``, or showing ``player_id``."""

        def work(s: Session) -> list[VideoRow]:
            q = select(Video).order_by(Video.id.desc())
            if env is not None:
                q = q.where(Video.env == env)
            return [_row(v) for v in s.scalars(q)]

        rows = self._read(work) if self.held() else []
        return rows if player_id is None else [v for v in rows if player_id in v.players]

    def get(self, video_id: int) -> VideoRow | None:
        """The recording ``video_id``, or None."""
        if not self.held():
            return None
        return self._read(lambda s: (lambda v: None if v is None else _row(v))(s.get(Video, int(video_id))))

    def file(self, row: VideoRow) -> Path | None:
        """The file ``row`` names, only where it is a regular file inside ``<home>/videos`` once every symlink is
        followed (see the module docstring); None otherwise."""
        folder = self.folder()
        parts = _plain_parts(row.path)
        if folder is None or parts is None:
            return None
        try:
            root = folder.resolve(strict=True)
            target = folder.joinpath(*parts).resolve(strict=True)
        except (OSError, RuntimeError):
            return None
        if not target.is_relative_to(root) or not target.is_file():
            return None
        return target
