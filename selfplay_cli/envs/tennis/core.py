"""The tennis game's batched core: N games in numpy arrays, stepped together (no Python loop over games).

Layout: the ball is ``ball[(x, y, vx, vy, spin), game]`` and the bats ``bat[(x, y, vx, vy, angle, rate), seat,
game]``, in world coordinates (x along the table, seat 0 at the -x end) except a bat's angle and rate, which are
egocentric tilts (see :mod:`selfplay_cli.envs.tennis`). A step moves the bats (clamped to their boxes), then runs
:data:`~selfplay_cli.envs.tennis.config.SUBSTEPS` physics substeps, each a flight step of every ball in play and swept
tests against both bats, the net and the table; the few games with a contact in a substep are then resolved on
their own (index arrays), which is where the rules are applied.

Randomness is counter-based (:mod:`selfplay_cli.envs.rng`): each game has a 64-bit key from its seed, and the
first server and every toss's place are ``hash(key, counter)``; a game therefore plays the same alone or in a batch
of thousands, and ``reset(games, seeds)`` reproduces it.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..contract import IllegalActionError, reset_slots
from ..rng import game_key, uniform
from .config import (
    ANGLE_MAX,
    BALL_R,
    BAT_0,
    DOUBLE_BOUNCE,
    DOUBLE_HIT,
    DT,
    E_BAT,
    E_TABLE,
    FLOOR_Y,
    HIT_COOLDOWN,
    HIT_OUT,
    HOME_X,
    HOME_Y,
    INTO_NET,
    K_DRAG,
    K_MAGNUS,
    LIVE_OPTIONS,
    MISSED_SERVE,
    MU_BAT,
    MU_TABLE,
    N_FEATURES,
    NET,
    NET_GAP,
    NET_H,
    NO_POINT,
    NONE,
    NOT_RETURNED,
    OBS_HIGH,
    OBS_LOW,
    OMEGA_MAX,
    OUT,
    OWN_HALF,
    SERVE_NO_BOUNCE,
    SPIN_DECAY,
    SPIN_SCALE,
    SUBSTEPS,
    TABLE_0,
    TABLE_HALF,
    TOSS_VY,
    TOSS_X,
    TOSS_Y,
    V_MAX,
    VEL_SCALE,
    VOLLEY,
    X_BACK,
    X_OUT,
    Y_HIGH,
    Y_LOW,
    H,
    TennisConfig,
)
from .physics import accel, contact, game_won, server_of

_SIGMA = np.array([[1.0], [-1.0]])  # each seat's forward along x: seat 0 plays toward +x
_LOW64, _HIGH64 = OBS_LOW.astype(np.float64), OBS_HIGH.astype(np.float64)
_NEVER = 1e9  # time since the last hit, before any
_PER_DT = 1.0 / DT


class TennisCore:
    """N tennis games stepped at once (the :class:`~selfplay_cli.envs.contract.BatchedCore` protocol).

    ``actions[seat]``: ``(n, 3)`` floats in [-1, 1], or ``(n, 3)`` ints in 0..2 with ``discrete``. Beyond the
    protocol's arrays the core exposes the rally for tests and statistics: ``server``, ``hitter`` (the last hitter,
    -1 while a toss is in the air), ``landed`` (the last hit has landed on the opponent's half), ``tossing``,
    ``surface`` (the last surface the ball touched), ``turn`` (who must hit next), ``reason`` and ``winner`` of the
    last point, and per seat and game the counts ``serves``, ``serves_in`` (serves that landed on the receiver's
    half), ``returns`` and ``returns_in``. The core never resets a game by itself: a finished game stands still,
    keeping its score, until :meth:`reset`.
    """

    n_seats = 2

    def __init__(self, n_games: int, config: TennisConfig | None = None) -> None:
        if n_games < 1:
            raise ValueError(f"n_games must be at least 1, not {n_games}")
        self.n = n = int(n_games)
        self.config = config or TennisConfig()
        self.discrete = self.config.discrete
        self.ball = np.zeros((5, n))  # x, y, vx, vy, spin
        self.bat = np.zeros((6, 2, n))  # x, y, vx, vy, angle, rate per seat
        self.score = np.zeros((2, n))
        self.steps = np.zeros(n, dtype=np.int64)
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        self.over = np.zeros(n, dtype=bool)
        self.key = np.zeros(n, dtype=np.uint64)
        self.first_server = np.zeros(n, dtype=np.int8)
        self.server = np.zeros(n, dtype=np.int8)
        self.tossing = np.zeros(n, dtype=bool)
        self.hitter = np.full(n, -1, dtype=np.int8)
        self.landed = np.zeros(n, dtype=bool)
        self.serve_shot = np.zeros(n, dtype=bool)  # the ball in flight was served
        self.serve_bounced = np.zeros(n, dtype=bool)  # (serve_bounce) the serve has bounced on the server's half
        self.since_hit = np.full(n, _NEVER)
        self.clock = np.zeros(n)  # seconds the toss has been in the air
        self.surface = np.zeros(n, dtype=np.int8)
        self.reason = np.zeros(n, dtype=np.int8)
        self.winner = np.full(n, -1, dtype=np.int8)
        self.serves = np.zeros((2, n), dtype=np.int64)
        self.serves_in = np.zeros((2, n), dtype=np.int64)
        self.returns = np.zeros((2, n), dtype=np.int64)
        self.returns_in = np.zeros((2, n), dtype=np.int64)
        self._rewards = np.zeros((2, n))
        self._point_over = np.zeros(n, dtype=bool)
        self._apply_config()
        self.reset(np.arange(n), np.arange(n))

    def _apply_config(self) -> None:
        cfg = self.config
        self.half = 0.5 * cfg.bat_length
        self._kd, self._km = K_DRAG * cfg.drag, K_MAGNUS * cfg.magnus

    # ----------------------------------------------------------------------------------------------------
    @property
    def turn(self) -> np.ndarray:
        """``(n,)``: the seat that must hit the ball next (the server while the toss is in the air)."""
        return np.where(self.tossing, self.server, 1 - self.hitter).astype(np.int8)

    def set_options(self, **values: Any) -> None:
        """Change ``hit_reward``, ``return_reward``, ``point_reward`` and ``bat_scale`` of every game, running ones
        included, from the next step on (the curricula's hook). Values are checked as the options are (finite;
        ``bat_scale`` in (0, 5]; ``point_reward`` not negative); anything else is refused."""
        other = sorted(set(values) - set(LIVE_OPTIONS))
        if other:
            raise ValueError(f"set_options changes only {', '.join(LIVE_OPTIONS)}, not {', '.join(other)}")
        self.config = replace(self.config, **values)
        self._apply_config()

    # ----------------------------------------------------------------------------------------------------
    def reset(self, games: Any, seeds: Any) -> None:
        """New games in the slots ``games`` with the given seeds."""
        g, s = reset_slots(games, seeds)
        if g.size == 0:
            return
        self.key[g] = game_key(s)
        self.first_server[g] = (uniform(self.key[g], np.zeros(g.size, dtype=np.int64)) >= 0.5).astype(np.int8)
        self.score[:, g] = 0.0
        self.steps[g] = 0
        self.terminated[g] = self.truncated[g] = self.over[g] = False
        self.reason[g] = NO_POINT
        self.winner[g] = -1
        self.surface[g] = NONE
        for counts in (self.serves, self.serves_in, self.returns, self.returns_in):
            counts[:, g] = 0
        self._new_point(g)

    def _new_point(self, g: np.ndarray) -> None:
        """The toss of the next point: the ball thrown up in front of the server's bat, both bats home."""
        points = self.score[:, g].sum(axis=0).astype(np.int64)
        server = server_of(self.first_server[g], points, self.config.points_to_win)
        self.server[g] = server
        u = uniform(self.key[g], 1 + points)
        forward = np.where(server == 0, 1.0, -1.0)
        self.ball[0, g] = forward * (TOSS_X + (2.0 * u - 1.0) * self.config.toss_jitter)
        self.ball[1, g] = TOSS_Y
        self.ball[2, g] = 0.0
        self.ball[3, g] = TOSS_VY
        self.ball[4, g] = 0.0
        self.bat[0, :, g] = (_SIGMA * HOME_X).T
        self.bat[1, :, g] = HOME_Y
        self.bat[2:, :, g] = 0.0
        self.tossing[g] = True
        self.hitter[g] = -1
        self.landed[g] = False
        self.serve_shot[g] = False
        self.serve_bounced[g] = False
        self.since_hit[g] = _NEVER
        self.clock[g] = 0.0  # (surface keeps what ended the last point: the toss touches nothing)

    # ----------------------------------------------------------------------------------------------------
    def _actions(self, actions: Any, running: np.ndarray) -> np.ndarray:
        n = self.n
        if self.discrete:
            a = np.asarray(actions)
            if a.shape != (2, n, 3):
                a = a.reshape(2, n, 3)
            bad = ((a < 0) | (a > 2) | (a != np.floor(a))).any(axis=2) & running
            if bad.any():
                seat, game = np.argwhere(bad)[0]
                raise IllegalActionError(seat, game, a[seat, game].tolist(), "outside MultiDiscrete([3, 3, 3])")
            return a.astype(np.float64) - 1.0
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (2, n, 3):
            a = a.reshape(2, n, 3)
        bad = ~np.isfinite(a).all(axis=2) & running
        if bad.any():
            seat, game = np.argwhere(bad)[0]
            raise IllegalActionError(seat, game, a[seat, game].tolist(), "not finite numbers")
        return np.clip(a, -1.0, 1.0)

    def step(self, actions: Any) -> np.ndarray:
        """One step of every running game; the rewards ``(2, n)`` float32."""
        running = ~self.over
        a = self._actions(actions, running)
        rewards = self._rewards
        rewards.fill(0.0)
        point_over = self._point_over
        point_over.fill(False)
        bat = self.bat
        # The bats: tilt, then position within the box (no part of a bat across the net's plane)
        x0, y0, ang0 = bat[0].copy(), bat[1].copy(), bat[4].copy()
        ang1 = np.clip(ang0 + a[..., 2] * (OMEGA_MAX * DT), -ANGLE_MAX, ANGLE_MAX)
        ego = _SIGMA * x0 + a[..., 0] * (V_MAX * DT)
        ego = np.minimum(np.maximum(ego, -X_BACK), -(NET_GAP + self.half * np.abs(np.sin(ang1))))
        x1 = _SIGMA * ego
        y1 = np.clip(y0 + a[..., 1] * (V_MAX * DT), Y_LOW, Y_HIGH)
        kept = None if running.all() else bat[:, :, ~running].copy()  # finished games stand still
        bat[0], bat[1], bat[4] = x1, y1, ang1
        bat[2] = np.clip((x1 - x0) * _PER_DT, -V_MAX, V_MAX)
        bat[3] = np.clip((y1 - y0) * _PER_DT, -V_MAX, V_MAX)
        bat[5] = (ang1 - ang0) * _PER_DT
        if kept is not None:
            bat[:, :, ~running] = kept
            x1, y1, ang1 = bat[0], bat[1], bat[4]
        cos0, sin0 = np.cos(ang0), np.sin(ang0)
        motion = (x0, y0, x1 - x0, y1 - y0, cos0, sin0, np.cos(ang1) - cos0, np.sin(ang1) - sin0)
        live = running.copy()
        for k in range(SUBSTEPS):
            self._substep(k, motion, live)
            live &= ~point_over
        # The serve clock
        toss = self.tossing & live
        self.clock[toss] += DT
        late = toss & (self.clock >= self.config.serve_time - 1e-9)
        if late.any():
            g = np.flatnonzero(late)
            self._award(g, 1 - self.server[g], MISSED_SERVE)
        # Points, games, next tosses
        if point_over.any():
            g = np.flatnonzero(point_over)
            w = self.winner[g].astype(np.int64)
            self.score[w, g] += 1.0
            pr = self.config.point_reward
            rewards[w, g] += pr
            rewards[1 - w, g] -= pr
            won = game_won(self.score[w, g], self.score[1 - w, g], self.config.points_to_win)
            self.terminated[g[won]] = True
            if (~won).any():
                self._new_point(g[~won])
        self.steps[running] += 1
        np.greater_equal(self.steps, self.config.max_steps, out=self.truncated)
        self.truncated &= running & ~self.terminated
        self.terminated &= running
        self.over |= self.terminated | self.truncated
        return rewards.astype(np.float32)

    def _substep(self, k: int, motion: tuple, live: np.ndarray) -> None:
        """One physics substep of the balls in play (``live``): flight, then bats, net, table and the room."""
        x0, y0, dx, dy, cos0, sin0, dcos, dsin = motion
        b = self.ball
        px, py, vx, vy, w = b[0].copy(), b[1].copy(), b[2], b[3], b[4]
        ax, ay = accel(vx, vy, w, self._kd, self._km)
        nvx, nvy = vx + ax * H, vy + ay * H
        nx, ny = px + nvx * H, py + nvy * H
        nw = w * (1.0 - SPIN_DECAY * H)
        if live.all():
            b[0], b[1], b[2], b[3], b[4] = nx, ny, nvx, nvy, nw
        else:
            b[0], b[1] = np.where(live, nx, px), np.where(live, ny, py)
            b[2], b[3], b[4] = np.where(live, nvx, vx), np.where(live, nvy, vy), np.where(live, nw, w)
        self.since_hit += H
        # --- bats: the ball's path against each bat's line, the bat moving and turning through the substep
        fa, fb = k / SUBSTEPS, (k + 1) / SUBSTEPS
        cxa, cya, cxb, cyb = x0 + dx * fa, y0 + dy * fa, x0 + dx * fb, y0 + dy * fb
        ca, sa, cb, sb = cos0 + dcos * fa, sin0 + dsin * fa, cos0 + dcos * fb, sin0 + dsin * fb
        d0 = (px - cxa) * (_SIGMA * ca) + (py - cya) * sa
        d1 = (b[0] - cxb) * (_SIGMA * cb) + (b[1] - cyb) * sb
        side = np.where(d0 >= 0.0, 1.0, -1.0)
        sd1 = side * d1
        near = (sd1 < BALL_R) & live
        done = np.zeros(self.n, dtype=bool)
        if near.any():
            done = self._bats(near, side, d0, d1, px, py, (cxa, cya, cxb, cyb, cb, sb))
        # --- net, table, room (what a bat did not just touch)
        bx, by = b[0], b[1]
        open_ = live & ~done
        low = by < NET_H + BALL_R
        crossed = (px < 0.0) != (bx < 0.0)
        net = open_ & ((crossed | (np.abs(bx) < BALL_R)) & low)
        if net.any():
            g = np.flatnonzero(net)
            f = np.clip(px[g] / np.where(crossed[g], px[g] - bx[g], 1.0), 0.0, 1.0)
            y_at = np.where(crossed[g], py[g] + f * (by[g] - py[g]), by[g])
            g = g[y_at >= 0.0]  # below the table's surface the ball was already dead
            if g.size:
                b[0, g] = 0.0
                self.surface[g] = NET
                self._net(g)
                open_[g] = False
        table = open_ & (by < BALL_R) & (py >= BALL_R) & (b[3] < 0.0) & (np.abs(bx) <= TABLE_HALF)
        if table.any():
            g = np.flatnonzero(table)
            zero = np.zeros(g.size)
            b[2, g], b[3, g], b[4, g] = contact(b[2, g], b[3, g], b[4, g], zero, zero + 1.0, 0.0, 0.0, E_TABLE,
                                                MU_TABLE)
            b[1, g] = np.maximum(2.0 * BALL_R - by[g], BALL_R)
            half = (b[0, g] >= 0.0).astype(np.int8)
            self.surface[g] = TABLE_0 + half
            self._table(g, half)
            open_[g] = False
        dead = open_ & ((by <= FLOOR_Y + BALL_R) | (np.abs(bx) > X_OUT) | ((by < 0.0) & (np.abs(bx) < TABLE_HALF)))
        if dead.any():
            g = np.flatnonzero(dead)
            self.surface[g] = OUT
            self._dead(g)

    def _bats(self, near: np.ndarray, side: np.ndarray, d0: np.ndarray, d1: np.ndarray, px: np.ndarray,
              py: np.ndarray, pose: tuple) -> np.ndarray:
        """Resolve the bat contacts among the candidates ``near`` (seat, game); returns the games hit."""
        cxa, cya, cxb, cyb, cb, sb = pose
        b, bat = self.ball, self.bat
        seat, g = np.nonzero(near)
        s = side[seat, g]
        sd0, sd1 = s * d0[seat, g], s * d1[seat, g]
        f = np.where(sd0 > BALL_R, (sd0 - BALL_R) / np.maximum(sd0 - sd1, 1e-12), 1.0)
        f = np.clip(f, 0.0, 1.0)
        sig = _SIGMA[seat, 0]
        inv = 1.0 / np.sqrt(cb[seat, g] ** 2 + sb[seat, g] ** 2)
        nx, ny = sig * cb[seat, g] * inv, sb[seat, g] * inv  # the face normal at the substep's end
        tx, ty = -ny, nx
        cx = cxa[seat, g] + f * (cxb[seat, g] - cxa[seat, g])
        cy = cya[seat, g] + f * (cyb[seat, g] - cya[seat, g])
        qx = px[g] + f * (b[0, g] - px[g])
        qy = py[g] + f * (b[1, g] - py[g])
        tau = (qx - cx) * tx + (qy - cy) * ty
        omega = sig * bat[5, seat, g]  # the face's turn rate in the world
        cvx = bat[2, seat, g] - omega * tau * nx  # the contact point's velocity
        cvy = bat[3, seat, g] - omega * tau * ny
        approach = s * ((b[2, g] - cvx) * nx + (b[3, g] - cvy) * ny) < 0.0
        hit = (np.abs(tau) <= self.half + 0.5 * BALL_R) & approach
        if not hit.any():
            return np.zeros(self.n, dtype=bool)
        seat, g, s, nx, ny, tx, ty, tau, cvx, cvy = (v[hit] for v in (seat, g, s, nx, ny, tx, ty, tau, cvx, cvy))
        g, first = np.unique(g, return_index=True)  # one bat per game (bats never reach one ball together)
        seat, s, nx, ny, tx, ty, tau, cvx, cvy = (v[first] for v in (seat, s, nx, ny, tx, ty, tau, cvx, cvy))
        b[2, g], b[3, g], b[4, g] = contact(b[2, g], b[3, g], b[4, g], s * nx, s * ny, cvx, cvy, E_BAT, MU_BAT)
        tau = np.clip(tau, -self.half, self.half)
        b[0, g] = cxb[seat, g] + tau * tx + s * nx * (BALL_R + 1e-4)
        b[1, g] = cyb[seat, g] + tau * ty + s * ny * (BALL_R + 1e-4)
        self._bat(g, seat.astype(np.int8))
        done = np.zeros(self.n, dtype=bool)
        done[g] = True
        return done

    # ----------------------------------------------------------------------------------------------------
    # The rules: each event on the games g where it happened
    def _award(self, g: np.ndarray, winner: Any, reason: int) -> None:
        if g.size == 0:
            return
        self.winner[g] = winner
        self.reason[g] = reason
        self._point_over[g] = True

    def _legal_hit(self, g: np.ndarray, seat: np.ndarray, serve: bool) -> None:
        self.hitter[g] = seat
        self.landed[g] = False
        self.serve_shot[g] = serve
        self.serve_bounced[g] = False
        self.since_hit[g] = 0.0
        self.tossing[g] = False
        (self.serves if serve else self.returns)[seat, g] += 1
        if self.config.hit_reward:  # a legal stroke, not a foul's touch (see the package's Rewards)
            self._rewards[seat, g] += self.config.hit_reward

    def _bat(self, g: np.ndarray, seat: np.ndarray) -> None:
        hitter, toss, landed = self.hitter[g], self.tossing[g], self.landed[g]
        same = hitter == seat
        stroke = same & ~toss & (self.since_hit[g] < HIT_COOLDOWN)  # the same stroke still: physics only
        self.surface[g] = np.where(stroke, self.surface[g], BAT_0 + seat)
        serve = toss & (seat == self.server[g])
        if serve.any():
            self._legal_hit(g[serve], seat[serve], True)
        self._award(g[toss & ~serve], self.server[g[toss & ~serve]], VOLLEY)
        play = ~toss & ~stroke
        self._award(g[play & same & landed], seat[play & same & landed], NOT_RETURNED)
        self._award(g[play & same & ~landed], 1 - seat[play & same & ~landed], DOUBLE_HIT)
        back = play & ~same & landed
        if back.any():
            self._legal_hit(g[back], seat[back], False)
        self._award(g[play & ~same & ~landed], hitter[play & ~same & ~landed], VOLLEY)

    def _table(self, g: np.ndarray, half: np.ndarray) -> None:
        toss, landed, h = self.tossing[g], self.landed[g], self.hitter[g]
        self._award(g[toss], 1 - self.server[g[toss]], MISSED_SERVE)
        dealt = toss
        if self.config.serve_bounce:  # a serve's first bounce: on the server's own half, else a fault
            first = ~toss & self.serve_shot[g] & ~self.serve_bounced[g]
            self.serve_bounced[g[first & (half == h)]] = True
            short = first & (half != h)
            self._award(g[short], 1 - h[short], SERVE_NO_BOUNCE)
            dealt = toss | first
        good = ~dealt & ~landed & (half != h)
        if good.any():
            gg, hh = g[good], h[good]
            self.landed[gg] = True
            served = self.serve_shot[gg]
            self.serves_in[hh[served], gg[served]] += 1
            self.returns_in[hh[~served], gg[~served]] += 1
            if self.config.return_reward:  # the stroke landed on the opponent's half (practice)
                self._rewards[hh, gg] += self.config.return_reward
        own = ~dealt & ~landed & (half == h)
        self._award(g[own], 1 - h[own], OWN_HALF)
        again = ~dealt & landed
        self._award(g[again], h[again], np.where(half[again] != h[again], DOUBLE_BOUNCE, NOT_RETURNED))

    def _net(self, g: np.ndarray) -> None:
        self._ended_by(g, INTO_NET)

    def _dead(self, g: np.ndarray) -> None:
        self._ended_by(g, HIT_OUT)

    def _ended_by(self, g: np.ndarray, fault: int) -> None:
        """The ball is dead (net or out): a missed serve, the last hitter's fault before it landed, or after it
        landed the opponent's failure to return it."""
        toss, landed, h = self.tossing[g], self.landed[g], self.hitter[g]
        self._award(g[toss], 1 - self.server[g[toss]], MISSED_SERVE)
        self._award(g[~toss & ~landed], 1 - h[~toss & ~landed], fault)
        self._award(g[~toss & landed], h[~toss & landed], NOT_RETURNED)

    # ----------------------------------------------------------------------------------------------------
    def observe(self) -> np.ndarray:
        """Each seat's 25 egocentric values ``(2, n, 25)`` float32, clipped to the declared bounds."""
        b, bat, sig = self.ball, self.bat, _SIGMA
        other = bat[:, ::-1]
        me = np.array([0, 1], dtype=np.int8)[:, None]
        play = ~self.tossing
        mine = play & (self.hitter == me)
        theirs = play & (self.hitter == 1 - me)
        toss = self.tossing & (self.server == me)
        left = np.where(self.tossing, 1.0 - self.clock / self.config.serve_time, 0.0)
        vs = 1.0 / VEL_SCALE
        ones = np.ones((2, 1))
        feats = (
            sig * bat[0], bat[1], sig * bat[2] * vs, bat[3] * vs, bat[4], bat[5] * (1.0 / OMEGA_MAX),
            sig * other[0], other[1], sig * other[2] * vs, other[3] * vs, other[4], other[5] * (1.0 / OMEGA_MAX),
            sig * b[0], ones * b[1], sig * b[2] * vs, ones * b[3] * vs, sig * b[4] * (1.0 / SPIN_SCALE),
            theirs & ~self.landed, theirs & self.landed, mine & ~self.landed, mine & self.landed,
            toss, self.tossing & ~toss, ones * left, np.full((2, self.n), 2.0 * self.half),
        )
        obs = np.empty((2, self.n, N_FEATURES))
        for i, f in enumerate(feats):
            obs[:, :, i] = f
        np.clip(obs, _LOW64, _HIGH64, out=obs)
        return obs.astype(np.float32)

    def action_masks(self) -> list[None]:
        return [None, None]

    def to_act(self) -> np.ndarray:
        """``(2, n)``: both seats act in every running game."""
        return np.broadcast_to(~self.over, (2, self.n)).copy()

    # ----------------------------------------------------------------------------------------------------
    _STATE = ("ball", "bat", "score", "steps", "terminated", "truncated", "over", "key", "first_server", "server",
              "tossing", "hitter", "landed", "serve_shot", "serve_bounced", "since_hit", "clock", "surface", "reason",
              "winner", "serves", "serves_in", "returns", "returns_in")

    def get_state(self, games: Any = None) -> dict[str, np.ndarray]:
        """A copy of the games' state (all games when None), game on the last axis."""
        g = np.arange(self.n) if games is None else np.asarray(games, dtype=np.int64).reshape(-1)
        return {name: getattr(self, name)[..., g].copy() for name in self._STATE}

    def set_state(self, state: dict[str, np.ndarray], games: Any = None) -> None:
        """Put a state from :meth:`get_state` into the slots ``games`` (all when None)."""
        g = np.arange(self.n) if games is None else np.asarray(games, dtype=np.int64).reshape(-1)
        for name in self._STATE:
            getattr(self, name)[..., g] = state[name]



def mirrored(state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The state of the mirrored world (x -> -x): the ball's x, vx and spin negated, the seats swapped (their bats'
    x and vx negated, their egocentric tilts kept), and every seat-indexed record swapped with them."""
    m = {k: v.copy() for k, v in state.items()}
    m["ball"][[0, 2, 4]] *= -1.0
    bat = state["bat"][:, ::-1].copy()
    bat[[0, 2]] *= -1.0
    m["bat"] = bat
    for name in ("score", "serves", "serves_in", "returns", "returns_in"):
        m[name] = state[name][::-1].copy()
    for name in ("first_server", "server", "winner", "hitter"):
        v = state[name]
        m[name] = np.where(v >= 0, 1 - v, v).astype(v.dtype)
    s = state["surface"]
    swap = {TABLE_0: TABLE_0 + 1, TABLE_0 + 1: TABLE_0, BAT_0: BAT_0 + 1, BAT_0 + 1: BAT_0}
    m["surface"] = np.array([swap.get(int(v), int(v)) for v in s.reshape(-1)], dtype=s.dtype).reshape(s.shape)
    return m

