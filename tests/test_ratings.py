"""Tests for selfplay_cli.stats: Elo arithmetic, match statistics, GSPRT and Bradley-Terry fits."""

from __future__ import annotations

import math
import subprocess
import sys
from statistics import NormalDist

import numpy as np
import pytest

from selfplay_cli.stats.bradley_terry import (
    DEFAULT_PRIOR,
    FLAG_DISCONNECTED,
    FLAG_PERFECT,
    FLAG_UNRATED,
    FLAG_ZERO,
    fit_bradley_terry,
    prior_draws,
)
from selfplay_cli.stats.elo import MAX_ELO, elo_to_score, elo_update, normal_quantile, score_to_elo
from selfplay_cli.stats.intervals import (
    bootstrap_ci,
    bootstrap_intervals,
    laplace_ci,
    laplace_intervals,
)
from selfplay_cli.stats.match import match_stats
from selfplay_cli.stats.sprt import SPRT, sprt_bounds, sprt_llr

Z95 = 1.959963984540054  # Phi^{-1}(0.975)


def _games(*blocks: tuple[int, int, int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Expand (i, j, wins_i, losses_i, draws) blocks into per-game arrays (a, b, score_a)."""
    a: list[int] = []
    b: list[int] = []
    s: list[float] = []
    for i, j, wins, losses, draws in blocks:
        for score, count in ((1.0, wins), (0.0, losses), (0.5, draws)):
            a += [i] * count
            b += [j] * count
            s += [score] * count
    return np.array(a), np.array(b), np.array(s)


def _expected(d: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + 10.0 ** (-d / 400.0))


# ------------------------------------------------------------------------------------------------
# Elo arithmetic
# ------------------------------------------------------------------------------------------------


def test_score_elo_conversions() -> None:
    # 400 log10(0.75 / 0.25) = 400 log10(3) = 190.849
    assert score_to_elo(0.75) == pytest.approx(190.85, abs=0.005)
    assert score_to_elo(0.5) == 0.0
    # 1 / (1 + 10^(-1/4)) = 0.640065
    assert elo_to_score(100.0) == pytest.approx(0.6401, abs=5e-5)
    assert elo_to_score(-100.0) == pytest.approx(1.0 - 0.640065, abs=1e-6)
    for d in (-700.0, -35.5, 0.0, 12.0, 900.0):
        assert score_to_elo(elo_to_score(d)) == pytest.approx(d, abs=1e-9)
    # clipped, finite at 0 and 1; no overflow for absurd differences
    assert score_to_elo(1.0) == pytest.approx(MAX_ELO)
    assert score_to_elo(0.0) == pytest.approx(-MAX_ELO)
    assert elo_to_score(1e6) == 1.0 and elo_to_score(-1e6) == 0.0


def test_normal_quantile_matches_stdlib() -> None:
    nd = NormalDist()
    for p in (1e-300, 1e-50, 1e-12, 1e-6, 0.001, 0.02425, 0.025, 0.1, 0.3, 0.5, 0.7, 0.975, 0.999, 1 - 1e-12):
        assert normal_quantile(p) == pytest.approx(nd.inv_cdf(p), abs=1e-9)
    assert normal_quantile(0.975) == pytest.approx(Z95, abs=1e-12)
    with pytest.raises(ValueError):
        normal_quantile(0.0)


def test_online_elo_update() -> None:
    # Equal players: E = 1/2, delta = 16 (1 - 1/2) = +8
    assert elo_update(1500.0, 1500.0, 1.0) == pytest.approx((1508.0, 1492.0))
    assert elo_update(1500.0, 1500.0, 0.5) == pytest.approx((1500.0, 1500.0))
    # A 100 Elo stronger, loses with K=32: delta = 32 (0 - 0.640065) = -20.482
    ra, rb = elo_update(1600.0, 1500.0, 0.0, k=32.0)
    assert ra == pytest.approx(1600.0 - 20.482, abs=1e-3)
    assert ra + rb == pytest.approx(3100.0)  # zero-sum


# ------------------------------------------------------------------------------------------------
# Match statistics
# ------------------------------------------------------------------------------------------------


def test_match_stats_trinomial_interval_by_hand() -> None:
    # W=60, D=20, L=20: s = 0.7
    # var per game = [60 (0.3)^2 + 20 (0.2)^2 + 20 (0.7)^2] / 100 = (5.4 + 0.8 + 9.8) / 100 = 0.16
    # se = sqrt(0.16 / 100) = 0.04; score CI = 0.7 -+ 1.96 * 0.04 = [0.62160, 0.77840]
    # Elo: 400 log10(0.7/0.3) = 147.19; 400 log10(0.6216/0.3784) = 86.23; 400 log10(0.7784/0.2216) = 218.25
    st = match_stats(60, 20, 20)
    assert st.games == 100 and st.score == pytest.approx(0.7)
    assert st.elo == pytest.approx(147.19, abs=0.01)
    lo_s, hi_s = 0.7 - Z95 * 0.04, 0.7 + Z95 * 0.04
    assert st.elo_low == pytest.approx(400 * math.log10(lo_s / (1 - lo_s)), abs=1e-9)
    assert st.elo_high == pytest.approx(400 * math.log10(hi_s / (1 - hi_s)), abs=1e-9)
    assert st.elo_low == pytest.approx(86.23, abs=0.01) and st.elo_high == pytest.approx(218.25, abs=0.01)
    assert not st.bounded and not st.used_pentanomial
    # LOS = Phi((0.7 - 0.5) / 0.04) = Phi(5) = 0.99999971
    assert st.los == pytest.approx(0.99999971, abs=1e-8)


def test_match_stats_pentanomial_interval_by_hand() -> None:
    # 50 pairs (LL, LD, WL+DD, WD, WW) = (5, 10, 20, 10, 5), pair-mean scores (0, .25, .5, .75, 1): mu = 0.5
    # var_pair = [5 * .25 + 10 * .0625 + 0 + 10 * .0625 + 5 * .25] / 50 = 3.75 / 50 = 0.075
    # se = sqrt(0.075 / 50) = 0.038730; CI = 0.5 -+ 0.075910 -> Elo -+ 400 log10(0.575910/0.424090) = -+53.16
    # The same 100 games as W/D/L = 35/30/35 give the wider trinomial se = sqrt(0.175/100) = 0.041833.
    st = match_stats(35, 30, 35, pentanomial=(5, 10, 20, 10, 5))
    half = Z95 * math.sqrt(0.075 / 50)
    expected_hi = 400 * math.log10((0.5 + half) / (0.5 - half))
    assert st.used_pentanomial
    assert st.elo == pytest.approx(0.0, abs=1e-12)
    assert st.elo_high == pytest.approx(expected_hi, abs=1e-9)
    assert st.elo_high == pytest.approx(53.16, abs=0.01)
    assert st.elo_low == pytest.approx(-expected_hi, abs=1e-9)
    tri = match_stats(35, 30, 35)
    assert tri.elo_high > st.elo_high  # pairs remove the opening correlation -> narrower interval


def test_los_value() -> None:
    # LOS = Phi((s - 1/2) / se), the se of the interval. W=10, D=7, L=5 (trinomial): s = 13.5 / 22 = 0.613636,
    # var_g = [10 (0.386364)^2 + 7 (0.113636)^2 + 5 (0.613636)^2] / 22 = 3.465909 / 22 = 0.157541,
    # se = sqrt(0.157541 / 22) = 0.084623, t = 0.113636 / 0.084623 = 1.342862 -> Phi(t) = 0.91034
    # (the interval, [-36.4, +219.4], holds 0 and the LOS is below 97.5 %)
    st = match_stats(10, 7, 5)
    assert st.los == pytest.approx(NormalDist().cdf(1.342862), abs=1e-6)
    assert st.los == pytest.approx(0.91034, abs=1e-5)
    assert st.elo_low == pytest.approx(-36.42, abs=0.01) and st.elo_high == pytest.approx(219.36, abs=0.01)
    assert match_stats(3, 4, 3).los == 0.5
    assert match_stats(0, 5, 0).los == 0.5


def test_los_trinomial_agrees_with_its_interval() -> None:
    # W=5, D=0, L=1: s = 5/6, var_g = [5 (1/6)^2 + (5/6)^2] / 6 = 5/36, se = sqrt(5/216) = 0.152145,
    # t = (1/3) / 0.152145 = 2.190890 -> LOS = Phi(t) = 0.985770; the interval's low end s - 1.96 se = 0.535134
    # -> 400 log10(0.535134 / 0.464866) = +24.45 Elo: it excludes 0, and the LOS is beyond 97.5 %.
    # (The W/L-only formula said Phi(4 / sqrt 6) = 94.9 %, beside an interval excluding 0.)
    st = match_stats(5, 0, 1)
    assert not st.used_pentanomial
    assert st.elo_low == pytest.approx(24.45, abs=0.01)
    assert st.los == pytest.approx(0.985770, abs=1e-6)


def test_los_pentanomial_by_hand() -> None:
    """A tennis-like match: 96 pairs won and lost (the server wins) and 4 pairs won twice, W=104 D=0 L=96."""
    # s = 104 / 200 = 0.52; pair means: 96 x 0.5 and 4 x 1.0, mu = 0.52,
    # var_p = 0.96 (0.02)^2 + 0.04 (0.48)^2 = 0.000384 + 0.009216 = 0.0096, se = sqrt(0.0096 / 100) = 0.0097980
    # interval 0.52 -+ 1.959964 * 0.0097980 = [0.5007964, 0.5392036] -> Elo [+0.553, +27.298], Elo +13.905
    # LOS = Phi(0.02 / 0.0097980) = Phi(2.041241) = 0.979387 (W/L alone said Phi(8 / sqrt 200) = 0.7142)
    st = match_stats(104, 0, 96, pentanomial=(0, 0, 96, 0, 4))
    assert st.used_pentanomial and st.score == pytest.approx(0.52)
    assert st.elo == pytest.approx(13.905, abs=1e-3)
    assert st.elo_low == pytest.approx(0.553, abs=1e-3) and st.elo_high == pytest.approx(27.298, abs=1e-3)
    assert st.los == pytest.approx(0.979387, abs=1e-6)


@pytest.mark.parametrize("confidence", [0.8, 0.9, 0.95, 0.99])
def test_the_interval_excludes_0_exactly_when_the_los_is_beyond_its_confidence(confidence) -> None:
    """Over many random records, paired (pentanomial) or not, small or large, lopsided or level, 0 % / 100 %: the
    interval excludes 0 iff the LOS is above (1 + c) / 2 or below (1 - c) / 2 - one claim, not two."""
    rng = np.random.default_rng(48)
    # a pair's games for A: LL, LD, WL, DD, WD, WW -> (wins, draws, losses) and the pentanomial bin
    kinds = np.array([[0, 0, 2], [0, 1, 1], [1, 0, 1], [0, 2, 0], [1, 1, 0], [2, 0, 0]])
    bins = np.array([0, 1, 2, 2, 3, 4])
    records = [((104, 0, 96), (0, 0, 96, 0, 4)), ((5, 0, 1), None)]  # the two cases above
    for _ in range(3000):
        n = int(rng.choice([1, 2, 3, 5, 10, 30, 100, 400]))
        p = rng.dirichlet(np.full(6, rng.choice([0.2, 1.0, 5.0])))
        counts = rng.multinomial(n, p)
        wdl = tuple(int(x) for x in counts @ kinds)
        penta = tuple(int(x) for x in np.bincount(bins, weights=counts, minlength=5).astype(int))
        records.append((wdl, penta if rng.random() < 0.5 else None))
    disagreements = []
    for (w, d, lo), penta in records:
        st = match_stats(w, d, lo, pentanomial=penta, confidence=confidence)
        excludes = st.elo_low > 0 or st.elo_high < 0
        beyond = st.los > (1 + confidence) / 2 or st.los < (1 - confidence) / 2
        if excludes != beyond:
            disagreements.append(((w, d, lo), penta, round(st.elo_low, 2), round(st.elo_high, 2), round(st.los, 4)))
    assert not disagreements, f"{len(disagreements)} of {len(records)}, e.g. {disagreements[:3]}"


def test_match_stats_extreme_scores_are_finite_and_flagged() -> None:
    win = match_stats(10, 0, 0)
    assert win.bounded and win.score == 1.0
    # one virtual draw: (10 + 1/2) / 11 -> 400 log10(21) = 528.9
    assert win.elo == pytest.approx(400 * math.log10(21), abs=1e-9)
    assert win.elo_high == MAX_ELO and math.isfinite(win.elo_low) and win.elo_low < win.elo
    loss = match_stats(0, 0, 7, pentanomial=(3, 1, 0, 0, 0))
    assert loss.bounded and loss.elo_low == -MAX_ELO and math.isfinite(loss.elo_high)
    assert loss.elo == pytest.approx(-400 * math.log10(15), abs=1e-9)  # (0.5 / 8) -> odds 1/15
    empty = match_stats(0, 0, 0)
    assert empty.games == 0 and empty.elo == 0.0 and empty.los == 0.5
    assert (empty.elo_low, empty.elo_high) == (-MAX_ELO, MAX_ELO)
    for st in (win, loss, empty):
        assert all(math.isfinite(x) for x in (st.elo, st.elo_low, st.elo_high, st.los))


# ------------------------------------------------------------------------------------------------
# SPRT
# ------------------------------------------------------------------------------------------------


def test_sprt_bounds() -> None:
    lo, hi = sprt_bounds(0.05, 0.05)
    assert lo == pytest.approx(-2.944, abs=5e-4) and hi == pytest.approx(2.944, abs=5e-4)
    assert hi == pytest.approx(math.log(19.0))


def _penta(ll: int, ld: int, wl: int, dd: int, wd: int, ww: int) -> list[int]:
    """fastchess ``Stats(ll, ld, wl, dd, wd, ww)`` -> our ascending pentanomial (LL, LD, WL+DD, WD, WW)."""
    return [ll, ld, wl + dd, wd, ww]


def _tri(wins: int, losses: int, draws: int) -> list[int]:
    """fastchess ``Stats(wins, losses, draws)`` -> our trinomial (losses, draws, wins)."""
    return [losses, draws, wins]


# Published vectors from fastchess, app/tests/sprt_test.cpp (github.com/Disservin/fastchess), whose
# ``Stats`` constructors are Stats(wins, losses, draws) and Stats(ll, ld, wl, dd, wd, ww)
# (app/src/matchmaking/stats.hpp); all with alpha = beta = 0.05.
FASTCHESS_CASES = [
    # (name, counts, elo0, elo1, elo_model, published LLR)
    ("logistic pentanomial 1", _penta(223, 9863, 20279, 1000, 10037, 246), 0.5, 2.5, "logistic", -3.07),
    ("logistic pentanomial 2", _penta(871, 26175, 55003, 980, 26678, 821), 0.0, 2.0, "logistic", -4.98),
    ("logistic trinomial 1", _tri(21404, 21184, 40708), 0.5, 2.5, "logistic", -1.57),
    ("logistic trinomial 2", _tri(57433, 57030, 106593), 0.0, 2.0, "logistic", -2.59),
    ("normalized pentanomial 1", _penta(365, 16618, 36029, 200, 16974, 390), 0.0, 2.0, "normalized", 2.25),
    ("normalized pentanomial 2", _penta(127, 4883, 10311, 401, 5150, 104), -1.75, 0.25, "normalized", 3.01),
    ("normalized trinomial 1", _tri(36433, 36027, 68692), 0.0, 2.0, "normalized", 0.92),
    ("normalized trinomial 2", _tri(10871, 10650, 20431), -1.75, 0.25, "normalized", 2.30),
]


@pytest.mark.parametrize(("name", "counts", "elo0", "elo1", "model", "published"), FASTCHESS_CASES)
def test_sprt_llr_reproduces_fastchess(
    name: str, counts: list[int], elo0: float, elo1: float, model: str, published: float
) -> None:
    llr = sprt_llr(counts, elo0, elo1, elo_model=model)  # type: ignore[arg-type]
    assert abs(llr - published) <= 0.005, name  # equal to 2 decimals


def test_sprt_llr_reproduces_openbench_and_fastchess_console_output() -> None:
    # OpenBench (ob.expositor.dev/test/299, quoted in github.com/cosmobobak/viridithas PR #371):
    #   LLR +2.95 (-2.94, +2.94) for [0.00, 3.00]; PENTA +2: 1573, +1: 45113, 0: 95783, -1: 44719, -2: 1260
    #   That instance tests in normalized Elo.
    ob = [1260, 44719, 95783, 45113, 1573]
    assert round(sprt_llr(ob, 0.0, 3.0, elo_model="normalized"), 2) == 2.95
    # fastchess console output (default normalized model):
    #   "Ptnml(0-2): [0, 0, 2, 0, 37] ... LLR: 2.96 (100.6%) (-2.94, 2.94) [0.00, 20.00]"
    # This also exercises the regularisation of empty bins (three zero counts).
    assert round(sprt_llr([0, 0, 2, 0, 37], 0.0, 20.0, elo_model="normalized"), 2) == 2.96


def test_sprt_llr_edge_cases() -> None:
    assert sprt_llr([0, 0, 0, 0, 0], 0.0, 5.0) == 0.0
    assert sprt_llr([0, 0, 0], 0.0, 5.0, model="trinomial") == 0.0
    # Empty bins are regularised: finite results, sign in the right direction.
    assert 0.0 < sprt_llr([0, 0, 0, 0, 30], 0.0, 20.0) < math.inf
    assert sprt_llr([30, 0, 0, 0, 0], 0.0, 20.0) < 0.0
    # Data exactly at H0 -> H0 is the unconstrained MLE, so the generalised LLR is <= 0.
    assert sprt_llr([100, 200, 100], 0.0, 5.0, model="trinomial") < 0.0
    # Hypotheses far on the wrong side of the data: still finite (normal-approximation fallback).
    assert sprt_llr([549, 54, 33, 1, 0], 500.0, 1500.0, elo_model="normalized") < 0.0
    with pytest.raises(ValueError):
        sprt_llr([1, 2, 3, 4], 0.0, 5.0)
    with pytest.raises(ValueError):
        sprt_llr([1, 2, 3], 0.0, 5.0, model="pentanomial")


def test_sprt_decide() -> None:
    test = SPRT(elo0=0.0, elo1=5.0)
    assert test.lower == pytest.approx(-2.944, abs=5e-4)
    assert test.decide(3.0) == "H1"
    assert test.decide(-3.0) == "H0"
    assert test.decide(0.1) is None
    llr = test.llr(_penta(223, 9863, 20279, 1000, 10037, 246))
    assert llr == pytest.approx(sprt_llr(_penta(223, 9863, 20279, 1000, 10037, 246), 0.0, 5.0))
    with pytest.raises(ValueError):
        SPRT(elo0=5.0, elo1=0.0)


# ------------------------------------------------------------------------------------------------
# Bradley-Terry
# ------------------------------------------------------------------------------------------------


def test_bt_two_players_seven_of_ten() -> None:
    a, b, s = _games((0, 1, 7, 3, 0))
    fit = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0)
    # E(d) = 0.7 -> d = 400 log10(7/3) = 147.19
    assert fit.ratings[0] == pytest.approx(400 * math.log10(7 / 3), abs=1e-6)
    assert fit.ratings[0] == pytest.approx(147.2, abs=0.05)
    assert fit.flags == [None, None] and fit.converged
    assert list(fit.wins) == [7, 3] and list(fit.losses) == [3, 7] and list(fit.games) == [10, 10]


def test_bt_draws_count_half() -> None:
    # 6 wins, 2 draws, 2 losses = 7 points of 10, the same likelihood as 7 wins / 3 losses.
    a, b, s = _games((0, 1, 6, 2, 2))
    fit = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0)
    assert fit.ratings[0] == pytest.approx(400 * math.log10(7 / 3), abs=1e-6)
    assert fit.draws[0] == 2 and fit.score[0] == pytest.approx(0.7)
    # Draws given from B's side count the same.
    a2, b2, s2 = _games((1, 0, 2, 6, 2))
    fit2 = fit_bradley_terry(a2, b2, s2, 2, anchor=1, anchor_rating=0.0)
    assert fit2.ratings[0] == pytest.approx(fit.ratings[0], abs=1e-9)


def test_bt_three_player_round_robin_by_hand() -> None:
    # 15 games per pair, A-B 10:5 (odds 2), B-C 10:5 (odds 2), A-C 12:3 (odds 4 = 2 * 2).
    # The pairwise odds are consistent, so E(r_i - r_j) = s_ij holds for every pair and each score
    # equation sum_j n_ij (s_ij - E(r_i - r_j)) = 0 term by term: r_A - r_B = r_B - r_C = 400 log10 2.
    a, b, s = _games((0, 1, 10, 5, 0), (1, 2, 10, 5, 0), (0, 2, 12, 3, 0))
    fit = fit_bradley_terry(a, b, s, 3, anchor=1, anchor_rating=1500.0)
    step = 400 * math.log10(2)  # 120.41
    assert fit.ratings == pytest.approx([1500 + step, 1500.0, 1500 - step], abs=1e-6)
    # An inconsistent round robin with draws: check the score equations and an independent solver.
    a, b, s = _games((0, 1, 6, 3, 3), (1, 2, 4, 4, 2), (2, 0, 5, 2, 1))
    fit = fit_bradley_terry(a, b, s, 3, anchor=0, anchor_rating=0.0)
    points = np.zeros((3, 3))
    games = np.zeros((3, 3))
    np.add.at(points, (a, b), s)
    np.add.at(points, (b, a), 1 - s)
    np.add.at(games, (a, b), 1)
    np.add.at(games, (b, a), 1)
    residual = (points - games * _expected(fit.ratings[:, None] - fit.ratings[None, :])).sum(axis=1)
    assert np.abs(residual).max() < 1e-6
    assert fit.ratings == pytest.approx(_mm_reference(points, games, anchor=0), abs=0.5)


def _mm_reference(points: np.ndarray, games: np.ndarray, anchor: int, sweeps: int = 20000) -> np.ndarray:
    """Independent check: Hunter's (2004) MM iteration gamma_i <- W_i / sum_j n_ij / (gamma_i + gamma_j)."""
    n = points.shape[0]
    gamma = np.ones(n)
    wins = points.sum(axis=1)
    for _ in range(sweeps):
        for i in range(n):
            denom = sum(games[i, j] / (gamma[i] + gamma[j]) for j in range(n) if j != i)
            gamma[i] = wins[i] / denom
        gamma /= gamma[anchor]
    return 400 * np.log10(gamma)


def test_bt_matches_mm_on_random_population() -> None:
    rng = np.random.default_rng(3)
    n, g = 6, 600
    true = rng.normal(0, 150, n)
    a = rng.integers(0, n, g)
    b = (a + rng.integers(1, n, g)) % n
    p = _expected(true[a] - true[b])
    u = rng.random(g)
    s = np.where(u < p - 0.1, 1.0, np.where(u < p + 0.1, 0.5, 0.0))
    fit = fit_bradley_terry(a, b, s, n, anchor=2, anchor_rating=1000.0)
    points = np.zeros((n, n))
    games = np.zeros((n, n))
    np.add.at(points, (a, b), s)
    np.add.at(points, (b, a), 1 - s)
    np.add.at(games, (a, b), 1)
    np.add.at(games, (b, a), 1)
    ref = 1000.0 + _mm_reference(points, games, anchor=2, sweeps=3000)
    assert np.abs(fit.ratings - ref).max() < 0.5
    residual = (points - games * _expected(fit.ratings[:, None] - fit.ratings[None, :])).sum(axis=1)
    assert np.abs(residual).max() < 1e-6
    assert all(f is None for f in fit.flags) and fit.converged


def test_bt_anchor_shifts_everything() -> None:
    a, b, s = _games((0, 1, 6, 3, 3), (1, 2, 4, 4, 2), (2, 0, 5, 2, 1), (3, 1, 2, 2, 2))
    f0 = fit_bradley_terry(a, b, s, 4, anchor=0, anchor_rating=1000.0)
    f2 = fit_bradley_terry(a, b, s, 4, anchor=2, anchor_rating=1234.0)
    assert f0.ratings[0] == 1000.0 and f2.ratings[2] == 1234.0
    diff = f2.ratings - f0.ratings
    assert diff == pytest.approx(np.full(4, diff[0]), abs=1e-6)


def test_bt_unbounded_players_get_finite_flagged_ratings() -> None:
    a, b, s = _games(
        (0, 1, 10, 5, 0), (1, 2, 10, 5, 0), (0, 2, 12, 3, 0),  # A, B, C: the well-posed core
        (3, 0, 2, 0, 0),  # D won both games against A: perfect score
        (4, 2, 0, 3, 0),  # E lost all 3 games against C: zero score
        (5, 6, 3, 1, 0),  # F, G only played each other: not connected to the anchor
    )  # H (7) never played
    fit = fit_bradley_terry(a, b, s, 8, anchor=1, anchor_rating=1500.0)
    assert np.all(np.isfinite(fit.ratings))
    assert fit.flags == [None, None, None, FLAG_PERFECT, FLAG_ZERO, FLAG_DISCONNECTED, FLAG_DISCONNECTED,
                         FLAG_UNRATED]
    step = 400 * math.log10(2)
    assert fit.ratings[:3] == pytest.approx([1500 + step, 1500.0, 1500 - step], abs=1e-6)  # core is exact
    # Bound = performance with one virtual draw: D scores (2 + 1/2) / 3 = 5/6 against A -> A + 400 log10 5.
    assert fit.ratings[3] == pytest.approx(fit.ratings[0] + 400 * math.log10(5), abs=1e-6)
    # E scores (0 + 1/2) / 4 = 1/8 against C -> C - 400 log10 7.
    assert fit.ratings[4] == pytest.approx(fit.ratings[2] - 400 * math.log10(7), abs=1e-6)
    # F, G: exact relative fit (3/4 -> 400 log10 3 apart), centred on the anchor rating.
    assert fit.ratings[5] - fit.ratings[6] == pytest.approx(400 * math.log10(3), abs=1e-6)
    assert (fit.ratings[5] + fit.ratings[6]) / 2 == pytest.approx(1500.0)
    assert fit.ratings[7] == 1500.0 and fit.games[7] == 0 and fit.score[7] == 0.5
    # A group beating everybody outside it (neither member has a literal 100 % score) is "perfect".
    a2, b2, s2 = _games((0, 1, 3, 2, 0), (2, 0, 2, 0, 0), (3, 2, 1, 0, 0), (2, 3, 1, 0, 0))
    fit2 = fit_bradley_terry(a2, b2, s2, 4, anchor=0, anchor_rating=0.0)
    assert fit2.flags == [None, None, FLAG_PERFECT, FLAG_PERFECT]
    assert np.all(np.isfinite(fit2.ratings)) and fit2.ratings[2] > 0 and fit2.ratings[3] > 0


def test_bt_perfect_anchor_and_no_games() -> None:
    a, b, s = _games((0, 1, 4, 0, 0), (0, 2, 3, 0, 0))  # the anchor won everything
    fit = fit_bradley_terry(a, b, s, 3, anchor=0, anchor_rating=1000.0)
    assert fit.ratings[0] == 1000.0 and fit.flags == [None, FLAG_ZERO, FLAG_ZERO]
    assert fit.ratings[1] == pytest.approx(1000.0 - 400 * math.log10(9), abs=1e-6)  # 0.5 / 5 = 1/10
    empty = fit_bradley_terry(np.array([], int), np.array([], int), np.array([]), 3)
    assert empty.flags == [FLAG_UNRATED] * 3 and np.all(empty.ratings == 1000.0)


def test_bt_prior_games_and_weights() -> None:
    a, b, s = _games((0, 1, 7, 3, 0))
    ml = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0)
    shrunk = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0, prior_games=2.0)
    # BayesElo: prior 2 between two players that only met each other = 2 virtual draws A-B
    # -> A scores (7 + 1) / 12 = 2/3 -> 400 log10 2
    assert shrunk.ratings[0] == pytest.approx(400 * math.log10(2), abs=1e-6)
    assert 0 < shrunk.ratings[0] < ml.ratings[0]
    # weights multiply games: weight 2 on every game changes nothing, weight 0 drops a game
    w2 = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0, weights=np.full(10, 2.0))
    assert w2.ratings[0] == pytest.approx(ml.ratings[0], abs=1e-6) and w2.games[0] == 20
    w0 = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0, weights=np.r_[np.ones(7), np.zeros(3)])
    assert w0.flags[0] == FLAG_PERFECT and np.isfinite(w0.ratings[0])


