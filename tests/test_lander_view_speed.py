"""The lander's views play one game with :class:`ScalarLander` (the core's rules in Python floats around the same
Box2D world, several times faster than a batch of one): it must be the core's game, exactly. Each test plays the core
(the oracle) beside it and compares everything bit for bit: observations, rewards, scores, endings, truncations,
infos, the global state and the rendered frames, for discrete and continuous actions, 1 to 4 landers, wind and
turbulence, other gravities, gymnasium's leg flag, scaled engines, time limits and landers ending at different
times. And the worlds, made faster from definitions made once, are those gymnasium's keyword calls make."""

from __future__ import annotations

import numpy as np
import pytest

from selfplay_cli.envs.lander.bots import heuristic_continuous_rule, heuristic_rule
from selfplay_cli.envs.lander.config import CRASHED, FLYING, LANDED, OUT, RESULT_NAMES, LanderConfig
from selfplay_cli.envs.lander.core import LanderCore
from selfplay_cli.envs.lander.render import LanderRenderer
from selfplay_cli.envs.lander.scalar import ScalarLander
from selfplay_cli.envs.lander.view import LanderAECEnv, LanderParallelEnv

OPTIONS = [
    {"landers": 1},
    {"landers": 2},
    {"landers": 3, "enable_wind": True, "wind_power": 20.0, "turbulence_power": 2.0},
    {"landers": 4, "continuous": True},
    {"landers": 2, "continuous": True, "enable_wind": True, "gravity": -11.5},
    {"landers": 2, "gravity": -3.0, "gym_leg_contact": True},
    {"landers": 3, "gym_leg_contact": True, "engine_scale": np.float32(2.5)},
    {"landers": 2, "max_steps": 90},
]


def bits(a: np.ndarray) -> np.ndarray:
    """The array's bits (so that -0.0 and 0.0, or two NaNs, are told apart as they are)."""
    a = np.ascontiguousarray(a)
    return a.view(np.uint32 if a.dtype == np.float32 else np.uint64)


class Pilots:
    """Each lander flown its own way, redrawn per game: gymnasium's heuristic with a random action now and then,
    random actions (beyond the bounds too, with continuous ones), no engine at all (it falls), or its side engines
    mostly (it drifts away, often out of bounds); so that landers land, crash and leave at different times."""

    def __init__(self, config: LanderConfig, rng: np.random.Generator) -> None:
        self.config, self.rng = config, rng
        self.ways = rng.integers(0, 4, config.landers)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(landers, 1)`` ints or ``(landers, 1, 2)`` float32 for the observations ``(landers, 8)``."""
        rng, L = self.rng, self.config.landers
        if self.config.continuous:
            a = heuristic_continuous_rule(obs).astype(np.float32)
            noise = rng.uniform(-1.3, 1.3, (L, 2)).astype(np.float32)
            side = np.stack([rng.uniform(-0.2, 0.2, L), rng.choice([-1.0, 1.0], L)], axis=1).astype(np.float32)
            a = np.select([self.ways[:, None] == 1, self.ways[:, None] == 2, self.ways[:, None] == 3],
                          [noise, np.zeros_like(a), side], a)
            a[(self.ways == 0) & (rng.random(L) < 0.1)] = noise[0]
            return a[:, None]
        a = heuristic_rule(obs)
        noise = rng.integers(0, 4, L)
        a = np.select([self.ways == 1, self.ways == 2, self.ways == 3], [noise, 0, np.where(noise < 2, 1, 3)], a)
        a[(self.ways == 0) & (rng.random(L) < 0.1)] = noise[0]
        return a[:, None]


def seat_actions(a: np.ndarray) -> list:
    """The core's actions of game 0 as the views hand them to the game (ints, or pairs of float32 values)."""
    return [x.tolist() for x in a[:, 0]]


