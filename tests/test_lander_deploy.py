"""A lander team trained with N landers flown with M (seed 001's question), through the commands: the game's seats
follow its options (``landers=M``), scripted players follow them too (the heuristic's continuous form), and a
network that cannot play the seats those options make is one clear line."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest

from selfplay_cli.cli import main
from selfplay_cli.envs import get_env
from selfplay_cli.league.store import League
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.rated.lineup import Lineup, refit


def run(capsys, *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def run_json(capsys, *args: str):
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    return json.loads(out)


@pytest.fixture
def home(tmp_path, monkeypatch):
    h = tmp_path / "league"
    monkeypatch.setenv("MARL_HOME", str(h))
    monkeypatch.delenv("MARL_DB", raising=False)
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    return h


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


def test_a_fups_team_trained_with_two_landers_flies_one_to_four(home, tmp_path, capsys):
    run_json(capsys, "train", "lander", "--agents", "2", "--sharing", "fups", "--steps", "4000",
             "--snapshot-steps", "4000", "--games", "8", "--eval-games", "0", "--run", "l2")
    returns = {}
    for m in (1, 2, 4):
        r = run_json(capsys, "match", "l2/s4k", "heuristic", "--games", "4", "--env-option", f"landers={m}")
        assert r["games"] == 4 and r["kind"] == "cooperative"
        league = League.open(home=home)
        try:
            g = league.game(r["game_ids"][0])
            assert len(g.players) == m  # the stored game has M seats
            assert league.match_info(r["match_id"])[1]["env_options"]["landers"] == m
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