def test_prior_draws_follow_bayeselo_add_prior() -> None:
    """BayesElo's CCondensedResults::AddPrior: player i adds prior * 0.25 * N_ij / N_i to each of the four draw
    counters of each opponent j (d_ij, d_ji on both sides), i.e. (prior / 2) N_ij / N_i draws of the pair."""
    assert DEFAULT_PRIOR == 2.0  # BayesElo's default: Prior(2.0) in CEloRatingCUI.cpp
    # A(0)-B(1) 10 games, A-C(2) 30 games, B-C none: N_A = 40, N_B = 10, N_C = 30.
    n = np.array([[0.0, 10.0, 30.0], [10.0, 0.0, 0.0], [30.0, 0.0, 0.0]])
    v = prior_draws(n, 2.0)
    assert v[0, 1] == v[1, 0] == pytest.approx(10 / 40 + 10 / 10)  # 1.25
    assert v[0, 2] == v[2, 0] == pytest.approx(30 / 40 + 30 / 30)  # 1.75
    assert v[1, 2] == v[2, 1] == 0.0 and np.all(np.diag(v) == 0.0)
    # Every player spreads prior / 2 = 1 draw over its opponents: half the row sums of the unsymmetrised part.
    assert prior_draws(n, 4.0) == pytest.approx(2 * v)
    assert np.all(prior_draws(n, 0.0) == 0.0)
    with pytest.raises(ValueError):
        prior_draws(n, -1.0)


