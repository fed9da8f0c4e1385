"""The lander game: one lander is gymnasium's LunarLander-v3 step for step; every rule of the multi-lander game
(contacts, engine costs, each lander's own ending); the heuristic; both PettingZoo views; seeds; the renderer."""

from __future__ import annotations

import dataclasses
import math
import threading

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.envs.box2d.lunar_lander import heuristic as gym_heuristic
from pettingzoo.test import api_test, parallel_api_test

from selfplay_cli.envs.lander import LANDER
from selfplay_cli.envs.lander import core as lander_core
from selfplay_cli.envs.lander.bots import heuristic_continuous_rule, heuristic_rule
from selfplay_cli.envs.lander.config import (
    CRASHED,
    FLYING,
    LANDED,
    MAIN,
    OUT,
    LanderConfig,
    make_config,
)
from selfplay_cli.envs.lander.core import LanderCore, LanderWorld
from selfplay_cli.envs.lander.view import LanderAECEnv, LanderParallelEnv
from selfplay_cli.play import Game, play
from selfplay_cli.policies import ScriptedPolicy


def core_of(landers=2, seeds=(0,), **options) -> LanderCore:
    c = LanderCore(len(seeds), LanderConfig(landers=landers, **options))
    c.reset(np.arange(len(seeds)), list(seeds))
    return c


def floating(landers=2) -> LanderCore:
    """Landers in (nearly) no gravity, high up and drifting slowly down (fast enough to stay awake), after 100
    steps in which their legs swung down from where they start."""
    c = core_of(landers, gravity=-0.01)
    for _ in range(100):
        for seat in range(landers):
            move(c, seat, 0.0, 0.0, v=(0.0, -0.05))
        c.step(np.zeros((landers, 1), dtype=np.int64))
    assert c.alive.all()
    return c


def heuristic_actions(c: LanderCore) -> np.ndarray:
    return heuristic_rule(c.observe().reshape(-1, 8)).reshape(c.n_seats, c.n)


def shaping(s: np.ndarray) -> np.ndarray:
    """gymnasium's shaping, written out again from its documentation."""
    return (-100 * np.hypot(s[..., 0], s[..., 1]) - 100 * np.hypot(s[..., 2], s[..., 3]) - 100 * np.abs(s[..., 4])
            + 10 * s[..., 6] + 10 * s[..., 7])


def move(c: LanderCore, seat: int, dx: float, dy: float, v=(0.0, 0.0), game: int = 0):
    """Move lander ``seat`` rigidly (body and legs together): levelled, shifted by (dx, dy), at velocity ``v``."""
    w = c.worlds[game]
    body = w.bodies[seat]
    (cx, cy), turn = body.position, -body.angle
    cos, sin = math.cos(turn), math.sin(turn)
    for part in (body, *w.legs[seat]):
        (x, y), a = part.position, part.angle
        rx, ry = x - cx, y - cy
        part.transform = ((cx + cos * rx - sin * ry + dx, cy + sin * rx + cos * ry + dy), a + turn)
        part.linearVelocity = v
        part.angularVelocity = 0.0


NOOPS = np.zeros((2, 1), dtype=np.int64)


# ---------------------------------------------------------------------------------------------------------------
# One lander is gymnasium's LunarLander-v3
def _versus_gymnasium(seed: int, steps: int = 1000, **options):
    """Play gymnasium's env and a one-lander core on the same seed with the same actions (gymnasium's heuristic
    on gymnasium's observation, every 5th step a random action); yield both sides per step."""
    env = gym.make("LunarLander-v3", **{k: v for k, v in options.items() if k != "gym_leg_contact"}).unwrapped
    o, _ = env.reset(seed=seed)
    c = core_of(1, (seed,), **options)
    rng = np.random.default_rng(seed)
    for t in range(steps):
        yield o, c.observe()[0, 0], None, None
        if options.get("continuous"):
            a = gym_heuristic(env, o) if t % 5 else rng.uniform(-1, 1, 2)
            a = np.asarray(a, dtype=np.float32)
            mine = np.asarray(a, dtype=np.float32).reshape(1, 1, 2)
        else:
            a = gym_heuristic(env, o) if t % 5 else int(rng.integers(4))
            mine = np.array([[a]])
        o, r, term, trunc, _ = env.step(a)
        cr = c.step(mine)[0, 0]
        yield o, c.observe()[0, 0], (r, term), (cr, bool(c.terminated[0]), c)
        if term:
            return


