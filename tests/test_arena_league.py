"""Rated play and ratings for every kind of game: what the ledger keeps, what ratings are derived from it, matches,
SPRT, the gate, tournaments and the ladder, with the test games of ``arena_games`` (hand-computed results)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from arena_games import Const, Spy, registered

from selfplay_cli.cli import main
from selfplay_cli.evaluation.gate import gate_check
from selfplay_cli.evaluation.lineup import lineup
from selfplay_cli.evaluation.match import SPRTSettings, run_match
from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.ratings.pairs import head_to_head, plan_tournament
from selfplay_cli.results import FREE_FOR_ALL, GameResult, Rules, game_results
from selfplay_cli.stats.elo import elo_update

COOP, FFA, SEQ, SIDES = "arena-coop2", "arena-ffa3", "arena-seq2", "arena-sides4"


@pytest.fixture(autouse=True, scope="module")
def _test_games():
    with registered():
        yield


@pytest.fixture
def league(tmp_path: Path) -> League:
    lg = League.open(home=tmp_path / "league")
    yield lg
    lg.close()


def _players(league: League, env: str, names: list[str]) -> list[int]:
    league.roster.ensure_bots(env, names)
    by_name = {p.name: p.id for p in league.roster.players(env=env)}
    return [by_name[n] for n in names]


def _episode(env: str, player: int, seed: int, per_seat: float, seats: int = 2, truncated: bool = False) -> GameResult:
    return GameResult(env, (player,) * seats, seed, (per_seat,) * seats, (0.5,) * seats, 5, truncated)


def test_one_record_type_from_the_runner_to_the_ledger():
    assert GameResult is GameResult, "the ledger's GameResult is the runner's GameResult"
    r = GameResult("pong", ("a", "b"), 3, (21.0, 4.0), (1.0, 0.0), 900, False, b"x", index=7)
    stored = r.with_players({"a": 11, "b": 12})
    assert stored.players == (11, 12) and (stored.seed, stored.scores, stored.actions) == (3, (21.0, 4.0), b"x")
    assert r.points_of("a") == 1.0 and r.score_of("b") == 4.0


def test_both_game_loops_make_results_by_one_function():
    """game_results: one result per column of final scores, each seat's points by the rules, plain numbers."""
    scores = np.array([[3.0, 1.0], [2.0, 1.0], [1.0, 1.0]], dtype=np.float32)  # (seats, games)
    got = game_results(FFA, Rules(n_seats=3, kind=FREE_FOR_ALL), scores, [("a", "b", "c"), ("c", "b", "a")],
                       seeds=np.array([5, 6]), lengths=np.array([40, 9]), truncated=np.array([False, True]),
                       indices=[0, 3], actions=[b"x", None])
    first, second = got
    assert first == GameResult(FFA, ("a", "b", "c"), 5, (3.0, 2.0, 1.0), (1.0, 0.5, 0.0), 40, False, b"x", 0)
    assert second == GameResult(FFA, ("c", "b", "a"), 6, (1.0, 1.0, 1.0), (0.5, 0.5, 0.5), 9, True, None, 3)
    assert all(type(x) is float for x in (*second.scores, *second.outcome))
    assert type(second.seed) is int and type(second.length) is int and type(second.truncated) is bool


def test_free_for_all_gives_every_two_players_one_result_and_moves_elo_together(league):
    a, b, c = _players(league, FFA, ["a", "b", "c"])
    m = league.ledger.create_match(FFA, "match")
    assert league.ledger.match_info(m)[1]["rules"]["kind"] == "free-for-all", "the rules are kept with the match"
    (gid,) = league.ledger.record_games(m, [GameResult(FFA, (a, b, c), 0, (30.0, 6.0, 6.0), (1.0, 0.25, 0.25), 4,
                                                       False)])
    t = league.ledger.games(FFA)
    assert t.game_id.tolist() == [gid] * 3 and t.kind.tolist() == [2, 2, 2]
    assert list(zip(t.player_a.tolist(), t.player_b.tolist(), t.score_a.tolist(), strict=True)) == [
        (a, b, 1.0), (a, c, 1.0), (b, c, 0.5)]
    # From 1000 each, all three results at once: a +8 +8, b -8 +0, c -8 +0 (a draw between equals moves nothing).
    assert [league.roster.get_player(p).elo for p in (a, b, c)] == [1016.0, 992.0, 992.0]
    assert all(league.roster.get_player(p).games == 1 for p in (a, b, c))
    league.ledger.recompute_online_elo(FFA)
    assert [league.roster.get_player(p).elo for p in (a, b, c)] == [1016.0, 992.0, 992.0]