def test_prior_zero_is_exactly_maximum_likelihood() -> None:
    a, b, s = _games((0, 1, 6, 3, 3), (1, 2, 4, 4, 2), (2, 0, 5, 2, 1), (3, 1, 2, 0, 0), (4, 2, 0, 3, 0))
    ml = fit_bradley_terry(a, b, s, 6, anchor=0, anchor_rating=1000.0)
    zero = fit_bradley_terry(a, b, s, 6, anchor=0, anchor_rating=1000.0, prior_games=0.0)
    assert np.array_equal(zero.ratings, ml.ratings) and zero.flags == ml.flags
    assert ml.flags[3] == FLAG_PERFECT and ml.flags[4] == FLAG_ZERO and ml.flags[5] == FLAG_UNRATED
    # The ML score equations hold on the well-posed core (players 0, 1, 2 and their games among themselves).
    core = (a < 3) & (b < 3)
    points, games = np.zeros((3, 3)), np.zeros((3, 3))
    np.add.at(points, (a[core], b[core]), s[core])
    np.add.at(points, (b[core], a[core]), 1 - s[core])
    np.add.at(games, (a[core], b[core]), 1)
    np.add.at(games, (b[core], a[core]), 1)
    r = ml.ratings[:3]
    residual = (points - games * _expected(r[:, None] - r[None, :])).sum(axis=1)
    assert np.abs(residual).max() < 1e-6


