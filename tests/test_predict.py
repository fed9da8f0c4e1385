"""What a ladder predicts of a match not yet played: the score interval by hand, the spread of pairs around their
ratings measured from simulated ledgers, a pair's own games taking over from the ratings, and the coverage of the
predicted intervals on a simulated league (the check benchmarks/ladder_truth.py makes on real runs)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from selfplay_cli.league.forecast import Forecaster
from selfplay_cli.league.store import LeagueError
from selfplay_cli.stats.predict import pair_spread, predict_pair


def _expected(d):
    return 1.0 / (1.0 + 10.0 ** (-np.asarray(d) / 400.0))


def test_a_sure_difference_predicts_the_binomial_interval_of_its_score():
    """No uncertainty in the difference: the score of n games is Binomial(n, E(d)) / n; its central 95% interval
    by scipy's quantiles."""
    for diff, n in ((0.0, 200), (191.0, 200), (-400.0, 50)):
        p = float(_expected(diff))
        pred = predict_pair(diff, 0.0, n)
        assert pred.score == pytest.approx(p)
        assert (pred.low, pred.high) == (binom.ppf(0.025, n, p) / n, binom.ppf(0.975, n, p) / n)
    assert (predict_pair(0.0, 0.0, 200).low, predict_pair(0.0, 0.0, 200).high) == (0.43, 0.57)


def test_uncertain_ratings_and_a_spread_widen_the_interval_and_met_games_narrow_it():
    base = predict_pair(100.0, 0.0, 200)
    wide = predict_pair(100.0, 80.0, 200)
    wider = predict_pair(100.0, 80.0, 200, spread=120.0)
    assert base.high - base.low < wide.high - wide.low < wider.high - wider.low
    # 1,000 games between the two at 70% where pairs scatter around their ratings: the prediction follows them,
    # whatever the ratings said (50%)
    met = predict_pair(0.0, 10.0, 200, spread=100.0, met_points=700.0, met_games=1000.0)
    assert met.score == pytest.approx(0.70, abs=0.01) and met.low > 0.6 and met.high < 0.8
    # without spread the ratings are the whole model: the pair's games are already in them (its sd), not again
    assert predict_pair(0.0, 0.0, 200, met_points=700.0, met_games=1000.0).score == pytest.approx(0.5)
    with pytest.raises(ValueError):
        predict_pair(0.0, -1.0, 200)


def _pairs(rng, n_pairs, games, tau):
    d = rng.uniform(-400, 400, n_pairs)
    true = d + rng.normal(0.0, tau, n_pairs) if tau else d
    points = rng.binomial(games, _expected(true)).astype(float)
    return points, np.full(n_pairs, float(games)), d


def test_the_spread_of_pairs_is_measured_from_their_records():
    rng = np.random.default_rng(5)
    assert pair_spread(*_pairs(rng, 400, 50, 0.0)) < 40.0  # pairs as their ratings say: no spread to speak of
    tau = pair_spread(*_pairs(rng, 400, 50, 150.0))
    assert 110.0 < tau < 190.0, tau
    # a 0-8 far below: no evidence against the ratings (moment estimates on logits blow up there)
    assert pair_spread([0.0] * 50, [8.0] * 50, [-1500.0] * 50) == 0.0
    assert pair_spread([], [], []) == 0.0


def _simulated_league(rng, n_players=12, games=8):
    """A run-like population: ratings rising with the step, each player against its two predecessors and the
    anchor, ``games`` games a pair; returns the names, the games and the true ratings."""
    true = np.concatenate([[0.0], np.cumsum(rng.uniform(40, 160, n_players - 1))]) + 1000.0
    a, b, s = [], [], []
    for i in range(1, n_players):
        for j in {max(i - 1, 0), max(i - 2, 0), 0}:
            outcome = rng.random(games) < _expected(true[i] - true[j])
            a += [i] * games
            b += [j] * games
            s += outcome.astype(float).tolist()
    return [f"p{i}" for i in range(n_players)], np.array(a), np.array(b), np.array(s), true


def test_predicted_intervals_hold_their_coverage_on_a_simulated_league():
    """Leagues drawn from the model itself: 95% intervals of 200-game scores must hold for at least 90% of the
    pairs (their nominal 95%, less the pairs' own sampling noise in this test: 330 pairs)."""
    rng = np.random.default_rng(11)
    held = total = 0
    for _ in range(5):
        names, a, b, s, true = _simulated_league(rng)
        f = Forecaster.of_games(names, a, b, s, anchor="p0")
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                pred = f.predict(names[i], names[j], 200)
                score = rng.binomial(200, _expected(true[i] - true[j])) / 200
                held += pred.holds(score)
                total += 1
    assert total == 330 and held / total >= 0.90, held / total


def test_a_player_without_games_is_one_line():
    names, a, b, s, _ = _simulated_league(np.random.default_rng(0), 4)
    f = Forecaster.of_games(names + ["ghost"], a, b, s, anchor="p0")
    with pytest.raises(LeagueError, match="ghost's rating is not linked"):
        f.predict("p1", "ghost", 200)
    with pytest.raises(LeagueError, match="nobody has no rated games"):
        f.predict("nobody", "p1", 200)


def test_marl_league_predict_and_marl_match_say_what_the_ladder_expects(tmp_path, capsys):
    """`marl league predict` prints the forecaster's prediction (JSON: the same numbers); `marl match` reports the
    prediction made before its games and whether the games bore it out; an empty league is one line, exit 2."""
    from cli_helpers import run, run_json

    from selfplay_cli.league.store import League
    from selfplay_cli.results import GameResult

    home = str(tmp_path / "league")
    code, out, err = run(capsys, "league", "predict", "cpu", "random", "--env", "pong", "--home", home)
    assert code == 2 and err.count("\n") == 1 and "no rated games" in err
    with League.open(home) as league:
        league.ensure_bots("pong", ["random", "cpu"])
        rnd, cpu = (league.find_players(n, "pong")[0].id for n in ("random", "cpu"))
        mid = league.create_match("pong", "match")
        league.record_games(mid, [GameResult("pong", (cpu, rnd) if i % 2 else (rnd, cpu), seed=i,
                                             scores=(21, 3) if i % 2 else (3, 21),
                                             outcome=(1.0, 0.0) if i % 2 else (0.0, 1.0), length=100,
                                             truncated=False) for i in range(20)])
        expect = Forecaster.of_league(league, "pong").predict("cpu", "random", 50)
    data = run_json(capsys, "league", "predict", "cpu", "random", "--env", "pong", "--games", "50", "--home", home)
    assert (data["score"], data["low"], data["high"]) == (round(expect.score, 4), round(expect.low, 4),
                                                          round(expect.high, 4))
    assert data["met"] == 20 and data["met_score"] == 1.0 and data["low"] > 0.5
    report = run_json(capsys, "match", "cpu", "random", "--env", "pong", "--games", "40", "--home", home)
    assert report["predicted"]["games"] == 40 and report["predicted"]["held"] == (
        report["predicted"]["low"] <= report["score"] <= report["predicted"]["high"])
    assert report["first_seed"] == 20  # after the 20 stored games' seeds: none of them played again
