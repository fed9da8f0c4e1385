"""Offscreen pygame renderer for the tennis game (no window, no display, no audio): the table seen from the side,
the net, both bats at their tilt, the ball (with a short trail and a spin mark), the score, who serves, and the
last point's reason.

The surface is 24-bit with its channel masks set so that its memory is a row-major ``(360, 800, 3)`` RGB array (as
the lander's renderer): a frame leaves it as one copy.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..canvas import Canvas
from .config import BALL_R, FLOOR_Y, NET_H, REASON_NAMES, TABLE_HALF, X_OUT
from .core import TennisCore

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

WIDTH, HEIGHT = 800, 360
SCALE = 125.0  # pixels per metre
Y_TOP = 2.0  # the world's height at the top of the picture (m)
BACKGROUND, FLOOR = (24, 30, 48), (60, 52, 48)
TABLE, LINES, LEGS = (20, 70, 140), (235, 235, 235), (90, 90, 90)
NET_COLOUR, BALL, TRAIL = (225, 225, 225), (255, 160, 40), (150, 100, 40)
GREY, WHITE = (160, 160, 170), (240, 240, 240)
BAT_COLOURS = ((220, 50, 50), (40, 200, 120))  # seat 0, seat 1
_TRAIL = 6


def _px(x: float, y: float) -> tuple[int, int]:
    return round(WIDTH / 2 + x * SCALE), round((Y_TOP - y) * SCALE)


class TennisRenderer(Canvas):
    """Draws one game of a :class:`TennisCore` into an RGB array ``(360, 800, 3)`` uint8, the score, who serves and
    the last point's reason at the top. Each call returns a new array. The renderer keeps the ball's last few places
    per game slot for its trail. ``seat_colour`` gives each bat's colour to the recording's caption band (which
    names the players)."""

    def __init__(self) -> None:
        super().__init__(WIDTH, HEIGHT)
        pygame = self._pg
        self.font = pygame.font.Font(None, 22)
        self.big = pygame.font.Font(None, 40)
        self._trail: dict[int, tuple[tuple[int, int], list[tuple[int, int]]]] = {}

    @staticmethod
    def seat_colour(seat: int) -> tuple[int, int, int]:
        return BAT_COLOURS[seat]

    def draw(self, core: TennisCore, game: int = 0) -> np.ndarray:
        pg, surf = self._pg, self.surface
        surf.fill(BACKGROUND)
        # floor, table, net
        pg.draw.rect(surf, FLOOR, pg.Rect(0, _px(0, FLOOR_Y)[1], WIDTH, HEIGHT))
        left, top = _px(-TABLE_HALF, 0.0)
        right, _ = _px(TABLE_HALF, 0.0)
        for lx in (-TABLE_HALF + 0.15, TABLE_HALF - 0.15):
            a, b = _px(lx, 0.0), _px(lx, FLOOR_Y)
            pg.draw.line(surf, LEGS, a, b, 4)
        pg.draw.rect(surf, TABLE, pg.Rect(left, top, right - left, round(0.05 * SCALE)))
        pg.draw.line(surf, LINES, (left, top), (right, top), 2)
        pg.draw.line(surf, NET_COLOUR, _px(0.0, 0.0), _px(0.0, NET_H), 3)
        # bats
        half = core.half
        for seat in (0, 1):
            x, y, angle = core.bat[0, seat, game], core.bat[1, seat, game], core.bat[4, seat, game]
            forward = 1.0 if seat == 0 else -1.0
            tx, ty = -math.sin(angle), forward * math.cos(angle)  # along the face: the normal turned a quarter
            if ty < 0:  # the handle at the lower end
                tx, ty = -tx, -ty
            a, b = _px(x - half * tx, y - half * ty), _px(x + half * tx, y + half * ty)
            pg.draw.line(surf, BAT_COLOURS[seat], a, b, 6)
            handle = _px(x - (half + 0.05) * tx, y - (half + 0.05) * ty)
            pg.draw.line(surf, (150, 110, 70), a, handle, 4)
        # ball (and its trail), marked off-screen at the edge
        bx, by, spin = core.ball[0, game], core.ball[1, game], core.ball[4, game]
        px, py = _px(float(np.clip(bx, -X_OUT, X_OUT)), float(by))
        point = (int(core.score[:, game].sum()), int(core.steps[game]))
        last, trail = self._trail.get(game, ((-1, -1), []))
        if point[0] != last[0] or point[1] != last[1] + 1:  # a new point, or not the next step: no trail
            trail = []
        self._trail[game] = (point, trail)
        trail.append((px, py))
        del trail[:-_TRAIL]
        for i, p in enumerate(trail[:-1]):
            pg.draw.circle(surf, TRAIL, p, 1 + i // 2)
        r = max(round(BALL_R * SCALE), 4)
        py_shown = min(max(py, r), HEIGHT - r)
        pg.draw.circle(surf, BALL, (px, py_shown), r)
        if abs(spin) > 20:  # a mark on the ball's rim, ahead in the sense it turns
            s = 1 if spin > 0 else -1
            pg.draw.line(surf, WHITE, (px, py_shown), (px + s * r, py_shown - r), 2)
        if py < 0:
            pg.draw.polygon(surf, BALL, [(px - 5, 8), (px + 5, 8), (px, 2)])
        self._hud(core, game)
        return self.pixels()

    def _hud(self, core: TennisCore, game: int) -> None:
        surf = self.surface
        s0, s1 = int(core.score[0, game]), int(core.score[1, game])
        score = self.big.render(f"{s0}  :  {s1}", True, WHITE)
        surf.blit(score, (WIDTH // 2 - score.get_width() // 2, 8))
        server = int(core.server[game])
        dot_x = WIDTH // 2 + (-1 if server == 0 else 1) * (score.get_width() // 2 + 14)
        self._pg.draw.circle(surf, BALL, (dot_x, 22), 5)
        if core.winner[game] >= 0:
            last = self.font.render(f"last point: player {int(core.winner[game])} "
                                    f"({REASON_NAMES[int(core.reason[game])].replace('_', ' ')})", True, GREY)
            surf.blit(last, (WIDTH // 2 - last.get_width() // 2, 44))