def test_map_of_a_perfect_score_by_hand() -> None:
    """X wins 10-0 against the anchor A. Prior 2: 2 virtual draws between them, so X has 10 + 1 points of 12 and
    the MAP solves E(d) = 11/12: d = 400 log10 11 = +416.6. Maximum likelihood: d = +inf (flagged bound)."""
    a, b, s = _games((0, 1, 10, 0, 0))
    fit = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=1000.0, prior_games=2.0)
    assert fit.ratings[0] == pytest.approx(1000.0 + 400 * math.log10(11), abs=1e-6)  # 1416.55
    assert fit.ratings[0] == pytest.approx(1416.557, abs=1e-3)
    assert fit.flags == [None, None] and fit.converged
    assert fit_bradley_terry(a, b, s, 2, anchor=1, prior_games=0.0).flags == [FLAG_PERFECT, None]
    # Laplace: the log-posterior 11 log p + 1 log(1 - p) has curvature 12 p (1 - p) = 12 * 11/12 * 1/12 = 11/12
    # nats^-2 at the MAP, so se = sqrt(12 / 11) nats = 181.4 Elo.
    se = math.sqrt(12 / 11) * 400 / math.log(10)
    assert se == pytest.approx(181.44, abs=0.01)
    low, high = laplace_ci(a, b, 2, fit.ratings, anchor=1, confidence=0.95, prior_games=2.0)
    assert low[0] == pytest.approx(fit.ratings[0] - Z95 * se, abs=1e-6)  # 1060.9
    assert high[0] == pytest.approx(fit.ratings[0] + Z95 * se, abs=1e-6)  # 1772.2
    assert low[1] == high[1] == 1000.0


