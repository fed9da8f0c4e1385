"""The runner plays games of every shape: per-seat spaces, masks, turns, results by kind, replays of any action."""

from __future__ import annotations

import numpy as np
import pytest
from arena_games import Const, Random, Spy, registered
from gymnasium import spaces

from selfplay_cli.envs import get_env
from selfplay_cli.errors import MarlError
from selfplay_cli.play import Game, GameResult, play
from selfplay_cli.play.replay import ActionLog, SeatActions, decode_actions, encode_actions, replay_policies
from selfplay_cli.play.schedule import round_size, rounds
from selfplay_cli.policies import Policy
from selfplay_cli.results import Rules, compare, pairwise, points_between


@pytest.fixture(autouse=True, scope="module")
def _test_games():
    with registered():
        yield


def test_the_runner_asks_only_the_seats_that_act_and_gives_them_their_masks():
    high, low = Spy("high", "arena-seq2", highest=True), Spy("low", "arena-seq2", highest=False)
    games = [Game(0, (0, 1)), Game(1, (1, 0)), Game(2, (0, 1))]
    results = play("arena-seq2", [high, low], games, parallel=2)  # 3 games on 2 slots: a slot is reused
    for spy in (high, low):
        assert spy.calls, "every player was asked"
        for obs, mask in spy.calls:
            assert (obs[:, 4] == 1).all(), "only seats whose turn it is are asked"
            assert mask is not None and mask.shape == (len(obs), 4), "the masks come with the observations"
            assert (mask == (obs[:, :4] < 0.5)).all(), "each row's mask is its own game's"
    # 4 moves a game, 2 per seat: 3 games x 2 moves x 2 seats = 12 asked rows, no more.
    assert sum(len(o) for s in (high, low) for o, _ in s.calls) == 12
    # high takes 3 then 1 (4 points), low 0 then 2 (2 points), whoever starts: high wins every game.
    # seat 0 moves first: high first takes 3, low 0, high 2, low 1 -> 5-1; low first takes 0, high 3, low 1, high 2.
    assert [r.scores for r in results] == [(5.0, 1.0), (1.0, 5.0), (5.0, 1.0)]
    assert [r.outcome for r in results] == [(1.0, 0.0), (0.0, 1.0), (1.0, 0.0)]
    assert [r.players for r in results] == [("high", "low"), ("low", "high"), ("high", "low")]
    assert all(r.length == 4 and not r.truncated for r in results)


def test_an_action_the_mask_forbids_is_one_clear_error_naming_the_policy():
    cheat = Const("cheater", "arena-seq2", 3)  # takes 3 again on its second move
    with pytest.raises(MarlError) as e:
        play("arena-seq2", [cheat, Spy("low", "arena-seq2", highest=False)], [Game(7, (0, 1))])
    text = str(e.value)
    assert "cheater" in text and "action 3" in text and "seat p0" in text and "seed 7" in text and "\n" not in text


def test_free_for_all_results_come_from_the_final_order():
    players = [Const("a", "arena-ffa3", (2, 1)), Const("b", "arena-ffa3", (1, 0)), Const("c", "arena-ffa3", (1, 0))]
    (r,) = play("arena-ffa3", players, [Game(3, (0, 1, 2))])
    # 6 (k + 3 j): a 6 * 5 = 30, b and c 6 * 1 = 6 each, tied.
    assert r.scores == (30.0, 6.0, 6.0)
    assert r.outcome == (1.0, 0.25, 0.25)  # a beats both; b and c each lose to a and draw with the other
    rules = Rules.of(get_env("arena-ffa3"))
    assert pairwise(rules, r.players, r.scores, r.outcome) == [("a", "b", 1.0), ("a", "c", 1.0), ("b", "c", 0.5)]
    # A player on two seats scores the mean over its seats' pairings against the other.
    both = GameResult("arena-ffa3", ("a", "b", "a"), 0, (3.0, 2.0, 1.0), (1.0, 0.5, 0.0), 4, False)
    assert pairwise(rules, both.players, both.scores, both.outcome) == [("a", "b", 0.5)]


