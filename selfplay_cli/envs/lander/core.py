"""The lander game's batched core: N games, one Box2D world each, stepped in one process.

Everything that is not a call into Box2D is done once per step for all landers of all games with numpy (actions to
engine powers, dispersion to impulses, positions to observations and rewards, endings); what is left in Python is
one loop over the landers that fire (one impulse call each), one ``Step`` per running world and one loop reading
each flying lander's position, velocity, angle, spin and sleep. New games take gymnasium's opening step in Python
floats (:func:`read_lander`), game by game. The arithmetic is gymnasium's, operation for operation, so a one-lander
game is gymnasium's ``LunarLander-v3`` game for the same seed.

Layout: seats (landers) lead, games follow: a lander is ``(seat, game)``, flat index ``k = seat * n + game``.
Randomness: each game has its own ``numpy.random.Generator`` seeded by the game's seed (as gymnasium seeds its
own), so a game plays the same alone or in a batch. Draws per game, in gymnasium's order: the terrain (12), each
lander's initial force (2 each), the wind's phases (2, with wind), then at every step 2 dispersion values per
lander (drawn for every lander, flying or not; taken from blocks of 32 steps' draws, the same stream).
"""

from __future__ import annotations

import math
import threading
from math import sqrt as _sqrt
from typing import Any

import Box2D
import numpy as np
from Box2D import _Box2D
from Box2D.b2 import bodyDef, dynamicBody, edgeShape, fixtureDef, polygonShape, revoluteJointDef, staticBody

from ..contract import IllegalActionError, reset_slots
from .config import (
    CHUNKS,
    CRASHED,
    FLYING,
    FPS,
    HELIPAD_Y,
    INITIAL_RANDOM,
    LANDED,
    LANDER_POLY,
    LEG_AWAY,
    LEG_DOWN,
    LEG_H,
    LEG_SPRING_TORQUE,
    LEG_W,
    MAIN_ENGINE_POWER,
    MAIN_ENGINE_Y_LOCATION,
    N_FEATURES,
    OBS_HIGH,
    OBS_LOW,
    OUT,
    SCALE,
    SIDE_ENGINE_AWAY,
    SIDE_ENGINE_HEIGHT,
    SIDE_ENGINE_POWER,
    VIEWPORT_H,
    VIEWPORT_W,
    H,
    LanderConfig,
    W,
)

# Collision categories: the moon is Box2D's default 0x0001; landers collide with the moon and each other
BODY_BITS, LEG_BITS = 0x0010, 0x0020
_COLLIDE = 0x0001 | BODY_BITS | LEG_BITS
_TIME_STEP, _VEL_ITERS, _POS_ITERS = 1.0 / FPS, 6 * 30, 2 * 30
_BLOCK = 32  # steps of dispersion a game draws at a time

# gymnasium's observation constants, kept as its expressions evaluate them
_X_HALF = VIEWPORT_W / SCALE / 2
_Y_ZERO = HELIPAD_Y + LEG_DOWN / SCALE
_Y_HALF = VIEWPORT_H / SCALE / 2
_MAIN_Y = MAIN_ENGINE_Y_LOCATION / SCALE
_LOW64, _HIGH64 = OBS_LOW.astype(np.float64), OBS_HIGH.astype(np.float64)
_LOW64[6:] = 0.0  # +0.0: a leg off the ground reads 0, not -0
_POLY = [(x / SCALE, y / SCALE) for x, y in LANDER_POLY]

