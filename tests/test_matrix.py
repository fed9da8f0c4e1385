"""The score matrix of the league: Nash equilibria of the meta-game (stats.nash), significant 3-cycles
(stats.cycles), the matrix built from a ledger (report.matrix) and `marl league matrix`."""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run

from selfplay_cli.errors import MarlError
from selfplay_cli.league.store import League, PlayerRow
from selfplay_cli.ratings.pairs import pair_records
from selfplay_cli.report.matrix import build_matrix, write_matrix_png
from selfplay_cli.report.terminal import matrix_summary, matrix_table
from selfplay_cli.results import GameResult
from selfplay_cli.stats.cycles import edge_tests, holm_reject, sign_test_pvalue, three_cycles
from selfplay_cli.stats.nash import measured_subgame, solve_zero_sum, symmetric_nash

ENV = "pong"
ABC_ROTATIONS = (["a", "b", "c"], ["b", "c", "a"], ["c", "a", "b"])  # a beats b beats c beats a

# rock, paper, scissors: payoff = score - 0.5 of the row player
RPS = np.array([[0.0, -0.5, 0.5], [0.5, 0.0, -0.5], [-0.5, 0.5, 0.0]])


# --------------------------------------------------------------------------------------------------
# Nash
# --------------------------------------------------------------------------------------------------


def test_nash_of_rock_paper_scissors_is_uniform() -> None:
    res = symmetric_nash(RPS)
    np.testing.assert_allclose(res.mixture, [1 / 3, 1 / 3, 1 / 3], atol=1e-9)
    assert res.value == pytest.approx(0.0, abs=1e-9)
    assert sorted(res.support) == [0, 1, 2]


def test_nash_gives_a_dominated_strategy_no_weight() -> None:
    # A fourth strategy, "weak rock": like rock but it loses a little to rock and does worse against scissors.
    a = np.zeros((4, 4))
    a[:3, :3] = RPS
    a[3, :3] = [-0.1, -0.5, 0.4]
    a[:3, 3] = -a[3, :3]
    res = symmetric_nash(a)
    assert res.mixture[3] == 0.0
    np.testing.assert_allclose(res.mixture[:3], [1 / 3, 1 / 3, 1 / 3], atol=1e-9)
    assert 3 not in res.support
    # A player that beats everyone takes all the weight.
    strong = np.array([[0.0, 0.3, 0.2], [-0.3, 0.0, 0.1], [-0.2, -0.1, 0.0]])
    res = symmetric_nash(strong)
    np.testing.assert_allclose(res.mixture, [1.0, 0.0, 0.0])
    assert res.support == (0,)


def test_zero_sum_solver_on_an_asymmetric_game() -> None:
    # x1 * 2 - x2 = -x1 + x2  ->  x = (0.4, 0.6), value 0.2
    res = solve_zero_sum([[2.0, -1.0], [-1.0, 1.0]])
    np.testing.assert_allclose(res.mixture, [0.4, 0.6], atol=1e-9)
    assert res.value == pytest.approx(0.2, abs=1e-9)


def test_nash_rejects_bad_matrices() -> None:
    with pytest.raises(ValueError, match="antisymmetric"):
        symmetric_nash([[0.0, 0.2], [0.2, 0.0]])
    with pytest.raises(ValueError, match="square"):
        symmetric_nash([[0.0, 0.2, 0.1]])
    with pytest.raises(ValueError, match="non-finite"):
        symmetric_nash([[0.0, np.nan], [np.nan, 0.0]])


def test_measured_subgame_is_the_largest_fully_measured_group() -> None:
    m = np.ones((5, 5), dtype=bool)
    m[0, 1:] = m[1:, 0] = False  # the best player has no measured pair
    assert measured_subgame(m) == [1, 2, 3, 4]
    two_groups = np.zeros((5, 5), dtype=bool)
    for i, j in ((0, 1), (2, 3), (3, 4), (2, 4)):
        two_groups[i, j] = two_groups[j, i] = True
    assert measured_subgame(two_groups) == [2, 3, 4]  # bigger beats better-rated
    two_groups[2, 4] = two_groups[4, 2] = False
    assert measured_subgame(two_groups) == [0, 1]  # same size: the better-rated pair
    assert measured_subgame(np.zeros((3, 3), dtype=bool)) == [0]


# --------------------------------------------------------------------------------------------------
# Cycle statistics
# --------------------------------------------------------------------------------------------------