def lockstep(config: LanderConfig, seed: int, rng: np.random.Generator) -> tuple[list[int], list[int], bool]:
    """Play the core's game ``seed`` and the same game in Python floats side by side to the end, comparing every
    number after every step; then one step more (a finished game stands still). Returns how each lander ended, the
    step at which it did (0: it did not) and whether the game was truncated."""
    core, game = LanderCore(1, config), ScalarLander(config)
    core.reset([0], [seed])
    game.reset(seed)
    pilots, ended = Pilots(config, rng), [0] * config.landers
    while True:
        assert np.array_equal(bits(game.observe()), bits(core.observe()[:, 0]))
        assert np.array_equal(bits(np.array(game.state)), bits(core.state[:, 0]))
        assert game.result == core.result[:, 0].tolist() and game.alive == core.alive[:, 0].tolist()
        assert np.array_equal(bits(np.array(game.score)), bits(core.score[:, 0]))
        assert (game.steps, game.terminated, game.truncated, game.over) == (
            core.steps[0], core.terminated[0], core.truncated[0], core.over[0])
        assert game.main_power == core.main_power[:, 0].tolist()
        assert game.side_power == core.side_power[:, 0].tolist()
        if core.over[0]:
            break
        a = pilots.act(core.observe()[:, 0])
        assert list(game.step(seat_actions(a))) == core.step(a)[:, 0].tolist()
        ended = [e or (0 if game.alive[i] else game.steps) for i, e in enumerate(ended)]
    frozen, results, cut = game.observe(), game.result, game.truncated
    assert game.step(seat_actions(a)) == (0.0,) * config.landers == tuple(core.step(a)[:, 0].tolist())
    assert np.array_equal(game.observe(), frozen) and not (game.terminated or game.truncated)
    return results, ended, cut


@pytest.mark.slow
@pytest.mark.parametrize("options", OPTIONS)
def test_the_views_game_in_python_floats_is_the_cores_bit_for_bit(options):
    """Over many seeds with landers flown every way, the same game, number for number, through the endings the
    options allow: landings, crashes, leaving the screen, the time limit; landers ending at different steps."""
    config = LanderConfig(**options)
    rng = np.random.default_rng(len(options) * 100 + config.landers)
    results, truncated, staggered = set(), 0, 0
    for seed in range(12):
        result, ended, cut = lockstep(config, int(rng.integers(2**40)) if seed % 2 else seed, rng)
        results |= set(result)
        truncated += cut
        staggered += len(set(ended)) > 1
    assert len(results - {FLYING}) >= 2, results
    if "max_steps" in options:
        assert truncated >= 6
    if config.landers > 1:
        assert staggered >= 6


def core_actions(config: LanderConfig, given: dict, index: dict) -> np.ndarray:
    """What the views hand the core for the actions ``given`` (a lander given none fires no engine)."""
    buf = np.zeros((config.landers, 1, 2) if config.continuous else (config.landers, 1),
                   dtype=np.float32 if config.continuous else np.int64)
    for agent, action in given.items():
        buf[index[agent], 0] = action
    return buf


def expected_info(core: LanderCore, seat: int, seed: int) -> dict:
    return {"result": RESULT_NAMES[int(core.result[seat, 0])], "seed": seed}


def same_as_the_core(env, core: LanderCore) -> None:
    """The view's global state and its ``core`` (what a one-game core shows of its game) are the core's."""
    assert np.array_equal(bits(env.state()), bits(core.observe()[:, 0].reshape(-1)))
    shown = env.core
    for name in ("result", "alive", "score", "state", "steps", "terminated", "truncated", "over", "main_power",
                 "side_power"):
        want = getattr(core, name)
        assert getattr(shown, name).dtype == want.dtype and np.array_equal(getattr(shown, name), want), name
    assert shown.n_seats == core.n_seats and shown.worlds == [env.game.world]


@pytest.mark.parametrize("options", OPTIONS)
def test_the_parallel_view_gives_what_the_cores_game_gives(options):
    """Three games (``reset(seed=31)``, then two resets without a seed, whose games are those of the seeds drawn
    from a generator seeded by 31): every observation, reward, termination, truncation and info the view gives, and
    who is still playing, are what the core's game gives (as the view played it before it had a game of its own);
    a lander given no action fires no engine."""
    config = LanderConfig(**options)
    env = LanderParallelEnv(**options)
    rng, seeds, index = np.random.default_rng(7), np.random.default_rng(31), env._index
    for n in range(3):
        obs, infos = env.reset(seed=31) if n == 0 else env.reset()
        seed = 31 if n == 0 else int(seeds.integers(2**62))
        core = LanderCore(1, config)
        core.reset([0], [seed])
        assert env.agents == env.possible_agents
        assert infos == {a: expected_info(core, i, seed) for i, a in enumerate(env.agents)}
        assert all(np.array_equal(bits(obs[a]), bits(core.observe()[i, 0])) for i, a in enumerate(env.agents))
        same_as_the_core(env, core)
        pilots = Pilots(config, rng)
        while env.agents:
            a = pilots.act(core.observe()[:, 0])
            given = {ag: a[index[ag], 0] for ag in env.agents if rng.random() > 0.05}
            playing = list(env.agents)
            obs, rew, term, trunc, infos = env.step(given)
            r = core.step(core_actions(config, given, index))
            cut = bool(core.truncated[0])
            ended = {ag: bool(core.result[index[ag], 0] != FLYING) for ag in playing}
            assert all(np.array_equal(bits(obs[ag]), bits(core.observe()[index[ag], 0])) for ag in playing)
            assert rew == {ag: float(r[index[ag], 0]) for ag in playing}
            assert term == ended and trunc == {ag: cut and not ended[ag] for ag in playing}
            assert infos == {ag: expected_info(core, index[ag], seed) for ag in playing}
            assert env.agents == [ag for ag in playing if not (ended[ag] or cut)]
            same_as_the_core(env, core)
        assert core.over[0]