# Box2D's functions called directly, without pybox2d's Python wrappers of them (properties, methods that take a
# definition apart and check it again each time): reading a lander back costs a third less, and a world is made in
# half the time
_POSITION, _VELOCITY = _Box2D.b2Body___GetPosition, _Box2D.b2Body___GetLinearVelocity
_ANGLE, _SPIN, _AWAKE = _Box2D.b2Body___GetAngle, _Box2D.b2Body___GetAngularVelocity, _Box2D.b2Body___IsAwake
_X, _Y = _Box2D.b2Vec2_x_get, _Box2D.b2Vec2_y_get
_IMPULSE, _FORCE = _Box2D.b2Body_ApplyLinearImpulse, _Box2D.b2Body_ApplyForceToCenter
_CREATE_BODY, _CREATE_JOINT = _Box2D.b2World___CreateBody, _Box2D.b2World___CreateJoint
_CREATE_FIXTURE, _SET_ACTIVE = _Box2D.b2Body___CreateFixture, _Box2D.b2Body___SetActive
_SET_DATA, _DATA = _Box2D.b2Fixture___SetUserData, _Box2D.b2Fixture___GetUserData
_FIXTURE_A, _FIXTURE_B = _Box2D.b2Contact___GetFixtureA, _Box2D.b2Contact___GetFixtureB
_EDGE_V1, _EDGE_V2 = _Box2D.b2EdgeShape_vertex1_set, _Box2D.b2EdgeShape_vertex2_set

# A world's definitions (gymnasium's keywords), made once: Box2D copies a definition and its shape into what it makes.
# The moon: a static body with the floor's edge (pybox2d's default fixture for ``shapes=``) and one edge fixture per
# terrain chunk (the edge's vertices set as ``edgeShape.vertices`` sets two). A lander: a dynamic body and two legs,
# one fixture each, the legs joined to the body by revolute joints. Those set anew for each body are each thread's
# own (:class:`_Definitions`): worlds made in two threads at once take nothing from each other.
_MOON = bodyDef(type=staticBody)
_FLOOR = fixtureDef(shape=edgeShape(vertices=[(0, 0), (W, 0)]))
_BODY_SHAPE, _LEG_SHAPE = polygonShape(vertices=_POLY), polygonShape(box=(LEG_W / SCALE, LEG_H / SCALE))
_BODY_FIXTURE = fixtureDef(shape=_BODY_SHAPE, density=5.0, friction=0.1, categoryBits=BODY_BITS, maskBits=_COLLIDE,
                           restitution=0.0)
_LEG_FIXTURE = fixtureDef(shape=_LEG_SHAPE, density=1.0, restitution=0.0, categoryBits=LEG_BITS, maskBits=_COLLIDE)


def _leg_joint(i: int) -> Any:
    """The joint of the leg on side ``i`` (-1 left, +1 right); its bodies are set when it is used."""
    rjd = revoluteJointDef(localAnchorA=(0, 0), localAnchorB=(i * LEG_AWAY / SCALE, LEG_DOWN / SCALE),
                           enableMotor=True, enableLimit=True, maxMotorTorque=LEG_SPRING_TORQUE, motorSpeed=+0.3 * i)
    rjd.lowerAngle, rjd.upperAngle = (0.9 - 0.5, 0.9) if i == -1 else (-0.9, -0.9 + 0.5)
    return rjd


class _Definitions(threading.local):
    """The definitions a world's making sets anew for each body it makes (positions, a terrain edge's vertices, a
    joint's bodies), one set per thread."""

    def __init__(self) -> None:
        self.edge = edgeShape(vertices=[(0, 0), (1, 0)])
        self.ground = fixtureDef(shape=self.edge, density=0, friction=0.1)
        self.lander, self.leg = bodyDef(type=dynamicBody, angle=0.0), bodyDef(type=dynamicBody)
        self.joints = [_leg_joint(-1), _leg_joint(+1)]


_DEFINITIONS = _Definitions()