@pytest.mark.parametrize("seed, options", [(0, {}), (1, {}), (2, {}), (3, {"enable_wind": True}),
                                           (4, {"enable_wind": True, "wind_power": 5.0, "turbulence_power": 0.5}),
                                           (5, {"continuous": True}), (6, {"gravity": -5.0})])
def test_one_lander_is_gymnasiums_lander_bit_for_bit_with_gymnasiums_leg_flag(seed, options):
    steps = 0
    for theirs, mine, gym_out, my_out in _versus_gymnasium(seed, gym_leg_contact=True, **options):
        assert np.array_equal(theirs, mine), f"step {steps}: observations {theirs} != {mine}"
        if gym_out is not None:
            (r, term), (cr, cterm, _) = gym_out, my_out
            assert np.float32(r) == cr and term == cterm, f"step {steps}: reward {r} vs {cr}"
            steps += 1
    assert steps > 50, "the comparison covered a real flight"


@pytest.mark.slow
def test_one_lander_by_default_differs_from_gymnasium_only_in_the_leg_flag_gymnasium_drops():
    """With the same actions the physics is the same (the leg flag is no input to it): positions, velocities,
    angles are equal at every step; a leg gymnasium says touches touches here too; a reward differs only by the
    +10 per leg where the flags differ."""
    flag_differs = 0
    for seed in range(4):
        prev = None
        for theirs, mine, gym_out, my_out in _versus_gymnasium(seed):
            assert np.array_equal(theirs[:6], mine[:6])
            assert (mine[6:] >= theirs[6:]).all(), "gymnasium's contact is always one here"
            legs = mine[6:].sum() - theirs[6:].sum()
            flag_differs += legs > 0
            if gym_out is not None and not gym_out[1]:
                (r, _), (cr, _, _) = gym_out, my_out
                assert cr - np.float32(r) == pytest.approx(10 * (legs - prev), abs=1e-3)
            prev = legs
    assert flag_differs > 0, "the seeds meet gymnasium's lost flag (a leg across two terrain edges)"


def test_heuristic_scores_at_least_200_over_20_seeds_with_one_lander():
    c = core_of(1, tuple(range(20)))
    while not c.over.all():
        c.step(heuristic_actions(c))
    assert c.score.mean() >= 200, c.score
    assert (c.result == LANDED).sum() >= 18


def test_heuristic_rule_is_gymnasiums_heuristic():
    rng = np.random.default_rng(0)
    obs = rng.uniform(-1.5, 1.5, (500, 8)).astype(np.float32)
    obs[:, 6:] = rng.random((500, 2)) < 0.2
    env = gym.make("LunarLander-v3").unwrapped
    assert heuristic_rule(obs).tolist() == [gym_heuristic(env, o) for o in obs]
    cont = gym.make("LunarLander-v3", continuous=True).unwrapped
    assert np.array_equal(heuristic_continuous_rule(obs), np.array([gym_heuristic(cont, o) for o in obs],
                                                                   dtype=np.float32))


# ---------------------------------------------------------------------------------------------------------------
# Contacts
def test_bodies_touching_crash_both_landers():
    c = floating()
    (x0, _), (x1, _) = c.worlds[0].bodies[0].position, c.worlds[0].bodies[1].position
    move(c, 0, 0.0, -3.0, v=(0.0, -0.05))
    move(c, 1, x0 - x1, -3.0 + 1.6, v=(0.0, -3.0))  # right above: its legs pass outside lander 0's body
    for _ in range(60):
        r = c.step(NOOPS)
        if not c.alive[:, 0].all():
            break
    assert c.result[:, 0].tolist() == [CRASHED, CRASHED] and r[:, 0].tolist() == [-100.0, -100.0]
    assert c.terminated[0]


