"""The offscreen canvas the built-in games' renderers draw on: a pygame surface whose pixels become an RGB array.

pygame is imported only when a renderer is made (recording, ``obs_mode=rgb``), never by importing a game.
"""

from __future__ import annotations

import numpy as np


class Canvas:
    """A ``width`` x ``height`` 24-bit surface (``self.surface``, with ``self._pg`` the pygame module) whose bytes
    are R, G, B per pixel, rows top to bottom, on little-endian machines; :meth:`pixels` copies it out as an
    ``(height, width, 3)`` uint8 array (straight from the surface's memory where that reads as RGB, else through
    pygame's slower conversion)."""

    def __init__(self, width: int, height: int) -> None:
        import pygame

        pygame.font.init()
        self._pg = pygame
        self.size = (width, height)
        self.surface = pygame.Surface(self.size, 0, 24, (0x0000FF, 0x00FF00, 0xFF0000, 0))
        self.surface.fill((1, 2, 3))
        self._direct = bool((self._view_copy()[0, 0] == (1, 2, 3)).all())

    def _view_copy(self) -> np.ndarray:
        """A copy of the surface's memory; the buffer (which locks the surface) is released on return."""
        w, h = self.size
        rows = np.frombuffer(self.surface.get_buffer(), dtype=np.uint8).reshape(h, self.surface.get_pitch())
        return rows[:, : w * 3].reshape(h, w, 3).copy()

    def pixels(self) -> np.ndarray:
        """What is drawn on the surface now, as a new ``(height, width, 3)`` uint8 array."""
        if self._direct:
            return self._view_copy()
        w, h = self.size
        return np.frombuffer(self._pg.image.tobytes(self.surface, "RGB"), dtype=np.uint8).reshape(h, w, 3).copy()