def read_lander(body: Any, position: Any, velocity: Any, legs: Any) -> tuple[float, float, list[float], float]:
    """One lander read back from Box2D after a step (its body, position and velocity vectors, its legs' ground
    contacts), in Python floats: its x and y, gymnasium's state (8 values, unclipped) and its shaping. The same
    doubles as the core's arrays: the same IEEE operations in the same order (math's sqrt, like numpy's, is correctly
    rounded)."""
    x, y, angle = _X(position), _Y(position), _ANGLE(body)
    s0 = (x - _X_HALF) / _X_HALF
    s1 = (y - _Y_ZERO) / _Y_HALF
    s2 = _X(velocity) * _X_HALF / FPS
    s3 = _Y(velocity) * _Y_HALF / FPS
    s5 = 20.0 * _SPIN(body) / FPS
    s6, s7 = (1.0 if legs[0] > 0 else 0.0), (1.0 if legs[1] > 0 else 0.0)
    shaping = (-100 * _sqrt(s0 * s0 + s1 * s1) - 100 * _sqrt(s2 * s2 + s3 * s3) - 100 * abs(angle)
               + 10 * s6 + 10 * s7)
    return x, y, [s0, s1, s2, s3, angle, s5, s6, s7], shaping


def seed_generator(seed: int) -> np.random.Generator:
    """A game's generator: ``default_rng(seed)`` (gymnasium's seeding); a negative seed wraps to 64 bits."""
    return np.random.Generator(np.random.PCG64(int(seed) % (1 << 64)))  # (default_rng's, without its checks)


class _Contacts(Box2D.b2ContactListener):
    """Box2D's contact callbacks for one world, written into the core's arrays (or the one-game lists of
    :class:`~.scalar.ScalarLander`): ``crashed[k]``, ``legs[k][leg]``.

    A lander's fixtures' ``userData`` is ``3 * k + part`` (part 0 the lander body, 1 and 2 its legs) for lander ``k``,
    None for the moon's. A lander body touching anything crashes it; a leg touching the moon counts as a ground
    contact (a count, so a leg on two terrain edges at once stays in contact until it leaves both; with ``flag``,
    gymnasium's flag, set by any contact beginning and cleared by any ending)."""

    def __init__(self, crashed: Any, legs: Any, flag: bool = False) -> None:
        super().__init__()
        self.crashed, self.legs, self.flag = crashed, legs, flag

    def _touch(self, code: Any, other: Any, delta: int) -> None:
        k, part = divmod(code, 3)
        if part == 0:
            if delta > 0:
                self.crashed[k] = True
        elif other is None:
            if self.flag:
                self.legs[k][part - 1] = int(delta > 0)
            else:
                self.legs[k][part - 1] += delta

    def BeginContact(self, contact: Any) -> None:  # noqa: N802 (Box2D's name)
        a, b = _DATA(_FIXTURE_A(contact)), _DATA(_FIXTURE_B(contact))
        if a is not None:
            self._touch(a, b, 1)
        if b is not None:
            self._touch(b, a, 1)

    def EndContact(self, contact: Any) -> None:  # noqa: N802
        a, b = _DATA(_FIXTURE_A(contact)), _DATA(_FIXTURE_B(contact))
        if a is not None and b is None:
            self._touch(a, b, -1)
        elif b is not None and a is None:
            self._touch(b, a, -1)


