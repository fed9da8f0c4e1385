"""The game contract of selfplay_cli/envs/contract.py, seat_spaces.py and bots.py: what an EnvSpec may declare, the
seat spaces it gives, the space rules, and the random player defined for every action space."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gymnasium import spaces

from selfplay_cli.envs import (
    EnvError,
    EnvSpec,
    IllegalActionError,
    SeatSpace,
    check_spaces,
    describe_space,
    get_env,
    random_rule,
)
from selfplay_cli.envs.seat_spaces import SpaceError, seat_space_of

BOX = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)


def _spec(**changes) -> EnvSpec:
    return dataclasses.replace(get_env("pong"), name="test-game", **changes)


def test_pong_registration_is_valid_with_the_defaults():
    spec = get_env("pong")
    assert (spec.turns, spec.kind, spec.sides, spec.tie_tolerance) == ("simultaneous", "two-sides", None, 0.0)
    assert check_spaces(spec) == spec.seat_spaces(spec.config())


@pytest.mark.parametrize("changes, why", [
    ({"turns": "whenever"}, "turns must be one of simultaneous, sequential"),
    ({"kind": "zero-sum"}, "kind must be one of two-sides, cooperative, free-for-all"),
    ({"tie_tolerance": -1.0}, "tie_tolerance must be a finite number >= 0"),
    ({"tie_tolerance": float("nan")}, "tie_tolerance"),
    ({"sides": ((0,), (0,))}, "sides must split the seats"),
    ({"sides": ((0, 1),)}, "sides must split the seats"),
    ({"kind": "cooperative", "sides": ((0,), (1,))}, "sides are for two-sides games"),
    ({"agents": ("a", "b", "c")}, "must declare its sides"),
    ({"agents": ("a", "a")}, "names a seat twice"),
    ({"agents": ()}, "has no seats"),
])
def test_a_declaration_that_cannot_hold_is_refused(changes, why):
    with pytest.raises(ValueError, match=why):
        _spec(**changes)


def test_sides_by_kind():
    assert _spec(agents=("a", "b", "c", "d"), sides=((0, 3), (1, 2))).side_seats() == ((0, 3), (1, 2))
    assert _spec(agents=("a", "b", "c"), kind="cooperative").side_seats() == ((0, 1, 2),)
    assert _spec(agents=("a", "b", "c"), kind="free-for-all").side_seats() == ((0,), (1,), (2,))


def test_seat_spaces_default_and_per_seat_declarations_are_checked():
    seats = (SeatSpace(BOX, spaces.Discrete(2)), SeatSpace(BOX, spaces.Box(-1, 1, (2,), dtype=np.float32)))
    spec = _spec(make_seat_spaces=lambda cfg: seats)
    assert spec.seat_spaces() == seats
    bad = _spec(make_seat_spaces=lambda cfg: (seats[0], SeatSpace(BOX, spaces.Box(0, np.inf, (2,)))))
    with pytest.raises(EnvError, match="game 'test-game', seat 'right': .*finite bounds"):
        bad.seat_spaces()
    masked_box = _spec(make_seat_spaces=lambda cfg: (seats[0], SeatSpace(BOX, seats[1].action, True)))
    with pytest.raises(EnvError, match="seat 'right': action masks need a Discrete action space"):
        check_spaces(masked_box)
    short = _spec(make_seat_spaces=lambda cfg: seats[:1])
    with pytest.raises(EnvError, match="declares 2 seats but 1 seat spaces"):
        short.seat_spaces()


def test_seat_space_of_reads_dict_observations_and_normalises_what_policies_see():
    d = spaces.Dict({"observation": spaces.Box(0, 255, (3, 3), dtype=np.uint8),
                     "action_mask": spaces.MultiBinary(5)})
    seat = seat_space_of(d, spaces.Discrete(5))
    assert seat.mask and seat.observation.dtype == np.float32 and seat.observation.shape == (3, 3)
    assert seat.observation.high.max() == 255
    assert seat_space_of(BOX, spaces.Discrete(4, start=1)).action == spaces.Discrete(4)
    assert seat_space_of(BOX, spaces.MultiDiscrete([2, 3])).action == spaces.MultiDiscrete([2, 3])
    assert seat_space_of(BOX, BOX).observation is BOX


@pytest.mark.parametrize("obs, act, why", [
    (spaces.Text(5), spaces.Discrete(2), "Text.*no fixed size"),
    (spaces.Tuple([BOX, spaces.Sequence(spaces.Discrete(2))]), spaces.Discrete(2), "Sequence.*no fixed size"),
    (spaces.Dict({"observation": BOX, "action_mask": spaces.MultiBinary(2)}), spaces.Box(-1, 1, (2,)),
     "action_mask needs a Discrete action space"),
    (spaces.Box(0, 1, (0,)), spaces.Discrete(2), "is empty"),
    (BOX, spaces.Box(-1, 1, (2,), dtype=np.int64), "must be floating point"),
    (BOX, spaces.MultiDiscrete([[2, 2], [2, 2]]), "one flat vector"),
    (BOX, spaces.Text(5), "Text.*Discrete, MultiDiscrete and Box actions"),
    (spaces.Dict({"observation": BOX, "action_mask": spaces.Box(0, 1, (3, 1))}), spaces.Discrete(3),
     "MultiBinary\\(3\\) or a Box of shape \\(3,\\)"),
])
def test_unsupported_spaces_say_which_and_why(obs, act, why):
    with pytest.raises(SpaceError, match=why):
        seat_space_of(obs, act)


def test_describe_space():
    assert describe_space(spaces.Discrete(3)) == "Discrete(3)"
    assert describe_space(spaces.Discrete(3, start=2)) == "Discrete(3, start=2)"
    assert describe_space(BOX) == "Box(-1, 1, (4,), float32)"
    assert describe_space(spaces.MultiDiscrete([2, 3])) == "MultiDiscrete([2, 3])"


def test_illegal_action_error_names_seat_game_and_action():
    e = IllegalActionError(1, 7, 4)
    assert isinstance(e, ValueError) and (e.seat, e.game, e.action) == (1, 7, 4)
    assert str(e) == "illegal action 4 for seat 1 in game slot 7: forbidden by its action mask"


# ---------------------------------------------------------------------------------------------------------------
# The random player for every action space
def test_random_discrete_without_mask_draws_as_before():
    rule = random_rule(spaces.Discrete(3))
    a = rule(np.zeros((1000, 2)), np.random.default_rng(5))
    assert np.array_equal(a, np.random.default_rng(5).integers(0, 3, size=1000)), "pong's random player unchanged"


def test_random_discrete_with_a_mask_is_uniform_over_the_allowed_actions():
    rule = random_rule(spaces.Discrete(5))
    mask = np.zeros((20_000, 5), dtype=bool)
    mask[:10_000, [1, 3]] = True
    mask[10_000:, 4] = True
    a = rule(np.zeros((20_000, 1)), np.random.default_rng(0), mask)
    assert mask[np.arange(20_000), a].all(), "never a forbidden action"
    first = np.bincount(a[:10_000], minlength=5)
    assert first[[0, 2, 4]].sum() == 0 and abs(first[1] - 5000) < 250
    assert (a[10_000:] == 4).all()
    with pytest.raises(ValueError, match="allows no action"):
        rule(np.zeros((1, 1)), np.random.default_rng(0), np.zeros((1, 5), dtype=bool))


def test_random_multidiscrete_and_box():
    md = random_rule(spaces.MultiDiscrete([2, 7]))(np.zeros((5000, 1)), np.random.default_rng(1))
    assert md.shape == (5000, 2) and set(md[:, 0]) == {0, 1} and set(md[:, 1]) == set(range(7))
    box = spaces.Box(np.array([-1.0, 0.0], dtype=np.float32), np.array([1.0, 10.0], dtype=np.float32))
    b = random_rule(box)(np.zeros((5000, 1)), np.random.default_rng(2))
    assert b.shape == (5000, 2) and b.dtype == np.float32 and all(box.contains(x) for x in b)
    assert b[:, 1].max() > 9 and b[:, 1].min() < 1
    with pytest.raises(TypeError, match="no rule for action space"):
        random_rule(spaces.MultiBinary(2))


def test_every_fixed_size_observation_space_is_read_flat_in_a_stated_order():
    from selfplay_cli.envs.obs_spaces import FlatObs

    space = spaces.Dict({"b": spaces.Tuple([spaces.Discrete(3, start=1), spaces.MultiBinary(2)]),
                         "a": spaces.Box(-2, 2, (2,), dtype=np.float64), "c": spaces.MultiDiscrete([2, 3])})
    seat = seat_space_of(space, spaces.Discrete(2))
    assert seat.observation.shape == (12,) and seat.observation.dtype == np.float32 and not seat.mask
    assert seat.observation.low.tolist() == [-2, -2] + [0] * 10 and seat.observation.high.tolist() == [2, 2] + [1] * 10
    row = FlatObs(space).read({"a": np.array([0.5, -1.0]), "b": (2, np.array([1, 0])), "c": np.array([1, 2])})
    # keys in the Dict's order (a, b, c); Discrete(3, start=1) of 2 is one-hot at 1; MultiDiscrete a one-hot per entry
    assert row.tolist() == [0.5, -1.0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 1]
    assert seat_space_of(spaces.Discrete(5), spaces.Discrete(2)).observation.shape == (5,)
    masked = seat_space_of(spaces.Dict({"board": spaces.MultiBinary((3, 3)), "turn": spaces.Discrete(2),
                                        "action_mask": spaces.MultiBinary(9)}), spaces.Discrete(9))
    assert masked.mask and masked.observation.shape == (11,)  # the mask is not read as observation
