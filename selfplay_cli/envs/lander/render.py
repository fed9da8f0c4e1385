"""Offscreen pygame renderer for the lander game (no window, no display, no audio): gymnasium's picture (black sky,
white moon, yellow flags, purple landers) with every lander in its own colour, engine flames, and how each ended.

The surface is 24-bit with its channel masks set so that its memory is a row-major ``(400, 600, 3)`` RGB array (as
pong's renderer): a frame leaves it as one copy.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..canvas import Canvas
from .config import CRASHED, FLYING, LANDED, SCALE, VIEWPORT_H, VIEWPORT_W
from .core import LanderCore

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

BLACK, WHITE = (0, 0, 0), (255, 255, 255)
FLAG, POLE = (204, 204, 0), (255, 255, 255)
FLAME, WRECK, OUTLINE = (255, 140, 0), (110, 110, 110), (77, 77, 128)
LANDED_MARK = (60, 200, 90)


PALETTE = ((128, 102, 230), (230, 126, 34), (46, 204, 113), (52, 152, 219), (231, 76, 60), (241, 196, 15),
           (26, 188, 156), (236, 100, 180))


def lander_colour(seat: int) -> tuple[int, int, int]:
    """gymnasium's lander purple for seat 0, a distinct hue for each other seat."""
    return PALETTE[seat % len(PALETTE)]


def _screen(x: float, y: float) -> tuple[float, float]:
    """World metres to pixels, y pointing down."""
    return x * SCALE, VIEWPORT_H - y * SCALE


class LanderRenderer(Canvas):
    """Draws one game of a :class:`LanderCore` into an RGB array ``(400, 600, 3)`` uint8, the team's return top
    right. Each call returns a new array. ``seat_colour`` gives each lander's colour to the recording's caption band
    (which names the players)."""

    def __init__(self) -> None:
        super().__init__(VIEWPORT_W, VIEWPORT_H)
        pygame = self._pg
        self.font = pygame.font.Font(None, 22)

    seat_colour = staticmethod(lander_colour)

    def draw(self, core: LanderCore, game: int = 0) -> np.ndarray:
        pg, surf = self._pg, self.surface
        world = core.worlds[game]
        surf.fill(WHITE)
        # the sky above the terrain, black (the moon is what stays white)
        ground = [_screen(x, y) for x, y in world.terrain]
        pg.draw.polygon(surf, BLACK, [(0, 0), (VIEWPORT_W, 0), *reversed(ground)])
        for x in (world.helipad_x1, world.helipad_x2):
            px, py = _screen(x, world.helipad_y)
            pg.draw.line(surf, POLE, (px, py), (px, py - 50))
            pg.draw.polygon(surf, FLAG, [(px, py - 50), (px, py - 40), (px + 25, py - 45)])
        wrecks = [s for s in range(core.n_seats) if core.result[s, game] not in (FLYING, LANDED)]
        for seat in wrecks + [s for s in range(core.n_seats) if s not in wrecks]:  # wrecks under the others
            self._lander(core, world, seat, game)
        self._hud(core, game)
        return self.pixels()

    def _lander(self, core: LanderCore, world, seat: int, game: int) -> None:
        pg, surf = self._pg, self.surface
        result = int(core.result[seat, game])
        colour = WRECK if result not in (FLYING, LANDED) else lander_colour(seat)
        body = world.bodies[seat]
        for part in (*world.legs[seat], body):
            t = part.transform
            path = [_screen(*(t * v)) for v in part.fixtures[0].shape.vertices]
            pg.draw.polygon(surf, colour, path)
            pg.draw.polygon(surf, OUTLINE, path, 1)
        x, y = body.position
        a = body.angle
        tip, side = (math.sin(a), math.cos(a)), (-math.cos(a), math.sin(a))
        if result == FLYING and core.alive[seat, game] and not core.over[game]:
            main = core.main_power[seat, game]
            if main > 0:  # a flame below the body, as long as the throttle
                length = 0.5 + 0.4 * min(main, 2.0)
                base = (x - tip[0] * 0.35, y - tip[1] * 0.35)
                end = (base[0] - tip[0] * length, base[1] - tip[1] * length)
                w = (side[0] * 0.15, side[1] * 0.15)
                pg.draw.polygon(surf, FLAME, [_screen(base[0] + w[0], base[1] + w[1]),
                                              _screen(base[0] - w[0], base[1] - w[1]), _screen(*end)])
            if core.side_power[seat, game] > 0:  # a puff on the side opposite to the push
                d = core.side_dir[seat, game]
                cx, cy = x - side[0] * d * 0.65 + tip[0] * 0.4, y - side[1] * d * 0.65 + tip[1] * 0.4
                end = (cx - side[0] * d * 0.35, cy - side[1] * d * 0.35)
                pg.draw.line(surf, FLAME, _screen(cx, cy), _screen(*end), 4)
        if result == LANDED:
            px, py = _screen(x, y)
            pg.draw.circle(surf, LANDED_MARK, (round(px), round(py) - 28), 4)
        elif result == CRASHED:
            px, py = _screen(x, y)
            c = (round(px), round(py))
            pg.draw.line(surf, (220, 40, 40), (c[0] - 6, c[1] - 6), (c[0] + 6, c[1] + 6), 3)
            pg.draw.line(surf, (220, 40, 40), (c[0] - 6, c[1] + 6), (c[0] + 6, c[1] - 6), 3)

    def _hud(self, core: LanderCore, game: int) -> None:
        team = self.font.render(f"team {core.score[:, game].sum():+.1f}", True, WHITE, BLACK)
        self.surface.blit(team, (VIEWPORT_W - team.get_width() - 8, 6))
