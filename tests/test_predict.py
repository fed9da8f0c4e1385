"""What a ladder predicts of a match not yet played: the score interval by hand, the spread of pairs around their
ratings measured from simulated ledgers, a pair's own games taking over from the ratings, and the coverage of the
predicted intervals on a simulated league (the check benchmarks/ladder_truth.py makes on real runs)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from selfplay_cli.league.store import LeagueError
from selfplay_cli.ratings.forecast import Forecaster
from selfplay_cli.stats.predict import belief, measure_spread


def _expected(d):
    return 1.0 / (1.0 + 10.0 ** (-np.asarray(d) / 400.0))


def test_a_sure_difference_predicts_the_binomial_interval_of_its_score():
    """No uncertainty in the difference: the score of n games is Binomial(n, E(d)) / n; its central 95% interval
    by scipy's quantiles."""
    for diff, n in ((0.0, 200), (191.0, 200), (-400.0, 50)):
        p = float(_expected(diff))
        pred = belief(diff, 0.0).predict(n)
        assert pred.score == pytest.approx(p)
        assert (pred.low, pred.high) == (binom.ppf(0.025, n, p) / n, binom.ppf(0.975, n, p) / n)
    assert (belief(0.0, 0.0).predict(200).low, belief(0.0, 0.0).predict(200).high) == (0.43, 0.57)


def test_draws_narrow_a_prediction_as_the_trinomial_of_half_points_says():
    """An even pair (no uncertainty) drawing half its games: each result is 0, 1/2 or 1 with chances 1/4, 1/2, 1/4,
    a spread of 1/8 against a coin's 1/4. The score of 200 games is (half-points of 200 results) / 400, its central
    95% interval by the exact convolution computed here by hand; a pair that always draws scores exactly 50%; a pair
    expected at 90% cannot draw more than 20% of its games (the rest of its mean would not fit)."""
    import dataclasses

    even = belief(0.0, 0.0)
    half = dataclasses.replace(even, draw=0.5).predict(200)
    pmf = np.array([1.0])
    for _ in range(200):
        pmf = np.convolve(pmf, [0.25, 0.5, 0.25])
    cdf = np.cumsum(pmf)
    low = int(np.searchsorted(cdf, 0.025 - 1e-12)) / 400
    high = int(np.flatnonzero(np.cumsum(pmf[::-1])[::-1] >= 0.025 - 1e-12)[-1]) / 400
    assert (half.low, half.high) == pytest.approx((low, high), abs=1e-9)
    assert (half.low, half.high) == pytest.approx((0.4525, 0.5475), abs=0.003)  # 1.96 sqrt(1/8 / 200) = 0.049
    coin = even.predict(200)
    assert coin.high - coin.low > 1.3 * (half.high - half.low)
    always = dataclasses.replace(even, draw=1.0).predict(200)
    assert (always.low, always.high) == pytest.approx((0.5, 0.5))
    strong = belief(400.0 * np.log10(9.0), 0.0)  # 90%
    capped = dataclasses.replace(strong, draw=0.9).predict(200)
    alone = dataclasses.replace(strong, draw=0.2).predict(200)
    assert (capped.low, capped.high) == (alone.low, alone.high)


def test_uncertain_ratings_and_a_spread_widen_the_interval_and_met_games_narrow_it():
    base = belief(100.0, 0.0).predict(200)
    wide = belief(100.0, 80.0).predict(200)
    wider = belief(100.0, 80.0, 120.0).predict(200)
    assert base.high - base.low < wide.high - wide.low < wider.high - wider.low
    # 1,000 games between the two at 70% where pairs scatter around their ratings: the prediction follows them,
    # whatever the ratings said (50%)
    met = belief(0.0, 10.0, 100.0, met_points=700.0, met_games=1000.0).predict(200)
    assert met.score == pytest.approx(0.70, abs=0.01) and met.low > 0.6 and met.high < 0.8
    # where the rest of the ledger knows the difference exactly and pairs do not scatter, the pair's games cannot
    # move it
    assert belief(0.0, 0.0, 0.0, met_points=700.0, met_games=1000.0).predict(200).score == pytest.approx(0.5)
    with pytest.raises(ValueError):
        belief(0.0, -1.0)
    with pytest.raises(ValueError):
        belief(0.0, 1.0, met_points=9.0, met_games=8.0)


