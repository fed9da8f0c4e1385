"""Offscreen pygame renderer for Pong (no window, no display, no audio)."""

from __future__ import annotations

import os

import numpy as np

from .pong import BALL_R, HEIGHT, PADDLE_H, PADDLE_W, PADDLE_X, WIDTH, PongCore

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

WHITE = (255, 255, 255)
GREY = (90, 90, 90)
BLACK = (0, 0, 0)


class PongRenderer:
    """Draws one game of a :class:`PongCore` into an RGB array ``(400, 800, 3)`` uint8.

    Only pygame's font module is initialised (``pygame.init()`` would also start audio, which prints ALSA
    errors on machines without sound). The surface is reused between frames.
    """

    def __init__(self) -> None:
        import pygame

        pygame.font.init()
        self._pg = pygame
        self.surface = pygame.Surface((WIDTH, HEIGHT))
        self.score_font = pygame.font.Font(None, 56)
        self.label_font = pygame.font.Font(None, 24)

    def draw(self, core: PongCore, game: int = 0, labels: tuple[str, str] | None = None,
             caption: str | None = None) -> np.ndarray:
        pg, surf = self._pg, self.surface
        surf.fill(BLACK)
        for y in range(0, HEIGHT, 20):  # the net
            pg.draw.rect(surf, GREY, (WIDTH // 2 - 1, y + 5, 2, 10))
        pg.draw.rect(surf, WHITE, (PADDLE_X, round(core.paddle[0, game]), PADDLE_W, PADDLE_H))
        pg.draw.rect(surf, WHITE, (WIDTH - PADDLE_X - PADDLE_W, round(core.paddle[1, game]), PADDLE_W, PADDLE_H))
        pg.draw.circle(surf, WHITE, (round(core.bx[game]), round(core.by[game])), BALL_R)
        left, right = int(core.score[0, game]), int(core.score[1, game])
        for text, cx in ((str(left), WIDTH // 2 - 60), (str(right), WIDTH // 2 + 60)):
            img = self.score_font.render(text, True, WHITE)
            surf.blit(img, (cx - img.get_width() // 2, 12))
        if labels:
            a = self.label_font.render(labels[0], True, GREY)
            b = self.label_font.render(labels[1], True, GREY)
            surf.blit(a, (45, HEIGHT - 26))
            surf.blit(b, (WIDTH - 45 - b.get_width(), HEIGHT - 26))
        if caption:
            c = self.label_font.render(caption, True, GREY)
            surf.blit(c, (WIDTH // 2 - c.get_width() // 2, HEIGHT - 26))
        # surfarray is (width, height, 3); frames are (height, width, 3)
        return np.ascontiguousarray(pg.surfarray.pixels3d(surf).transpose(1, 0, 2))