def test_bootstrap_of_a_perfect_score_is_never_narrower_than_laplace() -> None:
    """Every replicate of a 10-0 record is 10-0: the percentile interval alone would be one point."""
    a, b, s = _games((0, 1, 10, 0, 0))
    point = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=1000.0, prior_games=2.0).ratings
    # Without the floor: the bare replicates all give the same rating (what the floor is there for).
    bare_low, bare_high = bootstrap_ci(a, b, s, 2, anchor=1, n_boot=50, seed=3, prior_games=0.0)
    assert bare_high[0] - bare_low[0] == pytest.approx(0.0, abs=1e-6)
    low, high = bootstrap_ci(a, b, s, 2, anchor=1, anchor_rating=1000.0, n_boot=50, seed=3, prior_games=2.0)
    lap_low, lap_high = laplace_ci(a, b, 2, point, anchor=1, prior_games=2.0)
    assert low[0] == pytest.approx(lap_low[0], abs=1e-6) and high[0] == pytest.approx(lap_high[0], abs=1e-6)
    assert high[0] - low[0] == pytest.approx(2 * Z95 * math.sqrt(12 / 11) * 400 / math.log(10), abs=1e-6)
    # With informative data too the reported interval contains the Laplace one (and the estimate).
    a2, b2, s2 = _games((0, 1, 14, 6, 0))
    p2 = fit_bradley_terry(a2, b2, s2, 2, anchor=1, prior_games=2.0).ratings
    lo2, hi2 = bootstrap_ci(a2, b2, s2, 2, anchor=1, n_boot=200, seed=1, prior_games=2.0)
    llo2, lhi2 = laplace_ci(a2, b2, 2, p2, anchor=1, prior_games=2.0)
    assert lo2[0] <= llo2[0] and hi2[0] >= lhi2[0]
    assert lo2[0] < p2[0] < hi2[0]


