"""The caption band of a recording: who plays which seat, the running score, the step and which game this is.

Every recording carries it, whatever the game: a band of text under the game's own frame (the frame itself is left
as the game drew it). It is built from what every game declares and the game loop knows, so nothing here depends on
one game's shape:

* one entry per side (:meth:`~selfplay_cli.envs.contract.EnvSpec.side_seats`: each seat of a two-sides game or a
  free-for-all, the whole team of a cooperative one), with the names of the players on its seats and the side's
  running score (the sum of its seats' scores, which is what decides a result; a cooperative team's return);
* a status line: the game's number (``game 2 of 3``), the step, and on the last frame how the game ended.

A renderer may offer ``seat_colour(seat) -> (r, g, b)`` (the lander's landers, the tennis bats): each seat's name
then gets a swatch of its colour, so the names can be matched with what moves on screen. A frame narrower than
:data:`MIN_WIDTH` (a board game's 96-pixel board) is first enlarged by a whole factor, pixels repeated, so that
the text fits and the board reads.

Text is drawn with pygame's font module only (no display, no audio), as the built-in games' renderers do. Names
and scores recur from frame to frame and are rendered once; the band of a frame whose text did not change is
reused as it is.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Sequence

import numpy as np

from ..envs import EnvSpec
from ..results import COOPERATIVE, format_score

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

__all__ = ["MIN_WIDTH", "CaptionBand", "side_entries"]

MIN_WIDTH = 360
"""Frames narrower than this are enlarged by a whole factor before the band is added (96 px -> 384 px)."""
COLUMN = 260  # the least width an entry gets: the band has as many columns as fit, at most one per side
FONT_SIZE, LINE, PAD = 22, 22, 6
BACKGROUND, NAME, SCORE, STATUS = (24, 24, 28), (200, 200, 205), (255, 255, 255), (150, 150, 155)
_CACHE = 512

Colour = tuple[int, int, int]


def _score(x: float) -> str:
    return format_score(round(float(x), 2))


def side_entries(spec: EnvSpec, labels: Sequence[str]) -> list[tuple[tuple[int, ...], str]]:
    """Per side: its seats and who sits there, as people read it: ``x: alice`` for a side of one seat (its seat's
    name, then its player's), ``team: lander-1/s6M x3`` for a cooperative team, ``side 1: a, b`` for a side of
    several seats (a player on several seats of the side named once, with how many)."""
    out = []
    for k, seats in enumerate(spec.side_seats()):
        if len(seats) == 1:
            out.append((seats, f"{spec.agents[seats[0]]}: {labels[seats[0]]}"))
            continue
        counts: dict[str, int] = {}
        for s in seats:
            counts[str(labels[s])] = counts.get(str(labels[s]), 0) + 1
        names = ", ".join(name if n == 1 else f"{name} x{n}" for name, n in counts.items())
        who = "team" if spec.kind == COOPERATIVE else f"side {k + 1}"
        out.append((seats, f"{who}: {names}"))
    return out


class CaptionBand:
    """Adds the caption band under the frames of one recording (see the module docstring).

    ``labels``: the players' names by seat. ``heading``: what comes first on the status line (``game 2 of 3``),
    or None. ``seat_colour``: the renderer's colour of a seat, if it has one. Call it with each frame, the seats'
    running scores and the status (``step 41 · final``); it returns a new array, the band included. Every frame of
    a recording must have the same size (the first one fixes it)."""

    def __init__(self, spec: EnvSpec, labels: Sequence[str], heading: str | None = None,
                 seat_colour: Callable[[int], Colour] | None = None) -> None:
        import pygame

        pygame.font.init()
        self._pg = pygame
        self.font = pygame.font.Font(None, FONT_SIZE)
        self.cooperative = spec.kind == COOPERATIVE
        self.entries = side_entries(spec, labels)
        self.heading = heading
        self.seat_colour = seat_colour
        self._texts: dict[tuple[str, Colour], object] = {}
        self._shape: tuple[int, ...] | None = None
        self._last: tuple[tuple[str, ...], np.ndarray] | None = None

    # ------------------------------------------------------------------------------------------------------------
    def _layout(self, shape: tuple[int, ...]) -> None:
        """Fix the sizes from the first frame: the enlargement, the band's columns, rows and height."""
        h, w = shape[:2]
        self.scale = max(1, math.ceil(MIN_WIDTH / w))
        self.width, self.frame_h = w * self.scale, h * self.scale
        self.cols = max(1, min(len(self.entries), self.width // COLUMN))
        rows = math.ceil(len(self.entries) / self.cols)
        self.height = PAD + LINE * (rows + 1) + PAD
        self.height += self.height % 2  # even, as H.264 in yuv420p wants
        self.surface = self._pg.Surface((self.width, self.height), 0, 24, (0x0000FF, 0x00FF00, 0xFF0000, 0))
        self._shape = shape

    def _text(self, text: str, colour: Colour, cache: bool = True):
        key = (text, colour)
        img = self._texts.get(key)
        if img is None:
            img = self.font.render(text, True, colour, BACKGROUND)
            if cache:
                if len(self._texts) >= _CACHE:
                    self._texts.clear()
                self._texts[key] = img
        return img

    def _fit(self, text: str, room: int) -> str:
        """``text``, cut with ``...`` to fit ``room`` pixels."""
        if self.font.size(text)[0] <= room:
            return text
        while text and self.font.size(text + "...")[0] > room:
            text = text[:-1]
        return text + "..."

    def _band(self, scores: Sequence[str], status: str) -> np.ndarray:
        surf = self.surface
        surf.fill(BACKGROUND)
        col_w = self.width // self.cols
        for i, ((seats, who), score) in enumerate(zip(self.entries, scores, strict=True)):
            row, col = divmod(i, self.cols)
            y = PAD + LINE * row
            score_img = self._text(score, SCORE)
            swatches = len(seats) * 14 if self.seat_colour is not None else 0
            room = col_w - 16 - score_img.get_width() - 10 - swatches
            name_img = self._text(self._fit(who, max(room, 20)), NAME)
            width = swatches + name_img.get_width() + 10 + score_img.get_width()
            right = self.cols == 2 and col == 1  # two sides: the second one against the right edge, as it faces
            x = col * col_w + (col_w - 8 - width if right else 8)
            if self.seat_colour is not None:
                for s in seats:
                    surf.fill(self.seat_colour(s), (x, y + 4, 10, 10))
                    x += 14
            surf.blit(name_img, (x, y + 1))
            surf.blit(score_img, (x + name_img.get_width() + 10, y + 1))
        line = self._text(self._fit(status, self.width - 16), STATUS, cache=False)
        surf.blit(line, ((self.width - line.get_width()) // 2, self.height - PAD - LINE + 1))
        if sys.byteorder == "little":  # the surface's memory is then R, G, B per pixel: one copy
            rows = np.frombuffer(surf.get_buffer(), dtype=np.uint8).reshape(self.height, surf.get_pitch())
            return rows[:, : self.width * 3].reshape(self.height, self.width, 3).copy()
        return np.frombuffer(self._pg.image.tobytes(surf, "RGB"), dtype=np.uint8).reshape(
            self.height, self.width, 3).copy()  # pragma: no cover - big-endian machines

    def lines(self, scores: Sequence[float], status: str) -> list[str]:
        """The text of the band for these scores and status, as drawn: one ``who  score`` per side, then the status
        line (names cut to fit are drawn shorter)."""
        return [f"{who}  {score}" for (_, who), score in zip(self.entries, self.scores_text(scores), strict=True)] + [
            " · ".join(s for s in (self.heading, status) if s)]

    def scores_text(self, scores: Sequence[float]) -> list[str]:
        """Each side's running score as shown: the sum of its seats' scores (a cooperative team: its return)."""
        sums = [sum(float(scores[s]) for s in seats) for seats, _ in self.entries]
        return [f"return {_score(x)}" if self.cooperative else _score(x) for x in sums]

    def __call__(self, frame: np.ndarray, scores: Sequence[float], status: str) -> np.ndarray:
        if self._shape is None:
            self._layout(frame.shape)
        elif frame.shape != self._shape:
            raise ValueError(f"frame of shape {frame.shape} in a recording of {self._shape} frames")
        status = " · ".join(s for s in (self.heading, status) if s)
        texts = (*self.scores_text(scores), status)
        if self._last is None or self._last[0] != texts:
            self._last = (texts, self._band(texts[:-1], status))
        out = np.empty((self.frame_h + self.height, self.width, 3), dtype=np.uint8)
        if self.scale == 1:
            out[: self.frame_h] = frame
        else:
            out[: self.frame_h] = frame.repeat(self.scale, axis=0).repeat(self.scale, axis=1)
        out[self.frame_h:] = self._last[1]
        return out
