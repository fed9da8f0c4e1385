"""Games played for stakes (poker): a result is worth the chips won, not the hand, so a player that wins many small
pots and loses the big ones is rated behind, a match's score is its chips, and the SPRT and the gate count them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from selfplay_cli.envs import get_env
from selfplay_cli.evaluation.match import run_match
from selfplay_cli.league.store import League
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.ratings.pairs import head_to_head
from selfplay_cli.results import GameResult, Rules
from selfplay_cli.stats.elo import score_to_elo
from selfplay_cli.stats.match import match_stats, points_stats
from selfplay_cli.stats.sprt import round_counts, sprt_llr

KUHN = "openspiel:kuhn_poker"


def test_a_hand_is_worth_the_chips_it_wins():
    """Kuhn poker's stakes are its pot, 2 chips (OpenSpiel's max_utility): +1 chip is 1/2 + 2 / 8 = 0.75, +2 is 1,
    -1 is 0.25, a split 0.5; tic-tac-toe's stakes of 1 give exactly its wins, draws and losses."""
    rules = Rules.of(get_env(KUHN))
    assert rules.stakes == 2.0
    out = rules.outcome(np.array([[1.0, 2.0, -1.0, -2.0, 0.0], [-1.0, -2.0, 1.0, 2.0, 0.0]]))
    assert out.tolist() == [[0.75, 1.0, 0.25, 0.0, 0.5], [0.25, 0.0, 0.75, 1.0, 0.5]]
    board = Rules.of(get_env("openspiel:tic_tac_toe"))
    assert board.stakes == 1.0
    assert board.outcome(np.array([[1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]])).tolist() == [[1, 0, 0.5], [0, 1, 0.5]]
    assert Rules.from_json(rules.to_json()) == rules and "stakes" not in Rules().to_json()
    assert Rules.of(get_env("openspiel:leduc_poker(players=3)")).stakes is None  # a free-for-all: by the order
    for bad in (0.0, -1.0, math.inf):
        with pytest.raises(ValueError):
            Rules(stakes=bad)
    with pytest.raises(ValueError):
        Rules(n_seats=3, kind="free-for-all", stakes=2.0)


