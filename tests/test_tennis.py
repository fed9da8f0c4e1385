"""The tennis game: the ball's physics (spin on the bounce, drag, Magnus, no tunnelling), the bats, every rule and
who it scores for, serve order and 11 by 2, egocentric mirror symmetry, seeds, the curricula's hook, the options,
the serve-bot, the PettingZoo view, the arena and the renderer."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo.test import parallel_api_test

from selfplay_cli.envs import get_env
from selfplay_cli.envs.tennis import TENNIS
from selfplay_cli.envs.tennis.bots import plan_launch, serve_bot_for, serve_bot_rule_for
from selfplay_cli.envs.tennis.config import (
    BALL_R,
    BALL_X,
    BAT_0,
    BAT_ANGLE,
    BAT_LENGTH,
    BAT_X,
    BAT_Y,
    DOUBLE_BOUNCE,
    DOUBLE_HIT,
    FLOOR_Y,
    HIT_OUT,
    HOME_X,
    HOME_Y,
    I_SERVE,
    INCOMING,
    INTO_NET,
    MISSED_SERVE,
    MY_TURN,
    N_FEATURES,
    NET,
    NET_GAP,
    NET_H,
    NOT_RETURNED,
    OBS_HIGH,
    OBS_LOW,
    OUT,
    OUTGOING,
    OWN_HALF,
    REASON_NAMES,
    SERVE_NO_BOUNCE,
    TABLE_0,
    TABLE_1,
    THEY_SERVE,
    VOLLEY,
    TennisConfig,
    make_config,
)
from selfplay_cli.envs.tennis.core import TennisCore, mirrored
from selfplay_cli.envs.tennis.physics import game_won, server_of
from selfplay_cli.envs.tennis.scalar import ScalarTennis
from selfplay_cli.envs.tennis.view import TennisParallelEnv
from selfplay_cli.play import Game, play
from selfplay_cli.policies import ScriptedPolicy

STILL = np.zeros((2, 1, 3))


def core_of(seeds=(0,), **options) -> TennisCore:
    c = TennisCore(len(seeds), TennisConfig(**options))
    c.reset(np.arange(len(seeds)), list(seeds))
    return c


def park(c: TennisCore, g: int = 0) -> None:
    """Both bats far from play: high up at the back of their boxes."""
    c.bat[:, :, g] = 0.0
    c.bat[0, :, g] = [-2.87, 2.87]
    c.bat[1, :, g] = 1.6


def rally(c: TennisCore, hitter: int, landed: bool = False, g: int = 0, ball=None) -> None:
    """A rally in progress: ``hitter`` struck last (long ago), the ball (x, y, vx, vy, spin) in flight."""
    c.tossing[g] = False
    c.hitter[g] = hitter
    c.landed[g] = landed
    c.serve_shot[g] = False
    c.since_hit[g] = 1e9
    if ball is not None:
        c.ball[:, g] = ball


def run_point(c: TennisCore, actions=STILL, limit: int = 300) -> int:
    """Step until the current point of game 0 ends (``actions``: fixed, or a function of nothing called each
    step); the steps it took."""
    points = c.score[:, 0].sum()
    for t in range(1, limit + 1):
        c.step(actions() if callable(actions) else actions)
        if c.score[:, 0].sum() != points or c.over[0]:
            return t
    raise AssertionError("the point did not end")


def bot_actions(c: TennisCore, rule, seats=(0, 1)) -> np.ndarray:
    obs = c.observe()
    a = np.zeros((2, c.n, 3), dtype=np.float32)
    for s in seats:
        a[s] = rule(obs[s])
    return a


# ---------------------------------------------------------------------------------------------------------------
# Physics: the bounce, drag, Magnus, no tunnelling
def bounce(vx: float, vy: float, spin: float, **options) -> tuple[float, float, float]:
    """A ball meeting seat 1's half with velocity (vx, vy) and ``spin`` (w < 0 is topspin for a ball going +x):
    its horizontal speed and angle just after the bounce (measured in still air, so that nothing but the bounce
    changes them: drag and Magnus off) and the top of its bounce (in the game's air)."""
    def run(**air):
        c = core_of(**{**options, **air})
        park(c)
        rally(c, 0, ball=[0.5, BALL_R + 0.004, vx, vy, spin])
        c.step(STILL)  # the bounce is in the first substep
        assert c.landed[0] and c.surface[0] == TABLE_1
        return c

    c = run(drag=0.0, magnus=0.0)
    out_vx, out_vy = c.ball[2, 0], c.ball[3, 0]
    c = run()
    apex = c.ball[1, 0]
    while c.ball[3, 0] > 0:
        c.step(STILL)
        apex = max(apex, c.ball[1, 0])
    return out_vx, math.degrees(math.atan2(out_vy, out_vx)), apex


@pytest.mark.parametrize("vx, vy", [(4.0, -3.0), (5.0, -3.5), (3.0, -2.5), (2.0, -2.0), (4.0, -4.0)])
@pytest.mark.parametrize("spin", [100.0, 150.0])
def test_topspin_bounces_lower_and_faster_backspin_higher_and_slower(vx, vy, spin):
    top, none, back = bounce(vx, vy, -spin), bounce(vx, vy, 0.0), bounce(vx, vy, spin)
    assert top[0] > none[0] + 0.3 and none[0] > back[0] + 0.3, "speed after the bounce: topspin > none > backspin"
    assert top[1] < none[1] < back[1], "angle of the bounce: topspin lowest, backspin highest"
    assert top[2] < none[2] < back[2], "top of the bounce: topspin lowest, backspin highest"
    assert none[0] < vx - 0.5, "friction slows a ball without spin (and gives it topspin)"


def test_a_flat_ball_that_slides_through_the_bounce_loses_the_same_speed_with_or_without_backspin():
    """Coulomb friction: a ball that slides through the whole contact (flat and fast: no spin cannot stop its
    slip) loses mu (1 + e) |vy| of horizontal speed whatever its backspin; backspin still rises higher."""
    none, back = bounce(8.0, -3.0, 0.0), bounce(8.0, -3.0, 150.0)
    assert back[0] == pytest.approx(none[0], abs=1e-9) and none[0] < 8.0 - 1.0
    assert bounce(8.0, -3.0, -150.0)[0] > none[0] + 0.3, "topspin is still faster"
    assert bounce(8.0, -3.0, 150.0)[2] > bounce(8.0, -3.0, 0.0)[2], "backspin floats higher (Magnus)"


def flight(spin: float = 0.0, steps: int = 15, **options) -> np.ndarray:
    """A ball launched high over the table toward +x, after ``steps`` steps: (x, y, vx, vy, spin)."""
    c = core_of(**options)
    park(c)
    rally(c, 0, ball=[-1.0, 1.2, 8.0, 2.0, spin])
    for _ in range(steps):
        c.step(STILL)
    assert c.score.sum() == 0, "still in the air"
    return c.ball[:, 0].copy()


def test_drag_slows_a_ball():
    with_drag, without = flight(), flight(drag=0.0)
    assert without[2] == pytest.approx(8.0), "no drag: the horizontal speed stays"
    assert with_drag[2] < 8.0 - 0.5, "drag takes off horizontal speed"
    assert with_drag[0] < without[0]
    speeds = [flight(steps=k)[2] for k in (1, 5, 10)]
    assert speeds[0] > speeds[1] > speeds[2], "and keeps slowing it"


def test_magnus_topspin_dips_and_backspin_floats():
    top, none, back = flight(-150.0), flight(0.0), flight(150.0)
    assert top[1] < none[1] - 0.05 and back[1] > none[1] + 0.05, "topspin dips, backspin floats"
    assert flight(-150.0, magnus=0.0)[1] == pytest.approx(flight(0.0, magnus=0.0)[1]), "no Magnus: spin no matter"
    assert abs(top[4]) < 150.0, "spin decays a little in the air"


def test_a_fast_ball_cannot_pass_through_the_net_or_a_bat():
    c = core_of()
    park(c)
    rally(c, 0, ball=[-0.3, 0.1, 40.0, 0.0, 0.0])  # 80 cm a step, 20 cm a substep, at the net's height
    c.step(STILL)
    assert c.surface[0] == NET and c.reason[0] == INTO_NET and c.winner[0] == 1
    c = core_of()
    park(c)
    c.bat[:, 1, 0] = [1.6, 0.5, 0.0, 0.0, 0.0, 0.0]  # seat 1's bat upright in the ball's path
    rally(c, 0, landed=True, ball=[0.8, 0.5, 35.0, 0.0, 0.0])  # 17 cm a substep
    for _ in range(3):
        c.step(STILL)
    assert c.surface[0] == BAT_0 + 1 and c.hitter[0] == 1, "seat 1's bat returned it"
    assert c.ball[2, 0] < -20.0 and c.ball[0, 0] < 1.6, "bounced back off the face, on the near side"


def stroke(bat_v=(0.0, 0.0), angle=0.0, ball_v=(-5.0, 0.0), ball_spin=0.0) -> np.ndarray:
    """Seat 0's bat at (-1.8, 0.3), tilted ``angle``, moving at ``bat_v``, meets a ball coming at ``ball_v``;
    the ball just after."""
    c = core_of()
    park(c)
    c.bat[0, 0, 0], c.bat[1, 0, 0], c.bat[4, 0, 0] = -1.8 - bat_v[0] * 0.02, 0.3 - bat_v[1] * 0.02, angle
    rally(c, 1, landed=True, ball=[-1.8 + BALL_R + 0.08, 0.3, ball_v[0], ball_v[1], ball_spin])
    a = np.zeros((2, 1, 3))
    a[0, 0, :2] = np.asarray(bat_v) / 6.0
    c.step(a)
    assert c.hitter[0] == 0 and c.returns[0, 0] == 1, "a legal return"
    return c.ball[:, 0].copy()


def test_the_bats_angle_and_velocity_set_the_return():
    flat = stroke()
    assert flat[2] == pytest.approx(0.85 * 5.0, abs=0.2) and abs(flat[3]) < 0.2, "upright still bat: e times back"
    assert stroke(angle=0.5)[3] > 1.0 > abs(flat[3]), "an open face lifts the ball"
    assert stroke(angle=-0.5)[3] < -1.0, "a closed face sends it down"
    assert stroke(bat_v=(4.0, 0.0))[2] > flat[2] + 4.0, "a bat moving forward hits harder"
    assert stroke(bat_v=(0.0, 4.0))[4] < -50.0, "brushing up gives topspin (w < 0 going +x)"
    assert stroke(bat_v=(0.0, -4.0))[4] > 50.0, "chopping down gives backspin"
    assert stroke(bat_v=(0.0, 4.0))[3] > 1.0, "and the brush lifts the ball"


def test_a_bat_stays_in_its_box_and_never_crosses_the_net():
    c = core_of(bat_scale=3.0)
    forward = np.zeros((2, 1, 3))
    forward[:, 0] = [1.0, 1.0, 1.0]  # full speed toward the net, up, opening the face
    for _ in range(30):  # within the toss's flight (a new point brings the bats home)
        c.step(forward)
        x, y, angle = c.bat[0, :, 0], c.bat[1, :, 0], c.bat[4, :, 0]
        reach = c.half * np.abs(np.sin(angle))
        assert x[0] + reach[0] <= -NET_GAP + 1e-9 and x[1] - reach[1] >= NET_GAP - 1e-9
    assert (y == 1.6).all() and np.allclose(angle, math.pi / 2)
    o = c.observe()
    assert np.allclose(o[:, 0, 2:4], 0.0) and np.allclose(o[:, 0, 5], 0.0), "a bat held at its box does not move"


# ---------------------------------------------------------------------------------------------------------------
# The rules: every fault scored for the right player, with the game's records
def test_into_the_net_is_the_hitters_fault():
    for hitter in (0, 1):
        c = core_of()
        park(c)
        d = 1 if hitter == 0 else -1
        rally(c, hitter, ball=[-0.3 * d, 0.12, 5.0 * d, 0.0, 0.0])
        run_point(c)
        assert (c.winner[0], c.reason[0], c.surface[0]) == (1 - hitter, INTO_NET, NET)
        assert c.score[:, 0].tolist() == ([0, 1] if hitter == 0 else [1, 0])


def test_hitting_out_is_the_hitters_fault():
    c = core_of()
    park(c)
    rally(c, 0, ball=[-0.5, 0.5, 9.0, 1.0, 0.0])  # long: over the far end, to the floor
    run_point(c)
    assert (c.winner[0], c.reason[0], c.surface[0]) == (1, HIT_OUT, OUT)


def test_landing_on_ones_own_half_is_the_hitters_fault():
    c = core_of()
    park(c)
    rally(c, 1, ball=[0.5, 0.3, 2.0, -1.0, 0.0])  # seat 1 hit it; it comes down on seat 1's half
    run_point(c)
    assert (c.winner[0], c.reason[0], c.surface[0]) == (0, OWN_HALF, TABLE_1)


def test_a_second_bounce_on_the_receivers_half_is_the_hitters_point():
    c = core_of()
    park(c)
    rally(c, 0, ball=[0.2, 0.3, 1.5, 0.0, 0.0])  # short and slow: bounces twice on seat 1's half
    c.step(STILL)
    bounces = []
    while c.score.sum() == 0:
        landed = c.landed[0]
        c.step(STILL)
        if c.landed[0] and not landed:
            bounces.append(c.surface[0])
    assert bounces == [TABLE_1], "the first bounce landed the ball"
    assert (c.winner[0], c.reason[0]) == (0, DOUBLE_BOUNCE)


def test_hitting_twice_is_a_fault_and_one_stroke_is_not():
    c = core_of()
    park(c)
    c.bat[:, 0, 0] = [-1.6, 0.3, 0.0, 0.0, math.pi / 2, 0.0]  # seat 0's face up, flat, still
    rally(c, 1, landed=True, ball=[-1.6, 0.3 + BALL_R + 0.05, 0.0, -1.0, 0.0])  # falling onto it
    hits = []
    while c.score.sum() == 0:
        c.step(STILL)
        hits.append(int(c.returns[0, 0]))
    assert hits[-1] == 1 and max(hits) == 1, "the first touch was a legal return"
    assert (c.winner[0], c.reason[0], c.surface[0]) == (1, DOUBLE_HIT, BAT_0)
    assert len(hits) > 5, "the second touch came when the ball fell back on the face"


def test_volleying_a_ball_before_it_bounced_is_a_fault():
    c = core_of()
    park(c)
    c.bat[:, 0, 0] = [-0.3, 0.27, 0.0, 0.0, 0.0, 0.0]  # seat 0's bat over its own half, in the ball's way
    rally(c, 1, ball=[0.3, 0.3, -6.0, 0.0, 0.0])
    run_point(c)
    assert (c.winner[0], c.reason[0], c.surface[0]) == (1, VOLLEY, BAT_0)


def test_the_hit_reward_pays_a_legal_stroke_never_a_fouls_touch():
    """The hit reward pays a serve of one's own toss and a return of a ball that bounced on one's own half; a foul's
    touch (here a volley) earns nothing and loses the point. (Seed 002 paid fouls too; learners then volleyed.)"""
    c = core_of(hit_reward=0.25, point_reward=2.0)
    park(c)
    c.bat[:, 0, 0] = [-0.3, 0.27, 0.0, 0.0, 0.0, 0.0]
    rally(c, 1, ball=[0.3, 0.3, -6.0, 0.0, 0.0])
    total = np.zeros(2)
    while c.score.sum() == 0:
        total += c.step(STILL)[:, 0]
    assert c.reason[0] == VOLLEY and c.surface[0] == BAT_0, "seat 0's bat touched the ball"
    assert total.tolist() == [-2.0, 2.0], "no hit reward for the volley"
    c = core_of(hit_reward=0.25, point_reward=2.0)
    rule = serve_bot_for(c.config)
    paid, returned = np.zeros(2), False
    while c.score.sum() == 0:
        paid += c.step(bot_actions(c, rule))[:, 0]
        returned |= bool(c.returns[:, 0].sum())
        if returned:
            break
    assert returned, "the bot returned the serve"
    assert paid.tolist() == [0.25, 0.25], "the serve and the return each earned the hit reward"


def test_the_return_reward_pays_for_a_stroke_that_lands_on_the_opponents_half_only():
    """Seed 002's practice reward for "the ball not only across the net but also onto the opponent's table": paid
    when the ball lands there, and never for a stroke that lands on the hitter's own half."""
    c = core_of(return_reward=0.5)
    park(c)
    rally(c, 1, ball=[0.5, 0.4, -4.0, 0.0, 0.0])  # seat 1's ball on its way to seat 0's half
    total, paid_at_landing = np.zeros(2), None
    while c.score.sum() == 0:
        r = c.step(STILL)[:, 0]
        if c.landed[0] and paid_at_landing is None:
            paid_at_landing = r.tolist()
        total += r
    assert paid_at_landing == [0.0, 0.5], "paid on the step the ball lands"
    assert c.reason[0] == NOT_RETURNED and total.tolist() == [-1.0, 1.5]
    c = core_of(return_reward=0.5)
    park(c)
    rally(c, 1, ball=[0.5, 0.4, 2.0, 1.0, 0.0])  # seat 1's ball onto its own half
    total = np.zeros(2)
    while c.score.sum() == 0:
        total += c.step(STILL)[:, 0]
    assert c.reason[0] == OWN_HALF and total.tolist() == [1.0, -1.0]


def test_a_missed_toss_is_the_servers_fault_and_the_serve_clock_runs_out():
    c = core_of()
    server = int(c.server[0])
    steps = run_point(c)  # nobody strikes: the toss falls to the floor
    assert (c.winner[0], c.reason[0], c.surface[0]) == (1 - server, MISSED_SERVE, OUT)
    assert 30 < steps < 50, "the toss falls in about 0.8 s"
    c = core_of(serve_time=0.3)
    server = int(c.server[0])
    assert run_point(c) == 15 and (c.winner[0], c.reason[0]) == (1 - server, MISSED_SERVE)


def test_a_ball_that_lands_and_is_not_returned_is_the_hitters_point():
    c = core_of()
    park(c)
    rally(c, 1, ball=[0.5, 0.4, -4.0, 0.0, 0.0])
    c.step(STILL)
    assert c.turn[0] == 0 and c.hitter[0] == 1 and not c.landed[0]
    obs = c.observe()
    assert obs[0, 0, INCOMING] == 1 and obs[1, 0, OUTGOING] == 1
    while not c.landed[0]:
        c.step(STILL)
    obs = c.observe()
    assert c.surface[0] == TABLE_0 and obs[0, 0, MY_TURN] == 1 and obs[0, 0, INCOMING] == 0
    run_point(c)
    assert (c.winner[0], c.reason[0]) == (1, NOT_RETURNED)


def test_a_serve_must_land_on_the_receivers_half():
    c = core_of(seeds=(3,))
    server = int(c.server[0])
    sigma = 1.0 if server == 0 else -1.0
    assert c.tossing[0] and c.hitter[0] == -1 and c.turn[0] == server
    assert c.observe()[server, 0, I_SERVE] == 1 and c.observe()[1 - server, 0, THEY_SERVE] == 1
    c.ball[2:, 0] = [sigma * 1.0, 1.0, 0.0]  # as if struck softly: it comes down on the server's own half
    c.tossing[0], c.hitter[0], c.serve_shot[0], c.since_hit[0] = False, server, True, 1e9
    park(c)
    run_point(c)
    assert (c.winner[0], c.reason[0]) == (1 - server, OWN_HALF)


def served(c: TennisCore, ball) -> int:
    """Game 0's toss struck by its server (long ago): the ball (world x, y, vx, vy, spin) in flight; the server."""
    server = int(c.server[0])
    c.tossing[0], c.hitter[0], c.serve_shot[0], c.since_hit[0] = False, server, True, 1e9
    c.ball[:, 0] = ball
    park(c)
    return server


def test_under_the_bounce_rule_a_serve_bounces_on_the_servers_half_then_the_receivers():
    sigma = lambda c: 1.0 if c.server[0] == 0 else -1.0  # noqa: E731 - the server's forward
    # straight onto the receiver's half: a fault (the default, direct rule, takes it)
    for bounce, reason in ((True, SERVE_NO_BOUNCE), (False, DOUBLE_BOUNCE)):  # (unreturned, it bounces again)
        c = core_of(seeds=(3,), serve_bounce=bounce)
        f = sigma(c)
        server = served(c, [f * 0.5, BALL_R + 0.004, f * 3.0, -2.0, 0.0])
        run_point(c)
        assert (c.reason[0], c.serves_in[server, 0]) == (reason, 0 if bounce else 1)
        assert c.winner[0] == (1 - server if bounce else server)
    # first on its own half, then over the net onto the receiver's: in (the direct rule: a fault on its own half)
    for bounce in (True, False):
        c = core_of(seeds=(3,), serve_bounce=bounce)
        f = sigma(c)
        server = served(c, [f * -0.5, BALL_R + 0.004, f * 3.0, -3.0, 0.0])
        c.step(STILL)  # the bounce on the server's own half
        assert c.surface[0] == TABLE_0 + server
        if bounce:
            assert c.serve_bounced[0] and c.score[:, 0].sum() == 0, "the rule: play on"
            run_point(c)
            assert (c.winner[0], c.reason[0], c.serves_in[server, 0]) == (server, DOUBLE_BOUNCE, 1)
        else:
            assert (c.winner[0], c.reason[0], c.serves_in[server, 0]) == (1 - server, OWN_HALF, 0)
    # twice on its own half: a fault
    c = core_of(seeds=(3,), serve_bounce=True)
    f = sigma(c)
    server = served(c, [f * -0.9, BALL_R + 0.004, f * 0.5, -1.0, 0.0])
    run_point(c)
    assert (c.winner[0], c.reason[0]) == (1 - server, OWN_HALF)


# ---------------------------------------------------------------------------------------------------------------
# Serves, games, seeds
def test_serves_alternate_every_two_points_and_every_point_from_ten_all():
    c = core_of(seeds=(5,), max_steps=3000)
    first = int(c.server[0])
    servers, scores = [], []
    while not c.over[0]:
        servers.append(int(c.server[0]))
        scores.append(tuple(c.score[:, 0]))
        run_point(c)  # nobody strikes: the receiver wins every point
    assert len(servers) > 26 and c.truncated[0], "past 10-10: the receivers alternate, so nobody wins by 2"
    expect = [first if (p // 2) % 2 == 0 else 1 - first for p in range(20)]
    assert servers[:20] == expect
    assert scores[20] == (10.0, 10.0)
    assert servers[20:] == [first if k % 2 == 0 else 1 - first for k in range(len(servers) - 20)]
    assert server_of(np.array([0]), np.array([20]), 11)[0] == 0 and server_of(np.array([1]), np.array([3]), 11)[0] == 0


def test_a_game_is_won_at_eleven_by_two():
    assert game_won(np.array([11, 11, 12, 10, 13]), np.array([9, 10, 10, 8, 11]), 11).tolist() == [
        True, False, True, False, True]
    rule = serve_bot_for(TennisConfig())
    c = core_of(seeds=(2,))
    c.score[:, 0] = [10.0, 10.0]
    c._new_point(np.array([0]))
    seen = []
    while not c.over[0]:  # seat 0 plays the serve-bot, seat 1 stands still: seat 0 wins every point
        c.step(bot_actions(c, rule, seats=(0,)))
        if not seen or tuple(c.score[:, 0]) != seen[-1]:
            seen.append(tuple(c.score[:, 0]))
    assert seen == [(10.0, 10.0), (11.0, 10.0), (12.0, 10.0)]
    assert c.terminated[0] and not c.truncated[0] and not c.to_act().any()
    frozen = c.observe().copy()
    c.step(np.ones((2, 1, 3)))
    assert np.array_equal(frozen, c.observe()), "a finished game stands still"


def test_a_game_to_eleven_from_love_and_the_time_limit():
    c = core_of(seeds=(4,))
    rule = serve_bot_for(c.config)
    rewards = np.zeros(2)
    while not c.over[0]:
        rewards += c.step(bot_actions(c, rule, seats=(0,)))[:, 0]
    assert c.score[:, 0].tolist() == [11.0, 0.0] and c.terminated[0]
    assert rewards.tolist() == [11.0, -11.0], "zero-sum point rewards"
    c = core_of(max_steps=40)
    for _ in range(40):
        c.step(STILL)
    assert c.truncated[0] and not c.terminated[0] and c.steps[0] == 40


def play_random(seeds, steps=150, action_seed=0) -> list[np.ndarray]:
    c = core_of(seeds=seeds)
    rng = np.random.default_rng(action_seed)
    out = []
    for _ in range(steps):
        out.append(c.observe())
        c.step(rng.uniform(-1, 1, (2, len(seeds), 3)))
    out.append(c.score.copy())
    return out


def test_same_seeds_same_games_alone_or_batched_and_seeds_differ():
    a, b = play_random((7, 8)), play_random((7, 8))
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    other = play_random((9, 10))
    assert not np.array_equal(a[0], other[0]), "another seed, another toss"
    one = core_of(seeds=(8,))
    batch = core_of(seeds=(7, 8, 9))
    rng = np.random.default_rng(1)
    for _ in range(200):
        a1 = rng.uniform(-1, 1, (2, 1, 3))
        a3 = rng.uniform(-1, 1, (2, 3, 3))
        a3[:, 1:2] = a1
        one.step(a1)
        batch.step(a3)
        assert np.array_equal(one.observe()[:, 0], batch.observe()[:, 1])
    servers = {int(core_of(seeds=(s,)).server[0]) for s in range(12)}
    assert servers == {0, 1}, "the first server is drawn"


# ---------------------------------------------------------------------------------------------------------------
# Egocentric observations
def test_mirroring_the_world_swaps_the_seats_observations_and_games_exactly():
    c = core_of(seeds=(11, 12, 13, 14))
    rng = np.random.default_rng(0)
    rule = serve_bot_for(c.config)
    for _ in range(60):  # a played state: serves, rallies, spins
        c.step(bot_actions(c, rule))
    c.ball[4] = rng.uniform(-300, 300, c.n)
    c.bat[2:4] = rng.uniform(-6, 6, (2, 2, c.n))
    c.bat[4] = rng.uniform(-1.5, 1.5, (2, c.n))
    m = TennisCore(c.n, c.config)
    m.set_state(mirrored(c.get_state()))
    o, om = c.observe(), m.observe()
    assert np.array_equal(o[0], om[1]) and np.array_equal(o[1], om[0])
    assert not np.array_equal(o[0], o[1])
    for _ in range(300):  # the mirrored game is the same game with the seats swapped
        a = np.stack([rule(o[0]), rng.uniform(-1, 1, (c.n, 3)).astype(np.float32)])
        r, rm = c.step(a), m.step(a[::-1])
        o, om = c.observe(), m.observe()
        assert np.array_equal(r, rm[::-1]) and np.array_equal(o[0], om[1]) and np.array_equal(o[1], om[0])
    assert np.array_equal(c.score, m.score[::-1]) and c.score.sum() > 0


def test_observations_are_within_their_declared_bounds():
    space = TENNIS.observation_space(TENNIS.config())
    assert space.shape == (N_FEATURES,) and space.dtype == np.float32
    assert np.array_equal(space.low, OBS_LOW) and np.array_equal(space.high, OBS_HIGH)
    c = core_of(seeds=tuple(range(16)))
    rng = np.random.default_rng(3)
    for _ in range(400):
        o = c.observe()
        assert (o >= space.low).all() and (o <= space.high).all()
        c.step(rng.uniform(-1, 1, (2, 16, 3)))
    assert o[0, 0, BAT_LENGTH] == pytest.approx(0.15)


# ---------------------------------------------------------------------------------------------------------------
# The curricula's hook and the options
def test_set_options_changes_rewards_and_the_bat_of_running_games():
    c = core_of(seeds=(1, 2), hit_reward=0.5)
    rule = serve_bot_for(c.config)
    r = np.zeros((2, 2))
    while not r.any():  # the serves
        r = c.step(bot_actions(c, rule))
    assert sorted(r[r != 0].tolist()) == [0.5] * int((r != 0).sum()), "a hit earns hit_reward"
    c.set_options(hit_reward=0.125, point_reward=3.0, bat_scale=2.0)
    assert c.config.hit_reward == 0.125 and c.half == pytest.approx(0.15)
    assert (c.observe()[..., BAT_LENGTH] == np.float32(0.3)).all()
    # game 0: a ball into the net; game 1: a ball falling onto seat 1's upright bat after bouncing on its half
    for g in (0, 1):
        park(c, g)
    rally(c, 0, g=0, ball=[-0.05, 0.12, 5.0, 0.0, 0.0])
    c.bat[:, 1, 1] = [1.6, 0.18, 0.0, 0.0, 0.0, 0.0]  # its centre 12 cm below the ball: 7.5 cm would miss
    rally(c, 0, landed=True, g=1, ball=[1.53, 0.3, 4.0, 0.0, 0.0])
    r = c.step(np.zeros((2, 2, 3)))
    assert r[:, 0].tolist() == [-3.0, 3.0] and r[:, 1].tolist() == [0.0, 0.125]
    assert c.hitter[1] == 1, "a bat of twice the length reaches the ball"
    for bad in ({"bat_scale": 0.0}, {"bat_scale": -1.0}, {"bat_scale": float("nan")}, {"hit_reward": float("inf")},
                {"point_reward": float("nan")}, {"point_reward": -1.0}, {"max_steps": 10}, {"bat_scale": "big"}):
        with pytest.raises(ValueError):
            c.set_options(**bad)
    assert c.config.bat_scale == 2.0 and c.config.hit_reward == 0.125, "a refused change changes nothing"


def test_options_are_checked():
    assert make_config(serve_mode="spin", bat_scale=2).bat_length == pytest.approx(0.3)
    for bad in ({"serve_mode": "lob"}, {"bat_scale": 0}, {"bat_scale": 6.0}, {"discrete": "yes"}, {"max_steps": 0},
                {"points_to_win": 2.0}, {"hit_reward": float("nan")}, {"serve_time": 0.0}, {"drag": -1.0}):
        with pytest.raises(ValueError):
            make_config(**bad)
    with pytest.raises(ValueError, match="unknown tennis option"):
        make_config(bat_size=2)


def test_discrete_option():
    cfg = TENNIS.config(discrete=True)
    assert TENNIS.action_space(cfg) == spaces.MultiDiscrete([3, 3, 3])
    assert TENNIS.action_space(TENNIS.config()) == spaces.Box(-1, 1, (3,), dtype=np.float32)
    c = core_of(discrete=True)
    up = np.ones((2, 1, 3), dtype=np.int64)
    up[:, 0, 1] = 2  # +1 on the vertical axis, 0 on the others
    y = c.bat[1, :, 0].copy()
    c.step(up)
    assert np.allclose(c.bat[1, :, 0] - y, 6.0 * 0.02) and np.allclose(c.bat[0, :, 0], [-1.8, 1.8])
    from selfplay_cli.envs.contract import IllegalActionError

    with pytest.raises(IllegalActionError):
        c.step(np.full((2, 1, 3), 3))
    rule = TENNIS.bots["serve-bot"].rule_for(cfg)
    acts = rule(c.observe()[0])
    assert acts.dtype == np.int64 and set(np.unique(acts)) <= {0, 1, 2}


# ---------------------------------------------------------------------------------------------------------------
# The serve-bot
@pytest.mark.slow
@pytest.mark.parametrize("bounce", [False, True], ids=["direct", "bounce"])
@pytest.mark.parametrize("mode, rate", [("fixed", 0.97), ("velocity", 0.93), ("spin", 0.93), ("mixed", 0.93)])
def test_serve_bot_serves_land_legally_in_each_mode(mode, rate, bounce):
    """Under either serve rule (serve_bounce: first on its own half, then on the receiver's). Spin: velocity's
    serves carry none, spin's mostly 20 rad/s or more, mixed's either, about half each."""
    c = core_of(seeds=tuple(range(100, 132)), serve_mode=mode, serve_bounce=bounce)
    rule = serve_bot_for(c.config)
    served = landed = 0
    speeds: list[float] = []
    spins: list[float] = []
    for _ in range(700):  # seat 0 serves with the bot, seat 1 stands still (it never strikes: it misses its toss)
        before = (c.serves[0].copy(), c.serves_in[0].copy())
        tossing = c.tossing & (c.server == 0)
        c.step(bot_actions(c, rule, seats=(0,)))
        struck = tossing & (c.serves[0] > before[0])
        speeds += np.hypot(c.ball[2, struck], c.ball[3, struck]).tolist()
        spins += np.abs(c.ball[4, struck]).tolist()
        served += int((c.serves[0] - before[0]).sum())
        landed += int((c.serves_in[0] - before[1]).sum())
    assert served >= 60
    assert landed / served >= rate, f"{mode}: {landed}/{served} serves landed on the receiver's half"
    spread = float(np.std(speeds))
    assert (spread > 0.8) if mode != "fixed" else (spread < 0.4), f"{mode}: serves' speeds vary by {spread:.2f} m/s"
    spun = float(np.mean(np.array(spins) > 20.0))
    want = {"fixed": (0.0, 0.0), "velocity": (0.0, 0.0), "spin": (0.75, 1.0), "mixed": (0.3, 0.7)}[mode]
    assert want[0] <= spun <= want[1], f"{mode}: {spun:.0%} of the serves spun at 20 rad/s or more"


@pytest.mark.slow
@pytest.mark.parametrize("bounce", [False, True], ids=["direct", "bounce"])
@pytest.mark.parametrize("mode", ["fixed", "velocity", "spin", "mixed"])
def test_serve_bot_returns_its_own_balls_and_rallies(mode, bounce):
    """Against itself the bot rallies (either serve rule); in the randomized (practice) modes it waits for a serve
    at a random place near its home, so a learner cannot tie its serve to where the receiver stands, and still
    returns."""
    c = core_of(seeds=tuple(range(12)), serve_mode=mode, serve_bounce=bounce)
    rule = serve_bot_for(c.config)
    waits = set()
    for _ in range(800):
        tossing, served = c.tossing.copy(), c.serves.sum(axis=0)
        obs = c.observe()
        c.step(bot_actions(c, rule))
        for g in np.flatnonzero(tossing & (c.serves.sum(axis=0) > served)):  # the receiver, as the serve is struck
            waits.add(tuple(np.round(obs[1 - c.hitter[g], g, [BAT_X, BAT_Y, BAT_ANGLE]].astype(float), 2).tolist()))
    returns, good = c.returns.sum(), c.returns_in.sum()
    assert good / returns >= 0.9, f"{good}/{returns} returns landed"
    if mode not in ("spin", "mixed"):  # the bot misjudges spin, so spin serves beat it
        assert (c.serves.sum() + returns) / max(c.score.sum(), 1) >= 4, "rallies of 4 hits or more on average"
    if mode == "fixed":
        assert waits == {(HOME_X, HOME_Y, 0.0)}, "it waits at home, upright"
    else:
        spread = np.ptp(np.array(sorted(waits)), axis=0)
        assert len(waits) >= 10 and (spread > [0.6, 0.6, 1.5]).all(), f"{mode}: it waited within {spread} (m, m, rad)"


def bot_plays(rule, balls, steps: int = 90) -> tuple[np.ndarray, ...]:
    """Seat 0 has just hit each ball (vx, vy, spin) from 1.2 m before the net; seat 1 plays ``rule`` for ``steps``
    steps. Returns which balls landed on seat 1's half, which of those seat 1 returned onto seat 0's half, where each
    return landed there (m past the net; nan where none did) and the spin seat 1's stroke gave it (topspin toward
    seat 0 positive; nan where it did not hit)."""
    n = len(balls)
    c = core_of(seeds=tuple(range(n)))
    for g, (vx, vy, w) in enumerate(balls):
        park(c, g)
        c.bat[0:2, 1, g] = [1.8, 0.2]
        rally(c, 0, g=g, ball=[-1.2, 0.3, vx, vy, w])
    landed = np.zeros(n, dtype=bool)
    depth, spin = np.full(n, np.nan), np.full(n, np.nan)
    for _ in range(steps):
        a = np.zeros((2, n, 3), dtype=np.float32)
        a[1] = rule(c.observe()[1])
        c.step(a)
        landed |= c.landed & (c.hitter == 0)
        struck = (c.hitter == 1) & np.isnan(spin)
        spin[struck] = c.ball[4, struck]
        back = c.landed & (c.hitter == 1) & np.isnan(depth)
        depth[back] = -c.ball[0, back]
    return landed, c.returns_in[1] > 0, depth, spin


def returned(rule, balls, steps: int = 90) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bot_plays`'s balls landed on seat 1's half and returned onto seat 0's."""
    return bot_plays(rule, balls, steps)[:2]


def test_serve_bot_plans_a_ball_at_the_net_without_overflow():
    """A ball at the net gave the planner's parabola a near-zero run, launch speeds of thousands of m/s and an
    overflowing flight model (RuntimeWarnings on a user's terminal); it now plans from 5 cm behind the net."""
    x0 = np.array([-1e-4, -0.01, -0.5])
    with np.errstate(all="raise"):
        vx, vy = plan_launch(x0, np.array([0.3, 1.2, 0.2]), np.zeros(3), np.full(3, 0.8), np.full(3, 0.25))
    assert np.isfinite(vx).all() and np.isfinite(vy).all() and (np.abs(vy) <= 30).all() and (vx <= 16).all()


@pytest.mark.parametrize("ball", [[-1.0, 0.3, 8.0, 1.0, 0.0], [-0.6, 0.3, 9.0, 1.5, 0.0], [-0.8, 0.4, 7.0, 2.0, 0.0]])
def test_serve_bot_keeps_its_bat_out_of_the_way_of_a_ball_going_long(ball):
    """A ball that will not land on its half is the hitter's fault if let alone; the bot standing at home in its
    path made it a volley, the bot's fault (learners found that and served into its bat instead of playing)."""
    c = core_of()
    park(c)
    c.bat[0:2, 1, 0] = [-HOME_X, HOME_Y]  # the bot (seat 1) waiting at home
    rally(c, 0, ball=ball)
    rule = serve_bot_for(c.config)
    run_point(c, actions=lambda: bot_actions(c, rule, seats=(1,)))
    assert (c.winner[0], c.reason[0]) == (1, HIT_OUT), REASON_NAMES[c.reason[0]]


def test_serve_bot_smashes_a_ball_that_bounces_above_its_reach():
    """Learners found a serve the bot could not return: struck up to 5 m, it lands just past the net and bounces
    2 m high. The bot waited for the top of the bounce, above its bat's reach, and then planned a stroke no bat can
    swing (down over the net as steeply as a straight line). It now meets such a ball coming down through 1.2 m
    and smashes it over the net (a fixed snapshot of such a learner: 0 of 476 such serves returned before, 374 of
    390 after)."""
    balls = [(vx, vy, 0.0) for vx in (1.3, 1.5) for vy in (7.0, 8.0, 9.0, 10.0, 11.0)]
    landed, back = returned(serve_bot_for(TennisConfig()), balls, steps=250)
    assert landed.all(), "every ball lands on the bot's half (0.1-0.8 m past the net), bouncing 1.2-1.8 m high"
    assert back.all(), f"the bot returned {back.sum()} of {len(balls)}"


def test_serve_bot_practice_returns_go_back_at_the_pace_they_came():
    """In the practice modes the bot sends a fast ball back deep and low (in spin mode with topspin) and a slow one
    short, so a learner practises against the pace it plays; its fixed mode returns every ball the same way."""
    balls = [(vx, vy, 0.0) for vx, vy in ((3.0, 2.6), (3.5, 2.2), (10.5, 0.0), (11.0, -0.3))]
    *_, depth, flat = bot_plays(serve_bot_for(TennisConfig(serve_mode="velocity")), balls)
    assert not np.isnan(depth).any(), f"it returned every ball: {depth}"
    assert depth[2:].min() > depth[:2].max() + 0.25, f"fast balls come back deeper: {depth} m past the net"
    *_, fixed, _ = bot_plays(serve_bot_for(TennisConfig(serve_mode="fixed")), balls)
    assert not np.isnan(fixed).any() and np.ptp(fixed) < 0.2, f"fixed: one return, {fixed} m past the net"
    *_, spin = bot_plays(serve_bot_for(TennisConfig(serve_mode="spin")), balls)
    assert np.allclose(spin[:2], flat[:2], atol=2.0) and (spin[2:] > flat[2:] + 30).all(), \
        f"spin mode: topspin on the fast returns only, {spin} rad/s (velocity mode: {flat})"


def test_serve_bot_misjudges_spin_so_spin_beats_it():
    balls = [(vx, vy, w) for vx in (5.0, 6.5, 8.0, 9.5) for vy in (0.0, 1.0, 2.0) for w in (-300.0, -200.0, 0.0)]
    spin = np.array([b[2] for b in balls]) != 0
    landed, perfect = returned(serve_bot_rule_for(spin_read=1.0), balls)
    assert landed.sum() >= 12 and perfect[landed].all(), "reading spin right, it returns every ball"
    _, bot = returned(serve_bot_for(TennisConfig()), balls)
    assert bot[landed & ~spin].all(), "it returns the balls without spin"
    assert bot[landed & spin].mean() < 0.5, "it misses most heavy topspin"


def test_random_loses_to_the_serve_bot_through_the_arena():
    spec = get_env("tennis")
    assert (spec.kind, spec.turns, spec.n_seats, spec.anchor) == ("two-sides", "simultaneous", 2, "serve-bot")
    assert list(spec.bots) == ["serve-bot"] and spec.side_seats() == ((0,), (1,))
    assert spec.max_steps() == 6000 and spec.render_fps == 50
    live = ("hit_reward", "return_reward", "point_reward", "bat_scale")
    assert spec.live_options == live, "what a curriculum may drive"
    players = [ScriptedPolicy("tennis", "serve-bot", seed=1), ScriptedPolicy("tennis", "random", seed=1)]
    results = play(spec, players, [Game(s, (0, 1)) for s in range(2)] + [Game(s, (1, 0)) for s in range(2)])
    bot_points = [r.scores[0] for r in results[:2]] + [r.scores[1] for r in results[2:]]
    random_points = [r.scores[1] for r in results[:2]] + [r.scores[0] for r in results[2:]]
    assert bot_points == [11.0] * 4 and max(random_points) <= 2, (bot_points, random_points)


def test_serve_bot_rule_follows_the_options():
    spec = get_env("tennis")
    bot = spec.bots["serve-bot"]
    c = core_of(seeds=(0,))
    server = int(c.server[0])
    for _ in range(5):
        c.step(STILL)
    obs = c.observe()[server]
    fixed, spin = bot.rule_for(spec.config()), bot.rule_for(spec.config(serve_mode="spin"))
    assert not np.array_equal(fixed(obs), spin(obs)), "serve_mode changes the serve"
    with pytest.raises(ValueError, match="serve_mode must be one of"):
        serve_bot_rule_for("lob")
    assert obs[0, BALL_X] == c.observe()[server, 0, BALL_X], "the toss's place (the serve's choices) is fixed"


# ---------------------------------------------------------------------------------------------------------------
# Views, the contract, the renderer
@pytest.mark.parametrize("options", [{}, {"discrete": True}])
def test_view_passes_pettingzoos_parallel_api_test(options):
    parallel_api_test(TennisParallelEnv(**options), num_cycles=300)


def test_view_is_the_cores_game():
    env = TennisParallelEnv()
    obs, infos = env.reset(seed=9)
    c = core_of(seeds=(9,))
    rule = serve_bot_for(c.config)
    assert infos["player_0"]["seed"] == 9 and infos["player_0"]["turn"] == c.turn[0]
    for _ in range(300):
        acts = bot_actions(c, rule)
        assert all(np.array_equal(obs[a], c.observe()[i, 0]) for i, a in enumerate(env.possible_agents))
        obs, rew, term, trunc, info = env.step({a: acts[i, 0] for i, a in enumerate(env.possible_agents)})
        r = c.step(acts)
        assert [rew[a] for a in env.possible_agents] == r[:, 0].tolist()
    assert info["player_0"]["score"] == tuple(int(s) for s in c.score[:, 0])
    assert info["player_1"]["score"] == tuple(int(s) for s in c.score[::-1, 0])


def _lockstep(game: ScalarTennis, core: TennisCore, rule, steps: int, rng, random_play: bool) -> None:
    """Play ``game`` and the one-game ``core`` side by side (the bot, with a random stroke now and then, or random
    actions beyond [-1, 1] too): the same observations, rewards and state at every step, bit for bit; a game that
    ends starts again with a new seed in both."""
    discrete = core.config.discrete
    for _ in range(steps):
        obs = core.observe()
        assert np.array_equal(game.observe().view(np.uint32), obs[:, 0].view(np.uint32))
        if random_play:
            acts = rng.integers(0, 3, (2, 1, 3)) if discrete else rng.uniform(-1.3, 1.3, (2, 1, 3)).astype(np.float32)
        else:
            acts = np.stack([rule(obs[0]), rule(obs[1])])
            if rng.random() < 0.1:
                acts[rng.integers(2)] = rng.integers(0, 3, 3) if discrete else rng.uniform(-1, 1, 3)
        rewards = game.step(acts[0, 0].tolist(), acts[1, 0].tolist())
        assert list(rewards) == core.step(acts)[:, 0].tolist()
        state, want = game.get_state(), core.get_state()
        for name, value in want.items():
            assert value.dtype == state[name].dtype and np.array_equal(value, state[name]), name
        if core.over[0]:
            seed = int(rng.integers(2**40))
            core.reset([0], [seed])
            game.reset(seed)


@pytest.mark.parametrize("options", [
    {},
    {"serve_mode": "mixed", "hit_reward": 0.3, "return_reward": 0.5, "bat_scale": 3.0},
    {"drag": 0.0, "magnus": 2.0, "points_to_win": 3, "max_steps": 400, "toss_jitter": 0.0, "serve_time": 0.3},
])
def test_the_views_game_in_python_floats_is_the_cores_bit_for_bit(options):
    """The view plays one game in Python floats (:class:`ScalarTennis`, several times faster than a batch of one): it
    is the core's game, every observation, reward and number of the state, in rallies, faults, serves running out of
    time, games won and cut by the time limit, with the live options changed between steps."""
    config = TennisConfig(**options)
    rng = np.random.default_rng(len(options))
    seed = int(rng.integers(100))
    core, game = core_of(seeds=(seed,), **options), ScalarTennis(config)
    game.reset(seed)
    rule = serve_bot_for(config)
    _lockstep(game, core, rule, 400, rng, random_play=False)
    _lockstep(game, core, rule, 150, rng, random_play=True)
    core.set_options(hit_reward=0.125, return_reward=0.25, point_reward=3.0, bat_scale=2.0)
    game.set_options(hit_reward=0.125, return_reward=0.25, point_reward=3.0, bat_scale=2.0)
    _lockstep(game, core, rule, 400, rng, random_play=False)


@pytest.mark.parametrize("options", [{}, {"serve_bounce": True, "hit_reward": 0.2, "return_reward": 0.3},
                                     {"discrete": True, "bat_scale": 2.5}])
@pytest.mark.slow
def test_the_views_game_follows_the_core_through_every_rule(options):
    """Games in Python floats set in rallies of every kind (a ball anywhere, at any speed and spin, whoever hit it,
    landed or not, bats anywhere in their boxes, scores near the end of a game) and played on beside the core's
    (random strokes, the bot, standing still): the same observations, rewards and states, bit for bit, while the
    points end for every reason."""
    n, rng = 128, np.random.default_rng(11)
    c = core_of(seeds=tuple(range(n)), **options)
    state = c.get_state()
    rally = rng.random(n) < 0.8  # the others: tossing
    k = int(rally.sum())
    state["ball"][:, rally] = [rng.uniform(-2.5, 2.5, k), rng.uniform(-0.05, 1.2, k), rng.uniform(-12, 12, k),
                               rng.uniform(-5, 5, k), rng.uniform(-600, 600, k)]
    state["tossing"][rally] = False
    state["hitter"][rally] = rng.integers(0, 2, k)
    state["landed"][rally] = rng.random(k) < 0.5
    state["serve_shot"][rally] = rng.random(k) < 0.5
    state["serve_bounced"][rally] = rng.random(k) < 0.5
    state["since_hit"][rally] = np.where(rng.random(k) < 0.3, rng.uniform(0.0, 0.05, k), 1e9)
    ego = rng.uniform(-2.87, -0.05, (2, n))
    state["bat"][0] = ego * np.array([[1.0], [-1.0]])
    state["bat"][1] = rng.uniform(-0.4, 1.6, (2, n))
    state["bat"][4] = rng.uniform(-1.5, 1.5, (2, n))
    state["score"] = rng.integers(8, 12, (2, n)).astype(np.float64)
    c.set_state(state)
    games = []
    for g in range(n):
        games.append(ScalarTennis(c.config))
        games[-1].set_state(c.get_state([g]))
    rule = serve_bot_for(c.config)
    how = rng.integers(0, 3, n)  # random strokes, the bot, standing still
    reasons = set()
    for _ in range(40):
        obs = c.observe()
        if c.config.discrete:
            acts = np.where(how[:, None] == 2, 1, rng.integers(0, 3, (2, n, 3)))
        else:
            acts = np.where(how[:, None] == 2, 0.0, rng.uniform(-1.2, 1.2, (2, n, 3))).astype(np.float32)
        acts[:, how == 1] = [rule(obs[0, how == 1]), rule(obs[1, how == 1])]
        before = c.score.sum(axis=0)
        rewards = c.step(acts)
        reasons |= {REASON_NAMES[r] for r in c.reason[c.score.sum(axis=0) != before]}
        for g, game in enumerate(games):
            assert np.array_equal(game.observe().view(np.uint32), obs[:, g].view(np.uint32)), g
            assert list(game.step(acts[0, g].tolist(), acts[1, g].tolist())) == rewards[:, g].tolist(), g
            mine, want = game.get_state(), c.get_state([g])
            assert all(np.array_equal(mine[name], value) for name, value in want.items()), g
        done = np.flatnonzero(c.over)
        c.reset(done, done + 1000)
        for g in done:
            games[g].reset(int(g) + 1000)
    assert reasons >= {"net", "out", "own_half", "double_bounce", "volley", "missed_serve", "not_returned"}, reasons
    assert "serve_no_bounce" in reasons or not options.get("serve_bounce")


def test_the_views_game_takes_up_a_cores_game_and_the_view_hands_it_back():
    """A core's game put into the view's (``set_state``) goes on as in the core; the view's ``core`` is a copy of its
    game (stepping it leaves the view's game as it was); the view's state round-trips."""
    c = core_of(seeds=(3, 4))
    rule = serve_bot_for(c.config)
    for _ in range(140):
        c.step(bot_actions(c, rule))
    game = ScalarTennis(c.config)
    game.set_state(c.get_state([1]))
    one = TennisCore(1, c.config)
    one.set_state(c.get_state([1]))
    _lockstep(game, one, rule, 300, np.random.default_rng(0), random_play=False)
    env = TennisParallelEnv()
    env.reset(seed=5)
    for _ in range(60):
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
    copy = env.core
    assert np.array_equal(copy.observe()[:, 0], np.stack([obs[a] for a in env.possible_agents]))
    copy.step(np.ones((2, 1, 3)))
    assert np.array_equal(env.state(), obs["player_0"]), "stepping the copy leaves the view's game"
    saved = env.get_state()
    after = env.step({a: np.full(3, 0.5, dtype=np.float32) for a in env.agents})
    env.set_state(saved)
    again = env.step({a: np.full(3, 0.5, dtype=np.float32) for a in env.agents})
    assert all(np.array_equal(after[0][a], again[0][a]) for a in env.possible_agents) and after[1] == again[1]


@pytest.mark.slow
def test_the_game_keeps_the_game_contract():
    """The conformance test's check, on tennis and on its discrete form."""
    import dataclasses
    import sys
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[1])
    if root not in sys.path:
        sys.path.insert(0, root)
    from tests.test_conformance import check_game

    check_game(TENNIS)
    check_game(dataclasses.replace(TENNIS, make_config=lambda **o: make_config(**{"discrete": True, **o})))


def test_renderer_draws_the_table_the_bats_and_the_ball():
    r = TENNIS.make_renderer()
    c = core_of(seeds=(1,))
    first = r.draw(c, 0)
    rule = serve_bot_for(c.config)
    for _ in range(30):
        c.step(bot_actions(c, rule))
    frame = r.draw(c, 0)
    assert frame.shape == (360, 800, 3) and frame.dtype == np.uint8
    assert not np.array_equal(first, frame)
    from selfplay_cli.envs.tennis.render import BALL, BAT_COLOURS

    for colour in (*BAT_COLOURS, BALL):
        assert (frame == colour).all(axis=2).sum() > 10, f"{colour} is drawn"
    env = TennisParallelEnv(render_mode="rgb_array")
    env.reset(seed=0)
    assert env.render().shape == (360, 800, 3)
    assert FLOOR_Y < 0 < NET_H


@pytest.mark.slow
def test_tennis_trains_with_its_own_defaults_and_flags_and_files_override_them(tmp_path, monkeypatch, capsys):
    """`marl train tennis` as typed: SAC against the serve bot's randomized serves, the seed's curricula and its
    practice reward (`marl envs tennis` prints them); a flag and a --config file override them."""
    from cli_helpers import run

    monkeypatch.setenv("MARL_HOME", str(tmp_path / "league"))
    small = ("--steps", "256", "--games", "8", "--eval-games", "0", "--quiet")
    assert run(capsys, "train", "tennis", "--agents", "2", "--run", "d", *small)[0] == 0
    cfg = json.loads((tmp_path / "league" / "runs" / "d" / "config.json").read_text())
    assert (cfg["algo"], cfg["sharing"], cfg["league_games"]) == ("sac", "fups", 0.5)
    assert cfg["opponents"]["bots"] == {"serve-bot": 0.75}
    assert cfg["env_options"]["serve_mode"] == "mixed" and cfg["env_options"]["return_reward"] == 0.5
    assert cfg["curriculum"]["bat_scale"] == {"start": 3.0, "end": 1.0, "until": 0.8}
    assert cfg["curriculum"]["hit_reward"] == {"start": 0.3, "end": 0.0, "until": 0.6}
    assert cfg["curriculum"]["point_reward"] == {"start": 0.1, "end": 1.0, "from": 0.3, "until": 0.9}
    assert (cfg["sac"]["replay_ratio"], cfg["sac"]["n_step"]) == (0.0625, 5)
    assert cfg["teacher"] == {"player": "serve-bot", "weight": {"start": 2.0, "end": 0.2, "until": 0.5},
                              "states": 300_000}
    assert (cfg["sac"]["arch"]["hidden"], cfg["sac"]["arch"]["activation"]) == ([256, 256], "relu")
    (tmp_path / "c.toml").write_text("[env_options]\nreturn_reward = 0.0\n"
                                     "[curriculum]\nbat_scale = 2.0\n")
    assert run(capsys, "train", "tennis", "--algo", "ppo", "--run", "o", "--config", str(tmp_path / "c.toml"),
               *small)[0] == 0
    cfg = json.loads((tmp_path / "league" / "runs" / "o" / "config.json").read_text())
    assert cfg["algo"] == "ppo" and cfg["env_options"] == {"serve_mode": "mixed", "return_reward": 0.0}
    assert cfg["curriculum"]["bat_scale"] == 2.0, "a plain number holds the bat at one size (the default's off)"
    assert cfg["teacher"]["player"] == "serve-bot" and cfg["ppo"]["arch"]["hidden"] == [256, 256]
    assert run(capsys, "train", "tennis", "--teacher", "none", "--run", "t0", *small)[0] == 0
    cfg = json.loads((tmp_path / "league" / "runs" / "t0" / "config.json").read_text())
    assert cfg["teacher"]["player"] == "", "--teacher none switches the game's teacher off"
    # one learner: the game's shared network and share of league games (for learners on both seats) do not apply,
    # and are dropped; typed, each is still one line
    assert run(capsys, "train", "tennis", "--agents", "1", "--run", "a1", *small)[0] == 0
    cfg = json.loads((tmp_path / "league" / "runs" / "a1" / "config.json").read_text())
    assert (cfg["sharing"], cfg["league_games"], cfg["opponents"]["bots"]) == ("nops", 0.0, {"serve-bot": 0.75})
    code, _, err = run(capsys, "train", "tennis", "--agents", "1", "--league-games", "0.5", "--run", "a2", *small)
    assert code == 2 and "--league-games is for --agents 2" in err
    code, _, err = run(capsys, "train", "tennis", "--agents", "1", "--sharing", "fups", "--run", "a3", *small)
    assert code == 2 and "--sharing fups" in err and "--agents 2" in err