@pytest.mark.parametrize("options", [{"landers": 1}, {"landers": 3}, {"landers": 2, "continuous": True},
                                     {"landers": 4, "enable_wind": True, "max_steps": 300}])
def test_the_aec_view_gives_what_the_cores_game_gives(options):
    """Landers taking turns (engines scaled by N): after each turn, every lander's observation, reward, termination,
    truncation and info are what the core's game gives when that lander's action is stepped alone; over two games
    (the second without a seed)."""
    env = LanderAECEnv(**options)
    config, index, rng = env.config, env._index, np.random.default_rng(3)
    seeds = np.random.default_rng(5)
    for n in range(2):
        env.reset(seed=5) if n == 0 else env.reset()
        seed = 5 if n == 0 else int(seeds.integers(2**62))
        core = LanderCore(1, config)
        core.reset([0], [seed])
        pilots, turns = Pilots(config, rng), 0
        for agent in env.agent_iter():
            obs, _, term, trunc, _ = env.last()
            assert np.array_equal(bits(obs), bits(core.observe()[index[agent], 0]))
            if term or trunc:
                env.step(None)
                continue
            action = pilots.act(core.observe()[:, 0])[index[agent], 0]
            env.step(action)
            r = core.step(core_actions(config, {agent: action}, index))
            cut, turns = bool(core.truncated[0]), turns + 1
            for ag in env.agents:
                i = index[ag]
                ended = bool(core.result[i, 0] != FLYING)
                assert env.rewards[ag] == float(r[i, 0])
                assert (env.terminations[ag], env.truncations[ag]) == (ended, cut and not ended)
                assert env.infos[ag] == expected_info(core, i, seed)
            assert np.array_equal(bits(env.game.observe()), bits(core.observe()[:, 0]))
        assert core.over[0] and turns == core.steps[0] > 20


def test_the_views_frames_are_the_cores_frames():
    """``render()`` draws the view's game as the renderer draws the core's: the same pixels, flames, wrecks and
    landed landers included."""
    options = {"landers": 3, "continuous": True}
    env = LanderParallelEnv(render_mode="rgb_array", **options)
    config, index, rng = env.config, env._index, np.random.default_rng(2)
    env.reset(seed=5)
    core = LanderCore(1, config)
    core.reset([0], [5])
    renderer, pilots = LanderRenderer(), Pilots(config, rng)
    pilots.ways[:] = [0, 1, 2]  # the heuristic, random, falling
    frames = flames = 0
    while env.agents:
        if core.steps[0] % 25 == 0 or not core.alive[:, 0].all():
            assert np.array_equal(env.render(), renderer.draw(core, 0))
            frames += 1
            flames += bool((core.main_power > 0).any() or (core.side_power > 0).any())
        a = pilots.act(core.observe()[:, 0])
        given = {ag: a[index[ag], 0] for ag in env.agents}
        env.step(given)
        core.step(core_actions(config, given, index))
    assert np.array_equal(env.render(), renderer.draw(core, 0))
    assert frames > 10 and flames > 5 and core.result[:, 0].tolist() == [LANDED, OUT, CRASHED]