def test_a_belief_by_hand_a_normal_prior_and_no_games():
    """No games of its own: the pair's difference is the normal N(diff, sd^2 + tau^2); its interval diff -+ 1.96 *
    sqrt(sd^2 + tau^2) and the chance it is below 0 the normal's (by hand: 150 Elo with sd 60 and tau 80 is
    1.5 sd of 100 above 0, P = 6.68%)."""
    b = belief(150.0, 60.0, 80.0)
    assert b.mean == pytest.approx(150.0, abs=0.5) and b.sd == pytest.approx(100.0, rel=0.01)
    assert b.interval() == pytest.approx((150.0 - 195.996, 150.0 + 195.996), abs=2.0)
    assert b.below(0.0) == pytest.approx(0.0668, abs=0.002)


def _pairs(rng, n_pairs, games, tau):
    d = rng.uniform(-400, 400, n_pairs)
    true = d + rng.normal(0.0, tau, n_pairs) if tau else d
    points = rng.binomial(games, _expected(true)).astype(float)
    return points, np.full(n_pairs, float(games)), d


def test_the_spread_of_pairs_is_measured_from_their_records():
    rng = np.random.default_rng(5)
    assert measure_spread(*_pairs(rng, 400, 50, 0.0)).mean < 40.0  # pairs as their ratings say: no spread to speak of
    tau = measure_spread(*_pairs(rng, 400, 50, 150.0)).mean
    assert 110.0 < tau < 190.0, tau
    # with no pairs the prior (half-normal of scale 200: mean 200 sqrt(2 / pi) = 159.6); 0-8s far below say next to
    # nothing against the ratings, so leave it near there (moment estimates on logits blow up at such scores)
    prior = measure_spread([], [], [])
    assert prior.mean == pytest.approx(159.6, abs=3.0) and prior.pairs == 0
    assert measure_spread([0.0] * 50, [8.0] * 50, [-1500.0] * 50).mean == pytest.approx(prior.mean, abs=25.0)
    # a few pairs say little: the spread stays uncertain, and wide (not the most likely value, 0)
    few = measure_spread(*_pairs(rng, 3, 8, 0.0))
    assert few.mean > 60.0 and len(few.mixture[0]) > 1


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


@pytest.mark.slow
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
        league.roster.ensure_bots("pong", ["random", "cpu"])
        rnd, cpu = (league.roster.find_players(n, "pong")[0].id for n in ("random", "cpu"))
        mid = league.ledger.create_match("pong", "match")
        league.ledger.record_games(mid, [GameResult("pong", (cpu, rnd) if i % 2 else (rnd, cpu), seed=i,
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


def test_the_binomial_of_a_match_is_scipys_at_every_rate_and_length():
    """The match's luck in closed form (log-gamma) against scipy's binomial, rates 0 and 1 (certain counts) and
    200 rates between, matches of 1 to 2,000 results."""
    from scipy.stats import binom

    from selfplay_cli.stats.belief import _binomial

    p = np.concatenate([[0.0, 1.0, 1e-9, 1 - 1e-9], np.random.default_rng(0).uniform(size=200)])
    for n in (1, 8, 200, 2000):
        got = _binomial(n, p)
        assert got.shape == (p.size, n + 1)
        assert np.allclose(got, binom.pmf(np.arange(n + 1)[None, :], n, p[:, None]), rtol=0, atol=1e-12)
    assert _binomial(5, np.array([0.0]))[0, 0] == 1.0 and _binomial(5, np.array([1.0]))[0, 5] == 1.0