def test_legs_touching_legs_do_not_crash_and_are_no_ground_contact():
    c = floating()
    w = c.worlds[0]
    (x0, _), (x1, _) = w.bodies[0].position, w.bodies[1].position
    move(c, 0, 0.0, -3.0, v=(0.5, -0.05))
    move(c, 1, (x0 + 2.2) - x1, -3.0, v=(-0.5, -0.05))  # legs hang 0.83 m out: they meet, the bodies do not
    legs_met = 0
    for _ in range(50):
        c.step(NOOPS)
        assert (c.observe()[:, 0, 6:] == 0).all(), "a leg on a leg is no ground contact"
        legs_met += any(ce.contact.touching and 3 * 1 + 2 in (ce.contact.fixtureA.userData,
                                                              ce.contact.fixtureB.userData)
                        for ce in w.legs[0][0].contacts)
    assert legs_met >= 1, "lander 0's right leg pressed on lander 1's left leg"
    assert c.result[:, 0].tolist() == [FLYING, FLYING], "legs on legs are no crash"
    assert w.bodies[1].position[0] - w.bodies[0].position[0] > 1.13, "the bodies never met"


def test_another_landers_legs_on_a_body_crash_that_body_only():
    c = floating()
    (x0, _), (x1, _) = c.worlds[0].bodies[0].position, c.worlds[0].bodies[1].position
    move(c, 0, 0.0, -3.0, v=(0.0, -0.05))
    move(c, 1, x0 + 0.9 - x1, -3.0 + 1.2, v=(0.0, -1.0))  # above and aside: a leg comes down on lander 0's body
    for _ in range(60):
        c.step(NOOPS)
        if not c.alive[0, 0]:
            break
    assert c.result[:, 0].tolist() == [CRASHED, FLYING], "lander 1's leg hit lander 0's body"


def test_a_crashed_lander_is_a_wreck_that_stays_where_it_crashed_and_touches_no_lander_again():
    c = floating()
    (x0, _), (x1, _) = c.worlds[0].bodies[0].position, c.worlds[0].bodies[1].position
    move(c, 0, 0.0, -3.0, v=(0.0, -0.05))
    move(c, 1, x0 - x1, -3.0 + 1.6, v=(0.0, -3.0))  # lander 1 comes down where lander 0 crashes
    wreck = None
    while c.alive[:, 0].any():
        c.step(NOOPS)
        if c.result[0, 0] == CRASHED and wreck is None:
            parts = (c.worlds[0].bodies[0], *c.worlds[0].legs[0])
            wreck = [(tuple(p.position), p.angle) for p in parts]
    assert wreck is not None
    assert all(not p.active for p in parts), "a wreck is out of the simulation"
    assert [(tuple(p.position), p.angle) for p in parts] == wreck, "it stays where it crashed"


def _falling_wreck(world, i: int) -> None:
    """The rule before wrecks left the simulation: a crashed lander's parts fell on, colliding with the moon only
    (here a lost one falls on too, outside the moon: nothing is left out that could reach another lander)."""
    for part in (world.bodies[i], *world.legs[i]):
        fixture = part.fixtures[0]
        f = fixture.filterData
        f.maskBits = 0x0001
        fixture.filterData = f


def _world_made(seed: int) -> list:
    """What a 3-lander world is made of: its terrain's edges, each body's position and angle, each joint's bodies."""
    w = LanderWorld(LanderConfig(landers=3), seed, [0, 1, 2], np.zeros(3, dtype=bool), np.zeros((3, 2), np.int32))
    parts = [*w.bodies, *(leg for pair in w.legs for leg in pair)]
    made = [tuple(map(tuple, f.shape.vertices)) for f in w.moon.fixtures]
    made += [(tuple(p.position), p.angle) for p in parts]
    made += [(tuple(j.bodyA.position), tuple(j.bodyB.position), j.angle) for j in w.world.joints]
    w.close()
    return made


