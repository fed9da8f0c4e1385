"""Tests for selfplay_cli.train.matchmaking: opponent distributions per mode, sampling proportions
(chi-square goodness of fit), the decayed win-rate book (selfplay_cli.train.win_rates), config / --bots validation
and resume state."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from selfplay_cli.errors import MarlError
from selfplay_cli.train.matchmaking import Matchmaker, MatchmakerConfig, f_hard, f_var, parse_bots
from selfplay_cli.train.win_rates import LATEST_LEARNER, WinRates, load_win_rates

LEARNER = 1
BOTS = {"cpu": 900, "random": 901}

# Chi-square critical values at significance p = 0.001 (upper tail), by degrees of freedom
# (standard table values, e.g. NIST/SEMATECH e-Handbook 1.3.6.7.4). No scipy in this project.
CHI2_CRIT_001 = {1: 10.828, 2: 13.816, 3: 16.266, 4: 18.467, 5: 20.515, 6: 22.458, 7: 24.322, 8: 26.124,
                 9: 27.877, 10: 29.588}


def chi2_statistic(samples: np.ndarray, probs: dict[int, float]) -> tuple[float, int]:
    """Pearson's goodness-of-fit statistic of ``samples`` against ``probs`` and its degrees of freedom.

    Draws outside ``probs`` make the statistic infinite (impossible under the hypothesis)."""
    ids = np.array(list(probs), dtype=np.int64)
    p = np.array(list(probs.values()), dtype=np.float64)
    if not np.all(np.isin(samples, ids)):
        return float("inf"), len(ids) - 1
    observed = np.array([(samples == i).sum() for i in ids], dtype=np.float64)
    expected = p * samples.size
    return float(((observed - expected) ** 2 / expected).sum()), len(ids) - 1


def passes_chi2(samples: np.ndarray, probs: dict[int, float]) -> bool:
    stat, df = chi2_statistic(samples, probs)
    return stat < CHI2_CRIT_001[df]


def make(pool: list[int] | None = None, seed: int = 0, **cfg: object) -> Matchmaker:
    mm = Matchmaker(MatchmakerConfig(**cfg), np.random.default_rng(seed), BOTS)
    if pool is not None:
        mm.set_pool(pool)
    return mm


def rates_with(p: dict[int, float]) -> WinRates:
    """A book (no prior, no decay) where LEARNER beats opponent o with probability exactly p[o] = wins/games."""
    rates = WinRates(decay=1.0, prior=0.0)
    for opp, x in p.items():
        wins = round(x * 10)
        rates.update_many(LEARNER, np.full(10, opp), np.r_[np.ones(wins), np.zeros(10 - wins)])
        assert rates.p_win(LEARNER, opp) == pytest.approx(x)
    return rates


def assert_probs(got: dict[int, float], want: dict[int, float]) -> None:
    assert set(got) == set(want), (got, want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, abs=1e-12), (k, got, want)
    assert sum(got.values()) == pytest.approx(1.0, abs=1e-12)


def one_line(exc: pytest.ExceptionInfo[BaseException]) -> str:
    msg = str(exc.value)
    assert isinstance(exc.value, MarlError)
    assert msg and "\n" not in msg
    return msg


# --------------------------------------------------------------------------------------------------
# probabilities(): hand-computed distributions
# --------------------------------------------------------------------------------------------------


def test_self_mode_ignores_pool() -> None:
    mm = make([10, 11, 12], mode="self", bots={"cpu": 0.1})
    assert_probs(mm.probabilities(LEARNER, WinRates()), {900: 0.1, LATEST_LEARNER: 0.9})


def test_latest_mode() -> None:
    # bots 0.2; rest 0.8: self 0.8 * 0.25 = 0.2, newest snapshot 0.8 * 0.75 = 0.6
    mm = make([10, 11, 12], mode="latest", latest_ratio=0.25, bots={"cpu": 0.2})
    assert_probs(mm.probabilities(LEARNER, WinRates()), {900: 0.2, LATEST_LEARNER: 0.2, 12: 0.6})


def test_uniform_mode_over_window() -> None:
    # window 3 of pool 10..15 -> 13, 14, 15; self 0.5, each snapshot 0.5 / 3
    mm = make(list(range(10, 16)), mode="uniform", window=3, latest_ratio=0.5)
    assert_probs(mm.probabilities(LEARNER, WinRates()), {LATEST_LEARNER: 0.5, 13: 1 / 6, 14: 1 / 6, 15: 1 / 6})


def test_pfsp_hard_hand_computed() -> None:
    # P = 0.2, 0.5, 0.9 -> f_hard = (1-P)^2 = 0.64, 0.25, 0.01; total 0.90.
    # bots: cpu 0.1 -> rest 0.9; self 0.9 * 0.5 = 0.45; pool share 0.45:
    #   20: 0.45 * 0.64 / 0.90 = 0.32,  21: 0.45 * 0.25 / 0.90 = 0.125,  22: 0.45 * 0.01 / 0.90 = 0.005
    # total 0.1 + 0.45 + 0.32 + 0.125 + 0.005 = 1.
    assert np.allclose(f_hard([0.2, 0.5, 0.9]), [0.64, 0.25, 0.01])
    mm = make([20, 21, 22], mode="pfsp", pfsp="hard", latest_ratio=0.5, bots={"cpu": 0.1})
    got = mm.probabilities(LEARNER, rates_with({20: 0.2, 21: 0.5, 22: 0.9}))
    assert_probs(got, {900: 0.1, LATEST_LEARNER: 0.45, 20: 0.32, 21: 0.125, 22: 0.005})
    assert list(got) == [900, LATEST_LEARNER, 20, 21, 22]  # documented order


def test_pfsp_var_hand_computed() -> None:
    # f_var = P(1-P) = 0.16, 0.25, 0.09; total 0.5 -> 0.32, 0.5, 0.18. latest_ratio 0, no bots: pool gets all.
    assert np.allclose(f_var([0.2, 0.5, 0.9]), [0.16, 0.25, 0.09])
    mm = make([20, 21, 22], mode="pfsp", pfsp="var", latest_ratio=0.0)
    got = mm.probabilities(LEARNER, rates_with({20: 0.2, 21: 0.5, 22: 0.9}))
    assert_probs(got, {20: 0.32, 21: 0.5, 22: 0.18})


def test_pfsp_two_bots_and_ratio() -> None:
    # bots 0.1 + 0.3 = 0.4 -> rest 0.6; self 0.6 * 0.2 = 0.12; pool 0.48 split by f_hard:
    #   P 0.3 -> 0.49, P 0.7 -> 0.09; total 0.58 -> 0.48 * 0.49 / 0.58 and 0.48 * 0.09 / 0.58
    mm = make([5, 6], mode="pfsp", latest_ratio=0.2, bots={"cpu": 0.1, "random": 0.3})
    got = mm.probabilities(LEARNER, rates_with({5: 0.3, 6: 0.7}))
    assert_probs(got, {900: 0.1, 901: 0.3, LATEST_LEARNER: 0.12, 5: 0.48 * 0.49 / 0.58, 6: 0.48 * 0.09 / 0.58})


def test_pfsp_unseen_is_uniform_and_per_learner() -> None:
    mm = make([1, 2, 3, 4], mode="pfsp", latest_ratio=0.0)
    assert_probs(mm.probabilities(7, WinRates()), {1: 0.25, 2: 0.25, 3: 0.25, 4: 0.25})
    rates = WinRates()
    rates.update(8, 1, 1.0)  # learner 8 beat snapshot 1: weight lower for learner 8 only
    assert mm.probabilities(8, rates)[1] < 0.25
    assert_probs(mm.probabilities(7, rates), {1: 0.25, 2: 0.25, 3: 0.25, 4: 0.25})


def test_pfsp_zero_weights_without_prior() -> None:
    # prior 0: an always-beaten snapshot gets weight (1-1)^2 = 0 and is left out; if all are 0 -> uniform.
    mm = make([1, 2], mode="pfsp", latest_ratio=0.0)
    assert_probs(mm.probabilities(LEARNER, rates_with({1: 1.0, 2: 0.5})), {2: 1.0})
    assert_probs(mm.probabilities(LEARNER, rates_with({1: 1.0, 2: 1.0})), {1: 0.5, 2: 0.5})


def test_window_takes_last_k() -> None:
    pool = list(range(100, 120))
    mm = make(pool, mode="uniform", window=4, latest_ratio=0.0)
    assert mm.candidates == (116, 117, 118, 119)
    assert mm.pool == tuple(pool)
    assert_probs(mm.probabilities(LEARNER, WinRates()), {116: 0.25, 117: 0.25, 118: 0.25, 119: 0.25})
    mm.set_pool([100, 101])  # shorter than the window: all of it
    assert mm.candidates == (100, 101)
    pf = make(pool, mode="pfsp", window=2, latest_ratio=0.0)
    assert set(pf.probabilities(LEARNER, WinRates())) == {118, 119}


@pytest.mark.parametrize("mode", ["self", "latest", "uniform", "pfsp"])
def test_empty_pool_falls_back_to_self_and_bots(mode: str) -> None:
    mm = make(None, mode=mode, bots={"cpu": 0.1})
    assert_probs(mm.probabilities(LEARNER, WinRates()), {900: 0.1, LATEST_LEARNER: 0.9})
    mm.set_pool([])
    assert_probs(mm.probabilities(LEARNER, WinRates()), {900: 0.1, LATEST_LEARNER: 0.9})
    assert set(mm.sample(LEARNER, 200, WinRates()).tolist()) <= {900, LATEST_LEARNER}


def test_bots_summing_to_one_and_zero_entries_omitted() -> None:
    mm = make([1, 2], mode="uniform", bots={"cpu": 0.25, "random": 0.75})
    assert_probs(mm.probabilities(LEARNER, WinRates()), {900: 0.25, 901: 0.75})
    mm = make([1, 2], mode="uniform", bots={"cpu": 0.0}, latest_ratio=1.0)
    assert_probs(mm.probabilities(LEARNER, WinRates()), {LATEST_LEARNER: 1.0})


def test_unknown_bot_and_bad_pool() -> None:
    with pytest.raises(MarlError) as exc:
        Matchmaker(MatchmakerConfig(bots={"nobot": 0.1}), np.random.default_rng(0), BOTS)
    assert "nobot" in one_line(exc)
    mm = make()
    with pytest.raises(ValueError):
        mm.set_pool([1, 2, 1])
    with pytest.raises(ValueError):
        mm.set_pool([LATEST_LEARNER])


# --------------------------------------------------------------------------------------------------
# sample(): proportions
# --------------------------------------------------------------------------------------------------

N_DRAWS = 50_000


def test_sample_matches_probabilities_chi2() -> None:
    mm = make([20, 21, 22], seed=123, mode="pfsp", latest_ratio=0.5, bots={"cpu": 0.1})
    rates = rates_with({20: 0.2, 21: 0.5, 22: 0.9})
    probs = mm.probabilities(LEARNER, rates)
    draws = mm.sample(LEARNER, N_DRAWS, rates)
    assert draws.shape == (N_DRAWS,) and draws.dtype == np.int64
    stat, df = chi2_statistic(draws, probs)
    assert df == 4
    assert stat < CHI2_CRIT_001[df], stat


def test_chi2_has_power_against_wrong_proportions() -> None:
    # The same draws tested against slightly wrong proportions (0.02 moved from self to snapshot 20) must fail;
    # and a sampler that forgets the bots must fail against the right proportions.
    mm = make([20, 21, 22], seed=123, mode="pfsp", latest_ratio=0.5, bots={"cpu": 0.1})
    rates = rates_with({20: 0.2, 21: 0.5, 22: 0.9})
    right = mm.probabilities(LEARNER, rates)
    draws = mm.sample(LEARNER, N_DRAWS, rates)
    wrong = dict(right)
    wrong[LATEST_LEARNER] -= 0.02
    wrong[20] += 0.02
    assert passes_chi2(draws, right)
    assert not passes_chi2(draws, wrong)
    no_bots = make([20, 21, 22], seed=5, mode="pfsp", latest_ratio=0.5)
    assert not passes_chi2(no_bots.sample(LEARNER, N_DRAWS, rates), right)
    # uniform over the wrong window (first k instead of last k) fails too
    uni = make(list(range(10)), seed=9, mode="uniform", window=3, latest_ratio=0.0)
    first_k = {0: 1 / 3, 1: 1 / 3, 2: 1 / 3}
    assert not passes_chi2(uni.sample(LEARNER, 3000, WinRates()), first_k)


def test_sample_uniform_window_chi2() -> None:
    mm = make(list(range(30)), seed=7, mode="uniform", window=6, latest_ratio=0.4, bots={"random": 0.05})
    probs = mm.probabilities(LEARNER, WinRates())
    assert len(probs) == 8
    stat, df = chi2_statistic(mm.sample(LEARNER, N_DRAWS, WinRates()), probs)
    assert stat < CHI2_CRIT_001[df], stat


def test_sample_edge_cases() -> None:
    mm = make([3], mode="latest", latest_ratio=0.0)
    assert mm.sample(LEARNER, 0, WinRates()).shape == (0,)
    assert mm.sample(LEARNER, 50, WinRates()).tolist() == [3] * 50
    with pytest.raises(ValueError):
        mm.sample(LEARNER, -1, WinRates())


# --------------------------------------------------------------------------------------------------
# WinRates
# --------------------------------------------------------------------------------------------------


def test_winrates_decay_hand_computed() -> None:
    r = WinRates()  # decay 0.99, prior 1
    assert r.p_win(1, 2) == 0.5  # unseen
    r.update(1, 2, 1.0)  # wins 1, games 1 -> P = 1.5 / 2
    assert r.record(1, 2) == pytest.approx((1.0, 1.0))
    assert r.p_win(1, 2) == pytest.approx(0.75)
    r.update(1, 2, 0.0)  # wins 0.99, games 1.99
    assert r.record(1, 2) == pytest.approx((0.99, 1.99))
    r.update(1, 2, 0.5)  # draw: wins 0.99*0.99 + 0.5 = 1.4801, games 0.99*1.99 + 1 = 2.9701
    assert r.record(1, 2) == pytest.approx((1.4801, 2.9701))
    r.update(1, 2, 1.0)  # wins 0.99*1.4801 + 1 = 2.465299, games 0.99*2.9701 + 1 = 3.940399
    assert r.record(1, 2) == pytest.approx((2.465299, 3.940399), abs=1e-12)
    assert r.p_win(1, 2) == pytest.approx((2.465299 + 0.5) / (3.940399 + 1.0), abs=1e-12)
    # other pairs untouched (decay is per pair), direction matters
    assert r.p_win(2, 1) == 0.5 and r.p_win(1, 3) == 0.5
    # games against LATEST_LEARNER are ignored
    r.update(1, LATEST_LEARNER, 1.0)
    assert r.pairs() == [(1, 2)]
    with pytest.raises(ValueError):
        r.update(1, 2, 1.5)


def test_winrates_prior_and_decay_params() -> None:
    r = WinRates(decay=0.5, prior=2.0)
    r.update(1, 2, 1.0)  # wins 1, games 1
    r.update(1, 2, 1.0)  # wins 1.5, games 1.5 -> P = (1.5 + 1) / (1.5 + 2)
    assert r.p_win(1, 2) == pytest.approx(2.5 / 3.5)
    assert WinRates(decay=1.0, prior=0.0).p_win(1, 2) == 0.5


def test_update_many_equals_sequential_updates() -> None:
    rng = np.random.default_rng(1)
    opps = rng.choice([5, 6, 7, LATEST_LEARNER], size=300)
    scores = rng.choice([0.0, 0.5, 1.0], size=300)
    a, b = WinRates(), WinRates()
    a.update(1, 5, 0.0)
    b.update(1, 5, 0.0)
    a.update_many(1, opps[:100], scores[:100])
    a.update_many(1, opps[100:], scores[100:])
    for o, s in zip(opps, scores, strict=True):
        b.update(1, int(o), float(s))
    assert a.pairs() == b.pairs() == [(1, 5), (1, 6), (1, 7)]
    for pair in a.pairs():
        assert a.record(*pair) == pytest.approx(b.record(*pair), rel=1e-12)
        assert a.p_win(*pair) == pytest.approx(b.p_win(*pair), rel=1e-12)


def random_ledger(n: int, seed: int = 0) -> SimpleNamespace:
    rng = np.random.default_rng(seed)
    pa = rng.integers(0, 8, n)
    pb = (pa + rng.integers(1, 8, n)) % 8  # never equal to pa
    return SimpleNamespace(player_a=pa, player_b=pb, score_a=rng.choice([0.0, 0.5, 1.0], size=n))


def test_from_ledger_on_a_hand_computed_ledger() -> None:
    """Learner 0 against 5: a win, a draw, a loss, in that order, decay 0.5. By hand: wins 0.5*(0.5*1 + 0.5) + 0
    = 0.5, games 0.5*(0.5*1 + 1) + 1 = 1.75; p_win with a prior of 2 games: (0.5 + 1) / (1.75 + 2) = 0.4. The same
    games from 5's side (it is no learner here) are not recorded; 0's game against 6 (as player b, a loss of 6's) is
    0's win."""
    table = SimpleNamespace(player_a=[0, 5, 0, 6], player_b=[5, 0, 5, 0], score_a=[1.0, 0.5, 0.0, 0.0])
    got = WinRates.from_ledger(table, [0], decay=0.5, prior=2.0)
    assert got.record(0, 5) == pytest.approx((0.5, 1.75)) and got.p_win(0, 5) == pytest.approx(0.4)
    assert got.record(0, 6) == pytest.approx((1.0, 1.0)) and got.record(5, 0) == (0.0, 0.0)


def test_from_ledger_equals_incremental() -> None:
    table = random_ledger(2000)
    learners = [0, 1, 2]  # games 0-vs-1 etc. update both learners
    got = WinRates.from_ledger(table, learners, decay=0.97, prior=2.0)
    want = WinRates(decay=0.97, prior=2.0)
    for a, b, s in zip(table.player_a.tolist(), table.player_b.tolist(), table.score_a.tolist(), strict=True):
        if a in learners:
            want.update(a, b, s)
        if b in learners:
            want.update(b, a, 1.0 - s)
    assert got.pairs() == want.pairs()
    assert {p[0] for p in got.pairs()} == set(learners)
    for pair in want.pairs():
        assert got.record(*pair) == pytest.approx(want.record(*pair), rel=1e-10)
    empty = WinRates.from_ledger(SimpleNamespace(player_a=[], player_b=[], score_a=[]), learners)
    assert len(empty) == 0


def test_winrates_dict_round_trip() -> None:
    r = WinRates.from_ledger(random_ledger(300, seed=3), [0, 4], decay=0.9, prior=0.5)
    back = WinRates.from_dict(json.loads(json.dumps(r.to_dict())))
    assert back == r and back.decay == 0.9 and back.prior == 0.5
    for bad in ({}, {"decay": 0.9, "prior": 1.0, "pairs": [[1, 2, "x", 1.0]]},
                {"decay": 2.0, "prior": 1.0, "pairs": []}, {"decay": 0.9, "prior": 1.0, "pairs": [[1, 2, 5.0, 1.0]]}):
        with pytest.raises(MarlError) as exc:
            WinRates.from_dict(bad)
        one_line(exc)


def test_load_win_rates_from_league(tmp_path: Path) -> None:
    from selfplay_cli.league.store import League
    from selfplay_cli.results import GameResult

    lg = League.open(home=tmp_path / "league")
    try:
        lg.roster.create_run("r1", "pong", {})
        lg.roster.ensure_bots("pong", ["cpu"])
        cpu = next(p.id for p in lg.roster.players("pong", kind="bot"))
        snaps = [lg.roster.add_snapshot(env="pong", run="r1", name=f"s{i}", path=f"/x/s{i}.pt", sha256="0" * 64).id
                 for i in range(3)]
        learner = snaps[-1]
        games = [(learner, snaps[0], 1.0), (snaps[1], learner, 1.0), (learner, cpu, 0.5), (snaps[0], snaps[1], 0.0),
                 (learner, snaps[0], 0.0)]
        match = lg.ledger.create_match("pong", "training")
        lg.ledger.record_games(match, [GameResult(env="pong", players=(a, b), seed=i, scores=(s, 1 - s),
                                                  outcome=(s, 1 - s), length=10, truncated=False)
                                       for i, (a, b, s) in enumerate(games)])
        got = load_win_rates(lg, "pong", [learner])
    finally:
        lg.close()
    want = WinRates()
    want.update(learner, snaps[0], 1.0)
    want.update(learner, snaps[1], 0.0)
    want.update(learner, cpu, 0.5)
    want.update(learner, snaps[0], 0.0)
    assert got.pairs() == want.pairs()
    for pair in want.pairs():
        assert got.record(*pair) == pytest.approx(want.record(*pair))


# --------------------------------------------------------------------------------------------------
# Config and --bots validation
# --------------------------------------------------------------------------------------------------


def test_config_defaults() -> None:
    c = MatchmakerConfig()
    assert (c.mode, c.window, c.latest_ratio, c.bots, c.pfsp, c.decay, c.prior) == ("pfsp", 10, 0.5, {}, "hard",
                                                                                      0.99, 1.0)


@pytest.mark.parametrize("kwargs, needle", [
    ({"mode": "elo"}, "mode"),
    ({"pfsp": "soft"}, "PFSP"),
    ({"window": -1}, "window"),
    ({"window": 0}, "window"),
    ({"window": 2.5}, "window"),
    ({"latest_ratio": 1.5}, "ratio"),
    ({"latest_ratio": -0.1}, "ratio"),
    ({"latest_ratio": float("nan")}, "ratio"),
    ({"bots": {"cpu": -0.1}}, "cpu"),
    ({"bots": {"cpu": 0.7, "random": 0.4}}, "sum"),
    ({"bots": {"cpu": float("inf")}}, "cpu"),
    ({"bots": {"": 0.1}}, "bot name"),
    ({"decay": 0.0}, "decay"),
    ({"decay": 1.01}, "decay"),
    ({"prior": -1.0}, "prior"),
])
def test_config_validation(kwargs: dict[str, object], needle: str) -> None:
    with pytest.raises(MarlError) as exc:
        MatchmakerConfig(**kwargs)
    assert needle in one_line(exc)


def test_config_copies_bots() -> None:
    bots = {"cpu": 0.1}
    c = MatchmakerConfig(bots=bots)
    bots["cpu"] = 0.9
    assert c.bots == {"cpu": 0.1}


def test_parse_bots() -> None:
    assert parse_bots("cpu=0.1,random=0.05") == {"cpu": 0.1, "random": 0.05}
    assert parse_bots(" cpu = 0.1 , random=5e-2 ") == {"cpu": 0.1, "random": 0.05}
    assert parse_bots("") == {} and parse_bots("  ") == {}
    assert parse_bots("cpu=1") == {"cpu": 1.0}


@pytest.mark.parametrize("text", ["cpu", "cpu=", "=0.1", "cpu=abc", "cpu=0.1,,random=0.1", "cpu=0.1,cpu=0.2",
                                  "cpu=-0.1", "cpu=0.6,random=0.6", "cpu=nan", "cpu=0.1;random=0.1"])
def test_parse_bots_errors(text: str) -> None:
    with pytest.raises(MarlError) as exc:
        parse_bots(text)
    one_line(exc)


# --------------------------------------------------------------------------------------------------
# Resume
# --------------------------------------------------------------------------------------------------


def test_state_dict_round_trip_reproduces_samples() -> None:
    cfg = {"mode": "pfsp", "latest_ratio": 0.3, "bots": {"cpu": 0.1}}
    rates = rates_with({20: 0.2, 21: 0.5, 22: 0.9})
    mm = make([19, 20, 21, 22], seed=42, **cfg)
    mm.sample(LEARNER, 137, rates)  # advance the generator
    state = json.loads(json.dumps(mm.state_dict()))  # must survive JSON
    expected = [mm.sample(LEARNER, 64, rates) for _ in range(3)]

    other = make(None, seed=999, **cfg)
    other.load_state_dict(state)
    assert other.pool == (19, 20, 21, 22)
    got = [other.sample(LEARNER, 64, rates) for _ in range(3)]
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)


