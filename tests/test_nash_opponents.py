"""`--opponents nash`: PSRO's meta-strategy. The run's Nash mixture from the ledger (rated.meta_nash), the matchmaker
drawing from it (train.matchmaking), the payoff in points or in the game's scores (league.pairs), and a run through
the CLI whose gauntlets measure every pair of its snapshots."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run, run_json
from scipy.stats import chisquare

from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.ratings.meta_nash import nash_mixture, run_nash
from selfplay_cli.ratings.pairs import PAYOFFS, pair_payoffs
from selfplay_cli.report.matrix import build_matrix
from selfplay_cli.results import GameResult
from selfplay_cli.train.matchmaking import NASH_PAYOFFS, Matchmaker, MatchmakerConfig
from selfplay_cli.train.win_rates import WinRates

ENV = "pong"
KUHN = "openspiel:kuhn_poker"


@pytest.fixture
def league(tmp_path: Path) -> League:
    lg = League(f"sqlite:///{tmp_path}/league.db")
    lg.roster.create_run("r", ENV, {})
    yield lg
    lg.close()


def _snap(lg: League, name: str) -> PlayerRow:
    return lg.roster.add_snapshot(env=ENV, run="r", name=name, path=f"/snaps/{name}.safetensors", sha256="0" * 64)


def _play(lg: League, a: PlayerRow, b: PlayerRow, results: list[tuple[float, float]]) -> None:
    """Games of A against B, seats alternating: each ``(A's points, A's score)``; B scores minus A's score."""
    games = []
    for k, (pts, score) in enumerate(results):
        first = k % 2 == 0
        players, outcome, scores = ((a.id, b.id), (pts, 1 - pts), (score, -score)) if first else \
            ((b.id, a.id), (1 - pts, pts), (-score, score))
        games.append(GameResult(env=ENV, players=players, seed=k, scores=scores, outcome=outcome, length=10,
                                truncated=False))
    lg.ledger.record_games(lg.ledger.create_match(ENV, "match"), games)


def _wins(n: int, losses: int = 0) -> list[tuple[float, float]]:
    return [(1.0, 1.0)] * n + [(0.0, -1.0)] * losses


def _rps_league(lg: League) -> tuple[PlayerRow, PlayerRow, PlayerRow]:
    """Three snapshots in a cycle. Row's payoff (points - 1/2): A-B 0.25 (3 of 4), A-C -0.25 (1 of 4), B-C 0.5 (4 of
    4). By hand, x^T P = 0 for every column: -x_B/4 + x_C/4 = 0, x_A/4 - x_C/2 = 0, so x = (1/2, 1/4, 1/4), the one
    equilibrium (every cycle edge positive)."""
    a, b, c = _snap(lg, "a"), _snap(lg, "b"), _snap(lg, "c")
    _play(lg, a, b, _wins(3, 1))
    _play(lg, a, c, _wins(1, 3))
    _play(lg, b, c, _wins(4))
    return a, b, c


def _nash_matchmaker(pool: list[int]) -> Matchmaker:
    # window 1: the nash mode mixes over the whole pool regardless; latest_ratio 0: every game from the pool
    mm = Matchmaker(MatchmakerConfig(mode="nash", window=1, latest_ratio=0.0), np.random.default_rng(7), {})
    mm.set_pool(pool)
    return mm


def test_nash_opponents_follow_a_hand_solved_matrix(league: League) -> None:
    a, b, c = _rps_league(league)
    found = run_nash(league, "r")
    assert found is not None and found.over == (a.id, b.id, c.id) and found.games == 12
    mm = _nash_matchmaker([a.id, b.id, c.id])
    assert mm.probabilities(0, WinRates()) == {a.id: 1 / 3, b.id: 1 / 3, c.id: 1 / 3}  # no mixture yet: uniform
    mm.set_mixture(found.weights)
    probs = mm.probabilities(0, WinRates())
    assert probs == pytest.approx({a.id: 0.5, b.id: 0.25, c.id: 0.25}, abs=1e-6)
    draws = mm.sample(0, 20_000, WinRates())
    counts = [int(np.sum(draws == p)) for p in (a.id, b.id, c.id)]
    assert chisquare(counts, [10_000, 5_000, 5_000]).pvalue > 0.001
    assert nash_mixture(league, "r") == pytest.approx({"r/a": 0.5, "r/b": 0.25, "r/c": 0.25}, abs=1e-6)
    # a snapshot that can play no seat here (another role's): the mixture over the others, renormalised
    assert mm.probabilities(0, WinRates(), among={b.id, c.id}) == pytest.approx({b.id: 0.5, c.id: 0.5})


