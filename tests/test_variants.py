"""Ratings per variant: games under options that change a game are rated apart from its default ladder; neutral
options (what a policy sees, shaping rewards, how a game is drawn) split nothing; leagues written before variants
read the same way."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest
from cli_helpers import run, run_json

from selfplay_cli.envs.adapters.pettingzoo import adapt
from selfplay_cli.league.store import League
from selfplay_cli.league.variants import describe_variant, variant_flags, variant_key, variant_options
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot
from selfplay_cli.ratings.names import resolve
from selfplay_cli.results import GameResult

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

from tests.games.rendezvous import Rendezvous  # noqa: E402

TO_3 = '{"points_to_win":3}'
OLD_LEAGUE = Path(__file__).parent / "data" / "league_before_variants.db"
"""A league written by marl before variants (commit 01475a4): pong cpu-random matches of 4 games with the default
options, 6 with points_to_win=3 and 2 with frame_stack=4; a lander match of 2 games (one comparison) with landers=4."""


def ladder_json(capsys, *args: str) -> list[dict]:
    return run_json(capsys, "league", "ladder", "--bootstrap", "0", *args)


def games_of(rows: list[dict]) -> dict[str, int]:
    return {r["policy"]: r["games"] for r in rows}


# ---------------------------------------------------------------------------------------------------------------
# The key: one canonical name per variant


def test_the_variant_key_is_canonical_and_leaves_out_defaults_and_neutral_options():
    assert variant_key("pong", None) == variant_key("pong", {}) == ""
    assert variant_key("pong", {"points_to_win": 21}) == ""  # the default, asked for explicitly
    assert variant_key("pong", {"points_to_win": 3}) == TO_3
    assert variant_key("pong", {"points_to_win": 3.0}) == TO_3  # one form per value
    # neutral: what a policy sees, the touch reward (the score stays the points)
    assert variant_key("pong", {"frame_stack": 4, "obs_mode": "rgb", "r_for_hit": 0.1}) == ""
    assert variant_key("pong", {"frame_stack": 4, "points_to_win": 3}) == TO_3
    assert variant_key("pong", {"speedup": 1, "rules": "seed"}) == '{"rules":"seed","speedup":1}'  # sorted
    assert variant_key("lander", {"landers": 4}) == '{"landers":4}'
    assert variant_key("lander", {"landers": 2, "gravity": -10}) == ""
    # tennis: shaping rewards are neutral; the serve bot's serves are not (it anchors the ladder)
    assert variant_key("tennis", {"return_reward": 0.5, "hit_reward": 0.3, "point_reward": 0.1}) == ""
    assert variant_key("tennis", {"serve_mode": "mixed", "return_reward": 0.5}) == '{"serve_mode":"mixed"}'
    # a game this process cannot load: every option counts, still in one canonical form
    assert variant_key("nosuchgame", {"b": 2.0, "a": True}) == '{"a":true,"b":2}'
    assert variant_options(TO_3) == {"points_to_win": 3} and variant_options("") == {}
    assert describe_variant(TO_3) == "points_to_win=3" and describe_variant("") == "the default options"
    flags = variant_flags('{"rules":"seed","serve_mode":"a b"}')
    assert flags == "--env-option rules=seed --env-option 'serve_mode=a b'"


def test_a_users_pettingzoo_game_declares_its_defaults_and_how_it_is_drawn_splits_nothing():
    spec = adapt("rendezvous_variants", Rendezvous)  # the factory's keyword defaults: max_cycles=50, speed=0.1
    assert spec.variant_options({"max_cycles": 50, "speed": 0.1, "render_mode": "rgb_array"}) == {}
    assert spec.variant_options({"max_cycles": 20}) == {"max_cycles": 20}


# ---------------------------------------------------------------------------------------------------------------
# Matches are filed with their variant; every reader takes one


@pytest.mark.slow
def test_a_match_under_an_option_is_rated_apart_from_the_default_ladder(home, capsys):
    rep = run_json(capsys, "match", "cpu", "random", "--env", "pong", "--env-option", "points_to_win=3",
                   "--games", "20", "-q")
    assert rep["games"] == 20 and rep["variant"] == {"points_to_win": 3}
    # the default ladder has none of its games: without options the ladder shows the only variant with games ...
    assert ladder_json(capsys, "--env", "pong", "--env-option", "points_to_win=21") == []
    assert all(r["variant"] == {"points_to_win": 3} for r in ladder_json(capsys, "--env", "pong"))
    # ... its own ladder has all of them, and says which variant it fitted
    rows = ladder_json(capsys, "--env", "pong", "--env-option", "points_to_win=3")
    assert games_of(rows) == {"cpu": 20, "random": 20} and all(r["variant"] == {"points_to_win": 3} for r in rows)
    fit = run_json(capsys, "elo", "fit", "--env", "pong", "--env-option", "points_to_win=3", "--bootstrap", "0")
    assert games_of(fit) == {"cpu": 20, "random": 20} and fit[0]["variant"] == {"points_to_win": 3}

    rep = run_json(capsys, "match", "cpu", "random", "--env", "pong", "--games", "10", "-q")
    assert rep["variant"] == {}
    rows = ladder_json(capsys, "--env", "pong")
    assert games_of(rows) == {"cpu": 10, "random": 10} and all(r["variant"] == {} for r in rows)
    # the table of the default says, in one plain line, what else the league holds and how to see it
    code, out, err = run(capsys, "league", "ladder", "--env", "pong", "--bootstrap", "0")
    assert code == 0 and err == ""
    notes = [ln for ln in out.splitlines() if "other options" in ln]
    assert notes == ["pong also has rated games under other options, in ladders of their own: 20 games with "
                     "points_to_win=3 (marl league ladder --env pong --env-option points_to_win=3)"]
    # and the variant's table names the default's
    code, out, err = run(capsys, "elo", "fit", "--env", "pong", "--env-option", "points_to_win=3", "--bootstrap",
                         "0")
    assert code == 0 and "10 games with the default options (marl elo fit --env pong)" in out
    assert "points_to_win=3" in out.splitlines()[0]  # the title names the variant


def test_a_lander_match_with_more_landers_is_rated_apart(home, capsys):
    rep = run_json(capsys, "match", "heuristic", "random", "--env", "lander", "--env-option", "landers=4",
                   "--games", "4", "-q")
    assert rep["variant"] == {"landers": 4} and rep["wins"] + rep["draws"] + rep["losses"] == 2
    assert ladder_json(capsys, "--env", "lander", "--env-option", "landers=2") == []
    rows = ladder_json(capsys, "--env", "lander", "--env-option", "landers=4")
    assert games_of(rows) == {"heuristic": 2, "random": 2}  # two comparisons, each of two episodes
    assert all(r["variant"] == {"landers": 4} for r in rows) and all(r["mean_return"] is not None for r in rows)


@pytest.mark.slow
def test_a_neutral_option_does_not_split_the_ladder(home, capsys):
    run_json(capsys, "match", "cpu", "random", "--env", "pong", "--games", "6", "-q")
    rep = run_json(capsys, "match", "cpu", "random", "--env", "pong", "--env-option", "frame_stack=4",
                   "--games", "4", "-q")
    assert rep["variant"] == {}
    rows = ladder_json(capsys, "--env", "pong")
    assert games_of(rows) == {"cpu": 10, "random": 10}
    assert ladder_json(capsys, "--env", "pong", "--env-option", "frame_stack=4") == rows  # the same ladder
    code, out, err = run(capsys, "league", "ladder", "--env", "pong", "--bootstrap", "0")
    assert code == 0 and "other options" not in out


@pytest.mark.slow
def test_tournament_gate_and_matrix_work_in_one_variant(home, capsys):
    rows = run_json(capsys, "league", "tournament", "cpu", "random", "--env", "pong", "--env-option",
                    "points_to_win=3", "--games-per-pair", "10", "--bootstrap", "0")
    assert games_of(rows) == {"cpu": 10, "random": 10} and rows[0]["variant"] == {"points_to_win": 3}
    # the default variant's pair has no games yet: the same tournament without the option plays them all
    rows = run_json(capsys, "league", "tournament", "cpu", "random", "--env", "pong", "--games-per-pair", "10",
                    "--bootstrap", "0")
    assert games_of(rows) == {"cpu": 10, "random": 10} and rows[0]["variant"] == {}
    run_json(capsys, "match", "cpu", "random", "--env", "pong", "--games", "10", "-q")
    with League.open(home) as league:
        assert league.ledger.variants("pong") == {"": 20, TO_3: 10}
    # the gate reuses the stored games of the variant it plays in, and only those
    verdict = run_json(capsys, "elo", "gate", "cpu", "--vs", "random", "--env", "pong", "--env-option",
                       "points_to_win=3", "--games", "10")
    assert verdict["passed"] and (verdict["stored_games"], verdict["played_games"]) == (10, 0)
    verdict = run_json(capsys, "elo", "gate", "cpu", "--vs", "random", "--env", "pong", "--games", "10")
    assert verdict["passed"] and (verdict["stored_games"], verdict["played_games"]) == (20, 0)
    # the matrix counts one variant's games, and its fill command plays in that variant
    report = run_json(capsys, "league", "matrix", "--env", "pong", "--env-option", "points_to_win=3",
                      "--min-games", "50")
    assert report["variant"] == {"points_to_win": 3} and report["games"] == [[0, 10], [10, 0]]
    assert "--games-per-pair 50 --env-option points_to_win=3 --home" in report["command"]
    report = run_json(capsys, "league", "matrix", "--env", "pong")
    assert report["variant"] == {} and report["games"] == [[0, 20], [20, 0]]


@pytest.mark.slow
def test_networks_of_different_frame_stacks_share_one_ladder_through_the_bots(home, tmp_path, capsys):
    """frame_stack is neutral: a network of 4 frames and one of 8 cannot meet, but both meet cpu in the one game."""
    for name, frames in (("f4", 4), ("f8", 8)):
        arch = Arch(hidden=(16,))
        net = build_network((frames, 6), 3, arch, seed=frames)
        meta = SnapshotMeta(env="pong", obs_shape=(frames, 6), n_actions=3, arch=arch, run="fs", name=name,
                            algo="ppo", step=frames, env_options={"frame_stack": frames} if frames != 8 else {})
        save_snapshot(tmp_path / f"{name}.safetensors", net, meta)
        assert run(capsys, "checkpoint", "import", str(tmp_path / f"{name}.safetensors"))[0] == 0
    rows = run_json(capsys, "league", "tournament", "--run", "fs", "--vs", "cpu", "--games-per-pair", "4",
                    "--bootstrap", "0")
    assert rows[0]["variant"] == {} and games_of(rows) == {"cpu": 8, "fs/f4": 4, "fs/f8": 4}
    assert games_of(ladder_json(capsys, "--env", "pong")) == {"cpu": 8, "fs/f4": 4, "fs/f8": 4}
    # a variant apart: both flown to 3 points, their games rated in that ladder alone
    rows = run_json(capsys, "league", "tournament", "--run", "fs", "--vs", "cpu", "--games-per-pair", "2",
                    "--env-option", "points_to_win=3", "--bootstrap", "0")
    assert rows[0]["variant"] == {"points_to_win": 3} and games_of(rows) == {"cpu": 4, "fs/f4": 2, "fs/f8": 2}


def seed_two_variants(home: Path) -> dict[str, int]:
    """Two snapshots and the pong bots: ``r/a`` beats both bots in the default game and loses in the variant
    points_to_win=3, ``r/b`` the other way round. Games written straight to the ledger (results chosen by hand)."""
    with League.open(home) as lg:
        lg.roster.ensure_bots("pong", ["random", "cpu"])
        lg.roster.create_run("r", "pong", {})
        ids = {p.name: p.id for p in lg.roster.players("pong", kind="bot")}
        for name in ("a", "b"):
            ids[name] = lg.roster.add_snapshot(env="pong", run="r", name=name, path=f"/x/r/{name}.safetensors",
                                               sha256="0" * 64, step=1).id
        for options, winner, loser in (({}, "a", "b"), ({"points_to_win": 3}, "b", "a")):
            games = []
            for k, (x, y) in enumerate([(winner, bot) for bot in ("random", "cpu")] * 6
                                       + [(bot, loser) for bot in ("random", "cpu")] * 6 + [("cpu", "random")] * 4):
                games.append(GameResult(env="pong", players=(ids[x], ids[y]), seed=k, scores=(3.0, 1.0),
                                        outcome=(1.0, 0.0), length=100, truncated=False))
            match = lg.ledger.create_match("pong", "match", {"env_options": options})
            lg.ledger.record_games(match, games)
    return ids


def test_best_and_the_anchor_are_read_from_the_variant_asked_for(home, capsys):
    ids = seed_two_variants(home)
    with League.open(home) as league:
        assert resolve(league, "best", "pong").id == ids["a"]
        assert resolve(league, "best", "pong", variant=TO_3).id == ids["b"]
    rows = run_json(capsys, "elo", "fit", "--env", "pong", "--anchor", "best=1500", "--bootstrap", "0")
    assert next(r for r in rows if r["anchor"])["policy"] == "r/a"
    rows = run_json(capsys, "elo", "fit", "--env", "pong", "--env-option", "points_to_win=3", "--anchor",
                    "best=1500", "--bootstrap", "0")
    assert next(r for r in rows if r["anchor"])["policy"] == "r/b"
    assert {r["policy"]: r["games"] for r in rows}["r/a"] == 12


def test_only_the_default_variant_moves_the_online_elo(home):
    ids = seed_two_variants(home)
    with League.open(home) as league:
        online = {p.name: (round(p.elo, 6), p.games) for p in league.roster.players("pong")}
        assert online["b"][0] < 1000 < online["a"][0]  # the default games moved them (b lost there) ...
        assert online["a"][1] == online["b"][1] == 24  # ... and every game counts in the game counts
        league.ledger.recompute_online_elo("pong")
        assert {p.name: (round(p.elo, 6), p.games) for p in league.roster.players("pong")} == online
        # a variant's match alone moves no online Elo
        before = {p.id: p.elo for p in league.roster.players("pong")}
        match = league.ledger.create_match("pong", "match", {"env_options": {"points_to_win": 3}})
        league.ledger.record_games(match, [GameResult(env="pong", players=(ids["random"], ids["a"]), seed=99,
                                                      scores=(3.0, 0.0), outcome=(1.0,
                                                                                  0.0), length=10, truncated=False)])
        assert {p.id: p.elo for p in league.roster.players("pong")} == before


# ---------------------------------------------------------------------------------------------------------------
# A league written before variants


def test_a_league_written_before_variants_reads_per_variant(tmp_path, capsys):
    home = tmp_path / "old"
    home.mkdir()
    shutil.copy(OLD_LEAGUE, home / "league.db")
    # read-only, as the ladder opens it: no upgrade needed, games placed by the options their matches recorded
    rows = ladder_json(capsys, "--home", str(home), "--env", "pong")
    assert games_of(rows) == {"cpu": 6, "random": 6}  # 4 default games + 2 under the neutral frame_stack=4
    rows = ladder_json(capsys, "--home", str(home), "--env", "pong", "--env-option", "points_to_win=3")
    assert games_of(rows) == {"cpu": 6, "random": 6}
    assert ladder_json(capsys, "--home", str(home), "--env", "lander", "--env-option", "landers=2") == []
    rows = ladder_json(capsys, "--home", str(home), "--env", "lander", "--env-option", "landers=4")
    assert games_of(rows) == {"heuristic": 1, "random": 1}  # one comparison of two episodes
    # and it takes new games as any league does
    rep = run_json(capsys, "match", "cpu", "random", "--env", "pong", "--env-option", "points_to_win=3",
                   "--games", "2", "-q", "--home", str(home))
    assert rep["variant"] == {"points_to_win": 3}
    with League.open(home) as league:
        assert league.ledger.variants("pong") == {"": 6, TO_3: 8}


@pytest.mark.slow
def test_the_ladder_without_options_shows_the_games_the_newest_run_played(home, capsys):
    """`marl train tennis` plays serve_mode=mixed, not the game's default: the ladder a user gets without options is
    the variant the game's newest run played (a run of the default game after it brings the default back); with no
    run, the only variant with games, whichever it is; --env-option still picks any."""
    seed_two_variants(home)
    assert games_of(ladder_json(capsys, "--env", "pong"))["r/a"] == 12  # run r: the default game
    with League.open(home) as lg:
        lg.roster.create_run("t", "pong", {"env_options": {"points_to_win": 3}})
    rows = ladder_json(capsys, "--env", "pong")
    assert rows[0]["variant"] == {"points_to_win": 3} and games_of(rows)["r/a"] == 12
    assert {r["policy"] for r in rows if r["best"]} == {"r/b"}  # b wins the variant's games
    assert ladder_json(capsys, "--env", "pong", "--env-option", "points_to_win=21")[0]["variant"] == {}
    with League.open(home) as lg:
        lg.roster.create_run("u", "pong", {"env_options": {}})
    assert ladder_json(capsys, "--env", "pong")[0]["variant"] == {}
    # no run at all, one variant with games: that one
    other = home.parent / "other"
    with League.open(other) as lg:
        lg.roster.ensure_bots("pong", ["random", "cpu"])
        bots = {p.name: p.id for p in lg.roster.players("pong", kind="bot")}
        match = lg.ledger.create_match("pong", "match", {"env_options": {"points_to_win": 3}})
        lg.ledger.record_games(match, [GameResult(env="pong", players=(bots["cpu"], bots["random"]), seed=k,
                                                  scores=(3.0, 1.0), outcome=(1.0, 0.0), length=100, truncated=False)
                                for k in range(4)])
    rows = ladder_json(capsys, "--env", "pong", "--home", str(other))
    assert rows[0]["variant"] == {"points_to_win": 3} and games_of(rows) == {"cpu": 4, "random": 4}


def test_an_empty_league_names_commands_that_exist(home, capsys):
    code, out, err = run(capsys, "league", "ladder")
    assert code == 2 and err.count("\n") == 1 and "marl tournament" not in err
    assert "marl train" in err and "marl league tournament" in err