def test_worlds_made_in_two_threads_at_once_are_the_worlds_made_alone(monkeypatch):
    """A world is made from definitions kept between worlds (positions, vertices, a joint's bodies set anew for each
    body): two threads making worlds in lockstep (each body made only once the other thread has set its own
    definition too) make the same worlds as one thread alone."""
    alone = {seed: _world_made(seed) for seed in range(40)}
    together: dict[int, list] = {}
    lockstep = threading.Barrier(2, timeout=10)
    create_body = lander_core._CREATE_BODY

    def in_lockstep(world, definition):
        lockstep.wait()
        return create_body(world, definition)

    monkeypatch.setattr(lander_core, "_CREATE_BODY", in_lockstep)

    def make(seeds: range) -> None:
        for seed in seeds:
            together[seed] = _world_made(seed)

    threads = [threading.Thread(target=make, args=(range(k, 40, 2),)) for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert together == alone


@pytest.mark.parametrize("landers", [2, 3])
def test_a_wreck_changes_nothing_for_the_landers_still_in_play(landers, monkeypatch):
    """Taking a wreck out of the simulation is exact: with the heuristic flying one lander and random actions the
    others (so wrecks and landings both happen, often in one game), every step's rewards, states, results and ends
    are the same to the bit as with the wrecks left to fall on, colliding with the moon only."""
    import selfplay_cli.envs.lander.core as core_mod

    def play(retire: object) -> list[tuple[np.ndarray, ...]]:
        monkeypatch.setattr(core_mod.LanderWorld, "retire", retire)
        c = core_of(landers, tuple(range(500, 516)))
        rng = np.random.default_rng(3)
        out = []
        while not c.over.all():
            a = rng.integers(0, 4, (landers, c.n))
            a[0] = heuristic_rule(c.observe()[0])
            live = c.alive & ~c.over
            r = c.step(a)
            out.append((np.where(live, r, 0), np.where(c.alive[..., None], c.state, 0), c.result.copy(),
                        c.over.copy(), c.score.copy()))
        return out

    frozen = play(core_mod.LanderWorld.retire)
    fell = play(_falling_wreck)
    assert len(frozen) == len(fell)
    for a, b in zip(frozen, fell, strict=True):
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    results = frozen[-1][2]
    assert (results == CRASHED).any() and (results == LANDED).any()  # both kinds of end were played


# ---------------------------------------------------------------------------------------------------------------
# Rewards: shaping, legs, engines
@pytest.mark.parametrize("continuous, action, cost", [
    (False, 0, 0.0), (False, 1, 0.03), (False, 2, 0.30), (False, 3, 0.03),
    (True, (1.0, 0.0), 0.30), (True, (0.5, 0.0), 0.225), (True, (-1.0, 0.75), 0.0225), (True, (0.0, -1.0), 0.03),
    (True, (-0.3, 0.4), 0.0),
])
def test_reward_is_the_change_of_shaping_less_the_engines_fuel(continuous, action, cost):
    c = core_of(1, (11,), continuous=continuous)
    for _ in range(20):
        before = shaping(c.state[0, 0])
        a = np.array(action, dtype=np.float32).reshape(1, 1, 2) if continuous else np.array([[action]])
        r = c.step(a)[0, 0]
        assert r == pytest.approx(shaping(c.state[0, 0]) - before - cost, abs=1e-4)


def test_engine_scale_scales_the_fuel_cost():
    c = core_of(1, (11,), engine_scale=3.0)
    before = shaping(c.state[0, 0])
    r = c.step(np.array([[MAIN]]))[0, 0]
    assert r == pytest.approx(shaping(c.state[0, 0]) - before - 0.9, abs=1e-4)


def test_a_leg_touching_the_ground_earns_ten():
    c = core_of(1, (2,))
    seen = 0
    while not c.over[0]:
        legs = c.observe()[0, 0, 6:].copy()
        no_legs_before = shaping(c.state[0, 0]) - 10 * legs.sum()
        r = c.step(heuristic_actions(c))[0, 0]
        now = c.observe()[0, 0, 6:]
        if c.alive[0, 0] and now.sum() > legs.sum():
            s = c.state[0, 0]
            no_legs = shaping(s) - 10 * now.sum()
            fuel = 0.3 * c.main_power[0, 0] + 0.03 * c.side_power[0, 0]
            assert r == pytest.approx(no_legs - no_legs_before - fuel + 10 * (now.sum() - legs.sum()), abs=1e-4)
            seen += 1
    assert seen >= 1 and c.result[0, 0] == LANDED


# ---------------------------------------------------------------------------------------------------------------
# Each lander ends on its own
def test_each_lander_ends_on_its_own_and_then_neither_acts_nor_earns():
    c = core_of(2, (4,))
    rewards = []
    while not c.over[0]:
        a = heuristic_actions(c)
        a[0] = 0  # lander 0 falls: it crashes, lander 1 flies on and lands
        rewards.append(c.step(a)[:, 0].copy())
        if c.result[0, 0] == CRASHED and c.alive[1, 0]:
            assert c.to_act()[:, 0].tolist() == [False, True] and not c.terminated[0]
    rewards = np.array(rewards)
    crash = int(np.flatnonzero(rewards[:, 0] == -100.0)[0])
    assert (rewards[crash + 1 :, 0] == 0).all(), "no reward after the end"
    assert c.result[:, 0].tolist() == [CRASHED, LANDED] and rewards[-1, 1] == 100.0
    assert c.terminated[0] and not c.truncated[0] and not c.to_act().any()
    assert c.score[:, 0] == pytest.approx(rewards.sum(axis=0))
    assert not c.worlds[0].bodies[1].awake, "at rest is asleep"
    frozen = c.observe().copy()
    c.step(np.full((2, 1), MAIN))
    assert np.array_equal(c.observe(), frozen) and c.steps[0] == len(rewards), "a finished game stands still"


def test_out_of_bounds_ends_a_lander_with_minus_100_and_removes_it():
    c = floating()
    x0, _ = c.worlds[0].bodies[0].position
    move(c, 0, 0.2 - x0, 0.0, v=(-3.0, 0.0))
    for _ in range(20):
        r = c.step(NOOPS)
        if not c.alive[0, 0]:
            break
    assert c.result[:, 0].tolist() == [OUT, FLYING] and r[0, 0] == -100.0
    assert c.observe()[0, 0, 0] <= -1.0 and not c.worlds[0].bodies[0].active


def test_time_limit_truncates_the_landers_still_flying():
    c = core_of(2, (0, 1), max_steps=30)
    for _ in range(30):
        assert not (c.terminated | c.truncated).any()
        c.step(heuristic_actions(c))
    assert c.truncated.all() and not c.terminated.any() and (c.steps == 30).all()
    assert not c.to_act().any()


# ---------------------------------------------------------------------------------------------------------------
# Seeds, options, registration
def test_a_game_is_the_same_alone_or_in_a_batch_and_seeds_differ():
    def run(seeds, slot, steps=120):
        c = core_of(3, seeds)
        rng, others = np.random.default_rng(1), np.random.default_rng(len(seeds))
        out = []
        for _ in range(steps):
            a = others.integers(0, 4, (3, len(seeds)))
            a[:, slot] = rng.integers(0, 4, 3)
            out.append((c.observe()[:, slot].copy(), c.step(a)[:, slot].copy()))
        return out

    alone, batched, again = run((7,), 0), run((5, 7, 9), 1), run((7,), 0)
    assert all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) for a, b in zip(alone, batched, strict=True))
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(alone, again, strict=True))
    other = run((8,), 0)
    assert not np.array_equal(alone[0][0], other[0][0])


