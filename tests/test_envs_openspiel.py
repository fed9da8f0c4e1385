"""OpenSpiel games through marl's own adapter (``openspiel:GAME(params)``): returns exactly OpenSpiel's, chance dealt
from the seed, simultaneous moves, PPO learning Kuhn poker through the CLI, recordings, and one-line errors.

:func:`random_games` and :func:`replay` are also what ``benchmarks/openspiel_returns.py`` times (the adapter against
pyspiel stepped directly, on the same games)."""

from __future__ import annotations

import json
import sys

import imageio.v2 as iio
import numpy as np
import pyspiel
import pytest

from selfplay_cli.cli import main
from selfplay_cli.envs import get_env
from selfplay_cli.envs.bots import random_rule
from selfplay_cli.envs.contract import IllegalActionError
from selfplay_cli.envs.rng import game_key_int, uniform_int
from selfplay_cli.league.roster import check_env_name


def random_games(name: str, games: int, parallel: int = 64, seed: int = 0, record: bool = True) -> list[tuple]:
    """``games`` games of ``name`` played through the adapter's core by random legal actions, ``parallel`` at once
    (finished slots restart with the next seeds): per game ``(seed, [(seat, action), ...], score, summed rewards,
    truncated)`` (only the count of games when not ``record``)."""
    spec = get_env(name)
    core = spec.core(parallel)
    rule = random_rule(spec.seat_spaces()[0].action)
    rng = np.random.default_rng(seed)
    seeds = np.arange(parallel) + seed * 1_000_000
    core.reset(np.arange(parallel), seeds)
    next_seed = int(seeds[-1]) + 1
    moves: list[list[tuple[int, int]]] = [[] for _ in range(parallel)]
    sums = np.zeros((spec.n_seats, parallel))
    out: list[tuple] = []
    done_count = 0
    while done_count < games:
        obs, masks = core.observe(), core.action_masks()
        actions = [rule(obs[s], rng, masks[s]) for s in range(spec.n_seats)]
        if record:
            acting = core.to_act()
            for s, g in zip(*np.nonzero(acting.T)[::-1], strict=True):
                moves[g].append((int(s), int(actions[s][g])))
        rewards = core.step(actions)
        sums += rewards
        done = np.flatnonzero(core.terminated | core.truncated)
        if done.size:
            done_count += done.size
            if record:
                for g in done.tolist():
                    out.append((int(seeds[g]), moves[g], core.score[:, g].copy(), sums[:, g].copy(),
                                bool(core.truncated[g])))
                    moves[g] = []
            sums[:, done] = 0.0
            seeds[done] = np.arange(next_seed, next_seed + done.size)
            next_seed += done.size
            core.reset(done, seeds[done])
    return out if record else [done_count]


def play_chance(st, key: int, draws: list[int]) -> None:
    """Play ``st``'s chance nodes as the adapter documents: the k-th draw of a game (``draws[0]``, counted on) is
    ``uniform_int(key, k)``, taken against the cumulative ``chance_outcomes()``."""
    while st.is_chance_node():
        u = uniform_int(key, draws[0])
        draws[0] += 1
        outcomes = st.chance_outcomes()
        action = outcomes[-1][0]
        for a, p in outcomes:
            u -= p
            if u < 0.0:
                action = a
                break
        st.apply_action(action)


def replay(game, seed: int, moves: list[tuple[int, int]], observe: bool = False, arrays: bool = False) -> list[float]:
    """Game ``seed`` played on a plain pyspiel state: chance by the adapter's documented draws (the k-th draw of a
    game is ``uniform_int(game_key_int(seed), k)`` against the cumulative ``chance_outcomes()``), the players'
    ``moves`` in order (each by the player OpenSpiel says is to move); its ``returns()``. ``observe`` also reads
    what a player needs at each move (its tensor, its legal actions), as a loop of one's own would; ``arrays`` as
    numpy arrays (a network's input and mask) rather than OpenSpiel's lists."""
    st = game.new_initial_state()
    key, draws, i = game_key_int(seed), [0], 0
    info = game.get_type().provides_information_state_tensor
    while not st.is_terminal():
        if st.is_chance_node():
            play_chance(st, key, draws)
            continue
        seat, a = moves[i]
        i += 1
        assert st.current_player() == seat, f"game {seat}: the adapter let seat {seat} move out of turn"
        if arrays:
            np.asarray(st.information_state_tensor(seat) if info else st.observation_tensor(seat), np.float32)
            np.asarray(st.legal_actions_mask(seat), bool)
        elif observe:
            st.information_state_tensor(seat) if info else st.observation_tensor(seat)
            st.legal_actions(seat)
        st.apply_action(a)
    assert i == len(moves), "the game ended before all the adapter's moves were made"
    return st.returns()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["openspiel:kuhn_poker", "openspiel:leduc_poker", "openspiel:tic_tac_toe"])