def test_free_for_all_ladder_is_the_hand_computed_fit(league):
    a, b = _players(league, FFA, ["a", "b"])
    m = league.ledger.create_match(FFA, "match")
    # a holds two of the three seats: it beats b when both its seats end above b's, loses when both end below.
    won = [GameResult(FFA, (a, b, a), s, (3.0, 1.0, 2.0), (1.0, 0.0, 0.5), 4, False) for s in range(7)]
    lost = [GameResult(FFA, (b, a, a), s, (3.0, 1.0, 2.0), (1.0, 0.0, 0.5), 4, False) for s in range(3)]
    split = [GameResult(FFA, (a, b, a), 9, (3.0, 2.0, 1.0), (1.0, 0.5, 0.0), 4, False)]  # one above, one below
    league.ledger.record_games(m, won + lost + split)
    t = league.ledger.games(FFA)
    assert t.player_a.tolist() == [a] * 7 + [b] * 3 + [a], "player_a: the player of the lower first seat"
    assert np.where(t.player_a == a, t.score_a, 1 - t.score_a).tolist() == [1.0] * 7 + [0.0] * 3 + [0.5]
    rows = {r.policy: r for r in ladder(league, FFA, anchor="b", bootstrap=0, prior=0)}
    # 7 wins, 3 losses and a draw: a scores 7.5 / 11, ML difference 400 log10(7.5 / 3.5).
    assert rows["a"].elo == pytest.approx(1000.0 + 400.0 * math.log10(7.5 / 3.5), abs=1e-6)
    assert (rows["a"].wins, rows["a"].draws, rows["a"].losses) == (7, 1, 3) and rows["a"].mean_return is None
    assert "mean_return" not in rows["a"].to_json(), "a free-for-all ladder has no team return"


def test_cooperative_comparisons_pair_episodes_on_one_seed_within_one_match(league):
    a, b = _players(league, COOP, ["a", "b"])
    m = league.ledger.create_match(COOP, "match")
    assert league.ledger.match_info(m)[1]["rules"] == {"n_seats": 2, "kind": "cooperative", "sides": None,
                                                  "tie_tolerance": 0.5}
    ids = league.ledger.record_games(m, [
        _episode(COOP, a, 0, 5.0), _episode(COOP, b, 0, 4.8),  # 10 against 9.6: within 0.5, a draw
        _episode(COOP, a, 1, 5.0), _episode(COOP, b, 1, 4.5, truncated=True),  # 10 against 9: a wins
        _episode(COOP, b, 2, 1.5), _episode(COOP, a, 2, 0.5),  # b first, 3 against 1: b wins
        _episode(COOP, a, 3, 2.0),  # no partner in this match
        GameResult(COOP, (a, b), 4, (1.0, 1.0), (0.5, 0.5), 5, False),  # flown by both together: no comparison
    ])
    later = league.ledger.create_match(COOP, "match")
    league.ledger.record_games(later, [_episode(COOP, b, 3, 0.0)])  # seed 3 again, but in another match
    t = league.ledger.games(COOP)
    assert t.game_id.tolist() == [ids[1], ids[3], ids[5]], "a comparison is filed under its later episode"
    assert list(zip(t.player_a.tolist(), t.player_b.tolist(), t.score_a.tolist(), strict=True)) == [
        (a, b, 0.5), (a, b, 1.0), (b, a, 1.0)]
    assert t.truncated.tolist() == [False, True, False] and t.kind.tolist() == [1, 1, 1]
    # The online Elo moved once per comparison, in order.
    ra, rb = elo_update(1000.0, 1000.0, 0.5)
    ra, rb = elo_update(ra, rb, 1.0)
    rb, ra = elo_update(rb, ra, 1.0)
    assert (league.roster.get_player(a).elo, league.roster.get_player(b).elo) == (ra, rb)
    league.ledger.recompute_online_elo()
    assert (league.roster.get_player(a).elo, league.roster.get_player(b).elo) == (ra, rb)
    h = head_to_head(league, a, b)
    assert (h["wins"], h["draws"], h["losses"], h["results"], h["games"]) == (1, 1, 1, 3, 6)
    assert h["pentanomial"] == [0, 0, 0, 0, 0] and h["pairs"] == 0
    returns = league.ledger.mean_returns(COOP)
    assert returns[a] == (5, pytest.approx((10 + 10 + 1 + 4 + 2) / 5)) and returns[b][0] == 5
    assert plan_tournament(league, COOP, [a, b], 6) == [], "3 comparisons are the 6 games asked for"