def test_load_state_dict_rejects_bad_state() -> None:
    mm = make([1, 2], seed=1)
    good = mm.state_dict()
    before = mm.sample(LEARNER, 5, WinRates())
    mm.load_state_dict(good)
    bad_states = [
        {},
        {**good, "version": 99},
        {**good, "pool": [1, 1]},
        {**good, "rng": {**good["rng"], "bit_generator": "MT19937"}},
        "not a dict",
    ]
    for bad in bad_states:
        with pytest.raises(MarlError) as exc:
            mm.load_state_dict(bad)  # type: ignore[arg-type]
        one_line(exc)
    assert mm.pool == (1, 2)  # a failed load leaves the matchmaker as it was
    np.testing.assert_array_equal(mm.sample(LEARNER, 5, WinRates()), before)


def test_module_imports_no_torch_or_project_code() -> None:
    # Beyond what importing the package itself loads (its root hands the league the game catalog), matchmaking
    # brings in errors.py and its win-rate book alone: no torch, scipy or sqlalchemy, no other module of the project.
    code = ("import sys, selfplay_cli; root = set(sys.modules); import selfplay_cli.train.matchmaking; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('torch', 'scipy', 'sqlalchemy') or "
            "(m.startswith('selfplay_cli') and m not in root and m not in ('selfplay_cli.errors', "
            "'selfplay_cli.train', 'selfplay_cli.train.matchmaking', 'selfplay_cli.train.win_rates'))]; "
            "print(bad); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr


def test_learner_key_may_equal_a_player_id() -> None:
    # Learner keys are opaque (e.g. learner index 1 while snapshot 1 is a player id): still recorded.
    r = WinRates(decay=1.0, prior=0.0)
    r.update(1, 1, 1.0)
    assert r.p_win(1, 1) == 1.0