def test_the_mixture_a_run_had_at_an_earlier_step(league: League) -> None:
    a, b, c = (league.roster.add_snapshot(env=ENV, run="r", name=n, path=f"/snaps/{n}.safetensors", sha256="0" * 64,
                                          step=step) for n, step in (("a", 0), ("b", 10), ("c", 20)))
    _play(league, a, b, _wins(3, 1))  # the cycle of _rps_league: (1/2, 1/4, 1/4) over all three
    _play(league, a, c, _wins(1, 3))
    _play(league, b, c, _wins(4))
    then = run_nash(league, "r", until_step=10)  # before C: A beats B, the pure equilibrium
    assert then.over == (a.id, b.id) and then.by_name() == {"r/a": 1.0} and then.games == 4
    assert run_nash(league, "r", until_step=25).by_name() == pytest.approx({"r/a": 0.5, "r/b": 0.25, "r/c": 0.25})
    assert run_nash(league, "r", until_step=5).by_name() == {"r/a": 1.0}  # one snapshot: itself


def test_new_games_change_the_mixture_on_the_next_solve(league: League) -> None:
    a, b, c = _rps_league(league)
    mm = _nash_matchmaker([a.id, b.id, c.id])
    mm.set_mixture(run_nash(league, "r").weights)
    _play(league, c, b, _wins(8))  # B-C is now 4 of 12 for B: C beats both, the pure equilibrium
    assert mm.probabilities(0, WinRates())[a.id] == pytest.approx(0.5)  # (until solved again)
    mm.set_mixture(run_nash(league, "r").weights)
    assert mm.probabilities(0, WinRates()) == pytest.approx({c.id: 1.0})


def test_a_snapshot_not_measured_yet_weighs_nothing_and_no_games_means_no_mixture(league: League) -> None:
    a, b = _snap(league, "a"), _snap(league, "b")
    assert run_nash(league, "r") is None  # two snapshots, no games: uniform in the matchmaker
    _play(league, a, b, _wins(3, 1))
    c = _snap(league, "c")  # newer, not rated yet
    found = run_nash(league, "r")
    assert found.over == (a.id, b.id) and found.weights == {a.id: 1.0, b.id: 0.0, c.id: 0.0}
    with pytest.raises(LeagueError, match="no run named"):
        run_nash(league, "nope")
    league.roster.create_run("empty", ENV, {})
    with pytest.raises(LeagueError, match="no Nash mixture yet"):
        nash_mixture(league, "empty")