def test_landers_spread_across_the_top_and_options_are_checked():
    c = core_of(4)
    xs = [b.position[0] for b in c.worlds[0].bodies]
    assert xs == pytest.approx([20 * (i + 1) / 5 for i in range(4)], abs=0.1), "after the opening step"
    assert c.observe().shape == (4, 1, 8) and c.to_act().all()
    for bad in ({"landers": 0}, {"landers": 9}, {"landers": 2.0}, {"gravity": -13.0}, {"continuous": "yes"},
                {"max_steps": 0}):
        with pytest.raises(ValueError):
            make_config(**bad)
    with pytest.raises(ValueError, match="unknown lander option"):
        make_config(lander=3)


def test_continuous_option_box_actions():
    spec = LANDER
    assert spec.action_space(spec.config(continuous=True)) == spaces.Box(-1, 1, (2,), dtype=np.float32)
    c = core_of(1, tuple(range(6)), continuous=True)
    while not c.over.all():
        c.step(heuristic_continuous_rule(c.observe().reshape(-1, 8)).reshape(1, 6, 2))
    assert c.score.mean() >= 150 and (c.result == LANDED).sum() >= 4


def test_declaration_and_a_match_through_the_arena():
    spec = LANDER
    assert (spec.kind, spec.turns, spec.n_seats) == ("cooperative", "simultaneous", 2)
    assert list(spec.bots) == ["heuristic"]  # random is marl's own, for the config's action space
    assert spec.max_steps() == 1000 and spec.side_seats() == ((0, 1),)
    players = [ScriptedPolicy("lander", "heuristic", seed=1), ScriptedPolicy("lander", "random", seed=1)]
    results = play(spec, players, [Game(s, (0, 0)) for s in range(4)] + [Game(s, (1, 1)) for s in range(4)])
    team = [sum(r.scores) for r in results]
    assert np.mean(team[:4]) > 100 > np.mean(team[4:]), team