def test_sign_test_and_holm() -> None:
    assert sign_test_pvalue(10, 0) == pytest.approx(2.0**-10)
    assert sign_test_pvalue(5, 5) == pytest.approx(sum(math.comb(10, k) for k in range(5, 11)) / 1024)
    assert sign_test_pvalue(0, 0) == 1.0
    # Holm: 0.01 <= 0.05/3, 0.02 <= 0.05/2, 0.04 > 0.05/1? no: 0.04 <= 0.05 -> all three rejected
    assert holm_reject([0.04, 0.01, 0.02]).tolist() == [True, True, True]
    # 0.03 > 0.05/2 stops the procedure: only the smallest is rejected
    assert holm_reject([0.01, 0.03, 0.04]).tolist() == [True, False, False]


def test_three_cycles_lists_each_cycle_once() -> None:
    beats = np.zeros((4, 4), dtype=bool)
    for i, j in ((0, 1), (1, 2), (2, 0), (3, 0)):
        beats[i, j] = True
    assert three_cycles(beats) == [(0, 1, 2)]
    beats[2, 0] = False
    beats[0, 2] = True  # transitive now
    assert three_cycles(beats) == []


def test_edge_tests_only_test_measured_pairs() -> None:
    units = np.array([[0, 30, 0], [0, 0, 30], [30, 0, 0]])
    measured = np.ones((3, 3), dtype=bool)
    res = edge_tests(units, measured)
    assert res.tests == 6 and res.beats[0, 1] and res.beats[1, 2] and res.beats[2, 0] and not res.beats[1, 0]
    measured[0, 2] = measured[2, 0] = False
    res = edge_tests(units, measured)
    assert res.tests == 4 and not res.beats[2, 0] and res.p_value[2, 0] == 1.0


# --------------------------------------------------------------------------------------------------
# Ledgers
# --------------------------------------------------------------------------------------------------


@pytest.fixture
def league(tmp_path: Path) -> League:
    lg = League(f"sqlite:///{tmp_path}/league.db")
    yield lg
    lg.close()


def _snap(lg: League, name: str, run: str | None = None, step: int = 0) -> PlayerRow:
    return lg.roster.add_snapshot(env=ENV, run=run, name=name, path=f"/snaps/{name}.safetensors", sha256="0" * 64,
                                  step=step)


def _game(a: int, b: int, score_a: float, seed: int) -> GameResult:
    return GameResult(env=ENV, players=(a, b), seed=seed, scores=(21.0 * score_a, 21.0 * (1 - score_a)),
                      outcome=(score_a, 1.0 - score_a), length=100, truncated=False)


def _play(lg: League, a: PlayerRow, b: PlayerRow, wins: int, draws: int, losses: int) -> None:
    """Record A's wins, draws and losses against B: single games on distinct seeds, seats alternating."""
    results = [1.0] * wins + [0.5] * draws + [0.0] * losses
    m = lg.ledger.create_match(ENV, "match")
    lg.ledger.record_games(m, [_game(a.id, b.id, s, k) if k % 2 == 0 else _game(b.id, a.id, 1.0 - s, k)
                               for k, s in enumerate(results)])


def test_pair_records_count_game_pairs_as_one_unit(league: League) -> None:
    a, b = _snap(league, "a"), _snap(league, "b")
    m = league.ledger.create_match(ENV, "match")
    league.ledger.record_games(m, [
        _game(a.id, b.id, 1.0, 0), _game(b.id, a.id, 0.0, 0),  # seed 0: A wins both -> one unit for A
        _game(a.id, b.id, 1.0, 1), _game(b.id, a.id, 1.0, 1),  # seed 1: the seat decides -> level, no unit
        _game(a.id, b.id, 0.0, 2), _game(b.id, a.id, 0.5, 2),  # seed 2: 0.5 of 2 for A -> unit for B
        _game(a.id, b.id, 0.5, 3),                             # unpaired draw: no unit
        _game(b.id, a.id, 0.0, 4),                             # unpaired A win: a unit
    ])
    games, wins, draws, losses, units = pair_records(league.ledger.games(env=ENV), [a.id, b.id])
    assert games[0, 1] == games[1, 0] == 8
    assert (wins[0, 1], draws[0, 1], losses[0, 1]) == (4, 2, 2)
    assert (wins[1, 0], losses[1, 0]) == (2, 4)
    assert units[0, 1] == 2 and units[1, 0] == 1


def _cycle_league(lg: League) -> list[PlayerRow]:
    """A > B > C > A at 20-0 (significant) and D > E > F > D at 15-5 (p = 0.02 per edge: significant alone,
    not after the correction over the 12 edges tested)."""
    a, b, c, d, e, f = (_snap(lg, n) for n in "abcdef")
    for x, y in ((a, b), (b, c), (c, a)):
        _play(lg, x, y, 20, 0, 0)
    for x, y in ((d, e), (e, f), (f, d)):
        _play(lg, x, y, 15, 0, 5)
    return [a, b, c, d, e, f]