def test_returns_through_the_adapter_are_openspiels_own(name):
    game = pyspiel.load_game(name.partition(":")[2])
    played = random_games(name, 10_000)
    assert len(played) >= 10_000
    for seed, moves, score, summed, truncated in played:
        returns = replay(game, seed, moves)
        assert score.tolist() == returns, (seed, moves)  # exactly, not approximately
        assert np.allclose(summed, returns) and not truncated
    assert len({tuple(r[2]) for r in played}) > 2  # several outcomes, not one game over and over


def test_a_game_that_rewards_along_the_way_gives_openspiels_rewards_step_by_step():
    """2048 rewards every merge, and chance places a tile after every move: each step's reward is the one OpenSpiel
    gives for it (``rewards()`` after the move and its chance node, as its rl_environment reads it), counted once."""
    spec = get_env("openspiel:2048")
    core = spec.core(1)
    core.reset([0], [3])
    plain = pyspiel.load_game("2048").new_initial_state()
    key, draws = game_key_int(3), [0]
    play_chance(plain, key, draws)
    rng = np.random.default_rng(0)
    expected, got = [], []
    while not core.terminated[0]:
        a = int(rng.choice(np.flatnonzero(core.action_masks()[0][0])))
        got.append(float(core.step([np.array([a])])[0, 0]))
        plain.apply_action(a)
        play_chance(plain, key, draws)
        expected.append(plain.rewards()[0])
    returns = plain.returns()[0]
    assert len(got) > 20 and core.score[0, 0] == returns and sum(got) == pytest.approx(returns)
    assert got[:-1] == expected[:-1] and sum(got[:-1]) > 0  # merges rewarded step by step, not at the end


def test_the_same_seed_deals_the_same_cards_alone_or_in_a_batch():
    spec = get_env("openspiel:leduc_poker")
    a, b = spec.core(4), spec.core(1)
    a.reset([0, 1, 2, 3], [5, 5, 6, 7])
    b.reset([0], [5])
    obs_a, obs_b = a.observe(), b.observe()
    assert np.array_equal(obs_a[:, 0], obs_a[:, 1]) and np.array_equal(obs_a[:, 0], obs_b[:, 0])
    assert a.states[0].history() == b.states[0].history()
    deals = set()
    for seed in range(40):
        b.reset([0], [seed])
        deals.add(tuple(b.states[0].history()))
    assert len(deals) > 10  # two of Leduc's six cards, 30 ordered deals: other seeds deal other cards


def test_a_simultaneous_move_game_plays_every_player_at_once():
    name = "openspiel:goofspiel(imp_info=True,num_cards=4,points_order=descending)"
    spec = get_env(name)
    assert spec.turns == "simultaneous" and spec.kind == "two-sides" and spec.max_steps() == 4
    core = spec.core(8)
    game = pyspiel.load_game(name.partition(":")[2])
    plain = [game.new_initial_state() for _ in range(8)]
    rule, rng = random_rule(spec.seat_spaces()[0].action), np.random.default_rng(0)
    steps = 0
    while core.to_act().any():  # 3 moves: goofspiel plays the last card itself
        assert core.to_act().all()
        steps += 1
        obs, masks = core.observe(), core.action_masks()
        actions = [rule(obs[s], rng, masks[s]) for s in range(2)]
        core.step(actions)
        for g, st in enumerate(plain):
            st.apply_actions([int(actions[0][g]), int(actions[1][g])])
    assert steps == 3 and core.terminated.all() and (core.steps == 3).all()
    assert core.score.T.tolist() == [st.returns() for st in plain]
    core.reset([0], [1])
    core.step([np.zeros(8, dtype=np.int64), np.zeros(8, dtype=np.int64)])  # both bid their first card
    with pytest.raises(IllegalActionError, match="seat 0 in game slot 0"):  # a card already played is refused
        core.step([np.zeros(8, dtype=np.int64), np.ones(8, dtype=np.int64)])