def test_perfectly_separated_chain_is_finite_ordered_and_ranked_under_the_prior() -> None:
    """A beats B beats C, every game, 20 games a pair: ML ratings are infinite; the MAP is finite, unflagged and
    solves the score equations with the virtual draws added; the differences' intervals separate all three."""
    a, b, s = _games((0, 1, 20, 0, 0), (1, 2, 20, 0, 0), (0, 2, 20, 0, 0))
    ml = fit_bradley_terry(a, b, s, 3, anchor=2, anchor_rating=1000.0)
    assert ml.flags == [FLAG_PERFECT, FLAG_PERFECT, None]
    fit = fit_bradley_terry(a, b, s, 3, anchor=2, anchor_rating=1000.0, prior_games=2.0)
    assert fit.flags == [None, None, None] and np.all(np.isfinite(fit.ratings))
    assert fit.ratings[0] > fit.ratings[1] > fit.ratings[2] == 1000.0
    games = np.array([[0, 20, 20], [20, 0, 20], [20, 20, 0]], dtype=float)
    points = np.array([[0, 20, 20], [0, 0, 20], [0, 0, 0]], dtype=float)
    v = prior_draws(games, 2.0)  # 1 virtual draw a pair: (2/2) * 20 * (1/40 + 1/40)
    assert v[0, 1] == pytest.approx(1.0)
    r = fit.ratings
    residual = (points + v / 2 - (games + v) * _expected(r[:, None] - r[None, :])).sum(axis=1)
    assert np.abs(residual).max() < 1e-6
    for low, high, sd in (laplace_intervals(a, b, 3, r, 2, 0.95, 2.0),
                          bootstrap_intervals(a, b, s, 3, 2, 1000.0, 100, 0.95, 0, 2.0)):
        assert np.all(low <= r) and np.all(r <= high) and low[2] == high[2] == 1000.0
        z = normal_quantile(0.975)  # each step of the chain is separated by its difference's interval
        assert r[0] - r[1] - z * sd[0, 1] > 0 and r[1] - r[2] - z * sd[1, 2] > 0
    # By whole intervals alone A and B overlap (both carry the uncertainty of their link to C).
    low, high, _ = laplace_intervals(a, b, 3, r, 2, 0.95, 2.0)
    assert low[0] < high[1]