class LanderWorld:
    """One game's Box2D world: the moon, the landers (body, two legs each) and the game's generator."""

    def __init__(self, cfg: LanderConfig, seed: int, ks: list[int], crashed: Any, legs: Any) -> None:
        self.rng = rng = seed_generator(seed)
        self.world = world = Box2D.b2World(gravity=(0, cfg.gravity))
        self.listener = _Contacts(crashed, legs, cfg.gym_leg_contact)
        world.contactListener = self.listener
        # The moon: gymnasium's terrain (its numpy arithmetic in Python floats: the same doubles)
        height = rng.uniform(0, H / 2, size=(CHUNKS + 1,)).tolist()
        chunk_x = [W / (CHUNKS - 1) * i for i in range(CHUNKS)]
        self.helipad_x1, self.helipad_x2 = chunk_x[CHUNKS // 2 - 1], chunk_x[CHUNKS // 2 + 1]
        self.helipad_y = HELIPAD_Y
        height[CHUNKS // 2 - 2 : CHUNKS // 2 + 3] = [HELIPAD_Y] * 5
        smooth_y = [0.33 * (height[i - 1] + height[i + 0] + height[i + 1]) for i in range(CHUNKS)]
        self.moon = moon = _CREATE_BODY(world, _MOON)
        _CREATE_FIXTURE(moon, _FLOOR)
        self.terrain = terrain = list(zip(chunk_x, smooth_y, strict=True))
        defs = _DEFINITIONS
        edge, ground = defs.edge, defs.ground
        for i in range(CHUNKS - 1):  # (gymnasium's CreateEdgeFixture)
            _EDGE_V1(edge, terrain[i])
            _EDGE_V2(edge, terrain[i + 1])
            _CREATE_FIXTURE(moon, ground)
        # The landers, spread across the top; each pushed by its own random force
        n = len(ks)
        self.bodies, self.legs = bodies, pairs = [], []
        starts = [((i + 1) / (n + 1) * W, VIEWPORT_H / SCALE) for i in range(n)]
        body_def, leg_def = defs.lander, defs.leg
        force = rng.uniform(-INITIAL_RANDOM, INITIAL_RANDOM, size=2 * n).tolist()  # (x, y) per lander, drawn in turn
        for i, ((x, y), k) in enumerate(zip(starts, ks, strict=True)):
            body_def.position = (x, y)
            body = _CREATE_BODY(world, body_def)
            _SET_DATA(_CREATE_FIXTURE(body, _BODY_FIXTURE), 3 * k)
            _FORCE(body, (force[2 * i], force[2 * i + 1]), True)
            bodies.append(body)
        if cfg.enable_wind:  # gymnasium's wind phases; each lander keeps its own count of windy steps
            wind_idx, torque_idx = int(rng.integers(-9999, 9999)), int(rng.integers(-9999, 9999))
            self.wind_idx, self.torque_idx = [wind_idx] * n, [torque_idx] * n
        for body, k, (x, y) in zip(bodies, ks, starts, strict=True):
            pair = []
            for j, (i, rjd) in enumerate(zip((-1, +1), defs.joints, strict=True)):
                leg_def.position, leg_def.angle = (x - i * LEG_AWAY / SCALE, y), i * 0.05
                leg = _CREATE_BODY(world, leg_def)
                _SET_DATA(_CREATE_FIXTURE(leg, _LEG_FIXTURE), 3 * k + 1 + j)
                rjd.bodyA, rjd.bodyB = body, leg
                rjd.referenceAngle = i * 0.05  # (the leg's angle less the body's, as revoluteJointDef(bodyA=) sets it)
                _CREATE_JOINT(world, rjd)
                pair.append(leg)
            pairs.append(pair)

    def retire(self, i: int) -> None:
        """Lander i has crashed or is lost (out of bounds): its body and legs leave the simulation. A crashed lander's
        wreck stays where it crashed, drawn there; it could touch no lander again anyway (nothing it did could reach
        a lander still in play), so the game of the others is the same to the bit as with a wreck left to fall on
        (tested), and a world with a wreck steps as fast as one without."""
        for part in (self.bodies[i], *self.legs[i]):
            _SET_ACTIVE(part, False)

    def close(self) -> None:
        self.world.contactListener = None  # nothing calls back into the core while the world is torn down


class LanderCore:
    """N lander games stepped at once (the :class:`~selfplay_cli.envs.contract.BatchedCore` protocol).

    ``actions[seat]``: ``(n,)`` ints in 0..3, or ``(n, 2)`` floats with ``continuous``. A lander that has ended
    and every lander of a finished game are ignored. ``result`` ``(n_seats, n)`` says how each lander ended
    (:data:`~selfplay_cli.envs.lander.config.FLYING`, ``LANDED``, ``CRASHED``, ``OUT``). The core never resets a game by
    itself: a finished game stands still, keeping its score, until :meth:`reset`.
    """

    def __init__(self, n_games: int, config: LanderConfig | None = None) -> None:
        if n_games < 1:
            raise ValueError(f"n_games must be at least 1, not {n_games}")
        self.config = cfg = config or LanderConfig()
        self.n = n = int(n_games)
        self.n_seats = L = cfg.landers
        self.continuous = cfg.continuous
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        self.over = np.zeros(n, dtype=bool)  # finished games (stand still until reset)
        self.score = np.zeros((L, n))
        self.steps = np.zeros(n, dtype=np.int64)
        self.alive = np.zeros((L, n), dtype=bool)  # landers still in play
        self.result = np.zeros((L, n), dtype=np.int8)
        self.state = np.zeros((L, n, N_FEATURES))  # gymnasium's state (float64, unclipped)
        self._shaping = np.zeros((L, n))
        self._pos = np.zeros((2, L, n))  # Box2D's position and angle of each lander after the last step
        self._angle = np.zeros((L, n))
        self._crashed = np.zeros(L * n, dtype=bool)  # written by the contact listeners
        self._legs = np.zeros((L * n, 2), dtype=np.int32)
        # per game: its next _BLOCK steps' dispersion draws, in draw order (and a spare row, read by the games that
        # stand still with an empty block, whose draws nobody uses)
        self._block = np.zeros((n, _BLOCK + 1, L, 2))
        self._at = np.full(n, _BLOCK)  # per game: the row of its block this step takes (_BLOCK: draw a new block)
        self._ar = np.arange(n)
        self.main_power = np.zeros((L, n))  # the engines' powers of the last step (for the renderer)
        self.side_power = np.zeros((L, n))
        self.side_dir = np.zeros((L, n))
        self.worlds: list[LanderWorld | None] = [None] * n
        self._random: list[Any] = [None] * n  # per game: its generator's ``random``
        self._stepper: list[Any] = [None] * n  # per game: its world's ``Step``
        self._bodies: list[Any] = [None] * (L * n)
        # per lander: its body, and Box2D's position and velocity vectors of it (references into the body, which
        # follow it: read without asking the body for them again each step)
        self._readers: list[Any] = [None] * (L * n)
        self._zero = np.zeros((L, n))
        self.reset(np.arange(n), np.arange(n))

    # ----------------------------------------------------------------------------------------------------
    def reset(self, games: Any, seeds: Any) -> None:
        """New games in the slots ``games`` with the given seeds (each with gymnasium's opening no-op step)."""
        g, s = reset_slots(games, seeds)
        if g.size == 0:
            return
        n, L = self.n, self.n_seats
        for game, seed in zip(g.tolist(), s.tolist(), strict=True):
            ks = [seat * n + game for seat in range(L)]
            self._crashed[ks] = False
            self._legs[ks] = 0
            old = self.worlds[game]
            if old is not None:
                old.close()
            w = LanderWorld(self.config, seed, ks, self._crashed, self._legs)
            self.worlds[game] = w
            self._random[game] = w.rng.random
            self._stepper[game] = w.world.Step
            for seat, body in enumerate(w.bodies):
                p = _POSITION(body)
                self._bodies[seat * n + game] = body
                self._readers[seat * n + game] = (body, p, _VELOCITY(body))
                self._pos[0, seat, game], self._pos[1, seat, game] = _X(p), _Y(p)
                self._angle[seat, game] = _ANGLE(body)
        self.score[:, g] = 0.0
        self.steps[g] = 0
        self.terminated[g] = self.truncated[g] = self.over[g] = False
        self.result[:, g] = FLYING
        self.alive[:, g] = True
        self.main_power[:, g] = self.side_power[:, g] = 0.0
        self._opening_step(g.tolist())

    def _opening_step(self, games: list[int]) -> None:
        """gymnasium's reset step (a no-op) for the new ``games``: each draws its dispersion (its first block, of
        which this step takes the first row; no engine fires), feels the wind, steps, and its landers are read back
        (in Python floats, :func:`read_lander`: a few new games cost less than the core's arrays), setting their
        state and shaping; its reward is not given."""
        n, block, stepper, readers, legs = self.n, self._block, self._stepper, self._readers, self._legs
        for g in games:
            self._random[g](out=block[g, :_BLOCK])
            self._at[g] = 1
        if self.config.enable_wind:
            live = np.zeros((self.n_seats, n), dtype=bool)
            live[:, games] = True
            self._wind(live)
        for g in games:
            stepper[g](_TIME_STEP, _VEL_ITERS, _POS_ITERS)
            for seat in range(self.n_seats):
                k = seat * n + g
                x, y, row, shaping = read_lander(*readers[k], legs[k])
                self._pos[0, seat, g], self._pos[1, seat, g], self._angle[seat, g] = x, y, row[4]
                self.state[seat, g] = row
                self._shaping[seat, g] = shaping

    # ----------------------------------------------------------------------------------------------------
    def _powers(self, actions: Any, live: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The main engine's power, the side engine's power and its direction per lander, ``(L, n)`` each."""
        L, n = self.n_seats, self.n
        if self.continuous:
            a = np.asarray(actions, dtype=np.float64)
            if a.shape != (L, n, 2):
                a = a.reshape(L, n, 2)
            bad = ~np.isfinite(a).all(axis=2) & live
            if bad.any():
                seat, game = np.argwhere(bad)[0]
                raise IllegalActionError(seat, game, a[seat, game].tolist(), "not a finite number")
            a = np.clip(a, -1.0, 1.0)
            m, lat = a[..., 0], a[..., 1]
            main = np.where(m > 0.0, (np.clip(m, 0.0, 1.0) + 1.0) * 0.5, 0.0)
            absl = np.abs(lat)
            side = np.where(absl > 0.5, np.clip(absl, 0.5, 1.0), 0.0)
            direction = np.sign(lat)
        else:
            a = np.asarray(actions)
            if a.shape != (L, n):
                a = a.reshape(L, n)
            bad = (a < 0) | (a > 3)
            if a.dtype.kind not in "iub":
                bad |= a != np.floor(a)
            bad &= live
            if bad.any():
                seat, game = np.argwhere(bad)[0]
                raise IllegalActionError(seat, game, a[seat, game].item(), "outside Discrete(4)")
            main = (a == 2).astype(np.float64)
            side = ((a == 1) | (a == 3)).astype(np.float64)
            direction = a - 2.0
        scale = self.config.engine_scale
        if scale != 1.0:
            main, side = main * scale, side * scale
        return main * live, side * live, direction

    def step(self, actions: Any) -> np.ndarray:
        """One step of every running game; the rewards ``(n_seats, n)`` float32 (0 for landers not in play)."""
        running = ~self.over
        live = self.alive & running
        main, side, direction = self._powers(actions, live)
        games = np.flatnonzero(running).tolist()
        reward = self._advance(live, running, games, main, side, direction)
        self.score += reward
        self.steps += running
        ended = running & ~self.alive.any(axis=0)
        self.terminated[:] = ended
        np.greater_equal(self.steps, self.config.max_steps, out=self.truncated)
        self.truncated &= running & ~ended
        self.over |= self.terminated | self.truncated
        return reward.astype(np.float32)

    def _advance(self, live: np.ndarray, running: np.ndarray, games: list[int], main: np.ndarray, side: np.ndarray,
                 direction: np.ndarray) -> np.ndarray:
        """Fire the engines of the ``live`` landers, step the ``running`` games (``(n,)``; ``games``, their indices),
        read the landers back, and score them (gymnasium's step, for all at once). Returns the rewards ``(L, n)``
        (zero where not live)."""
        self._fire(running, main, side, direction)
        if self.config.enable_wind:
            self._wind(live)
        stepper = self._stepper
        for g in games:
            stepper[g](_TIME_STEP, _VEL_ITERS, _POS_ITERS)
        ks, seat, game, s, awake = self._read_back(live)
        shaping = (-100 * np.sqrt(s[:, 0] * s[:, 0] + s[:, 1] * s[:, 1])
                   - 100 * np.sqrt(s[:, 2] * s[:, 2] + s[:, 3] * s[:, 3])
                   - 100 * np.abs(s[:, 4]) + 10 * s[:, 6] + 10 * s[:, 7])
        mp, sp = main[seat, game], side[seat, game]
        rew = shaping - self._shaping[seat, game]
        rew -= mp * 0.30
        rew -= sp * 0.03
        self._shaping[seat, game] = shaping
        reward = np.zeros_like(self._zero)
        self.main_power[:] = main
        self.side_power[:] = side
        self.side_dir[:] = direction
        crashed = self._crashed[ks] | (np.abs(s[:, 0]) >= 1.0)
        rest = awake == 0.0
        rew[crashed] = -100.0
        rew[rest] = +100.0
        reward[seat, game] = rew
        done = crashed | rest
        if done.any():
            self._end(seat[done], game[done], rest[done], s[done, 0])
        return reward

    def _fire(self, running: np.ndarray, main: np.ndarray, side: np.ndarray, direction: np.ndarray) -> None:
        """Take this step's dispersion of every lander of the ``running`` games and apply the impulses of the engines
        that fire (main and side powers ``(L, n)``), as gymnasium does. A game draws its dispersion _BLOCK steps at a
        time (its generator's stream is the same whether drawn 2 values or 2 * L * _BLOCK at a time, and it draws
        nothing else once the game is made): per step 2 draws per lander, in lander order, gymnasium's two per step
        for one lander."""
        at, block = self._at, self._block
        empty = running & (at >= _BLOCK)
        if empty.any():
            for g in np.flatnonzero(empty).tolist():
                self._random[g](out=block[g, :_BLOCK])
            at[empty] = 0
        disp = block[self._ar, at]  # (n, L, 2)
        at += running
        fire, fire_side = np.flatnonzero(main.ravel()), np.flatnonzero(side.ravel())
        if not (fire.size or fire_side.size):
            return
        bodies = self._bodies
        d = (disp * 2.0 - 1.0) / SCALE
        d0, d1 = d[..., 0].T, d[..., 1].T  # (L, n)
        tip0, tip1 = np.sin(self._angle), np.cos(self._angle)
        side0, side1 = -tip1, tip0
        x, y = self._pos
        if fire.size:  # main engine: gymnasium's impulse, 4 px below the centre, +-2 for randomness
            t = _MAIN_Y + 2 * d0
            ox = tip0 * t + side0 * d1
            oy = -tip1 * t - side1 * d1
            args = np.stack([-ox * MAIN_ENGINE_POWER * main, -oy * MAIN_ENGINE_POWER * main, x + ox, y + oy])
            for k, (fx, fy, px, py) in zip(fire.tolist(), args.reshape(4, -1)[:, fire].T.tolist(), strict=True):
                _IMPULSE(bodies[k], (fx, fy), (px, py), True)
        if fire_side.size:  # side engines (gymnasium's 17 px lever, not SIDE_ENGINE_HEIGHT, kept as it is)
            u = 3 * d1 + direction * SIDE_ENGINE_AWAY / SCALE
            ox = tip0 * d0 + side0 * u
            oy = -tip1 * d0 - side1 * u
            args = np.stack([-ox * SIDE_ENGINE_POWER * side, -oy * SIDE_ENGINE_POWER * side,
                             x + ox - tip0 * 17 / SCALE, y + oy + tip1 * SIDE_ENGINE_HEIGHT / SCALE])
            for k, (fx, fy, px, py) in zip(fire_side.tolist(), args.reshape(4, -1)[:, fire_side].T.tolist(),
                                           strict=True):
                _IMPULSE(bodies[k], (fx, fy), (px, py), True)

    def _read_back(self, live: np.ndarray) -> tuple[np.ndarray, ...]:
        """Read the ``live`` landers back from Box2D after the step: their flat indices, seats and games, gymnasium's
        state ``(k, 8)`` of each (also written to :attr:`state`), and whether each body is awake."""
        n, readers = self.n, self._readers
        ks = np.flatnonzero(live.ravel())
        vals: list[float] = []
        ext = vals.extend
        x_, y_, angle_, spin_, awake_ = _X, _Y, _ANGLE, _SPIN, _AWAKE
        for k in ks.tolist():
            b, p, v = readers[k]
            ext((x_(p), y_(p), x_(v), y_(v), angle_(b), spin_(b), awake_(b)))
        r = np.array(vals).reshape(-1, 7)
        seat, game = np.divmod(ks, n)
        self._pos[0, seat, game] = r[:, 0]
        self._pos[1, seat, game] = r[:, 1]
        self._angle[seat, game] = r[:, 4]
        legs = self._legs[ks] > 0
        s = np.empty((len(ks), N_FEATURES))
        s[:, 0] = (r[:, 0] - _X_HALF) / _X_HALF
        s[:, 1] = (r[:, 1] - _Y_ZERO) / _Y_HALF
        s[:, 2] = r[:, 2] * _X_HALF / FPS
        s[:, 3] = r[:, 3] * _Y_HALF / FPS
        s[:, 4] = r[:, 4]
        s[:, 5] = 20.0 * r[:, 5] / FPS
        s[:, 6:] = legs
        self.state[seat, game] = s
        return ks, seat, game, s, r[:, 6]

    def _end(self, seat: np.ndarray, game: np.ndarray, rest: np.ndarray, x: np.ndarray) -> None:
        """The landers (seat, game) have ended, at rest or not: record how, and retire the crashed and the lost."""
        self.alive[seat, game] = False
        code = np.where(rest, LANDED, np.where(np.abs(x) >= 1.0, OUT, CRASHED))
        self.result[seat, game] = code
        for i, g, c in zip(seat.tolist(), game.tolist(), code.tolist(), strict=True):
            if c != LANDED:
                self.worlds[g].retire(i)

    def _wind(self, live: np.ndarray) -> None:
        """gymnasium's wind and turbulence on each live lander whose legs are off the ground (math's tanh, as
        gymnasium's: numpy's differs in the last bit)."""
        cfg, n = self.config, self.n
        touching = self._legs.reshape(-1, 2).any(axis=1)
        for k in np.flatnonzero(live.ravel() & ~touching).tolist():
            seat, g = divmod(k, n)
            w = self.worlds[g]
            i, j = w.wind_idx[seat], w.torque_idx[seat]
            wind = math.tanh(math.sin(0.02 * i) + math.sin(math.pi * 0.01 * i)) * cfg.wind_power
            torque = math.tanh(math.sin(0.02 * j) + math.sin(math.pi * 0.01 * j)) * cfg.turbulence_power
            w.wind_idx[seat], w.torque_idx[seat] = i + 1, j + 1
            body = self._bodies[k]
            body.ApplyForceToCenter((wind, 0.0), True)
            body.ApplyTorque(torque, True)

    # ----------------------------------------------------------------------------------------------------
    def observe(self) -> np.ndarray:
        """Each lander's 8 values ``(n_seats, n, 8)`` float32, clipped to the declared bounds; a lander that has
        ended shows its last observation."""
        return np.clip(self.state, _LOW64, _HIGH64).astype(np.float32)

    def action_masks(self) -> list[None]:
        return [None] * self.n_seats

    def to_act(self) -> np.ndarray:
        """``(n_seats, n)``: the landers still flying in running games."""
        return self.alive & ~self.over
