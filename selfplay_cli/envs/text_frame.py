"""A picture of a game that has none: lines of text drawn onto a fixed-size RGB frame, for recording games whose own
rendering is text (OpenSpiel's ``str(state)``: a poker hand's cards and bets, a board in characters).

The frame is always the same size (a video's frames must be), the text in a monospaced font where the system has one
(board games' columns then line up), else pygame's own. Lines too long for the frame are cut with ``...``, lines
beyond its height are left out with a last line saying how many. Drawn offscreen on :class:`~.canvas.Canvas`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .canvas import Canvas

__all__ = ["TextFrame"]

BACKGROUND, TITLE, TEXT = (250, 248, 240), (20, 60, 120), (20, 20, 24)


class TextFrame:
    """Draws lines of text on a ``width`` x ``height`` frame; the first line (a title) in another colour."""

    def __init__(self, width: int = 640, height: int = 400, font_size: int = 18, margin: int = 12) -> None:
        self.canvas = Canvas(width, height)
        pg = self.canvas._pg
        path = pg.font.match_font("dejavusansmono,liberationmono,couriernew,monospace")
        self.font = pg.font.Font(path, font_size)
        self.line = self.font.get_linesize()
        self.margin = margin
        self.rows = max(1, (height - 2 * margin) // self.line)

    def _fit(self, text: str) -> str:
        room = self.canvas.size[0] - 2 * self.margin
        if self.font.size(text)[0] <= room:
            return text
        while text and self.font.size(text + "...")[0] > room:
            text = text[:-1]
        return text + "..."

    def draw(self, lines: Sequence[str]) -> np.ndarray:
        """The frame of ``lines`` (tabs as spaces), as a new ``(height, width, 3)`` uint8 array."""
        lines = [str(x).expandtabs(4) for x in lines]
        if len(lines) > self.rows:
            lines = [*lines[: self.rows - 1], f"... ({len(lines) - self.rows + 1} more lines)"]
        surface = self.canvas.surface
        surface.fill(BACKGROUND)
        for i, text in enumerate(lines):
            if text:
                img = self.font.render(self._fit(text), True, TITLE if i == 0 else TEXT, BACKGROUND)
                surface.blit(img, (self.margin, self.margin + i * self.line))
        return self.canvas.pixels()