def test_kinds_turns_and_limits_come_from_the_game():
    three = get_env("openspiel:leduc_poker(players=3)")
    assert check_env_name(three.name) == "openspiel:leduc_poker(players=3)"  # the league files it as it is named
    assert three.agents == ("player_0", "player_1", "player_2") and three.kind == "free-for-all"
    assert three.seat_roles() == ("player",) * 3
    ttt = get_env("openspiel:tic_tac_toe")
    assert (ttt.turns, ttt.kind, ttt.max_steps()) == ("sequential", "two-sides", 9)
    assert ttt.seat_spaces()[0].observation.shape == (3, 3, 3)  # no information-state tensor: its observation's
    assert get_env("openspiel:kuhn_poker").seat_spaces()[0].observation.shape == (11,)  # information state


@pytest.mark.slow
def test_ppo_learns_kuhn_poker_through_the_cli_and_beats_random(tmp_path, capsys):
    """Trained against the random player, the learner folds bad hands and bets good ones: ~69% of games won where
    the best response to random wins 62.5-75% by seat (69% on seeds 0, 1, 2 at this budget)."""
    home = str(tmp_path / "league")
    code = main(["train", "openspiel:kuhn_poker", "--agents", "1", "--bots", "random=1", "--steps", "40000",
                 "--games", "16", "--seed", "0", "--eval", "inline", "--eval-games", "8", "--quiet", "--json",
                 "--home", home])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert json.loads(out.out)["run"] == "kuhn_poker-1"
    assert main(["match", "kuhn_poker-1/s40k", "random", "--games", "1000", "--seed", "9", "--json",
                 "--home", home]) == 0
    match = json.loads(capsys.readouterr().out)
    assert match["env"] == "openspiel:kuhn_poker" and match["games"] == 1000
    assert match["score"] > 0.6 and match["elo_low"] > 40 and match["points_for"] > 250


def test_marl_record_writes_an_mp4_of_kuhn_that_decodes(tmp_path, capsys):
    out = tmp_path / "kuhn.mp4"
    code = main(["record", "--ckpt", "random", "--vs", "random", "--env", "openspiel:kuhn_poker", "--out", str(out),
                 "--hold", "0", "--json", "--home", str(tmp_path / "league")])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    (rec,) = json.loads(printed.out)
    reader = iio.get_reader(out)
    try:
        frames = np.stack(list(reader.iter_data()))
    finally:
        reader.close()
    assert frames.shape[0] == rec["length"] + 1 and rec["length"] >= 2
    assert frames.shape[1:] == (456, 640, 3)  # the text frame and the caption band under it
    assert int(np.abs(frames[0].astype(np.int16) - frames[-1]).max()) > 40  # the text changed as the hand went on


@pytest.mark.parametrize(("name", "says"), [
    ("openspiel:kuhn_pokr", "unknown OpenSpiel game 'kuhn_pokr' in 'openspiel:kuhn_pokr'; did you mean "
                            "openspiel:kuhn_poker"),
    ("openspiel:kuhn_poker(bets=3)", "OpenSpiel game 'openspiel:kuhn_poker(bets=3)' cannot be made: Unknown "
                                     "parameter 'bets'. Available parameters are: players"),
    ("openspiel:leduc_poker(players=3", "cannot be made: Missing closing bracket ')'."),
    ("openspiel:mfg_crowd_modelling", "cannot be played by marl: it is a mean-field game"),
])
def test_a_bad_game_string_is_one_line_naming_the_game_and_why(name, says, capsys):
    assert main(["envs", name]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err


def test_without_openspiel_installed_the_extra_is_named_in_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "pyspiel", None)  # `import pyspiel` now fails as if it were not installed
    assert main(["train", "openspiel:liars_dice(dice_sides=4)", "--steps", "1000"]) == 2
    err = capsys.readouterr().err
    assert err == ("marl: error: game 'openspiel:liars_dice(dice_sides=4)' needs OpenSpiel, which is not installed: "
                   'pip install "selfplay-cli[openspiel]" (the extra [openspiel])\n')