def test_laplace_ci_without_prior_is_the_wald_interval() -> None:
    a, b, s = _games((0, 1, 7, 3, 0))
    fit = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0)
    low, high = laplace_ci(a, b, 2, fit.ratings, anchor=1)
    se = 400 / math.log(10) / math.sqrt(10 * 0.7 * 0.3)
    assert low[0] == pytest.approx(fit.ratings[0] - Z95 * se, abs=1e-6)
    assert high[0] == pytest.approx(fit.ratings[0] + Z95 * se, abs=1e-6)
    # With the prior the curvature includes the virtual draws: (10 + 2) p (1 - p) at p = 2/3.
    pf = fit_bradley_terry(a, b, s, 2, anchor=1, anchor_rating=0.0, prior_games=2.0)
    low, high = laplace_ci(a, b, 2, pf.ratings, anchor=1, prior_games=2.0)
    se_p = 400 / math.log(10) / math.sqrt(12 * (2 / 3) * (1 / 3))
    assert high[0] - pf.ratings[0] == pytest.approx(Z95 * se_p, abs=1e-6)


def test_bt_validation() -> None:
    with pytest.raises(ValueError):
        fit_bradley_terry(np.array([0]), np.array([0]), np.array([1.0]), 2)
    with pytest.raises(ValueError):
        fit_bradley_terry(np.array([0]), np.array([2]), np.array([1.0]), 2)
    with pytest.raises(ValueError):
        fit_bradley_terry(np.array([0]), np.array([1]), np.array([1.5]), 2)


