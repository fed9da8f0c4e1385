"""Tests for selfplay_cli.ratings.ladder, .fit, .ladder_rows and .verdicts (ladders, results CSV, tournament plans,
head-to-head) and selfplay_cli.ratings.names (name resolution)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from selfplay_cli.errors import MarlError
from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.ratings.fit import Fitted, _ranks_and_tiers, fit_rows, fit_table
from selfplay_cli.ratings.forecast import Forecaster
from selfplay_cli.ratings.ladder import _mark_best, ladder
from selfplay_cli.ratings.ladder_rows import LadderRow
from selfplay_cli.ratings.names import resolve, resolve_many
from selfplay_cli.ratings.pairs import PairPlan, head_to_head, plan_tournament
from selfplay_cli.ratings.results_csv import fit_csv, read_results_csv
from selfplay_cli.ratings.verdicts import select_rows, verdict_lines
from selfplay_cli.results import GameResult
from selfplay_cli.stats.bradley_terry import DEFAULT_PRIOR, FLAG_PERFECT, fit_bradley_terry
from selfplay_cli.stats.elo import NAT_TO_ELO, elo_to_score, normal_quantile
from selfplay_cli.stats.match import match_stats
from selfplay_cli.stats.predict import PairModel, Spread
from selfplay_cli.stats.sprt import sprt_llr

ENV = "pong"
JSON_KEYS = ["policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses", "rank",
             "tier", "score", "step", "flag", "anchor", "run", "best", "margin", "best_margin", "tied", "copy_of",
             "copies", "vs", "league_role", "exploitability", "circle"]
D_7_OF_10 = 400.0 * math.log10(7.0 / 3.0)  # +147.2: the ML Elo difference of a 7/10 score


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------


@pytest.fixture
def league(db_url: str) -> League:
    """A fresh league, once on SQLite and once on PostgreSQL (conftest's ``db_url``)."""
    lg = League(db_url)
    yield lg
    lg.close()


def _game(a: int, b: int, score_a: float, seed: int = 0, env: str = ENV) -> GameResult:
    scores = {1.0: (21.0, 10.0), 0.5: (15.0, 15.0), 0.0: (10.0, 21.0)}[score_a]
    return GameResult(env=env, players=(a, b), seed=seed, scores=scores, outcome=(score_a, 1.0 - score_a),
                      length=100, truncated=False)


def _snap(lg: League, run: str | None, name: str, env: str = ENV, step: int = 0) -> PlayerRow:
    return lg.roster.add_snapshot(env=env, run=run, name=name, path=f"/snaps/{run}/{name}.pt", sha256="0" * 64,
                                  step=step)


def _record(lg: League, results: list[tuple[int, int, float]], env: str = ENV) -> None:
    """Record games ``(a, b, score_a)`` alternating the seat order of each game."""
    m = lg.ledger.create_match(env, "match")
    games = []
    for k, (a, b, s) in enumerate(results):
        games.append(_game(a, b, s, k, env) if k % 2 == 0 else _game(b, a, 1.0 - s, k, env))
    lg.ledger.record_games(m, games)


def _results(a: int, b: int, wins: int, draws: int, losses: int) -> list[tuple[int, int, float]]:
    return [(a, b, 1.0)] * wins + [(a, b, 0.5)] * draws + [(a, b, 0.0)] * losses


def _csv(tmp_path: Path, lines: list[str], name: str = "results.csv") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def _csv_games(tmp_path: Path, records: list[tuple[str, str, int, int, int]]) -> Path:
    lines = ["player_a,player_b,result"]
    for a, b, w, d, lo in records:
        lines += [f"{a},{b},1"] * w + [f"{a},{b},0.5"] * d + [f"{a},{b},0"] * lo
    return _csv(tmp_path, lines)


def _by_name(rows: list[LadderRow]) -> dict[str, LadderRow]:
    return {r.policy: r for r in rows}


def _one_line(exc: pytest.ExceptionInfo[BaseException]) -> str:
    msg = str(exc.value)
    assert msg and "\n" not in msg and isinstance(exc.value, MarlError), msg
    return msg


# --------------------------------------------------------------------------------------------------
# fit_table / fit_csv: ratings checked by hand
# --------------------------------------------------------------------------------------------------


def test_two_players_closed_form(tmp_path: Path) -> None:
    path = _csv_games(tmp_path, [("alice", "bob", 7, 0, 3)])
    rows = fit_csv(path, bootstrap=0, prior=0)
    assert [r.policy for r in rows] == ["alice", "bob"]
    a, b = rows
    assert a.anchor and not b.anchor and a.kind == b.kind == "player"  # default anchor: first player
    assert a.elo == pytest.approx(1000.0) and b.elo == pytest.approx(1000.0 - D_7_OF_10, abs=0.01)
    assert abs(D_7_OF_10 - 147.2) < 0.05
    assert (a.games, a.wins, a.draws, a.losses, a.score) == (10, 7, 0, 3, 0.7)
    assert (b.wins, b.losses, b.score) == (3, 7, pytest.approx(0.3))
    # Normal approximation: Fisher information n p (1 - p) in nats^-2.
    se = NAT_TO_ELO / math.sqrt(10 * 0.7 * 0.3)
    z = normal_quantile(0.975)
    assert b.ci_low == pytest.approx(b.elo - z * se, abs=1e-6) and b.ci_high == pytest.approx(b.elo + z * se, abs=1e-6)
    assert a.ci_low == a.ci_high == 1000.0  # the anchor is fixed
    # Another anchor and rating: only the gauge moves.
    rows = fit_csv(path, anchor="bob", anchor_rating=1500.0, bootstrap=50, prior=0)
    assert _by_name(rows)["alice"].elo == pytest.approx(1500.0 + D_7_OF_10, abs=0.01)
    assert _by_name(rows)["bob"].elo == 1500.0 and _by_name(rows)["bob"].anchor
    # The default prior, BayesElo's 2 virtual draws between the two: alice scores (7 + 1) / 12 = 2/3 -> 400 log10 2.
    a, b = fit_csv(path, bootstrap=0)
    assert b.elo == pytest.approx(1000.0 - 400 * math.log10(2), abs=1e-6) and a.anchor
    se = NAT_TO_ELO / math.sqrt(12 * (2 / 3) * (1 / 3))  # the virtual draws count in the curvature too
    assert b.ci_high == pytest.approx(b.elo + z * se, abs=1e-6)
    assert (b.wins, b.draws, b.losses) == (3, 0, 7)  # the record shows real games only


def test_chain_and_cycle_solve_the_score_equations(tmp_path: Path) -> None:
    # Chain a > b > c, each 7/10: the score equations decouple, a - b = b - c = 147.2.
    rows = _by_name(fit_csv(_csv_games(tmp_path, [("c", "b", 3, 0, 7), ("a", "b", 7, 0, 3)]), bootstrap=0, prior=0))
    assert rows["c"].anchor and rows["c"].elo == 1000.0
    assert rows["b"].elo == pytest.approx(1000.0 + D_7_OF_10, abs=0.01)
    assert rows["a"].elo == pytest.approx(1000.0 + 2 * D_7_OF_10, abs=0.01)

    # A cycle with draws: check sum_j n_ij E(r_i - r_j) = points_i for every player.
    records = [("x", "y", 5, 2, 1), ("y", "z", 3, 3, 2), ("z", "x", 2, 1, 4), ("w", "x", 1, 1, 2)]
    path = _csv_games(tmp_path, records)
    rows = _by_name(fit_csv(path, anchor="y", bootstrap=0, prior=0))
    assert rows["y"].elo == 1000.0 and all(r.flag is None for r in rows.values())
    expected = dict.fromkeys(rows, 0.0)
    points = dict.fromkeys(rows, 0.0)
    for a, b, w, d, lo in records:
        n = w + d + lo
        e = elo_to_score(rows[a].elo - rows[b].elo)
        expected[a] += n * e
        expected[b] += n * (1.0 - e)
        points[a] += w + 0.5 * d
        points[b] += lo + 0.5 * d
    for name in rows:
        assert expected[name] == pytest.approx(points[name], abs=1e-3), name
        assert rows[name].score == pytest.approx(points[name] / rows[name].games)
    # Order: by rank, then Elo.
    ordered = fit_csv(path, anchor="y", bootstrap=0)
    assert [(r.rank, -r.elo) for r in ordered] == sorted((r.rank, -r.elo) for r in ordered)


def test_ranks_follow_the_order_and_tiers_say_what_cannot_be_told_apart(tmp_path: Path) -> None:
    for boot in (0, 100):
        far = fit_csv(_csv_games(tmp_path, [("strong", "weak", 90, 0, 10)]), bootstrap=boot)
        assert [(r.policy, r.rank, r.tier) for r in far] == [("strong", 1, 1), ("weak", 2, 2)]
        assert far[1].ci_high < far[0].ci_low and far[0].margin.separated and far[0].margin.over == "weak"
        close = fit_csv(_csv_games(tmp_path, [("p", "q", 11, 0, 9)]), bootstrap=boot)
        assert [(r.rank, r.tier) for r in close] == [(1, 1), (1, 1)]  # not told apart: one rank, one tier
        assert close[0].elo > close[1].elo and not close[0].margin.separated
        q = close[1]
        assert q.ci_low < q.elo < q.ci_high and q.ci_high > 1000.0


def test_ranks_count_the_players_above_beyond_doubt_and_tiers_part_only_where_every_pair_does() -> None:
    """Ranks and tiers by hand, from differences known exactly (no games yet, no spread): a-b 100 with sd 40 (100 -
    1.96 * 40 > 0: a above b beyond doubt), b-c 100 with sd 80 (not), a-c 200 sd 60, a-d 250 sd 50, b-d 150 sd 50
    (all beyond doubt), c-d 50 sd 50 (not). Rank = 1 + the players above beyond doubt: a 1, b 2, c 2 (only a is above
    it), d 3 (a and b are). Tiers: a boundary after a (a is above all three), none after b (b is not above c) nor
    after c (c is not above d): a | b c d. A flagged player is compared by whole intervals."""
    z = normal_quantile(0.975)
    sd = np.array([[0.0, 40.0, 60.0, 50.0], [40.0, 0.0, 80.0, 50.0], [60.0, 80.0, 0.0, 50.0],
                   [50.0, 50.0, 50.0, 0.0]])
    ratings = np.array([1300.0, 1200.0, 1100.0, 1050.0])
    low, high = ratings - 300.0, ratings + 300.0
    none = np.zeros((4, 4))
    pairs = PairModel(ratings, sd, [True] * 4, none, none, 2.0, spread=Spread.known(0.0), anchor=3)
    fitted = Fitted(["a", "b", "c", "d"], ratings, low, high, [None, None, None, None], 0.95, pairs)
    assert 100 - z * 40 > 0 and 100 - z * 80 < 0 and 150 - z * 50 > 0 and 50 - z * 50 < 0
    order, ranks, tiers, _ = _ranks_and_tiers(fitted, [0, 1, 2, 3])
    assert ranks == {0: 1, 1: 2, 2: 2, 3: 3} and tiers == {0: 1, 1: 2, 2: 2, 3: 2} and order == [0, 1, 2, 3]
    m = fitted.margin(1, 2)
    assert m.over == "c" and m.elo == pytest.approx(100.0, abs=0.5) and not m.separated
    assert (m.low, m.high) == pytest.approx((100 - z * 80, 100 + z * 80), abs=2.0)
    # d flagged (a bound): only whole intervals count, and they all overlap d's: nobody is above it
    flagged = replace(fitted, flags=[None, None, None, FLAG_PERFECT])
    order, ranks, tiers, _ = _ranks_and_tiers(flagged, [0, 1, 2, 3])
    assert ranks == {0: 1, 1: 2, 2: 2, 3: 1} and tiers == {0: 1, 1: 1, 2: 1, 3: 1}
    assert order == [0, 3, 1, 2]  # by rank, then Elo: nobody is above d beyond doubt
    assert flagged.margin(1, 3).low == pytest.approx(low[1] - high[3])


def test_a_margin_between_two_players_is_their_pairs_not_their_ratings_difference() -> None:
    """Two players rated far apart through a third (each 100 games against it: 90-10 and 50-50) whose own 40 games
    are even: the margin, rank and tier follow their own games (a margin near 0, not separated, one rank), a
    prediction of their match says an even score, and the ladder, the forecaster and a prediction give the one
    figure. Without games of their own, three pairs cannot say whether the ratings hold for pairs that never met: the
    margin follows the ratings, with an interval wide enough to hold 0."""
    names = ["bot", "hi", "lo"]
    a = [1] * 100 + [2] * 100 + [1] * 40
    b = [0] * 100 + [0] * 100 + [2] * 40
    s = [1.0] * 90 + [0.0] * 10 + [1.0] * 50 + [0.0] * 50 + [1.0, 0.0] * 20
    rows = {r.policy: r for r in fit_table(names, a, b, s, anchor="bot", bootstrap=0)}
    hi, lo = rows["hi"], rows["lo"]
    assert hi.elo - lo.elo > 150.0  # what the ratings alone say
    assert hi.margin.over == "lo" and abs(hi.margin.elo) < 40.0 and not hi.margin.separated
    assert hi.rank == lo.rank and hi.tier == lo.tier
    f = Forecaster.of_games(names, a, b, s, anchor="bot")
    pred = f.predict("hi", "lo", 200)
    assert pred.low < 0.5 < pred.high and abs(pred.score - 0.5) < 0.05
    belief = f.belief("hi", "lo")
    assert belief.mean == pytest.approx(hi.margin.elo) and belief.interval() == pytest.approx(
        (hi.margin.low, hi.margin.high))  # one claim, one figure
    apart = Forecaster.of_games(names, a[:200], b[:200], s[:200], anchor="bot").belief("hi", "lo")
    assert apart.mean > 300.0 and apart.interval()[0] < 0.0 < apart.interval()[1]


def test_the_best_of_a_run_says_by_how_much_and_when_it_cannot_tell(league: League) -> None:
    p = _population(league)
    rnd, cpu, e10, e90, r2 = (p[k].id for k in ("random", "cpu", "ep10", "ep90", "r2ep90"))
    _record(league, _results(cpu, rnd, 30, 0, 10) + _results(e10, cpu, 30, 0, 10) + _results(e90, e10, 11, 0, 9)
            + _results(r2, e10, 40, 0, 0) + _results(r2, rnd, 40, 0, 0))
    by = _by_name(ladder(league, bootstrap=0))
    best = by["r1/ep90"]
    assert best.best and best.best_margin.over == "r1/ep10" and not best.best_margin.separated
    assert best.tied == ("r1/ep10",)  # 11-9: the run's best by Elo, not beyond doubt
    assert best.best_margin.record == (11, 0, 9) and "(head to head 11-0-9; " in best.best_margin.text()
    forecast = Forecaster.of_league(league, "pong")
    belief = forecast.belief("r1/ep90", "r1/ep10")  # the same claim, the same figure
    assert (best.best_margin.elo, best.best_margin.low, best.best_margin.high) == pytest.approx(
        (belief.mean, *belief.interval()))
    # what a 200-game match of the two would measure: `marl league predict`'s score range, in Elo
    pred = forecast.predict("r1/ep90", "r1/ep10", 200)
    low, high = best.best_margin.match
    assert (elo_to_score(low), elo_to_score(high)) == pytest.approx((pred.low, pred.high))
    assert low < best.best_margin.low and high > best.best_margin.high  # the match's luck on top
    assert f"200 games would measure {low:+.0f} to {high:+.0f})" in best.best_margin.text()
    assert by["r2/ep90"].best and by["r2/ep90"].best_margin is None and by["r2/ep90"].tied == ()
    _record(league, _results(e90, e10, 60, 0, 10))
    best = _by_name(ladder(league, bootstrap=0))["r1/ep90"]
    assert best.best_margin.separated and best.tied == () and best.best_margin.low > 0
    d = best.to_json()
    assert d["best_margin"]["over"] == "r1/ep10" and d["best_margin"]["separated"] is True and d["tied"] == []
    assert d["best_margin"]["head_to_head"] == [71, 0, 19]
    assert d["best_margin"]["match"]["games"] == 200 and d["best_margin"]["match"]["low"] < d["best_margin"]["low"]


def test_a_margin_says_what_a_200_game_match_would_measure() -> None:
    """Issue 48: a margin's interval is about the pair's expected difference; the 200-game match a user checks it
    with adds its own luck. Known exactly (no uncertainty, no spread) at an even pair, the match is 200 coin tosses:
    95% of them score 86 to 114 wins (binomial quantiles), 43% to 57%, -49 to +49 Elo."""
    from selfplay_cli.ratings.ladder_rows import Margin
    from selfplay_cli.stats.elo import score_to_elo
    from selfplay_cli.stats.predict import belief

    m = Margin("b", 0.0, 0.0, 0.0, (0, 0, 0), belief(0.0, 0.0))
    assert m.match == pytest.approx((score_to_elo(0.43), score_to_elo(0.57)))
    assert m.match[1] == pytest.approx(48.9, abs=0.1)
    assert "(they never met; 200 games would measure -49 to +49)" in m.text()
    sure = Margin("b", 1500.0, 1400.0, 1600.0, (0, 0, 0), belief(1500.0, 50.0))  # 200 of 200 is in the range
    assert sure.match[1] is None and "would measure +" in sure.text() and " or more)" in sure.text()
    assert Margin("b", 10.0, -5.0, 25.0).match is None and Margin("b", 10.0, -5.0, 25.0).to_json()["match"] is None


def test_bootstrap_is_seeded(tmp_path: Path) -> None:
    path = _csv_games(tmp_path, [("a", "b", 6, 2, 4), ("b", "c", 5, 1, 3), ("a", "c", 4, 0, 2)])
    one = fit_csv(path, bootstrap=60, seed=3)
    assert one == fit_csv(path, bootstrap=60, seed=3)
    assert [r.ci_low for r in one] != [r.ci_low for r in fit_csv(path, bootstrap=60, seed=4)]


def test_json_keys_and_no_nan_with_perfect_player(tmp_path: Path) -> None:
    path = _csv_games(tmp_path, [("ref", "mid", 3, 2, 3), ("ace", "ref", 5, 0, 0), ("ace", "mid", 4, 0, 0)])
    for boot, prior in ((0, 0.0), (40, 0.0), (0, 2.0), (40, 2.0)):
        rows = fit_csv(path, bootstrap=boot, prior=prior)
        ace = _by_name(rows)["ace"]
        assert ace.flag == (FLAG_PERFECT if prior == 0 else None) and ace.rank == 1 and rows[0] is ace
        for r in rows:
            d = r.to_json()
            assert list(d) == JSON_KEYS
            text = json.dumps(d, allow_nan=False)  # raises on NaN / inf
            assert json.loads(text) == d
            assert all(math.isfinite(d[k]) for k in ("elo", "ci_low", "ci_high", "score"))
            assert d["elo"] == round(r.elo, 1) and d["score"] == round(r.score, 4)
        assert _by_name(rows)["ref"].to_json()["anchor"] is True
        assert ace.to_json()["flag"] == ace.flag and ace.to_json()["step"] is None
        assert ace.to_json()["vs"] == {} and ace.to_json()["run"] is None and ace.to_json()["best"] is False


def test_fit_table_generic_and_errors() -> None:
    names = ["a", "b", "c"]
    a, b, s = np.array([0, 1, 0]), np.array([1, 2, 2]), np.array([1.0, 0.5, 0.0])
    rows = fit_table(names, a, b, s, anchor="b", bootstrap=0, kinds={"a": "bot", "b": "snapshot"},
                     steps={"b": 500}, player_ids={"a": 1, "b": 2})
    by = _by_name(rows)
    assert by["a"].kind == "bot" and by["a"].player_id == 1 and by["a"].step is None
    assert by["b"].kind == "snapshot" and by["b"].step == 500 and by["c"].kind == "player"
    fit = fit_bradley_terry(a, b, s, 3, anchor=1, prior_games=DEFAULT_PRIOR)
    for i, n in enumerate(names):
        assert by[n].elo == pytest.approx(fit.ratings[i])
        assert by[n].flag == fit.flags[i]
    with pytest.raises(LeagueError) as exc:
        fit_table(names, a, b, s, anchor="zed")
    msg = _one_line(exc)
    assert "zed" in msg and "a, b, c" in msg
    with pytest.raises(LeagueError):
        fit_table(names, a[:0], b[:0], s[:0], anchor="a")
    with pytest.raises(LeagueError):
        fit_table(names, a, b, s, anchor="a", confidence=1.5)


# --------------------------------------------------------------------------------------------------
# Results CSV parsing
# --------------------------------------------------------------------------------------------------


def test_read_results_csv(tmp_path: Path) -> None:
    path = _csv(tmp_path, ["# a comment", " player_a , player_b , result ", "", "x,y,1", "y, z ,0.5",
                           "# another", "z,x,0", '"w",x,1.0', "x,w,0.0", "w,y,1/2"])
    names, a, b, s = read_results_csv(path)
    assert names == ["x", "y", "z", "w"]
    assert a.tolist() == [0, 1, 2, 3, 0, 3] and b.tolist() == [1, 2, 0, 0, 3, 1]
    assert s.tolist() == [1.0, 0.5, 0.0, 1.0, 0.0, 0.5]
    assert a.dtype == np.int64 and s.dtype == np.float64


@pytest.mark.parametrize(
    ("lines", "line", "words"),
    [
        (["player_a,player_b,score", "x,y,1"], 1, "header"),
        (["player_a,player_b,result", "x,y,1", "x,y", "x,y,0"], 3, "3 fields"),
        (["player_a,player_b,result", "x,y,1", "y,x,0", "x,y,2"], 4, "bad result"),
        (["player_a,player_b,result", "x,y,1", "y,x,0", "x,y,win"], 4, "bad result"),
        (["player_a,player_b,result", "x,,1"], 2, "empty"),
        (["player_a,player_b,result", "x,y,1", "x,x,1"], 3, "itself"),
        (["# comment", "", "a,b,c"], 3, "header"),
        (["player_a,player_b,result", "x,y,1,extra"], 2, "3 fields"),
    ],
)
def test_csv_errors_name_the_line(tmp_path: Path, lines: list[str], line: int, words: str) -> None:
    path = _csv(tmp_path, lines)
    with pytest.raises(LeagueError) as exc:
        read_results_csv(path)
    msg = _one_line(exc)
    assert msg.startswith(f"{path}:{line}: ") and words in msg


def test_csv_empty_or_missing(tmp_path: Path) -> None:
    for lines in ([], ["# nothing"], ["player_a,player_b,result"], ["player_a,player_b,result", "", "# x"]):
        path = _csv(tmp_path, lines)
        with pytest.raises(LeagueError) as exc:
            fit_csv(path)
        assert str(path) in _one_line(exc)
    with pytest.raises(LeagueError) as exc:
        read_results_csv(tmp_path / "nope.csv")
    assert "nope.csv" in _one_line(exc)


# --------------------------------------------------------------------------------------------------
# The ladder of a league
# --------------------------------------------------------------------------------------------------


def _population(lg: League) -> dict[str, PlayerRow]:
    lg.roster.ensure_bots(ENV, ["random", "cpu"])
    lg.roster.create_run("r1", ENV, {})
    lg.roster.create_run("r2", ENV, {})
    bots = {p.name: p for p in lg.roster.players(ENV, kind="bot")}
    return {
        "random": bots["random"],
        "cpu": bots["cpu"],
        "ep10": _snap(lg, "r1", "ep10", step=1000),
        "ep90": _snap(lg, "r1", "ep90", step=9000),
        "r2ep90": _snap(lg, "r2", "ep90", step=9000),
    }


def test_ladder_from_the_ledger(league: League) -> None:
    p = _population(league)
    rnd, cpu, e10, e90, r2 = (p[k].id for k in ("random", "cpu", "ep10", "ep90", "r2ep90"))
    _record(league, _results(cpu, rnd, 7, 0, 3) + _results(e10, cpu, 7, 0, 3) + _results(e90, e10, 6, 2, 2)
            + _results(r2, e90, 3, 2, 5) + _results(r2, rnd, 8, 1, 1))
    rows = ladder(league, bootstrap=0)  # the only env
    assert rows == ladder(league, env=ENV, bootstrap=0)
    by = _by_name(rows)
    assert set(by) == {"random", "cpu", "r1/ep10", "r1/ep90", "r2/ep90"}  # no "r1/ep..." without games
    assert by["random"].anchor and by["random"].elo == 1000.0 and by["random"].kind == "bot"
    assert by["r1/ep90"].kind == "snapshot" and by["r1/ep90"].step == 9000 and by["r1/ep90"].player_id == e90
    assert by["cpu"].step is None
    # Same numbers as a direct fit of the ledger.
    table = league.ledger.games(env=ENV)
    ids, a, b = table.indexed()
    k = int(np.flatnonzero(ids == rnd)[0])
    fit = fit_bradley_terry(a, b, table.score_a, ids.size, anchor=k, prior_games=DEFAULT_PRIOR)
    for pid, r in zip(ids.tolist(), fit.ratings.tolist(), strict=True):
        assert next(x for x in rows if x.player_id == pid).elo == pytest.approx(r)
    # --prior 0: exactly the maximum-likelihood fit.
    ml = fit_bradley_terry(a, b, table.score_a, ids.size, anchor=k)
    ml_rows = ladder(league, bootstrap=0, prior=0)
    for pid, r in zip(ids.tolist(), ml.ratings.tolist(), strict=True):
        assert next(x for x in ml_rows if x.player_id == pid).elo == r
    assert [(r.rank, -r.elo) for r in rows] == sorted((r.rank, -r.elo) for r in rows)
    assert by["r1/ep90"].elo > by["r1/ep10"].elo > by["cpu"].elo > by["random"].elo
    # Another anchor: a full name, an id or a player row (what names.resolve gives the commands).
    other = _by_name(ladder(league, anchor="r1/ep10", anchor_rating=1200.0, bootstrap=0))
    assert other["r1/ep10"].elo == 1200.0 and other["r1/ep10"].anchor
    assert other["random"].elo == pytest.approx(by["random"].elo + 1200.0 - by["r1/ep10"].elo)
    assert _by_name(ladder(league, anchor=e10, anchor_rating=1200.0, bootstrap=0)) == other
    assert _by_name(ladder(league, anchor=f"#{e10}", anchor_rating=1200.0, bootstrap=0)) == other
    assert _by_name(ladder(league, anchor=resolve(league, "ep10"), anchor_rating=1200.0, bootstrap=0)) == other
    with pytest.raises(LeagueError) as exc:
        ladder(league, anchor="nobody", bootstrap=0)
    assert "anchor 'nobody' has no games in pong" in _one_line(exc)
    # Bootstrap intervals contain the estimates; anchor interval is a point.
    boot = _by_name(ladder(league, bootstrap=30))
    assert all(r.ci_low <= r.elo <= r.ci_high for r in boot.values())
    assert boot["random"].ci_low == boot["random"].ci_high == 1000.0


def test_ladder_removed_snapshots_still_count(league: League) -> None:
    p = _population(league)
    rnd, cpu, e10 = p["random"].id, p["cpu"].id, p["ep10"].id
    _record(league, _results(cpu, rnd, 6, 0, 4) + _results(e10, cpu, 5, 0, 5) + _results(e10, rnd, 2, 0, 8))
    before = _by_name(ladder(league, bootstrap=0))
    league.roster.remove_snapshot(e10)
    after = _by_name(ladder(league, bootstrap=0))
    assert set(after) == {"random", "cpu"}
    assert after["cpu"].elo == pytest.approx(before["cpu"].elo)  # e10's games are still in the fit
    shown = _by_name(ladder(league, bootstrap=0, include_removed=True))
    assert set(shown) == {"random", "cpu", "r1/ep10"}
    assert before["r1/ep10"].best and not shown["r1/ep10"].best  # a removed snapshot is nobody's best
    unmarked = {k: replace(r, best=False) for k, r in shown.items()}
    assert unmarked == {k: replace(r, best=False) for k, r in before.items()}


def test_ladder_env_choice_and_default_anchor(league: League) -> None:
    assert ladder(league, env=ENV) == []
    with pytest.raises(LeagueError):
        ladder(league)  # no games at all
    # No random bot: the first bot with games anchors; no bots at all: the most active player.
    league.roster.ensure_bots(ENV, ["cpu"])
    cpu = league.roster.players(ENV, kind="bot")[0]
    s1, s2 = _snap(league, None, "a"), _snap(league, None, "b")
    _snap(league, None, "c")  # no games
    _record(league, _results(s1.id, cpu.id, 3, 0, 1) + _results(s1.id, s2.id, 2, 0, 2))
    assert _by_name(ladder(league, bootstrap=0))["cpu"].anchor
    other = "othergame"  # a second two-seat game (not registered: the ledger keeps games of any name)
    t1, t2 = _snap(league, None, "t1", env=other), _snap(league, None, "t2", env=other)
    _snap(league, None, "t3", env=other)
    _record(league, _results(t1.id, t2.id, 2, 1, 1), env=other)
    with pytest.raises(LeagueError) as exc:
        ladder(league)
    assert "several envs in the league (pong, othergame): pass --env" in _one_line(exc)
    rows = ladder(league, env=other, bootstrap=0)
    assert {r.policy for r in rows} == {"t1", "t2"}  # t3 has no games
    assert _by_name(rows)["t1"].anchor  # tie on games: lowest id
    assert not any(r.policy == "c" for r in ladder(league, env=ENV, bootstrap=0))


# --------------------------------------------------------------------------------------------------
# names.resolve
# --------------------------------------------------------------------------------------------------


def test_resolve_names(league: League) -> None:
    p = _population(league)
    rnd, cpu, e10, e90, r2 = (p[k].id for k in ("random", "cpu", "ep10", "ep90", "r2ep90"))
    league.roster.tag(e10, "champ")
    _record(league, _results(cpu, rnd, 6, 0, 4) + _results(e10, cpu, 8, 0, 2) + _results(e90, e10, 3, 0, 7)
            + _results(r2, rnd, 7, 1, 2))
    assert resolve(league, "ep10").id == e10
    assert resolve(league, "r1/ep90").id == e90
    assert resolve(league, "r2/ep90", env=ENV).id == r2
    assert resolve(league, "champ").id == e10
    assert resolve(league, str(e90)).id == e90 and resolve(league, f"#{e90}").id == e90
    assert resolve(league, "random").id == rnd and resolve(league, " cpu ").id == cpu
    assert resolve(league, "latest").id == r2 and resolve(league, "latest", env=ENV).id == r2
    assert resolve(league, "best", env=ENV).id == e10  # r1/ep10 beats cpu 8-2, r1/ep90 only 7-3
    assert [x.id for x in resolve_many(league, ["best", "ep10", "random", "best"], ENV)] == [e10, e10, rnd, e10]
    # A custom ladder function decides "best".
    fake = [LadderRow("cpu", cpu, "bot", None, 3000.0, 2900.0, 3100.0, 1, 1, 0, 0, 1.0, 1, None, False)]
    assert resolve(league, "best", ladder_fn=lambda lg, env: fake).id == cpu

    with pytest.raises(LeagueError) as exc:
        resolve(league, "ep90")
    assert _one_line(exc) == "'ep90' is ambiguous: r1/ep90, r2/ep90 — use run/name or an id"

    with pytest.raises(LeagueError) as exc:
        resolve(league, "ep91", env=ENV)
    msg = _one_line(exc)
    assert msg.startswith("no policy named 'ep91' in pong; closest: ")  # closest first, then the newest
    closest = msg.split("closest: ", 1)[1].split(";")[0].split(", ")
    assert closest[0] in ("ep90", "ep10") and "r1/ep90" in closest and len(closest) <= 5
    assert "random" in msg and "..." not in msg
    with pytest.raises(LeagueError) as exc:
        resolve(league, "nothing")
    assert "in the league; " in _one_line(exc) and "newest: r2/ep90" in _one_line(exc)
    for bad in ("r3/ep90", "r1/ep11", "999", "#999", ""):
        with pytest.raises(LeagueError):
            resolve(league, bad)
    with pytest.raises(LeagueError) as exc:
        resolve(league, str(e10), env="lander")
    assert "belongs to env pong" in _one_line(exc)

    # Removed snapshots: named -> error saying so; the other ep90 becomes unambiguous; ids need include_removed.
    league.roster.remove_snapshot(r2)
    assert resolve(league, "ep90").id == e90
    assert resolve(league, "latest").id == e90
    with pytest.raises(LeagueError) as exc:
        resolve(league, "r2/ep90")
    assert "removed" in _one_line(exc) and "r2/ep90" in str(exc.value)
    with pytest.raises(LeagueError) as exc:
        resolve(league, str(r2))
    assert "removed" in _one_line(exc)
    assert resolve(league, str(r2), include_removed=True).removed
    assert resolve(league, "r2/ep90", include_removed=True).id == r2
    assert resolve(league, "best").id == e10


def test_resolve_tag_and_bot_ambiguous_across_envs(league: League) -> None:
    league.roster.ensure_bots(ENV, ["cpu"])
    league.roster.create_run("r3", "lander", {})
    snap = _snap(league, "r3", "x", env="lander")
    league.roster.tag(snap.id, "cpu")  # allowed: lander has no cpu bot
    with pytest.raises(LeagueError) as exc:
        resolve(league, "cpu")
    assert _one_line(exc) == "'cpu' is ambiguous: cpu, r3/x — use run/name or an id"
    assert resolve(league, "cpu", env=ENV).kind == "bot"
    assert resolve(league, "cpu", env="lander").id == snap.id
    with pytest.raises(LeagueError) as exc:
        resolve(league, "latest", env=ENV)
    assert "no snapshot" in _one_line(exc)
    with pytest.raises(LeagueError) as exc:
        resolve(league, "best", env=ENV)
    assert "no rated policy" in _one_line(exc)


# --------------------------------------------------------------------------------------------------
# Tournament plans and head-to-head
# --------------------------------------------------------------------------------------------------


def test_plan_tournament_counts_existing_games(league: League) -> None:
    league.roster.ensure_bots(ENV, ["random", "cpu"])
    bots = {p.name: p.id for p in league.roster.players(ENV, kind="bot")}
    p1, p2, p3, p4 = bots["random"], bots["cpu"], _snap(league, None, "a").id, _snap(league, None, "b").id
    m = league.ledger.create_match(ENV, "tournament")
    league.ledger.record_games(m, [_game(p1, p2, 1.0), _game(p1, p2, 0.0), _game(p2, p1, 0.5)]  # 3 games, both orders
                               + [_game(p3, p1, 1.0, seed=s) for s in range(5)]
                               + [_game(p4, p2, 1.0)] * 2)  # p4 is not in the tournament
    plan = plan_tournament(league, ENV, [p1, p2, p3], games_per_pair=4)
    assert plan == [PairPlan(p1, p2, 3, 1), PairPlan(p2, p3, 0, 4)]  # p1-p3 already has 5
    assert plan_tournament(league, ENV, [p1, p2, p3], games_per_pair=2) == [PairPlan(p2, p3, 0, 2)]
    # Gauntlet: every player against vs only.
    plan = plan_tournament(league, ENV, [p1, p2, p4], games_per_pair=4, vs=p3)
    assert plan == [PairPlan(p2, p3, 0, 4), PairPlan(p4, p3, 0, 4)]
    assert plan_tournament(league, ENV, [p1, p3], games_per_pair=6, vs=p2) == [PairPlan(p1, p2, 3, 3),
                                                                               PairPlan(p3, p2, 0, 6)]
    with pytest.raises(LeagueError):
        plan_tournament(league, ENV, [p1], games_per_pair=2)
    with pytest.raises(LeagueError):
        plan_tournament(league, "lander", [p1, p2], games_per_pair=2)
    with pytest.raises(LeagueError):
        plan_tournament(league, ENV, [p1, 999], games_per_pair=2)


def test_head_to_head_pentanomial(league: League) -> None:
    league.roster.ensure_bots(ENV, ["random", "cpu"])
    bots = {p.name: p.id for p in league.roster.players(ENV, kind="bot")}
    a, b, c = bots["cpu"], bots["random"], _snap(league, None, "other").id

    def pair(seed: int, first: float, second: float) -> list[GameResult]:
        """Two games of one seed: a in seat 0 scoring ``first``, then a in seat 1 scoring ``second``."""
        return [_game(a, b, first, seed), _game(b, a, 1.0 - second, seed)]

    m1, m2 = league.ledger.create_match(ENV, "match"), league.ledger.create_match(ENV, "match")
    games = (pair(1, 1.0, 1.0)  # WW
             + pair(2, 1.0, 0.0)  # WL
             + pair(3, 0.5, 0.5)  # DD
             + pair(4, 0.0, 0.5)  # LD
             + pair(5, 0.0, 0.0)  # LL
             + pair(8, 1.0, 0.5)  # WD
             + [_game(a, b, 1.0, 6)]  # unpaired: no reversed game
             + [_game(a, b, 1.0, 7), _game(a, b, 0.5, 7)]  # same seed, same seat order: unpaired
             + [_game(a, c, 1.0, 9), _game(c, a, 1.0, 9)])  # another opponent: ignored
    league.ledger.record_games(m1, games)
    league.ledger.record_games(m2, [_game(b, a, 1.0, 1)])  # seed 1 again, but another match: unpaired
    h = head_to_head(league, a, b)
    assert h["pentanomial"] == [1, 1, 2, 1, 1]  # LL, LD, WL+DD, WD, WW
    assert h["pairs"] == 6 and h["unpaired"] == 4 and h["games"] == 16
    assert (h["wins"], h["draws"], h["losses"]) == (6, 5, 5)
    assert h["score"] == pytest.approx(8.5 / 16.0)
    assert (h["wins"], h["draws"], h["losses"]) == league.ledger.pair_counts(a, b)
    mirror = head_to_head(league, b, a)
    assert mirror["pentanomial"] == h["pentanomial"][::-1]
    assert (mirror["wins"], mirror["losses"]) == (h["losses"], h["wins"])
    # Feeds the statistics helpers.
    assert match_stats(h["wins"], h["draws"], h["losses"], pentanomial=tuple(h["pentanomial"])).used_pentanomial
    assert math.isfinite(sprt_llr(h["pentanomial"], 0.0, 10.0))
    with pytest.raises(LeagueError):
        head_to_head(league, a, a)


def test_flagged_players_have_open_intervals_whatever_the_interval_method(tmp_path):
    """Maximum likelihood: a perfect score has no upper limit and an unconnected player no limit at all."""
    # c beats a and b every time; a and b never met: a is the anchor, c is perfect, b is disconnected from a.
    names = ["a", "b", "c"]
    a = np.array([2] * 10 + [2] * 10)
    b = np.array([0] * 10 + [1] * 10)
    s = np.ones(20)
    for boot in (0, 50):
        rows = {r.policy: r for r in fit_table(names, a, b, s, anchor="a", bootstrap=boot, prior=0)}
        assert rows["c"].flag == "perfect" and rows["c"].ci_high - rows["c"].elo >= 2000, boot
        assert rows["b"].flag is not None
        assert rows["b"].ci_low < 0 and rows["b"].ci_high > 2000, boot
        assert rows["a"].ci_low == rows["a"].ci_high == 1000.0
        assert rows["b"].rank == 3 and rows["b"].tier is None, "b's offset is unknown: last, in no tier"


def test_prior_makes_the_same_ledger_finite_and_honest(tmp_path):
    """The same ledger under the default prior: c's MAP is finite and unflagged; b, linked to a only through c,
    gets a prior-determined rating (a and b have the same record, so the same rating) and a wide interval."""
    names = ["a", "b", "c"]
    a = np.array([2] * 20)
    b = np.array([0] * 10 + [1] * 10)
    s = np.ones(20)
    for boot in (0, 50):
        rows = {r.policy: r for r in fit_table(names, a, b, s, anchor="a", bootstrap=boot)}
        assert [rows[n].flag for n in names] == [None, None, None]
        assert rows["b"].elo == pytest.approx(1000.0, abs=1e-6)  # symmetric with the anchor
        assert rows["c"].elo > 1000.0 + 300
        assert rows["c"].ci_low > 1000.0 and rows["c"].tier == 1  # c beat both 10-0: above them beyond doubt
        assert rows["a"].tier == rows["b"].tier == 2 and rows["a"].rank == rows["b"].rank == 2  # never met
        # b's interval carries two links (b-c and c-a), so it is wider than c's (one link)
        assert rows["b"].ci_high - rows["b"].ci_low > rows["c"].ci_high - rows["c"].ci_low > 400


def test_perfectly_separated_ledger_under_the_prior(league: League) -> None:
    """cpu beats random, ep90 beats cpu and random, ep10 loses to everybody but random: all 100 %, 16 games a
    pair. Prior 0: perfect / zero flags and shared ranks; the default prior: finite, unflagged, distinct ratings
    in the order of the results and ranks that separate each step of the chain."""
    p = _population(league)
    rnd, cpu, e10, e90 = (p[k].id for k in ("random", "cpu", "ep10", "ep90"))
    chain = [e90, cpu, e10, rnd]  # strongest first: each beats every later one, every game
    results = []
    for i, x in enumerate(chain):
        for y in chain[i + 1:]:
            results += _results(x, y, 16, 0, 0)
    _record(league, results)
    ml = _by_name(ladder(league, bootstrap=0, prior=0))
    assert ml["r1/ep90"].flag == FLAG_PERFECT and ml["random"].flag is None  # the anchor's group: random alone
    assert ml["cpu"].flag == FLAG_PERFECT and ml["r1/ep10"].flag == FLAG_PERFECT
    for boot in (0, 60):
        rows = ladder(league, bootstrap=boot)
        assert [r.policy for r in rows] == ["r1/ep90", "cpu", "r1/ep10", "random"]
        assert all(r.flag is None for r in rows)
        elos = [r.elo for r in rows]
        assert all(math.isfinite(e) for e in elos) and elos == sorted(elos, reverse=True) and len(set(elos)) == 4
        assert [r.tier for r in rows] == [1, 2, 3, 4], [(r.policy, r.elo, r.ci_low, r.ci_high) for r in rows]
        assert [r.rank for r in rows] == [1, 2, 3, 4]
        for r in rows:
            assert r.ci_low <= r.elo <= r.ci_high
            if not r.anchor:
                assert r.ci_high - r.ci_low > 300  # never a made-up precision for all-wins records


# --------------------------------------------------------------------------------------------------
# run, best, scripted-player records, row selection
# --------------------------------------------------------------------------------------------------


def test_ladder_rows_carry_run_best_and_bot_records(league: League) -> None:
    p = _population(league)
    rnd, cpu, e10, e90, r2 = (p[k].id for k in ("random", "cpu", "ep10", "ep90", "r2ep90"))
    _record(league, _results(cpu, rnd, 7, 0, 3) + _results(e10, cpu, 6, 2, 2) + _results(e90, e10, 6, 2, 2)
            + _results(e90, cpu, 5, 1, 2) + _results(r2, e90, 3, 2, 5) + _results(r2, rnd, 8, 1, 1))
    rows = ladder(league, bootstrap=0)
    by = _by_name(rows)
    assert by["r1/ep10"].run == by["r1/ep90"].run == "r1" and by["r2/ep90"].run == "r2" and by["cpu"].run is None
    # Best of each run: the higher-rated snapshot of r1, the only one of r2; never a bot.
    assert by["r1/ep90"].elo > by["r1/ep10"].elo
    assert {r.policy for r in rows if r.best} == {"r1/ep90", "r2/ep90"}
    # Records against the bots, counted from the ledger by hand.
    vs = {name: {v.bot: (v.games, v.points) for v in by[name].vs} for name in by}
    assert [v.bot for v in by["cpu"].vs] == ["random", "cpu"]  # the env's bots, in league order
    assert vs["r1/ep10"] == {"random": (0, 0.0), "cpu": (10, 7.0)}  # 6 wins + 2 draws
    assert vs["r1/ep90"]["cpu"] == (8, 5.5) and vs["r2/ep90"]["random"] == (10, 8.5)
    assert vs["cpu"] == {"random": (10, 7.0), "cpu": (0, 0.0)}
    assert vs["random"]["cpu"] == (10, 3.0)
    d = by["r1/ep10"].to_json()
    assert list(d) == JSON_KEYS
    assert d["vs"] == {"random": {"score": None, "games": 0}, "cpu": {"score": 0.7, "games": 10}}
    assert d["run"] == "r1" and d["best"] is False and by["r1/ep90"].to_json()["best"] is True
    json.dumps([r.to_json() for r in rows], allow_nan=False)


def test_select_rows_keeps_ranks(league: League) -> None:
    p = _population(league)
    rnd, cpu, e10, e90, r2 = (p[k].id for k in ("random", "cpu", "ep10", "ep90", "r2ep90"))
    _record(league, _results(cpu, rnd, 9, 0, 1) + _results(e10, cpu, 9, 0, 1) + _results(e90, e10, 8, 0, 2)
            + _results(r2, e90, 9, 0, 1) + _results(r2, rnd, 10, 0, 0))
    rows = ladder(league, bootstrap=0)
    ranks = {r.policy: r.rank for r in rows}
    only_r1 = select_rows(rows, run="r1")
    assert [r.policy for r in only_r1] == [r.policy for r in rows if r.policy.startswith("r1/") or r.kind == "bot"]
    assert {r.policy for r in only_r1} == {"r1/ep10", "r1/ep90", "cpu", "random"}
    assert all(r.rank == ranks[r.policy] for r in only_r1)
    assert any(r.rank > 1 for r in only_r1) and min(r.rank for r in only_r1) >= 1
    assert select_rows(rows, top=2) == rows[:2]
    assert select_rows(rows, run="r1", top=1) == only_r1[:1]
    assert select_rows(rows, run="nope") == [r for r in rows if r.kind == "bot"]
    assert select_rows(rows) == rows
    with pytest.raises(LeagueError):
        select_rows(rows, top=0)


def test_removed_snapshots_leave_the_ranks(tmp_path: Path) -> None:
    """fit_table's hidden players are fitted but neither shown nor counted in anybody's rank."""
    path = _csv_games(tmp_path, [("top", "mid", 40, 0, 0), ("mid", "low", 40, 0, 0), ("top", "low", 40, 0, 0)])
    names, a, b, s = read_results_csv(path)
    full = _by_name(fit_table(names, a, b, s, anchor="low", bootstrap=0))
    assert [full[n].rank for n in ("top", "mid", "low")] == [1, 2, 3]
    part = _by_name(fit_table(names, a, b, s, anchor="low", bootstrap=0, hidden={"top"}))
    assert set(part) == {"mid", "low"} and part["mid"].rank == 1 and part["low"].rank == 2
    assert part["mid"].elo == full["mid"].elo  # top's games still count in the fit


# --------------------------------------------------------------------------------------------------
# one set of weights, one player
# --------------------------------------------------------------------------------------------------


def test_the_same_weights_under_two_names_are_one_player(league: League) -> None:
    """A run repeated with its seed in the same league makes bit-identical snapshots under new names: one player,
    whose games under either name count for one rating; the other name gets its row right under it, with that
    rating and place; head-to-head and tournaments see one player."""
    league.roster.ensure_bots(ENV, ["random", "cpu"])
    league.roster.create_run("r1", ENV, {})
    league.roster.create_run("r2", ENV, {})
    rnd, cpu = (league.roster.find_players(n, ENV)[0].id for n in ("random", "cpu"))
    first = league.roster.add_snapshot(env=ENV, run="r1", name="s6M", path="r1/s6M", sha256="1" * 64,
                                       meta={"weights_sha256": "f" * 64})
    copy = league.roster.add_snapshot(env=ENV, run="r2", name="s6M", path="r2/s6M", sha256="2" * 64,
                                      meta={"weights_sha256": "f" * 64})
    other = league.roster.add_snapshot(env=ENV, run="r2", name="s5M", path="r2/s5M", sha256="3" * 64,
                                       meta={"weights_sha256": "e" * 64})
    _record(league, _results(cpu, rnd, 7, 0, 3) + _results(first.id, cpu, 6, 0, 4) + _results(copy.id, cpu, 8, 0, 2)
            + _results(other.id, copy.id, 3, 0, 7))
    assert league.ledger.same_weights(ENV) == {copy.id: first.id}
    rows = ladder(league, bootstrap=0)
    by = _by_name(rows)
    one, two = by["r1/s6M"], by["r2/s6M"]
    assert one.copies == ("r2/s6M",) and two.copy_of == "r1/s6M" and one.copy_of is None
    assert (two.elo, two.rank, two.tier, two.games) == (one.elo, one.rank, one.tier, one.games)
    assert one.games == 30 and (one.wins, one.losses) == (21, 9)  # 6-4 and 8-2 against cpu, 7-3 against r2/s5M
    assert rows.index(two) == rows.index(one) + 1
    # the rating is the fit of every game filed under the first name
    table = league.ledger.games(ENV)
    assert copy.id not in set(table.player_a.tolist()) | set(table.player_b.tolist())
    assert len(league.ledger.games(ENV, pooled=False)) == len(table)
    h = head_to_head(league, copy.id, cpu)
    assert (h["games"], h["wins"], h["losses"]) == (20, 14, 6) == (head_to_head(league, first.id, cpu)["games"],
                                                                    14, 6)
    with pytest.raises(LeagueError, match="hold the same weights"):
        head_to_head(league, first.id, copy.id)
    # a tournament of both names and cpu: one pair to fill, counted from both names' games
    plan = plan_tournament(league, ENV, [first.id, copy.id, cpu], 24)
    assert [(p.existing, p.missing) for p in plan] == [(20, 4)]
    # the run of the copy has its best, the first name's rating, over its next
    assert two.best and two.best_margin.over == "r2/s5M"
    assert "copy_of" in two.to_json() and two.to_json()["copy_of"] == "r1/s6M"


def test_the_best_of_a_run_is_not_compared_with_its_own_weights_nor_its_teammates(league: League) -> None:
    """A run whose final snapshot holds the weights of an earlier one (training left them unchanged): the best's
    margin is over the run's next *other* player, not "+0 ... (they never met)" over its own copy. A cooperative
    game's team of per-seat snapshots flies as one: the best member's margin is over another moment's team, not
    over its own teammate."""
    league.roster.ensure_bots(ENV, ["random", "cpu"])
    league.roster.create_run("k", ENV, {})
    rnd, cpu = (league.roster.find_players(n, ENV)[0].id for n in ("random", "cpu"))
    early = league.roster.add_snapshot(env=ENV, run="k", name="s50k", path="k/s50k", sha256="1" * 64, step=50_000,
                                       meta={"weights_sha256": "f" * 64})
    same = league.roster.add_snapshot(env=ENV, run="k", name="s100k", path="k/s100k", sha256="2" * 64, step=100_000,
                                      meta={"weights_sha256": "f" * 64})
    first = league.roster.add_snapshot(env=ENV, run="k", name="s0", path="k/s0", sha256="3" * 64, step=0,
                                       meta={"weights_sha256": "e" * 64})
    _record(league, _results(cpu, rnd, 7, 0, 3) + _results(early.id, cpu, 8, 0, 2)
            + _results(same.id, first.id, 9, 0, 1) + _results(first.id, rnd, 5, 0, 5))
    by = _by_name(ladder(league, bootstrap=0))
    best = next(r for r in by.values() if r.best and r.run == "k")
    assert best.policy == "k/s50k" and by["k/s100k"].copy_of == "k/s50k"
    assert best.best_margin.over == "k/s0" and best.best_margin.record == (9, 0, 1) and "k/s100k" not in best.tied


def test_a_cooperative_teams_best_member_is_not_compared_with_its_teammate() -> None:
    """Each moment of a NoPS lander run is a team of two per-seat snapshots whose comparisons count for both: the
    best member's margin is over the other moment's team, never over its own teammate."""
    names = ["heuristic", "l/s1-lander_0", "l/s1-lander_1", "l/s2-lander_0", "l/s2-lander_1"]
    a, b, s = [], [], []
    for x, y, wins, losses in ((3, 0, 8, 2), (4, 0, 8, 2), (1, 0, 3, 7), (2, 0, 3, 7), (3, 1, 9, 1), (4, 2, 9, 1)):
        a += [x] * (wins + losses)
        b += [y] * (wins + losses)
        s += [1.0] * wins + [0.0] * losses
    rows, fitted = fit_rows(names, a, b, s, "heuristic", 1000.0, 0, 0.95, 0, None, None, None, prior=DEFAULT_PRIOR,
                            hidden=())
    rows = [replace(r, kind="snapshot", run="l", step=int(r.policy[3])) if r.policy.startswith("l/") else r
            for r in rows]
    best = next(r for r in _mark_best(rows, set(), fitted, teams=True) if r.best)
    assert best.step == 2 and best.best_margin.over.startswith("l/s1-") and "l/s2-lander_1" not in best.tied
    alone = next(r for r in _mark_best(rows, set(), fitted, teams=False) if r.best)  # (a two-sides game's seats)
    assert alone.best_margin.over.startswith("l/s2-")


def test_a_circle_of_claims_is_said_and_no_claim_across_it_is_broken() -> None:
    """Rock, paper and scissors as snapshots, each winning 36-4 against the next, all 20-20 with a bot: each above
    the next beyond doubt, so no order keeps all three claims. They stand together by rank and Elo, each row carries a
    shortest circle through it, and the verdict under the table says the circle."""
    names = ["bot", "rock", "paper", "scissors"]
    a, b, s = [], [], []
    for x, y in ((2, 1), (3, 2), (1, 3)):  # paper beats rock, scissors paper, rock scissors
        a += [x] * 40
        b += [y] * 40
        s += [1.0] * 36 + [0.0] * 4
    for x in (1, 2, 3):
        a += [x] * 40
        b += [0] * 40
        s += [1.0, 0.0] * 20
    rows = {r.policy: r for r in fit_table(names, a, b, s, anchor="bot", bootstrap=0)}
    for name in ("rock", "paper", "scissors"):
        c = rows[name].circle
        assert c[0] == name and set(c) == {"rock", "paper", "scissors"} and len(c) == 3
        assert rows[name].rank == 2  # one of the circle is above it beyond doubt
    assert rows["paper"].circle == ("paper", "rock", "scissors")  # paper above rock above scissors above paper
    table = fit_table(names, a, b, s, anchor="bot", bootstrap=0)
    lines = verdict_lines(table)
    circle = [line for line in lines if line.startswith("a circle beyond doubt: ")]
    assert len(circle) == 1 and circle[0].count(" above ") == 3, lines