def gymnasiums_landers(world, cfg: LanderConfig, rng: np.random.Generator, n: int) -> list:
    """Landers made as gymnasium makes its one (keyword calls, a definition each), n of them as the core places
    them: the reference for :class:`LanderWorld`'s definitions made once and reused."""
    from Box2D.b2 import fixtureDef, polygonShape, revoluteJointDef

    from selfplay_cli.envs.lander.config import (
        INITIAL_RANDOM,
        LEG_AWAY,
        LEG_DOWN,
        LEG_H,
        LEG_SPRING_TORQUE,
        LEG_W,
        SCALE,
    )
    from selfplay_cli.envs.lander.core import _COLLIDE, _POLY, BODY_BITS, LEG_BITS, H, W

    parts = []
    starts = [((i + 1) / (n + 1) * W, H) for i in range(n)]
    for x, y in starts:
        body = world.CreateDynamicBody(position=(x, y), angle=0.0, fixtures=fixtureDef(
            shape=polygonShape(vertices=_POLY), density=5.0, friction=0.1, categoryBits=BODY_BITS, maskBits=_COLLIDE,
            restitution=0.0))
        body.ApplyForceToCenter((rng.uniform(-INITIAL_RANDOM, INITIAL_RANDOM),
                                 rng.uniform(-INITIAL_RANDOM, INITIAL_RANDOM)), True)
        parts.append(body)
    if cfg.enable_wind:
        rng.integers(-9999, 9999, 2)
    for body, (x, y) in zip(list(parts), starts, strict=True):
        for i in (-1, +1):
            leg = world.CreateDynamicBody(position=(x - i * LEG_AWAY / SCALE, y), angle=i * 0.05, fixtures=fixtureDef(
                shape=polygonShape(box=(LEG_W / SCALE, LEG_H / SCALE)), density=1.0, restitution=0.0,
                categoryBits=LEG_BITS, maskBits=_COLLIDE))
            rjd = revoluteJointDef(bodyA=body, bodyB=leg, localAnchorA=(0, 0),
                                   localAnchorB=(i * LEG_AWAY / SCALE, LEG_DOWN / SCALE), enableMotor=True,
                                   enableLimit=True, maxMotorTorque=LEG_SPRING_TORQUE, motorSpeed=+0.3 * i)
            rjd.lowerAngle, rjd.upperAngle = (0.9 - 0.5, 0.9) if i == -1 else (-0.9, -0.9 + 0.5)
            world.CreateJoint(rjd)
            parts.append(leg)
    return parts


@pytest.mark.parametrize("landers", [1, 3, 8])
def test_a_world_made_from_reused_definitions_is_the_world_of_gymnasiums_keywords(landers):
    """The core's worlds (and so the views' games) are made from fixture, body and joint definitions made once and
    reused (a world is made in half the time): the bodies, fixtures and joints are those gymnasium's keyword calls
    make, and 300 steps of both worlds (landers falling onto the moon, legs on their springs) are the same, bit for
    bit."""
    import Box2D

    from selfplay_cli.envs.lander.core import _POS_ITERS, _TIME_STEP, _VEL_ITERS, LanderWorld

    cfg = LanderConfig(landers=landers, enable_wind=True)
    made = LanderWorld(cfg, 12, list(range(landers)), [False] * landers, [[0, 0] for _ in range(landers)])
    rng = np.random.default_rng(12)
    rng.uniform(0, 1, 12)  # the terrain's draws
    ref = Box2D.b2World(gravity=(0, cfg.gravity))
    ref.CreateStaticBody()  # (the moon, without its edges: the landers fall freely and meet each other)
    made.world.DestroyBody(made.moon)
    theirs = gymnasiums_landers(ref, cfg, rng, landers)
    mine = made.bodies + [leg for pair in made.legs for leg in pair]
    def joint(j) -> tuple:
        return (j.GetReferenceAngle(), tuple(j.GetLocalAnchorA()), tuple(j.GetLocalAnchorB()), j.lowerLimit,
                j.upperLimit, j.motorSpeed, j.GetMaxMotorTorque(), j.limitEnabled, j.motorEnabled,
                j.bodyA.mass, j.bodyB.mass)

    assert [joint(j) for j in made.world.joints] == [joint(j) for j in ref.joints]
    for _ in range(300):
        made.world.Step(_TIME_STEP, _VEL_ITERS, _POS_ITERS)
        ref.Step(_TIME_STEP, _VEL_ITERS, _POS_ITERS)
        assert [(*b.position, b.angle, *b.linearVelocity, b.angularVelocity) for b in mine] == \
            [(*b.position, b.angle, *b.linearVelocity, b.angularVelocity) for b in theirs]
    for a, b in zip(mine, theirs, strict=True):
        fa, fb = a.fixtures[0], b.fixtures[0]
        assert (fa.density, fa.friction, fa.restitution, fa.filterData.categoryBits, fa.filterData.maskBits,
                fa.shape.vertices, a.mass, a.inertia) == (fb.density, fb.friction, fb.restitution,
                                                          fb.filterData.categoryBits, fb.filterData.maskBits,
                                                          fb.shape.vertices, b.mass, b.inertia)