def _hands(lg: League, a: int, b: int, chips: list[float]) -> None:
    """Hands of A against B, A's chips in each, in seat-swapped pairs (seats alternating, a seed a pair)."""
    rules = Rules.of(get_env(KUHN))
    games = []
    for k, c in enumerate(chips):
        scores = np.array([[c], [-c]]) if k % 2 == 0 else np.array([[-c], [c]])
        players = (a, b) if k % 2 == 0 else (b, a)
        out = rules.outcome(scores)[:, 0]
        games.append(GameResult(KUHN, players, k // 2, tuple(scores[:, 0]), tuple(out), 3, False))
    lg.ledger.record_games(lg.ledger.create_match(KUHN, "match", {"rules": rules.to_json()}), games)


def test_the_ladder_rates_chips_not_hands(tmp_path):
    """``small`` wins 60% of its hands against ``big`` by 1 chip and loses the other 40% by 2: more hands, fewer
    chips (-0.2 a hand). The ladder puts it below, its score is its chips (0.6 * 0.75 + 0.4 * 0 = 0.45), its W-D-L
    still counts the hands."""
    with League(f"sqlite:///{tmp_path / 'l.db'}") as lg:
        lg.roster.ensure_bots(KUHN, ["random"])
        lg.roster.create_run("r", KUHN, {})
        small = lg.roster.add_snapshot(env=KUHN, run="r", name="small", path="r/small", sha256="1" * 64, step=1).id
        big = lg.roster.add_snapshot(env=KUHN, run="r", name="big", path="r/big", sha256="2" * 64, step=2).id
        rnd = lg.roster.find_players("random", KUHN)[0].id
        _hands(lg, small, big, [1.0, -2.0, 1.0, -2.0, 1.0, 1.0, 1.0, -2.0, 1.0, -2.0] * 10)
        _hands(lg, small, rnd, [1.0, -1.0] * 10)
        _hands(lg, big, rnd, [1.0, -1.0] * 10)
        rows = {r.policy: r for r in ladder(lg, KUHN, bootstrap=0)}
        h = head_to_head(lg, small, big)
    assert rows["r/big"].elo > rows["r/small"].elo
    assert (h["wins"], h["losses"]) == (60, 40) and h["score"] == pytest.approx(0.45)
    assert sorted(map(len, h["rounds"])) == [2] * 50  # seat-swapped pairs
    assert sorted({sum(r) for r in h["rounds"]}) == [0.75, 1.5]  # +1 and -2 chips; +1 and +1


def test_a_matchs_figures_are_its_chips():
    """A Kuhn poker match: its score is 1/2 + A's mean chips / 4 (its return over its games), not the share of hands
    won; the interval and LOS come from the pairs' mean points (points_stats); W-D-L still count the hands."""
    a = ScriptedPolicy(KUHN, "random", seed=1)
    b = ScriptedPolicy(KUHN, "random", seed=2)
    b.id = "another random"
    r = run_match(a, b, games=400, first_seed=0)
    chips = r.points_for / r.games
    assert r.stats.score == pytest.approx(0.5 + chips / 4)
    pts = np.array([x for p in r.round_points for x in p])
    assert set(np.unique(pts)) <= {0.0, 0.25, 0.5, 0.75, 1.0} and np.any((pts == 0.25) | (pts == 0.75))
    means = np.array([np.mean(p) for p in r.round_points])
    se = means.std() / math.sqrt(means.size)
    assert r.stats.elo_low == pytest.approx(score_to_elo(r.stats.score - 1.959964 * se), abs=0.01)
    assert r.stats.wins == int((pts > 0.5).sum()) and r.stats.losses == int((pts < 0.5).sum())


def test_points_stats_by_hand_and_as_match_stats_on_whole_results():
    """Two pairs of hands (0.75, 0.25) and (1.0, 0.75): score 0.6875; pair means 0.5 and 0.875, their spread 0.1875,
    se 0.1875 / sqrt(2); W-D-L 3-0-1. On wins, draws and losses only, points_stats is match_stats."""
    s = points_stats([[0.75, 0.25], [1.0, 0.75]], paired=True)
    assert s.score == pytest.approx(0.6875) and (s.wins, s.draws, s.losses) == (3, 0, 1)
    se = 0.1875 / math.sqrt(2)
    assert s.elo_low == pytest.approx(score_to_elo(0.6875 - 1.959964 * se), abs=0.01)
    assert s.los == pytest.approx(0.5 * (1 + math.erf(0.1875 / (se * math.sqrt(2)))))
    whole = [[1.0, 0.0], [1.0, 0.5], [1.0, 1.0], [0.0, 0.5]]
    assert points_stats(whole, paired=True) == match_stats(4, 2, 2, pentanomial=(0, 1, 1, 1, 1))
    assert points_stats(whole, paired=False) == match_stats(4, 2, 2)


def test_the_sprt_counts_chips_in_17_levels_and_hands_as_ever():
    """A round's mean points at 17 levels (1/16 apart) where results are worth any points; pentanomial or trinomial
    counts otherwise, as before. The categorical LLR is the GSPRT's over those levels: with every round at 0.75 it
    favours H1 (+10 Elo) over H0 (0 Elo)."""
    counts, model = round_counts([[0.75, 0.25], [1.0, 0.75], [0.75, 0.75]], paired=True)
    assert model == "categorical" and len(counts) == 17 and counts[8] == 1 and counts[14] == 1 and counts[12] == 1
    assert round_counts([[1.0, 0.0], [1.0, 1.0]], paired=True) == ([0, 0, 1, 0, 1], "pentanomial")
    assert round_counts([[1.0], [0.5], [0.0]], paired=False) == ([1, 1, 1], "trinomial")
    up = [0] * 17
    up[12] = 40
    assert sprt_llr(up, 0.0, 10.0, model="categorical") > 0.0
    down = [0] * 17
    down[4] = 40
    assert sprt_llr(down, 0.0, 10.0, model="categorical") < 0.0
    with pytest.raises(ValueError):
        sprt_llr(up, 0.0, 10.0, model="categorical", elo_model="normalized")


def test_a_runs_summary_gives_the_chips_against_each_bot():
    """The summary's score against a scripted player is its points (3 hands won and 1 lost, worth 2.75 points: 69%),
    not its hands (75%), with an interval around it."""
    from selfplay_cli.train.progress import SnapshotRecord

    rec = SnapshotRecord("k/s1", "learner", 1, {"random": (3, 0, 1), "other": (3, 0, 1)}, points={"random": 2.75})
    assert rec.score("random") == pytest.approx(0.6875) and rec.score("other") == pytest.approx(0.75)
    low, high = rec.interval("random")
    assert low < 0.6875 < high
    assert rec.to_json()["vs"]["random"]["score"] == 0.6875