def _population(n_games: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    true = np.array([1000.0, 1100.0, 900.0, 1250.0, 800.0])
    a = rng.integers(0, 5, n_games)
    b = (a + rng.integers(1, 5, n_games)) % 5
    s = (rng.random(n_games) < _expected(true[a] - true[b])).astype(float)
    return a, b, s, true


def test_bootstrap_ci_contains_estimate_and_narrows() -> None:
    a, b, s, true = _population(4000, seed=7)
    fit = fit_bradley_terry(a, b, s, 6, anchor=0, anchor_rating=1000.0)  # player 5 never plays
    low, high = bootstrap_ci(a, b, s, 6, anchor=0, anchor_rating=1000.0, n_boot=100, seed=1)
    assert np.all(np.isfinite(low)) and np.all(np.isfinite(high))
    assert np.all(low <= fit.ratings) and np.all(fit.ratings <= high)
    assert low[0] == high[0] == 1000.0  # the anchor is fixed
    assert np.all((low[1:5] <= true[1:5]) & (true[1:5] <= high[1:5]))
    assert (low[5], high[5]) == (1000.0 - MAX_ELO, 1000.0 + MAX_ELO)  # unrated: finite, very wide
    a_s, b_s, s_s, _ = _population(400, seed=7)
    low_s, high_s = bootstrap_ci(a_s, b_s, s_s, 5, anchor=0, anchor_rating=1000.0, n_boot=100, seed=1)
    width_small, width_large = high_s[1:] - low_s[1:], high[1:5] - low[1:5]
    assert np.all(width_large < width_small)  # 10x the games: about sqrt(10) narrower
    assert np.mean(width_small / width_large) == pytest.approx(math.sqrt(10), rel=0.35)


def test_bootstrap_ci_flagged_player_is_finite() -> None:
    a, b, s = _games((0, 1, 10, 5, 5), (2, 0, 4, 0, 0), (1, 3, 6, 0, 0))
    low, high = bootstrap_ci(a, b, s, 4, anchor=0, anchor_rating=0.0, n_boot=60, seed=2)
    assert np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(low <= high)


def test_stats_does_not_import_torch() -> None:
    code = ("import sys, selfplay_cli.stats.elo, selfplay_cli.stats.match, selfplay_cli.stats.sprt, "
            "selfplay_cli.stats.bradley_terry, selfplay_cli.stats.intervals; sys.exit('torch' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_a_sample_without_spread_still_has_an_interval():
    """2 pairs of one win and one loss each (or 10 draws) show no spread: that is not certainty. The interval is the
    one with a virtual result on either side (hand-computed: pairs 0.5, 0.5 plus 0.25 and 0.75 -> variance
    0.125 / 4 over 4 pairs; score 0.5 +- 1.96 * 0.0884 -> +-125.6 Elo), and it narrows as pairs come in."""
    from selfplay_cli.stats.match import match_stats

    two = match_stats(2, 0, 2, pentanomial=(0, 0, 2, 0, 0))
    se = math.sqrt(2 * 0.25**2 / 4 / 4)
    z = 1.959963984540054
    assert two.elo_high == pytest.approx(-400 * math.log10(1 / (0.5 + z * se) - 1), abs=0.01)
    assert two.elo_low == pytest.approx(-two.elo_high)
    assert two.elo_high == pytest.approx(125.57, abs=0.01)
    many = match_stats(200, 0, 200, pentanomial=(0, 0, 200, 0, 0))
    assert 0 < many.elo_high < 3
    draws = match_stats(0, 10, 0)
    assert draws.elo_low < 0 < draws.elo_high