def test_cooperative_ladder_shows_the_mean_return(league):
    a, b = _players(league, COOP, ["a", "b"])
    m = league.ledger.create_match(COOP, "match")
    outcomes = [(5.0, 1.0)] * 7 + [(1.0, 5.0)] * 3 + [(2.0, 2.2)] * 2  # 7 wins, 3 losses, 2 draws for a
    league.ledger.record_games(m, [g for s, (x, y) in enumerate(outcomes)
                                   for g in (_episode(COOP, a, s, x), _episode(COOP, b, s, y))])
    rows = {r.policy: r for r in ladder(league, COOP, anchor="b", bootstrap=0, prior=0)}
    # a scores (7 + 1) / 12 = 2/3: ML difference 400 log10 2.
    assert rows["a"].elo == pytest.approx(1000.0 + 400.0 * math.log10(2.0), abs=1e-6)
    assert (rows["a"].wins, rows["a"].draws, rows["a"].losses, rows["a"].games) == (7, 2, 3, 12)
    assert rows["a"].mean_return == pytest.approx(2 * (7 * 5 + 3 * 1 + 2 * 2) / 12)
    assert rows["b"].to_json()["mean_return"] == round(2 * (7 * 1 + 3 * 5 + 2 * 2.2) / 12, 4)
    assert list(rows["a"].to_json())[-1] == "mean_return"


def test_two_sides_of_several_seats_give_one_result_per_game(league):
    a, b, c = _players(league, SIDES, ["a", "b", "c"])
    m = league.ledger.create_match(SIDES, "match")
    league.ledger.record_games(m, [GameResult(SIDES, (a, a, b, b), 0, (2.0, 2.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0), 3,
                                              False),
                                   GameResult(SIDES, (b, b, a, a), 0, (2.0, 2.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0), 3,
                                              False),
                                   GameResult(SIDES, (a, a, b, c), 1, (1.0, 1.0, 1.0, 1.0), (0.5, 0.5, 0.5, 0.5), 3,
                                              False)])
    t = league.ledger.games(SIDES)
    assert list(zip(t.player_a.tolist(), t.player_b.tolist(), t.score_a.tolist(), strict=True)) == [
        (a, b, 1.0), (b, a, 1.0), (a, b, 0.5), (a, c, 0.5)]
    h = head_to_head(league, a, b)
    assert h["pentanomial"] == [0, 0, 1, 0, 0] and h["pairs"] == 1 and h["unpaired"] == 1, "seed 0: won and lost"


def test_a_ledger_refuses_what_it_cannot_rate(league):
    (a,) = _players(league, COOP, ["a"])
    m = league.ledger.create_match(COOP, "match")
    for bad in (GameResult(COOP, ("a", "a"), 0, (1.0, 1.0), (0.5, 0.5), 5, False),
                GameResult(COOP, (a, a), 0, (math.nan, 1.0), (0.5, 0.5), 5, False)):
        with pytest.raises(LeagueError) as e:
            league.ledger.record_games(m, [bad])
        assert "\n" not in str(e.value)
    with pytest.raises(LeagueError, match="rules are malformed"):
        league.ledger.create_match(COOP, "match", {"rules": {"kind": "tug-of-war"}})


# --------------------------------------------------------------------------------------------------- rated play
def test_cooperative_match_compares_team_returns_on_shared_seeds(league):
    high, mid, low = _players(league, COOP, ["high", "mid", "low"])
    a, b = Const("high", COOP, (1.0, 1.0)), Const("mid", COOP, (1.0, 0.0))
    rep = run_match(a, b, games=9, league=league, player_ids={"high": high, "mid": mid})
    assert rep.kind == "cooperative" and rep.games == 10, "rounded up to whole comparisons: 5 seeds, 2 episodes each"
    assert (rep.wins, rep.draws, rep.losses) == (5, 0, 0) and rep.pentanomial == (0, 0, 0, 0, 0)
    assert rep.points_for == 100 and rep.points_against == 50 and rep.mean_returns == (20.0, 10.0)
    assert rep.to_json()["mean_return"] == {"a": 20.0, "b": 10.0}
    assert [r.seed for r in rep.results] == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    assert all(set(r.players) == {p} for r, p in zip(rep.results, ["high", "mid"] * 5, strict=True))
    near = Const("near", COOP, (1.0, 0.96))  # 19.6 against 20: within the tolerance of 0.5
    assert run_match(a, near, games=4).draws == 2
    rows = {r.policy: r for r in ladder(league, COOP, anchor="mid", bootstrap=0)}
    assert rows["high"].mean_return == 20.0 and rows["mid"].mean_return == 10.0


def test_cooperative_sprt_counts_comparisons(league):
    a, b = Const("high", COOP, (1.0, 1.0)), Const("low", COOP, (-1.0, 0.0))
    rep = run_match(a, b, games=400, sprt=SPRTSettings(0.0, 10.0))
    assert rep.sprt["decision"] == "H1" and rep.sprt["model"] == "trinomial"
    assert rep.games == 2 * rep.sprt["pairs"] == 2 * rep.wins, "it stops at the comparison that decides"