def test_significant_cycle_found_and_insignificant_one_not(league: League) -> None:
    _cycle_league(league)
    rep = build_matrix(league, ENV, top=6, min_games=10)
    names = [p.policy for p in rep.players]
    assert sorted(names) == list("abcdef")
    assert rep.edges.tests == 12
    assert len(rep.cycles) == 1
    cyc = [names[i] for i in rep.cycles[0].players]
    assert cyc in ABC_ROTATIONS
    # the order is the direction of the cycle: each beats the next
    for x, y in zip(cyc, cyc[1:] + cyc[:1], strict=True):
        assert rep.scores[names.index(x), names.index(y)] == 1.0
    assert all(p == pytest.approx(2.0**-20) for p in rep.cycles[0].p_values)
    # the weaker cycle is real in the raw scores and each edge passes alone at 5%, but not after Holm
    d, e = names.index("d"), names.index("e")
    assert rep.scores[d, e] == 0.75 and rep.edges.p_value[d, e] < 0.05 and not rep.edges.beats[d, e]
    # the measured sub-game is one of the two triangles, the mixture over it uniform (a rock-paper-scissors)
    assert len(rep.nash_players) == 3
    np.testing.assert_allclose(rep.nash.mixture, [1 / 3] * 3, atol=1e-9)


def test_under_measured_pairs_left_out_and_the_command_to_fill_them(league: League) -> None:
    a, b, c = _snap(league, "a"), _snap(league, "b"), _snap(league, "c")
    _play(league, a, b, 12, 0, 0)
    _play(league, b, c, 12, 0, 0)
    _play(league, a, c, 3, 0, 0)  # too few games
    rep = build_matrix(league, ENV, min_games=10)
    assert [p.policy for p in rep.players] == ["a", "b", "c"]
    assert rep.under_measured() == [(0, 2, 3)]
    assert not rep.measured[0, 2] and rep.measured[0, 1]
    assert rep.edges.tests == 4 and rep.cycles == ()
    assert rep.fill_command() == "marl league tournament a c --env pong --games-per-pair 10"
    assert rep.fill_command(home="/my league") == ("marl league tournament a c --env pong --games-per-pair 10 "
                                                   "--home '/my league'")
    assert rep.nash_players == (0, 1) and rep.nash.mixture.tolist() == [1.0, 0.0]
    data = rep.to_json()
    json.dumps(data, allow_nan=False)
    assert data["score"][0][0] is None and data["score"][0][2] == 1.0 and data["games"][0][2] == 3
    assert data["under_measured"] == [{"a": "a", "b": "c", "games": 3}]


def test_matrix_png_is_a_valid_image(league: League, tmp_path: Path) -> None:
    import matplotlib.image

    _cycle_league(league)
    rep = build_matrix(league, ENV, top=6)
    out = write_matrix_png(rep, tmp_path / "matrix.png")
    img = matplotlib.image.imread(out)
    assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 300
    assert float(img[..., :3].std()) > 0.05  # not a blank canvas
    assert not list(tmp_path.glob(".*tmp"))  # the temporary file was renamed


def test_terminal_renderings_without_colour_stay_plain(league: League) -> None:
    from rich.console import Console

    _cycle_league(league)
    rep = build_matrix(league, ENV, top=6, min_games=10)
    con = Console(width=80, force_terminal=False, color_system=None, record=True)
    con.print(matrix_table(rep, unicode=False))
    con.print(matrix_summary(rep, unicode=False))
    text = con.export_text()
    assert "\x1b" not in text and all(len(line) <= 80 for line in text.splitlines())
    assert "a > b > c > a" in text and "33.3%" in text


# --------------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------------




def _one_line_error(code: int, out: str, err: str, needle: str) -> None:
    assert code != 0 and out == "" and err.startswith("marl: error: ") and err.count("\n") == 1, (code, out, err)
    assert needle in err, err