def test_the_game_keeps_the_game_contract():
    """The conformance test's check, on the lander game (it runs on every registered game)."""
    import sys
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[1])
    if root not in sys.path:  # as tests/test_conformance.py does
        sys.path.insert(0, root)
    from tests.test_conformance import check_game

    check_game(LANDER)
    check_game(dataclasses.replace(LANDER, agents=("a", "b", "c"),
                                   make_config=lambda **o: make_config(**{"landers": 3, **o})))


# ---------------------------------------------------------------------------------------------------------------
# PettingZoo views
@pytest.mark.parametrize("options", [{"landers": 1}, {"landers": 3}, {"landers": 2, "continuous": True}])
def test_views_pass_pettingzoos_api_tests(options):
    parallel_api_test(LanderParallelEnv(**options), num_cycles=200)
    api_test(LanderAECEnv(**options), num_cycles=200)


def test_parallel_view_is_the_cores_game():
    env = LanderParallelEnv(landers=2)
    obs, _ = env.reset(seed=9)
    c = core_of(2, (9,))
    while env.agents:
        acts = heuristic_actions(c)
        assert all(np.array_equal(obs[a], c.observe()[int(a[-1]), 0]) for a in env.agents)
        obs, rew, term, trunc, info = env.step({a: int(acts[int(a[-1]), 0]) for a in env.agents})
        r = c.step(acts)
        assert all(rew[a] == r[int(a[-1]), 0] for a in rew)
    assert c.over[0]


def _aec_heuristic(landers: int, seed: int, **options) -> np.ndarray:
    env = LanderAECEnv(landers=landers, **options)
    env.reset(seed=seed)
    for _agent in env.agent_iter():
        o, _, term, trunc, _ = env.last()
        env.step(None if term or trunc else int(heuristic_rule(o[None])[0]))
    return env.core.result[:, 0]