def test_two_sides_results_count_the_sides_totals():
    players = [Const("two", "arena-sides4", 2), Const("one", "arena-sides4", 1), Const("zero", "arena-sides4", 0)]
    (r, s) = play("arena-sides4", players, [Game(0, (0, 2, 1, 1)), Game(0, (0, 0, 1, 2))])
    assert r.scores == (6.0, 0.0, 3.0, 3.0) and r.outcome == (0.5, 0.5, 0.5, 0.5), "6 + 0 against 3 + 3: a draw"
    assert s.scores == (6.0, 6.0, 3.0, 0.0) and s.outcome == (1.0, 1.0, 0.0, 0.0), "12 against 3: the first side"
    rules = Rules.of(get_env("arena-sides4"))
    # One result per pair of different players across the sides; none between teammates.
    assert pairwise(rules, r.players, r.scores, r.outcome) == [("two", "one", 0.5), ("zero", "one", 0.5)]
    assert pairwise(rules, s.players, s.scores, s.outcome) == [("two", "one", 1.0), ("two", "zero", 1.0)]


def test_cooperative_games_have_a_team_return_and_box_actions_of_float32():
    high, low = Const("high", "arena-coop2", (1.0, 0.5)), Const("low", "arena-coop2", (-1.0, 0.25))
    results = play("arena-coop2", [high, low], [Game(0, (0, 0)), Game(0, (1, 1)), Game(1, (0, 1))])
    assert [r.scores for r in results] == [(7.5, 7.5), (-3.75, -3.75), (7.5, -3.75)]
    assert all(r.outcome == (0.5, 0.5) for r in results), "one episode has no winner"
    assert all(r.truncated and r.length == 5 for r in results), "cut by the game's time limit"
    rules = Rules.of(get_env("arena-coop2"))
    assert points_between(rules, results[:2], "high", "low") == [1.0]
    assert compare(10.0, 9.6, 0.5) == 0.5 and compare(10.0, 9.4, 0.5) == 1.0 and compare(1, 2) == 0.0


@pytest.mark.parametrize("env", ["arena-coop2", "arena-ffa3", "arena-seq2"])
def test_replays_of_any_action_space_reproduce_every_game(env):
    spec = get_env(env)
    space = spec.seat_spaces()[0].action
    players = [Random(f"r{i}", env, space, seed=i) for i in range(3)]
    n = len(spec.agents)
    games = [Game(seed, tuple((seed + k) % 3 for k in range(n))) for seed in range(7)]
    results = play(env, players, games, parallel=3, record_actions=True)
    for r in results:
        assert r.actions[:3] == (b"MA\x02" if env != "arena-seq2" else b"MA\x01"), "version 2 unless all Discrete"
        moves = decode_actions(r.actions, n, r.length)
        (again,) = play(env, replay_policies(r.players, env, moves), [Game(r.seed, tuple(range(n)))], parallel=1)
        assert (again.scores, again.length, again.players, again.outcome) == (r.scores, r.length, r.players,
                                                                               r.outcome)
    assert len({r.scores for r in results}) > 1, "the games differ"


def test_version_2_actions_round_trip_exactly_and_version_1_stays():
    rng = np.random.default_rng(0)
    steps = 300
    seats = [rng.integers(0, 5, steps), rng.integers(0, 7, (steps, 3)), rng.standard_normal((steps, 2, 2)).astype(
        np.float32), np.full((steps, 1), np.float32(1e-30))]
    back = decode_actions(encode_actions(seats), 4, steps)
    assert [b.dtype for b in back] == [np.int64, np.int64, np.float32, np.float32]
    for a, b in zip(seats, back, strict=True):
        assert a.shape == b.shape and np.array_equal(a, b), "bit for bit, float32 included"
    pong = rng.integers(0, 3, (500, 2))
    assert encode_actions([pong[:, 0], pong[:, 1]]) == encode_actions(pong), "Discrete seats: version 1, as before"
    with pytest.raises(MarlError, match="for 4 seats, the game has 3"):
        decode_actions(encode_actions(seats), 3)
    with pytest.raises(MarlError, match="cover 300 steps"):
        decode_actions(encode_actions(seats), 4, 299)
    with pytest.raises(MarlError, match="corrupt|cut short|unknown"):
        decode_actions(encode_actions(seats)[:-40], 4)