def test_payoff_in_score_units_gives_another_mixture(league: League, tmp_path: Path) -> None:
    # A wins 3 small pots (+1) and loses 1 big one (-5): 3 of 4 in points, -0.5 a game in score
    a, b = _snap(league, "a"), _snap(league, "b")
    _play(league, a, b, [(1.0, 1.0)] * 3 + [(0.0, -5.0)])
    table = league.ledger.games(env=ENV)
    np.testing.assert_allclose(pair_payoffs(table, [a.id, b.id], "points"), [[0.0, 0.25], [-0.25, 0.0]])
    np.testing.assert_allclose(pair_payoffs(table, [a.id, b.id], "score"), [[0.0, -0.5], [0.5, 0.0]])
    assert nash_mixture(league, "r") == {"r/a": 1.0}
    assert nash_mixture(league, "r", payoff="score") == {"r/b": 1.0}
    by_points = build_matrix(league, ENV, run="r", min_games=1)
    by_score = build_matrix(league, ENV, run="r", min_games=1, payoff="score")
    names = [p.policy for p in by_score.players]
    assert by_points.to_json()["nash"]["mixture"] == [{"policy": "r/a", "weight": 1.0}]
    assert by_score.to_json()["nash"]["mixture"] == [{"policy": "r/b", "weight": 1.0}]
    assert by_score.to_json()["nash"]["payoff"] == "score" and names  # the players are the same either way
    # the cells show the payoff the mixture was solved from: A's -0.5 a game, not its 75% of the points
    i, j = names.index("r/a"), names.index("r/b")
    assert by_score.to_json()["payoffs"][i][j] == -0.5 and by_score.to_json()["payoffs"][j][i] == 0.5
    assert by_points.to_json()["payoffs"] is None and by_points.cell(i, j) == ("75", 0.75)
    assert by_score.cell(i, j) == ("-0.50", 0.0) and by_score.cell(j, i) == ("+0.50", 1.0)
    from rich.console import Console

    from selfplay_cli.report.terminal import matrix_table

    console = Console(width=120, record=True)
    console.print(matrix_table(by_score, unicode=False))
    shown = console.export_text()
    assert "half the score" in shown and "-0.50" in shown and "+0.50" in shown and "75" not in shown
    from selfplay_cli.report.matrix import write_matrix_png

    png = write_matrix_png(by_score, tmp_path / "m.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(LeagueError, match="payoff"):
        run_nash(league, "r", payoff="chips")
    assert NASH_PAYOFFS == PAYOFFS  # (the matchmaker's names of them, which imports nothing of the league)


@pytest.mark.slow
def test_a_nash_run_through_the_cli_measures_every_pair_and_shows_its_mixture(tmp_path: Path, capsys) -> None:
    home = tmp_path / "league"
    for game, wrong, says in (
            (KUHN, ("--nash-payoff", "chips"), "unknown Nash payoff 'chips' (expected one of points, score)"),
            (KUHN, ("--eval-games", "0"), "--opponents nash draws from the Nash mixture of the run's rated games: it "
                                          "needs --eval-games above 0"),
            ("tests.games.chase:parallel_env", (),
             "the seats of tests.games.chase:parallel_env hold different roles (hunter, runner), whose snapshots never "
             "meet: use --opponents pfsp")):
        code, _, err = run(capsys, "train", game, "--agents", "1", "--opponents", "nash", *wrong, "--steps", "100",
                           "--home", str(home))
        assert code == 2 and says in err and "Traceback" not in err and not home.exists()
    report = run_json(capsys, "train", KUHN, "--agents", "1", "--opponents", "nash", "--nash-payoff", "score",
                      "--steps", "10240", "--snapshot-steps", "2048", "--games", "16", "--seed", "0",
                      "--eval-games", "4", "--eval-older", "0",  # (nash: every earlier snapshot all the same)
                      "--eval-playoff", "0", "--eval", "inline", "--quiet", "--home", str(home))
    assert len(report["snapshots"]) == 6  # s0, s2k, s4k, s6k, s8k, s10k
    assert report["nash"] and sum(report["nash"].values()) == pytest.approx(1.0)
    assert set(report["nash"]) <= set(report["snapshots"])
    league = League.open(home=home, readonly=True)
    try:
        same = league.ledger.same_weights(KUHN)
        ids = sorted({same.get(p.id, p.id) for p in league.roster.players(env=KUHN, kind="snapshot")})
        table = league.ledger.games(env=KUHN, players=ids)
        met = {frozenset(pair) for pair in zip(table.player_a.tolist(), table.player_b.tolist(), strict=True)}
        missing = [(x, y) for i, x in enumerate(ids) for y in ids[i + 1:] if frozenset((x, y)) not in met]
        assert len(ids) >= 3 and missing == []  # the matrix of the run's snapshots is whole
        counts = {}
        for pair in zip(table.player_a.tolist(), table.player_b.tolist(), strict=True):
            counts[frozenset(pair)] = counts.get(frozenset(pair), 0) + 1
        assert min(counts.values()) >= 4  # every cell its --eval-games: none cut short by a clear history
        assert nash_mixture(league, report["run"], payoff="score") == pytest.approx(report["nash"], abs=1e-6)
    finally:
        league.close()
    lines = [json.loads(s) for s in (home / "runs" / report["run"] / "metrics.jsonl").read_text().splitlines()]
    assert lines and all({"nash/support", "nash/weights", "nash/solved_step"} <= set(line) for line in lines)
    assert lines[0]["nash/weights"] == {f"{report['run']}/s0": 1.0}  # one snapshot: all its weight
    # solved again at the moment of s8k, over the snapshots whose gauntlets were in then: s0 to s6k (6 pairs x 4 games)
    assert lines[-1]["nash/over"] == 4 and lines[-1]["nash/games"] == 24 and lines[-1]["nash/solved_step"] == 8192
    assert sum(lines[-1]["nash/weights"].values()) == pytest.approx(1.0)

    code, out, err = run(capsys, "league", "matrix", "--run", report["run"], "--min-games", "1", "--payoff", "score",
                         "--json", "--home", str(home))
    assert code == 0, err
    assert json.loads(out)["nash"]["payoff"] == "score"
    code, _, err = run(capsys, "league", "matrix", "--run", report["run"], "--payoff", "chips", "--home", str(home))
    assert code == 2 and "--payoff must be one of points, score" in err and "Traceback" not in err


def _weights(net) -> dict:
    return {k: v.detach().clone() for k, v in net.state_dict().items()}


def test_a_psro_oracle_restarts_from_its_first_weights_after_each_snapshot_but_the_final(tmp_path: Path) -> None:
    import torch

    from selfplay_cli.policies.snapshot_reader import load_snapshot
    from selfplay_cli.train.config import TrainConfig
    from selfplay_cli.train.loop import Trainer

    league = League.open(tmp_path / "h")
    try:
        cfg = TrainConfig.from_dict({"env": KUHN, "run": "r", "agents": 1, "games": 8, "eval_games": 2,
                                     "restart_at_snapshot": True, "snapshot_steps": 1000,
                                     "opponents": {"mode": "nash", "nash_payoff": "score"}})
        league.roster.create_run("r", cfg.env, cfg.to_dict(), algo=cfg.algo)
        trainer = Trainer(league, cfg)
        trainer.moments.write("start")
        learner = trainer.learners[0]
        first = _weights(learner.net)

        def teach() -> dict:  # (as training would move them)
            with torch.no_grad():
                for p in learner.net.parameters():
                    p.add_(0.25)
            learner.updates = 7
            return _weights(learner.net)

        taught = teach()
        trainer.state.steps = 1000
        trainer.moments.write("steps")
        (row,) = [p for p in league.roster.players(kind="snapshot") if p.name == "s1k"]
        tensors, _ = load_snapshot(league.home / row.path)
        assert all(torch.equal(tensors[k], taught[k]) for k in taught)  # the snapshot holds what it learned
        assert all(torch.equal(v, first[k]) for k, v in _weights(learner.net).items())  # then the restart
        assert learner.updates == 0  # its optimiser and schedule too
        taught = teach()
        trainer.state.steps = 1500
        trainer.moments.write("final")
        assert all(torch.equal(v, taught[k]) for k, v in _weights(learner.net).items())  # the final: no restart
        saved = torch.load(trainer.moments.state_path, weights_only=True)
        assert all(torch.equal(saved["first"][0]["net"][k], first[k]) for k in first)  # a resumed run has them
    finally:
        league.close()


def test_restart_at_snapshot_with_league_roles_is_one_line(tmp_path: Path, capsys) -> None:
    home = tmp_path / "league"
    code, _, err = run(capsys, "train", "tests.games.tictactoe:env", "--league", "alphastar",
                       "--restart-at-snapshot", "--steps", "100", "--home", str(home))
    assert code == 2 and "with --league each role's own rule says when a learner restarts" in err
    assert "Traceback" not in err and not home.exists()


@pytest.mark.slow
def test_a_restarted_oracle_learns_at_the_full_rate_even_when_its_interval_is_shorter_than_a_rollout(
        tmp_path: Path, capsys) -> None:
    home = tmp_path / "league"
    # 32 games x a 128-step PPO rollout = 4,096 steps an update, more than the 2,048 between snapshots
    report = run_json(capsys, "train", KUHN, "--agents", "1", "--opponents", "nash", "--nash-payoff", "score",
                      "--latest-ratio", "0", "--restart-at-snapshot", "--steps", "12288", "--snapshot-steps", "2048",
                      "--games", "32", "--seed", "0", "--eval-games", "2", "--eval-playoff", "0", "--eval", "inline",
                      "--quiet", "--home", str(home))
    lines = [json.loads(s) for s in (home / "runs" / report["run"] / "metrics.jsonl").read_text().splitlines()]
    assert lines and all(line["learner/lr"] == pytest.approx(2e-3) for line in lines)  # each update: a restart's
    league = League.open(home=home, readonly=True)
    try:
        rows = [p for p in league.roster.players(env=KUHN, kind="snapshot") if p.run == report["run"]]
        same = league.ledger.same_weights(KUHN)
        assert len(rows) >= 3 and not same  # each snapshot learned something of its own from the first weights
    finally:
        league.close()