def test_free_for_all_match_plays_every_rotation(league):
    hi, lo = _players(league, FFA, ["high", "low"])
    a, b = Const("high", FFA, (2, 1)), Const("low", FFA, (0, 1))  # 6 (2 + 3) = 30 against 6 * 3 = 18
    rep = run_match(a, b, games=6, league=league, player_ids={"high": hi, "low": lo})
    assert [r.players for r in rep.results[:3]] == [("high", "low", "high"), ("low", "high", "high"),
                                                    ("high", "high", "low")]
    assert (rep.games, rep.wins, rep.losses, rep.kind) == (6, 6, 0, "free-for-all")
    assert rep.points_for == 6 * 2 * 30 and rep.points_against == 6 * 18
    assert len(league.ledger.games(FFA)) == 6 and head_to_head(league, hi, lo)["wins"] == 6


def test_turn_based_match_is_played_in_seat_swapped_pairs(league):
    hi, lo = _players(league, SEQ, ["high", "low"])
    rep = run_match(Spy("high", SEQ), Spy("low", SEQ, highest=False), games=8, league=league,
                    player_ids={"high": hi, "low": lo})
    assert (rep.wins, rep.losses, rep.pentanomial) == (8, 0, (0, 0, 0, 0, 4)) and rep.kind == "two-sides"
    assert head_to_head(league, hi, lo)["pentanomial"] == [0, 0, 0, 0, 4]
    assert all(league.ledger.game(g).actions[:3] == b"MA\x01" for g in rep.game_ids)


def test_gate_and_tournament_work_for_cooperative_games(league):
    league.roster.ensure_bots(COOP, ["high", "mid", "low"])
    rows = {p.name: p for p in league.roster.players(env=COOP)}
    verdict = gate_check(league, rows["high"], rows["low"], min_diff=0.0, games=20)
    assert verdict.passed and verdict.played_games == 20 and verdict.stats.wins == 10
    again = gate_check(league, rows["high"], rows["low"], min_diff=0.0, games=20)
    assert again.played_games == 0 and again.stored_games == 20, "stored comparisons are reused"
    plan = plan_tournament(league, COOP, [rows["high"].id, rows["mid"].id, rows["low"].id], 20)
    assert [(p.a_id, p.b_id, p.existing, p.missing) for p in plan] == [
        (rows["high"].id, rows["mid"].id, 0, 20), (rows["mid"].id, rows["low"].id, 0, 20)]


def test_lineups_follow_the_kind(league):
    league.roster.ensure_bots(COOP, ["high", "mid", "low"])
    league.roster.ensure_bots(SIDES, ["high", "low"])
    league.roster.ensure_bots(FFA, ["high", "low"])
    assert lineup(league, "mid", env=COOP).names == ("mid", "mid"), "a team flies every seat, no opponent"
    assert lineup(league, "low", env=SIDES).names == ("low", "low", "high", "high"), "a side each"
    assert lineup(league, "low", vs="high", env=FFA).names == ("low", "high", "high")


def test_the_commands_play_and_rate_a_cooperative_game(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MARL_HOME", str(tmp_path / "league"))
    monkeypatch.delenv("MARL_DB", raising=False)

    def run(*args: str):
        code = main([*args, "--json"])
        out = capsys.readouterr()
        return code, json.loads(out.out) if out.out.strip() else None, out.err

    code, rep, err = run("match", "high", "mid", "--env", COOP, "--games", "10", "--quiet")
    assert code == 0, err
    assert (rep["kind"], rep["games"], rep["wins"], rep["mean_return"]) == ("cooperative", 10, 5,
                                                                           {"a": 20.0, "b": 10.0})
    code, rows, err = run("league", "ladder", "--env", COOP, "--bootstrap", "0")
    assert code == 0, err
    assert {r["policy"]: r["mean_return"] for r in rows} == {"high": 20.0, "mid": 10.0}
    code, verdict, err = run("elo", "gate", "mid", "--vs", "low", "--env", COOP, "--games", "10")
    assert code == 0 and verdict["passed"] and verdict["wins"] == 5, err
    code, rows, err = run("league", "tournament", "high", "mid", "low", "--env", COOP, "--games-per-pair", "4",
                          "--bootstrap", "0", "--quiet")
    assert code == 0, err
    by = {r["policy"]: r for r in rows}
    assert by["high"]["elo"] > by["mid"]["elo"] > by["low"]["elo"]
    assert by["low"]["mean_return"] == -10.0 and np.isclose(by["mid"]["mean_return"], 10.0)
