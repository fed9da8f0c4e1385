"""A lander team trained with N landers flown with M (seed 001's question), through the commands: the game's seats
follow its options (``landers=M``), scripted players follow them too (the heuristic's continuous form), and a
network that cannot play the seats those options make is one clear line."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest
from cli_helpers import run, run_json

from selfplay_cli.envs import get_env
from selfplay_cli.evaluation.lineup import Lineup, refit
from selfplay_cli.league.store import League
from selfplay_cli.policies import ScriptedPolicy


def test_the_landers_option_makes_the_seats_and_pong_keeps_its_own():
    lander, pong = get_env("lander"), get_env("pong")
    assert lander.agents == ("lander_0", "lander_1")
    assert lander.for_options(landers=4).agents == ("lander_0", "lander_1", "lander_2", "lander_3")
    assert lander.for_options(landers=4).n_seats == 4 and lander.for_options(landers=2) is lander
    assert pong.for_options(points_to_win=3) is pong
    seats = lander.for_options(landers=3).seat_spaces(lander.config(landers=3))
    assert len(seats) == 3 and all(s.action.n == 4 for s in seats)


def test_scripted_players_follow_the_options_they_are_played_with():
    bot = ScriptedPolicy("lander", "heuristic", seed=0)
    obs = np.zeros((5, 8), np.float32)
    assert bot.act(obs).dtype == np.int64 and bot.act(obs).shape == (5,)
    bot.configure({"continuous": True})
    a = bot.act(obs)
    assert a.dtype == np.float32 and a.shape == (5, 2) and np.all(np.abs(a) <= 1)
    rnd = ScriptedPolicy("lander", "random", seed=0)
    rnd.configure({"continuous": True})
    assert rnd.act(obs).shape == (5, 2)


def test_a_team_grows_with_copies_of_its_members_and_shrinks_to_its_first_seats():
    a, b = object(), object()
    team = Lineup("lander", (a, b), focus=0)
    grown = refit(team, 5, seed=3)
    assert grown.players[:2] == (a, b) and set(map(id, grown.players[2:])) <= {id(a), id(b)}
    assert refit(team, 5, seed=3) == grown  # the same draw for the same seed
    assert refit(team, 1).players == (a,) and refit(team, 2) is team


@pytest.mark.slow
def test_a_fups_team_trained_with_two_landers_flies_one_to_four(home, tmp_path, capsys):
    run_json(capsys, "train", "lander", "--agents", "2", "--sharing", "fups", "--steps", "4000",
             "--snapshot-steps", "4000", "--games", "8", "--eval-games", "0", "--run", "l2")
    returns = {}
    for m in (1, 2, 4):
        r = run_json(capsys, "match", "l2/s4k", "heuristic", "--games", "4", "--env-option", f"landers={m}")
        assert r["games"] == 4 and r["kind"] == "cooperative"
        league = League.open(home=home)
        try:
            g = league.ledger.game(r["game_ids"][0])
            assert len(g.players) == m  # the stored game has M seats
            assert league.ledger.match_info(r["match_id"])[1]["env_options"]["landers"] == m
        finally:
            league.close()
        returns[m] = r["points_against"] / 2  # the heuristic's mean team return over its 2 episodes
    assert returns[4] > returns[1] > 0  # more landers, more landing bonuses for the heuristic team

    out = tmp_path / "l3.mp4"
    code, _, err = run(capsys, "record", "--ckpt", "l2/s4k", "--env-option", "landers=3", "--seconds", "1",
                       "--out", str(out))
    assert code == 0, err
    assert np.stack(list(iio.imiter(out))).shape[0] >= 50

    code, out_, err = run(capsys, "match", "l2/s4k", "heuristic", "--games", "2", "--env-option", "continuous=true")
    assert code == 2 and err.count("\n") == 1 and "l2/s4k reads observations" in err and "Box" in err, err


# ---------------------------------------------------------------------------------------------------------------
# SA: one agent over the team's joint observation and action (seed 001)


def test_joint_actions_round_trip_by_seed_001s_encoding():
    from selfplay_cli.policies.joint import decode, encode

    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 5):
        a = rng.integers(0, 4, size=(n, 50))
        b = encode(a, 4)
        assert b.max() < 4**n and np.array_equal(decode(b, n, 4), a)
    assert encode(np.array([[1], [2]]), 4).tolist() == [1 + 2 * 4]  # b = sum a_n 4^n
    assert decode(np.arange(16), 2, 4)[:, 5].tolist() == [1, 1]


def test_sa_refuses_what_it_cannot_be_in_one_line(home, capsys):
    for args, says in ((["lander", "--env-option", "landers=7"], "16,384 joint actions"),
                       (["lander", "--env-option", "continuous=true"], "joint action of Discrete actions"),
                       (["pong"], "cooperative team acting together")):
        code, out, err = run(capsys, "train", *args, "--sharing", "sa", "--run", "bad")
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert says in err, err
    assert not (home / "runs" / "bad").exists()


@pytest.mark.slow
def test_an_sa_agent_trains_plays_and_records_its_team(home, tmp_path, capsys):
    report = run_json(capsys, "train", "lander", "--sharing", "sa", "--steps", "4000", "--snapshot-steps", "4000",
                      "--games", "8", "--eval-games", "2", "--run", "sa")
    assert [f["snapshot"] for f in report["final"]] == ["sa/s4k"]
    shown = run_json(capsys, "checkpoint", "show", "sa/s4k")
    assert shown["file"]["act_space"] == {"kind": "discrete", "n": 16}  # 4 actions x 4 actions
    assert shown["file"]["obs_space"]["shape"] == [16] and shown["file"]["extra"]["joint"] == {"seats": 2, "base": 4}
    r = run_json(capsys, "match", "sa/s4k", "heuristic", "--games", "4")
    # an untrained agent against the heuristic: measured on seeds 0-4, its team returns -440 to -1,650 a game, the
    # heuristic's +277 on the same games, so it loses both comparisons on every seed
    assert r["games"] == 4 and r["losses"] >= 1
    rows = {r["policy"]: r for r in run_json(capsys, "league", "ladder")}
    assert rows["heuristic"]["anchor"] and rows["heuristic"]["elo"] == 1000.0  # the lander's anchor: its heuristic
    assert rows["sa/s4k"]["mean_return"] < 0.0 < rows["heuristic"]["mean_return"]  # (the returns above)
    code, _, err = run(capsys, "match", "sa/s4k", "heuristic", "--games", "2", "--env-option", "landers=3")
    assert code == 2 and "one agent for a team of 2 seats" in err and err.count("\n") == 1, err
    out = tmp_path / "sa.mp4"
    code, _, err = run(capsys, "record", "--ckpt", "sa/s4k", "--seconds", "1", "--out", str(out))
    assert code == 0, err
    assert np.stack(list(iio.imiter(out))).shape[0] >= 50


@pytest.mark.slow
def test_a_team_of_per_lander_networks_flies_together_and_grows_by_copies(home, capsys):
    run_json(capsys, "train", "lander", "--agents", "2", "--sharing", "nops", "--steps", "4000", "--snapshot-steps",
             "4000", "--games", "8", "--eval-games", "0", "--run", "np")
    r = run_json(capsys, "match", "np/s4k", "heuristic", "--games", "6", "--env-option", "landers=3")
    assert r["a"] == "np/s4k" and r["games"] == 6 and r["wins"] + r["draws"] + r["losses"] == 3  # 3 comparisons
    league = League.open(home=home)
    try:
        names = [[league.roster.get_player(p).full_name for p in league.ledger.game(i).players] for i in r["game_ids"]]
    finally:
        league.close()
    team = [n for n in names if "heuristic" not in n]
    assert len(team) == 3 and all(len(n) == 3 for n in team)
    for seats in team:  # each member on its own seat, the third lander a copy of one of them
        assert seats[:2] == ["np/s4k-lander_0", "np/s4k-lander_1"] and seats[2] in seats[:2]
    rows = {x["policy"]: x for x in run_json(capsys, "league", "ladder", "--env-option", "landers=3")}  # its variant
    assert rows["np/s4k-lander_0"]["games"] == rows["np/s4k-lander_1"]["games"] == 3  # the team's comparisons
    code, _, err = run(capsys, "match", "heuristic", "np/s4k", "--games", "2")
    assert code == 2 and "name it first" in err and err.count("\n") == 1, err


def test_one_learner_with_fups_is_a_shared_team_network_in_a_cooperative_game_only():
    from selfplay_cli.errors import MarlError
    from selfplay_cli.train.config import TrainConfig

    assert TrainConfig(env="lander", agents=1, sharing="fups", run="x").seat_plan().home == (0, 0)
    with pytest.raises(MarlError, match="needs --agents 2 or more"):
        TrainConfig(env="pong", agents=1, sharing="fups", run="x")


@pytest.mark.parametrize("env, algo, greedy", [
    ("pong", "ppo", False),  # against others a PPO policy samples (its argmax is another player)
    ("tennis", "ppo", False),
    ("lander", "ppo", True),  # a control task: its most likely action
    ("pong", "dqn", True),
    ("tennis", "sac", True),  # SAC is evaluated by its mean action
    ("no_such_game", "ppo", False),  # a game that cannot be loaded: its games cannot be played either
])
def test_how_a_snapshot_plays_in_rated_games(env, algo, greedy):
    from datetime import datetime

    from selfplay_cli.league.roster import PlayerRow
    from selfplay_cli.players.load import plays_greedy

    row = PlayerRow(1, env, "snapshot", "s1M", "r", 1, 0, algo, None, None, None, (), 1000.0, 0, False,
                    datetime.now())
    assert plays_greedy(row) is greedy


@pytest.mark.slow
def test_the_ladder_of_a_cooperative_game_shows_the_mean_return(home, capsys, monkeypatch):
    """A cooperative game's ladder has a mean return column (the team's mean return per game), as its JSON has."""
    code, out, err = run(capsys, "match", "heuristic", "random", "--env", "lander", "--games", "4")
    assert code == 0, err
    monkeypatch.setenv("COLUMNS", "200")
    code, out, err = run(capsys, "league", "ladder", "--env", "lander")
    assert code == 0, err
    assert "mean return" in out and "team's mean return per game" in out.replace("\n", " ")
    rows = {r["policy"]: r for r in run_json(capsys, "league", "ladder", "--env", "lander")}
    shown = [line for line in out.splitlines() if "heuristic (anchor)" in line][0]
    assert f"{rows['heuristic']['mean_return']:.1f}" in shown


@pytest.mark.slow
def test_a_nops_runs_gauntlet_rates_each_moment_as_the_team_it_flies_as(home, capsys):
    """The per-lander snapshots of a NoPS moment fly their rating games together, each on its own lander, as the run
    trained them (alone, each would fly both landers, one of them a seat it never learned); their comparisons count
    for both members, and two members of one moment never meet each other."""
    run_json(capsys, "train", "lander", "--agents", "2", "--sharing", "nops", "--steps", "4000", "--snapshot-steps",
             "2000", "--games", "8", "--eval-games", "2", "--eval-inline", "--run", "np")
    league = League.open(home=home)
    try:
        games = [league.ledger.game(i) for i in range(1, league.ledger.count_games() + 1)]
        names = {p.id: p.full_name for p in league.roster.players(env="lander")}
    finally:
        league.close()
    rated = [[names[p] for p in g.players] for g in games if g.match_kind == "eval"]
    flown = [seats for seats in rated if any(s.startswith("np/") for s in seats)]
    assert flown, "the gauntlets played"
    for seats in flown:  # a moment's team, lander_0 on seat 0 and lander_1 on seat 1; or a scripted player alone
        moment = seats[0].rsplit("-", 1)[0]
        assert seats == [f"{moment}-lander_0", f"{moment}-lander_1"], seats
    teams = {seats[0].rsplit("-", 1)[0] for seats in flown}
    assert teams == {"np/s0", "np/s2k", "np/s4k"}
    rows = {x["policy"]: x for x in run_json(capsys, "league", "ladder")}
    for moment in teams:
        assert rows[f"{moment}-lander_0"]["games"] == rows[f"{moment}-lander_1"]["games"] > 0
        assert rows[f"{moment}-lander_0"]["elo"] == pytest.approx(rows[f"{moment}-lander_1"]["elo"], abs=0.5)