def test_the_action_log_keeps_any_shape_across_its_blocks():
    layout = [SeatActions.of(spaces.Discrete(4)), SeatActions.of(spaces.MultiDiscrete([3, 3])),
              SeatActions.of(spaces.Box(-1, 1, (2,), np.float32))]
    log = ActionLog(layout, n_slots=2)
    rng = np.random.default_rng(1)
    history = []
    log.begin(np.arange(2))
    for t in range(600):  # past two blocks
        step = [rng.integers(0, 4, 2), rng.integers(0, 3, (2, 2)), rng.standard_normal((2, 2)).astype(np.float32)]
        history.append(step)
        log.append(step)
        if t == 99:
            log.begin(np.array([1]))  # slot 1 starts a new game at step 100
    first, second = log.take(0), log.take(1)
    assert len(first[0]) == 600 and len(second[0]) == 500
    for seat in range(3):
        assert np.array_equal(first[seat], np.stack([h[seat][0] for h in history]))
        assert np.array_equal(second[seat], np.stack([h[seat][1] for h in history[100:]]))


def test_schedules_by_kind():
    two = Rules(n_seats=4, sides=((0, 1), (2, 3)))
    assert [g.seats for g in rounds(two, (5, 6), 1, first_seed=9)] == [(5, 5, 6, 6), (6, 6, 5, 5)]
    coop = Rules.of(get_env("arena-coop2"))
    assert [(g.seed, g.seats) for g in rounds(coop, (0, 1), 2)] == [(0, (0, 0)), (0, (1, 1)), (1, (0, 0)),
                                                                    (1, (1, 1))]
    ffa = Rules.of(get_env("arena-ffa3"))
    assert [g.seats for g in rounds(ffa, (0, 1), 1)] == [(0, 1, 0), (1, 0, 0), (0, 0, 1)], "every seat, in turn"
    assert [g.seats for g in rounds(ffa, (0, 1, 2), 1)] == [(0, 1, 2), (1, 2, 0), (2, 0, 1)]
    assert (round_size(two, 2), round_size(coop, 2), round_size(ffa, 2)) == (2, 2, 3)
    assert [g.seats for g in rounds(Rules(), (0, 1), 2)] == [(0, 1), (1, 0), (0, 1), (1, 0)], "pong's pairs"


class _Lowest(Policy):
    """The lowest action its mask allows."""

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        assert mask is not None
        return mask.argmax(axis=1)


def test_a_game_stopped_early_gets_legal_filler_actions_while_the_others_play_on():
    """A game the runner stops (stop_when) goes on inside the core until its slot is reused; the seat whose turn it
    is there must be given an action its mask allows, or a masked game refuses the whole step. Here X takes square
    0 in every game, game 0 is stopped, and O's turn in it would get square 0 again without the filler."""
    spec = get_env("tests.games.tictactoe:env")
    players = [_Lowest("a", spec.name), _Lowest("b", spec.name)]
    games = [Game(seed, (0, 1)) for seed in range(4)]
    results = play(spec, players, games, parallel=4,
                   stop_when=lambda core: (np.arange(core.n) == 0) & (core.steps >= 1))
    assert [r.length for r in results] == [1, 7, 7, 7]  # X takes 0, 2, 4, 6 along the top row and the diagonal
    assert results[0].truncated and not any(r.truncated for r in results[1:])
    assert [r.outcome for r in results[1:]] == [(1.0, 0.0)] * 3
