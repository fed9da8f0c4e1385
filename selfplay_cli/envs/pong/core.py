"""Pong's batched core: N games in numpy arrays, stepped together (the rules are the package's docstring,
:mod:`selfplay_cli.envs.pong`).

Randomness is counter-based (:mod:`selfplay_cli.envs.rng`): each game has a 64-bit key (from its seed) and every
serve draws from ``hash(key, serve_number, draw)``. A game therefore plays the same whether it runs alone or inside a
batch of thousands, and ``reset(seed=...)`` makes it reproducible without any global random state.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..rng import game_key, uniform
from .config import (
    BALL_R,
    HEIGHT,
    LEFT_FACE,
    N_FEATURES,
    PADDLE_H,
    PADDLE_SPEED,
    PADDLE_W,
    PADDLE_X,
    PADDLE_Y_MAX,
    RIGHT_FACE,
    SERVE_SPEED,
    WIDTH,
    PongConfig,
)

_MOVE = np.array([0.0, -PADDLE_SPEED, PADDLE_SPEED])
_CENTRE = np.array([[WIDTH // 2], [HEIGHT // 2]], dtype=np.float64)  # where every serve starts, (x, y)

# The right seat's view of a frame from the left seat's: mirror x and vx, swap own and opponent paddles.
_MIRROR_PERM = np.array([0, 1, 3, 2, 4, 5])
_MIRROR_SIGN = np.array([-1, 1, 1, 1, -1, 1], dtype=np.float32)


def _clip(x: np.ndarray, bound: float) -> None:
    """``x`` clamped to [-bound, bound] in place (what np.clip does, without its wrapper's cost)."""
    np.maximum(x, -bound, out=x)
    np.minimum(x, bound, out=x)


def _mirror(frames: np.ndarray) -> np.ndarray:
    """The right seat's view of frames ``(..., 6)`` seen from the left."""
    return frames[..., _MIRROR_PERM] * _MIRROR_SIGN


def make_batched_core(n_games: int, config: PongConfig) -> PongCore:
    """The batched core for training and matches, which observe coordinates: ``obs_mode=rgb`` frames come from the
    PettingZoo view (one game at a time, rendered), and are refused here."""
    if config.obs_mode != "coords":
        raise ValueError("obs_mode=rgb is for pong's PettingZoo view (one rendered game at a time, make_parallel); "
                         "training and matches play the batched core, which observes coordinates")
    return PongCore(n_games, config)


# --------------------------------------------------------------------------------------------------------------
_DRAWS_PER_SERVE = 4  # left paddle y, right paddle y, side, target point on the paddle
_DRAW = np.arange(_DRAWS_PER_SERVE, dtype=np.int64)[:, None]


def _serve_draws(keys: np.ndarray, serves: np.ndarray) -> np.ndarray:
    """The uniform [0, 1) draws of serve number ``serves`` of the games with ``keys``: ``(4, len(keys))``."""
    return uniform(keys, serves * _DRAWS_PER_SERVE + _DRAW)


# --------------------------------------------------------------------------------------------------------------
class PongCore:
    """N Pong games stepped at once. Seats are the leading axis: ``actions[seat, game]``.

    The core never resets a game by itself: a finished game (terminated or truncated) keeps its final score
    until :meth:`reset` is called for it. Observations are built on demand by :meth:`observe` from a ring of
    raw frames, so stepping stays cheap when nobody looks.
    """

    n_seats = 2

    def __init__(self, n_games: int, config: PongConfig | None = None) -> None:
        if n_games < 1:
            raise ValueError(f"n_games must be at least 1, not {n_games}")
        self.n = n_games
        self.config = config or PongConfig()
        self._seed_rules = self.config.rules == "seed"
        self._max_angle = float(np.radians(self.config.max_bounce_deg))
        self._max_deflect = float(np.radians(self.config.max_deflect_deg))
        n = n_games
        # Ball and paddles in one array, rows in observation order, so a frame is recorded in two operations.
        self._s = np.zeros((6, n))
        self.bx, self.by = self._s[0], self._s[1]
        self.paddle = self._s[2:4]  # top edge y of each seat's paddle
        self.vx, self.vy = self._s[4], self._s[5]
        self._pos, self._vel = self._s[0:2], self._s[4:6]  # the ball's (x, y) and (vx, vy)
        self.score = np.zeros((2, n))  # points per seat (float, as the game contract has scores)
        self.touched = np.zeros((2, n), dtype=bool)
        self.rally_steps = np.zeros(n, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        self.serves = np.zeros(n, dtype=np.int64)
        self.key = np.zeros(n, dtype=np.uint64)
        self.hits = np.zeros((2, n), dtype=np.int64)  # paddle touches per seat (for stats and shaping)
        self.drawn_rallies = np.zeros(n, dtype=np.int64)  # rallies ended by the rally cap
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        k = self.config.frame_stack
        # The last k frames as each seat observes them, in a ring kept twice over: ring frame i sits at positions i and
        # i + k of (seat, game, 2k, 6), so the k newest, oldest first, are always positions head + 1 .. head + k and
        # an observation is one copy of a slice. The newest frame is at head (and head + k).
        self._ring = np.zeros((2, n, 2 * k, N_FEATURES), dtype=np.float32)
        self._head = 0
        vs = 1.0 / self.config.velocity_scale
        self._scale = np.array([2 / WIDTH, 2 / HEIGHT, 2 / PADDLE_Y_MAX, 2 / PADDLE_Y_MAX, vs, vs])
        self._offset = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0], dtype=np.float32)
        self._frame_buf = np.empty((2, N_FEATURES, n), dtype=np.float32)  # this step's frame of each seat
        self.reset(np.arange(n), np.arange(n))

    # ----------------------------------------------------------------------------------------------------
    def reset(self, games: np.ndarray | list[int], seeds: np.ndarray | list[int]) -> None:
        """Start new games in the slots ``games`` with the given seeds."""
        g = np.asarray(games, dtype=np.int64)
        if g.size == 0:
            return
        self.key[g] = game_key(np.asarray(seeds, dtype=np.int64))
        self.score[:, g] = 0
        self.hits[:, g] = 0
        self.drawn_rallies[g] = 0
        self.steps[g] = 0
        self.serves[g] = 0
        self.terminated[g] = False
        self.truncated[g] = False
        self._serve(g)
        # A fresh game's history is its first frame repeated.
        left = self._frame_of(g)
        self._ring[0, g] = left[:, None, :]
        self._ring[1, g] = _mirror(left)[:, None, :]

    def _serve(self, g: np.ndarray) -> None:
        """Ball to the centre, paddles re-placed at random, serve toward a random point of a random paddle."""
        serves = self.serves[g]
        u = _serve_draws(self.key[g], serves)
        paddles = np.floor(u[:2] * (PADDLE_Y_MAX + 1))  # each paddle's top edge
        to_left = u[2] < 0.5
        target_y = np.where(to_left, paddles[0], paddles[1]) + u[3] * PADDLE_H
        # From the centre to the target paddle's centre line in x, to target_y in y.
        dx = np.where(to_left, PADDLE_X + PADDLE_W // 2 - WIDTH // 2, WIDTH - PADDLE_X - PADDLE_W // 2 - WIDTH // 2)
        dy = target_y - HEIGHT // 2
        norm = np.sqrt(dx * dx + dy * dy)
        self.paddle[:, g] = paddles
        self._pos[:, g] = _CENTRE
        self.vx[g] = SERVE_SPEED * dx / norm
        self.vy[g] = SERVE_SPEED * dy / norm
        self.touched[:, g] = False
        self.rally_steps[g] = 0
        self.serves[g] = serves + 1

    # ----------------------------------------------------------------------------------------------------
    def step(self, actions: np.ndarray) -> np.ndarray:
        """Advance every game one step. ``actions`` is ``(2, n)`` ints in {0, 1, 2}.

        Returns the rewards ``(2, n)`` float32 (+1/-1 per point, zero-sum, plus ``r_for_hit`` per touch).
        ``self.terminated`` / ``self.truncated`` tell which games ended on this step.
        """
        cfg = self.config
        a = np.asarray(actions)
        if a.shape != (2, self.n):
            raise ValueError(f"actions must have shape (2, {self.n}), got {a.shape}")
        move = _MOVE.take(a)
        paddle = self.paddle
        if self._seed_rules:
            moved = paddle + move
            np.copyto(paddle, moved, where=(moved >= 0) & (moved <= PADDLE_Y_MAX))
        else:
            paddle += move
            np.maximum(paddle, 0.0, out=paddle)  # clamped at the walls (np.clip's wrapper costs more than both)
            np.minimum(paddle, PADDLE_Y_MAX, out=paddle)
        self._pos += self._vel

        rewards = np.zeros((2, self.n), dtype=np.float32)
        self.terminated.fill(False)
        if self._seed_rules:
            self._seed_events(rewards)
        else:
            # Walls, paddles and points happen only near the court's edges: handle just those games.
            bx, by = self.bx, self.by
            rare = (bx < LEFT_FACE + BALL_R) | (bx > RIGHT_FACE - BALL_R) | (by < BALL_R) | (by > HEIGHT - BALL_R)
            if rare.any():
                self._classic_events(np.flatnonzero(rare), rewards)

        self.rally_steps += 1
        self.steps += 1
        if cfg.max_rally_steps and self.rally_steps.max() >= cfg.max_rally_steps:
            g = np.flatnonzero(self.rally_steps >= cfg.max_rally_steps)  # the point ends as a draw: a new serve
            self.drawn_rallies[g] += 1
            self._serve(g)
        if cfg.max_steps:
            np.greater_equal(self.steps, cfg.max_steps, out=self.truncated)
            self.truncated &= ~self.terminated
        else:
            self.truncated.fill(False)
        self._record_frame()
        return rewards

    def _seed_events(self, rewards: np.ndarray) -> None:
        bx, by, vx, vy = self.bx, self.by, self.vx, self.vy
        wall = (by - BALL_R <= 0) | (by + BALL_R >= HEIGHT)
        np.negative(vy, out=vy, where=wall)
        # rules="seed" tests the ball's edge strictly inside the paddle's x-range and its centre strictly inside the
        # paddle's y-range, with no regard to the direction of travel.
        left_edge = bx - BALL_R
        hit0 = (left_edge > PADDLE_X) & (left_edge < LEFT_FACE)
        hit0 &= (by > self.paddle[0]) & (by < self.paddle[0] + PADDLE_H)
        np.negative(vx, out=vx, where=hit0)
        right_edge = bx + BALL_R
        hit1 = (right_edge > RIGHT_FACE) & (right_edge < WIDTH - PADDLE_X)
        hit1 &= (by > self.paddle[1]) & (by < self.paddle[1] + PADDLE_H)
        np.negative(vx, out=vx, where=hit1)
        self._touch(np.flatnonzero(hit0), 0, rewards)
        self._touch(np.flatnonzero(hit1), 1, rewards)
        out = (bx < 0) | (bx > WIDTH)
        if out.any():
            self._points(np.flatnonzero(out), rewards)

    def _classic_events(self, g: np.ndarray, rewards: np.ndarray) -> None:
        """Walls, swept paddle hits and points for the games ``g`` whose ball is near an edge."""
        bx, by, vx, vy = self.bx, self.by, self.vx, self.vy
        y = by[g]
        top = g[y < BALL_R]
        if top.size:
            by[top] = 2 * BALL_R - by[top]
            vy[top] = np.abs(vy[top])
        bottom = g[y > HEIGHT - BALL_R]
        if bottom.size:
            by[bottom] = 2 * (HEIGHT - BALL_R) - by[bottom]
            vy[bottom] = -np.abs(vy[bottom])
        # Swept test: the ball's leading edge crossed a paddle face on this step, moving toward it (the left face
        # moving left, the right face moving right: a game meets at most one), and the paddle is there.
        x, v = bx[g], vx[g]
        before = x - v
        left = (x < LEFT_FACE + BALL_R) & (v < 0) & (before >= LEFT_FACE + BALL_R)
        right = (x > RIGHT_FACE - BALL_R) & (v > 0) & (before <= RIGHT_FACE - BALL_R)
        crossed = left | right
        hit, seat = g[crossed], right[crossed].view(np.int8)  # seat 0: the left paddle, 1: the right one
        met = self._overlaps(hit, seat)
        hit, seat = hit[met], seat[met]
        if hit.size:
            bx[hit] = np.where(seat, 2 * (RIGHT_FACE - BALL_R), 2 * (LEFT_FACE + BALL_R)) - bx[hit]
            self._deflect(hit, seat)
            self._touch(hit, seat, rewards)
        x = bx[g]
        out = g[(x < 0) | (x > WIDTH)]
        if out.size:
            self._points(out, rewards)

    def _overlaps(self, g: np.ndarray, seat: np.ndarray) -> np.ndarray:
        """Whether the ball (centre within a radius of the paddle's span) meets seat's paddle in games g."""
        top = self.paddle[seat, g]
        y = self.by[g]
        return (y >= top - BALL_R) & (y <= top + PADDLE_H + BALL_R)

    def _deflect(self, g: np.ndarray, seat: np.ndarray) -> None:
        """Classic deflection off seat's paddle in games g: the ball reflects, and where it meets the paddle turns it
        by up to ``max_deflect_deg`` (edge hits steepen, centre hits keep the angle), clamped to ``max_bounce_deg``;
        each hit speeds the ball up by ``speedup``, capped at ``max_speed``."""
        cfg = self.config
        centre = self.paddle[seat, g] + PADDLE_H / 2
        offset = (self.by[g] - centre) / (PADDLE_H / 2 + BALL_R)
        _clip(offset, 1.0)
        vx, vy = self.vx[g], self.vy[g]
        speed = np.minimum(np.hypot(vx, vy) + cfg.speedup, cfg.max_speed)
        angle = np.arctan2(vy, np.abs(vx)) + offset * self._max_deflect
        _clip(angle, self._max_angle)
        away = speed * np.cos(angle)
        self.vx[g] = np.negative(away, out=away, where=seat == 1)  # off the right paddle, away is to the left
        self.vy[g] = speed * np.sin(angle)

    def _touch(self, g: np.ndarray, seat: int | np.ndarray, rewards: np.ndarray) -> None:
        if g.size:
            self.touched[seat, g] = True
            self.hits[seat, g] += 1
            if self.config.r_for_hit:
                rewards[seat, g] += np.float32(self.config.r_for_hit)

    def _points(self, g: np.ndarray, rewards: np.ndarray) -> None:
        """The ball left the court in games g: the side that touched it in this rally scores; then a new serve.

        A point overwrites any hit reward of the step with +1/-1; without one, rewards stay.
        """
        out_left = self.bx[g] < 0
        right_scores = g[out_left & self.touched[1, g]]
        left_scores = g[~out_left & self.touched[0, g]]
        self.score[1, right_scores] += 1
        self.score[0, left_scores] += 1
        rewards[:, right_scores] = ((-1.0,), (1.0,))
        rewards[:, left_scores] = ((1.0,), (-1.0,))
        score = self.score[:, g]
        self.terminated[g] = np.maximum(score[0], score[1]) >= self.config.points_to_win
        self._serve(g)

    # ----------------------------------------------------------------------------------------------------
    def _frame_of(self, g: np.ndarray | slice) -> np.ndarray:
        """The left seat's normalised view of the current frame of games g, (len(g), 6)."""
        return (self._s[:, g].T * self._scale).astype(np.float32) - self._offset

    def _record_frame(self) -> None:
        k = self.config.frame_stack
        self._head = (self._head + 1) % k
        buf = self._frame_buf  # both seats' frames computed contiguously, then one copy into both ring positions
        np.multiply(self._s, self._scale[:, None], out=buf[0], casting="same_kind")
        buf[0] -= self._offset[:, None]
        np.take(buf[0], _MIRROR_PERM, axis=0, out=buf[1])
        buf[1] *= _MIRROR_SIGN[:, None]
        self._ring[:, :, self._head :: k] = buf.transpose(0, 2, 1)[:, :, None, :]

    def _window(self) -> slice:
        """The ring positions of the k newest frames, oldest first."""
        return slice(self._head + 1, self._head + 1 + self.config.frame_stack)

    def observe(self) -> np.ndarray:
        """Egocentric stacked observations ``(2, n, k, 6)`` float32 in [-1, 1], oldest frame first.

        Per frame: ball x, ball y, own paddle y, opponent paddle y, ball vx, ball vy, positions scaled from the
        court to [-1, 1] and velocities divided by the largest possible component. The right seat sees x and vx
        mirrored and the paddles swapped, so both seats see themselves on the left.
        """
        return self._ring[:, :, self._window()].copy()

    def action_masks(self) -> list[None]:
        """Pong has no action masks: every action is legal for both seats."""
        return [None, None]

    def to_act(self) -> np.ndarray:
        """Both seats act at every step of every game: ``(2, n)`` all True."""
        return np.ones((2, self.n), dtype=bool)

    # ----------------------------------------------------------------------------------------------------
    def outcome(self) -> np.ndarray:
        """Points per seat for finished games: 1 win, 0.5 draw, 0 loss (by score), shape (2, n)."""
        diff = np.sign(self.score[0] - self.score[1]).astype(np.float64)
        left = 0.5 + 0.5 * diff
        return np.stack([left, 1.0 - left])

    _STATE_FIELDS = ("bx", "by", "vx", "vy", "paddle", "score", "touched", "rally_steps", "steps", "serves",
                     "key", "hits", "drawn_rallies", "terminated", "truncated")

    def get_state(self, games: np.ndarray | list[int] | None = None) -> dict[str, Any]:
        """An exact copy of the state of some games (all by default), history included."""
        g = slice(None) if games is None else np.asarray(games, dtype=np.int64)
        state = {name: getattr(self, name)[..., g].copy() for name in self._STATE_FIELDS}
        state["frames"] = np.array(self._ring[0][g, self._window()])  # the left seat's view, oldest first
        return state

    def set_state(self, state: dict[str, Any], games: np.ndarray | list[int] | None = None) -> None:
        """Restore what :meth:`get_state` returned (into the same or other game slots)."""
        g = slice(None) if games is None else np.asarray(games, dtype=np.int64)
        for name in self._STATE_FIELDS:
            getattr(self, name)[..., g] = state[name]
        frames = np.asarray(state["frames"], dtype=np.float32)
        if frames.shape[1] != self.config.frame_stack:
            raise ValueError(f"state has {frames.shape[1]} frames, this core stacks {self.config.frame_stack}")
        rows = np.arange(self.n)[g]
        k = self.config.frame_stack
        ring = frames[:, (np.arange(2 * k) - self._head - 1) % k]  # ring position p holds window frame p - head - 1
        self._ring[0, rows] = ring
        self._ring[1, rows] = _mirror(ring)