def test_cli_matrix_table_json_and_png(home: Path, capsys, tmp_path: Path) -> None:
    with League.open(home=home) as lg:
        _cycle_league(lg)
    code, out, err = run(capsys, "league", "matrix", "--env", "pong", "--top", "6", "--min-games", "10")
    assert code == 0, err
    assert "row player's score % against column player" in out
    assert "a > b > c > a" in out and "Holm" in out and "12 tests" in out
    assert "Nash equilibrium" in out and "33.3%" in out
    assert "Every pair has at least 10 games" not in out  # a-d and so on never played
    assert "marl league tournament" in out and "--games-per-pair 10" in out

    code, out, err = run(capsys, "league", "matrix", "--json")
    assert code == 0, err
    data = json.loads(out, parse_constant=lambda c: pytest.fail(f"non-finite {c} in JSON"))
    elos = [p["elo"] for p in data["players"]]
    assert elos == sorted(elos, reverse=True) and len(elos) == 6
    assert len(data["cycles"]) == 1 and data["cycles"][0]["players"] in ABC_ROTATIONS
    assert data["cycles"][0]["p_values"] == [pytest.approx(2.0**-20, rel=1e-2)] * 3
    assert data["cycle_test"]["tests"] == 12 and data["cycle_test"]["alpha"] == 0.05
    assert len(data["under_measured"]) == 15 - 6 and data["png"] is None
    assert data["command"].startswith("marl league tournament ")
    assert sum(m["weight"] for m in data["nash"]["mixture"]) == pytest.approx(1.0, abs=1e-5)

    png = tmp_path / "m.png"
    code, out, err = run(capsys, "league", "matrix", "--out", str(png), "--json")
    assert code == 0 and json.loads(out)["png"] == str(png)
    assert png.stat().st_size > 1000


@pytest.mark.slow
def test_cli_matrix_command_plays_the_missing_games(home: Path, capsys) -> None:
    with League.open(home=home) as lg:
        lg.roster.ensure_bots(ENV, ["random", "cpu"])
        cpu, rnd = (p for p in sorted(lg.roster.players(env=ENV), key=lambda p: p.name))
        _play(lg, cpu, rnd, 3, 0, 0)
    code, out, err = run(capsys, "league", "matrix", "--min-games", "6", "--json")
    data = json.loads(out)
    assert data["under_measured"] == [{"a": "cpu", "b": "random", "games": 3}] and data["nash"] is None
    words = shlex.split(data["command"])
    assert words[:5] == ["marl", "league", "tournament", "cpu", "random"]
    assert words[5:] == ["--env", "pong", "--games-per-pair", "6", "--home", str(home)]  # MARL_HOME is --home's
    code, out, err = run(capsys, *words[1:], "--quiet")
    assert code == 0, err
    code, out, err = run(capsys, "league", "matrix", "--min-games", "6", "--json")
    data = json.loads(out)
    assert data["games"][0][1] >= 6 and data["command"] is None and data["under_measured"] == []
    assert data["nash"]["mixture"] == [{"policy": "cpu", "weight": 1.0}]


def test_cli_matrix_errors_are_one_line(home: Path, capsys, tmp_path: Path) -> None:
    _one_line_error(*run(capsys, "league", "matrix"), "no rated games")
    with League.open(home=home) as lg:
        a, b = _snap(lg, "a"), _snap(lg, "b")
        _play(lg, a, b, 5, 0, 5)
    _one_line_error(*run(capsys, "league", "matrix", "--top", "1"), "--top must be at least 2")
    _one_line_error(*run(capsys, "league", "matrix", "--min-games", "0"), "--min-games must be at least 1")
    _one_line_error(*run(capsys, "league", "matrix", "--run", "nope"), "no run named 'nope'")
    _one_line_error(*run(capsys, "league", "matrix", "--out", str(tmp_path / "no" / "m.png")), "no folder")
    _one_line_error(*run(capsys, "league", "matrix", "--out", str(tmp_path / "m.txt")), "must end in .png")
    (tmp_path / "d.png").mkdir()
    _one_line_error(*run(capsys, "league", "matrix", "--out", str(tmp_path / "d.png")), "is a directory")
    _one_line_error(*run(capsys, "league", "matrix", "--env", "chess"), "chess")


def test_matrix_of_a_run_keeps_its_snapshots_and_the_bots(league: League) -> None:
    league.roster.create_run("r1", ENV, {})
    league.roster.create_run("r2", ENV, {})
    league.roster.ensure_bots(ENV, ["random"])
    rnd = league.roster.players(env=ENV, kind="bot")[0]
    x1, x2, y1 = _snap(league, "x1", "r1", 10), _snap(league, "x2", "r1", 20), _snap(league, "y1", "r2", 10)
    for s in (x1, x2, y1):
        _play(league, s, rnd, 8, 0, 4)
    rep = build_matrix(league, top=10, run="r1")
    assert sorted(p.policy for p in rep.players) == ["r1/x1", "r1/x2", "random"]
    with pytest.raises(MarlError, match="no run named 'r3'"):
        build_matrix(league, run="r3")
    with pytest.raises(MarlError, match="--top must be at least 2"):
        build_matrix(league, top=1)