def test_aec_view_scales_the_engines_so_the_heuristic_lands_three_landers():
    scaled = [_aec_heuristic(3, s) for s in range(3)]
    unscaled = [_aec_heuristic(3, s, engine_scale=1.0) for s in range(3)]
    assert sum((r == LANDED).sum() for r in scaled) >= 3
    assert sum((r == LANDED).sum() for r in unscaled) == 0, "seed 001: unsolvable without scaling"
    assert LanderAECEnv(landers=3).config.engine_scale == 3.0


# ---------------------------------------------------------------------------------------------------------------
# Renderer
def test_renderer_draws_even_frames_of_each_lander():
    spec = LANDER
    r = spec.make_renderer()
    c = core_of(3, (1,))
    first = r.draw(c, 0)
    for _ in range(40):
        c.step(heuristic_actions(c))
    frame = r.draw(c, 0)
    assert frame.shape == (400, 600, 3) and frame.dtype == np.uint8
    assert frame.shape[0] % 2 == 0 and frame.shape[1] % 2 == 0
    assert not np.array_equal(first, frame)
    from selfplay_cli.envs.lander.render import PALETTE

    for colour in PALETTE[:3]:
        assert (frame == colour).all(axis=2).sum() > 50, f"lander colour {colour} is drawn"
    assert math.isfinite(float(frame.mean()))


@pytest.mark.parametrize("cls", [LanderParallelEnv, LanderAECEnv])
def test_a_copied_lander_view_is_the_same_game_made_afresh_and_a_game_under_way_is_not_copied(cls):
    """SuperSuit's and RLlib's vector wrappers deep-copy (or pickle) the env they are given: Box2D's world cannot be
    copied, so a copy is the same game made afresh from its options, playing the same games for the same seeds."""
    import copy
    import pickle

    env = cls(landers=3, continuous=True, gravity=-8.0, render_mode="rgb_array")
    twins = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    assert all(type(t) is cls and t.config == env.config and t.render_mode == "rgb_array" for t in twins)

    def trace(e) -> list[float]:
        e.reset(seed=7)
        got, rng = [], np.random.default_rng(0)
        for _ in range(40):
            if cls is LanderParallelEnv:
                if not e.agents:
                    break
                _, rewards, _, _, _ = e.step({a: rng.uniform(-1, 1, 2).astype(np.float32) for a in e.agents})
                got += [rewards[a] for a in sorted(rewards)]
            else:
                agent = e.agent_selection
                done = e.terminations[agent] or e.truncations[agent]
                e.step(None if done else rng.uniform(-1, 1, 2).astype(np.float32))
                got.append(e.rewards.get(agent, 0.0))
        return got

    first = trace(env)
    assert len(first) > 20 and all(trace(t) == first for t in twins)
    with pytest.raises(TypeError, match=r"a lander view cannot be copied \(pickled\) with a game under way"):
        copy.deepcopy(env)  # (the traced game is still under way)


def test_options_given_as_numpy_numbers_play_the_game_of_the_same_python_numbers():
    """A config built from numpy's numbers (a YAML or a sweep hands them over) holds Python's: Box2D's calls take
    only those (a np.float32 wind crashed the first step), and the game is the one of the same values."""
    given = dict(enable_wind=np.bool_(True), wind_power=np.float32(12.5), turbulence_power=np.float64(1.25),
                 landers=np.int64(2), gravity=np.float32(-9.5))
    config = make_config(**given)
    assert all(type(getattr(config, k)) is type(v.item()) for k, v in given.items())

    def trace(options) -> list[float]:
        env = LanderParallelEnv(**options)
        env.reset(seed=3)
        out = []
        for _ in range(60):
            _, rewards, _, _, _ = env.step({a: 2 for a in env.agents})
            out += list(rewards.values())
        return out

    assert trace(given) == trace({k: v.item() for k, v in given.items()})
