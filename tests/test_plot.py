"""A run's rating curves (report.plots), their terminal chart (report.terminal) and `marl league plot`."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from cli_helpers import run

from selfplay_cli.errors import MarlError
from selfplay_cli.league.store import League, PlayerRow
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.report.plots import format_steps, run_curves, write_run_plot
from selfplay_cli.report.terminal import curves_chart, curves_summary, nice_ticks
from selfplay_cli.results import GameResult

ENV = "pong"
BRAILLE = range(0x2800, 0x2900)


def _game(a: int, b: int, score_a: float, seed: int) -> GameResult:
    return GameResult(env=ENV, players=(a, b), seed=seed, scores=(21.0 * score_a, 21.0 * (1 - score_a)),
                      outcome=(score_a, 1.0 - score_a), length=100, truncated=False)


def _play(lg: League, a: PlayerRow, b: PlayerRow, wins: int, losses: int) -> None:
    results = [1.0] * wins + [0.0] * losses
    m = lg.ledger.create_match(ENV, "match")
    lg.ledger.record_games(m, [_game(a.id, b.id, s, k) if k % 2 == 0 else _game(b.id, a.id, 1.0 - s, k)
                               for k, s in enumerate(results)])


def _snap(lg: League, run: str, name: str, step: int, learner: str | None) -> PlayerRow:
    return lg.roster.add_snapshot(env=ENV, run=run, name=name, path=f"/snaps/{run}/{name}.safetensors", sha256="0" * 64,
                                  step=step, meta={"learner": learner} if learner else {})


def _bots(lg: League) -> tuple[PlayerRow, PlayerRow]:
    lg.roster.ensure_bots(ENV, ["random", "cpu"])
    by_name = {p.name: p for p in lg.roster.players(env=ENV, kind="bot")}
    return by_name["random"], by_name["cpu"]


def _two_learner_run(lg: League, run: str = "r1") -> None:
    """``left`` gets better with training (10-10, 14-6, 18-2 against random), ``right`` worse (13-7, 10-10, 7-13);
    cpu beats random."""
    lg.roster.create_run(run, ENV, {})
    rnd, cpu = _bots(lg)
    _play(lg, cpu, rnd, 16, 4)
    for k, step in enumerate((100_000, 200_000, 300_000)):
        left = _snap(lg, run, f"ep{k}-left", step, "left")
        right = _snap(lg, run, f"ep{k}-right", step, "right")
        _play(lg, left, rnd, 10 + 4 * k, 10 - 4 * k)
        _play(lg, right, rnd, 13 - 3 * k, 7 + 3 * k)
        _play(lg, left, cpu, 2 + k, 8 - k)
        _play(lg, right, cpu, 2, 8)


@pytest.fixture
def league(tmp_path: Path) -> League:
    lg = League(f"sqlite:///{tmp_path}/league.db")
    yield lg
    lg.close()


# --------------------------------------------------------------------------------------------------
# curves
# --------------------------------------------------------------------------------------------------


def test_run_curves_a_line_per_learner_and_the_bots(league: League) -> None:
    _two_learner_run(league)
    curves = run_curves(league, "r1")
    assert curves.env == ENV and curves.run == "r1" and curves.anchor == ("random", 1000.0)
    assert [c.learner for c in curves.curves] == ["left", "right"]
    left, right = curves.curves
    assert [p.step for p in left.points] == [100_000, 200_000, 300_000]
    assert [p.policy for p in left.points] == ["r1/ep0-left", "r1/ep1-left", "r1/ep2-left"]
    assert left.points[0].elo < left.points[1].elo < left.points[2].elo
    assert right.points[0].elo > right.points[1].elo > right.points[2].elo
    assert [b.name for b in curves.bots] == ["cpu", "random"]
    rows = {r.policy: r for r in ladder(league, ENV)}  # the ladder's own numbers
    for p in left.points + right.points:
        assert (p.elo, p.ci_low, p.ci_high) == (rows[p.policy].elo, rows[p.policy].ci_low, rows[p.policy].ci_high)
        assert p.ci_low < p.elo < p.ci_high
    json.dumps(curves.to_json(), allow_nan=False)


def test_one_network_run_is_one_line_named_after_the_run(league: League) -> None:
    league.roster.create_run("solo", ENV, {})
    rnd, _ = _bots(league)
    for k in range(2):
        _play(league, _snap(league, "solo", f"ep{k}", 1000 * (k + 1), None), rnd, 6 + k, 4 - k)
    curves = run_curves(league, "solo")
    assert [c.learner for c in curves.curves] == ["solo"] and len(curves.curves[0].points) == 2
    assert [b.name for b in curves.bots] == ["random"]  # cpu never played: no level for it


def test_write_run_plot_writes_a_valid_png(league: League, tmp_path: Path) -> None:
    import matplotlib.image

    _two_learner_run(league)
    out = tmp_path / "plots" / "r1.png"
    out.parent.mkdir()
    out.write_bytes(b"old")
    assert write_run_plot(league, "r1", out) == out
    img = matplotlib.image.imread(out)
    assert img.shape[:2] == (550, 990)  # 9 x 5 inches at 110 dpi
    assert float(img[..., :3].std()) > 0.05
    assert [p.name for p in out.parent.iterdir()] == ["r1.png"]  # replaced; no temporary file left


def test_write_run_plot_errors(league: League, tmp_path: Path) -> None:
    _two_learner_run(league)
    league.roster.create_run("empty", ENV, {})
    with pytest.raises(MarlError, match="no run named 'nope' \\(runs: r1, empty\\)"):
        write_run_plot(league, "nope", tmp_path / "x.png")
    with pytest.raises(MarlError, match="run 'empty' has no rated snapshots yet"):
        write_run_plot(league, "empty", tmp_path / "x.png")
    with pytest.raises(MarlError, match="no folder"):
        write_run_plot(league, "r1", tmp_path / "missing" / "x.png")
    with pytest.raises(MarlError, match="must end in .png"):
        write_run_plot(league, "r1", tmp_path / "x.jpg")
    assert not (tmp_path / "x.png").exists()


# --------------------------------------------------------------------------------------------------
# terminal chart
# --------------------------------------------------------------------------------------------------


def test_nice_ticks_and_step_labels() -> None:
    assert nice_ticks(0, 300_000, 3) == [0, 100_000, 200_000, 300_000]
    assert nice_ticks(812, 1263, 5) == [900, 1000, 1100, 1200]
    assert [format_steps(x) for x in (0, 950, 300_000, 1_500_000, 6_000_000)] == ["0", "950", "300k", "1.5M", "6M"]


def _plot_area(text: str) -> tuple[list[str], int, int]:
    """The chart's rows and the first/last plot column (from the x axis line ``   +-----``)."""
    lines = text.splitlines()
    axis = next(i for i, line in enumerate(lines) if line.strip() and set(line.strip()) <= {"+", "-"})
    start = lines[axis].index("+") + 1
    return lines[1:axis], start, len(lines[axis].rstrip()) - 1


def test_ascii_chart_puts_the_points_where_they_belong(league: League) -> None:
    _two_learner_run(league)
    curves = run_curves(league, "r1")
    text = curves_chart(curves, width=80, unicode=False).plain
    assert all(len(line) <= 80 for line in text.splitlines())
    assert all(ord(ch) < 128 for ch in text)
    rows, first, last = _plot_area(text)

    def row_of(marker: str, col: int) -> int:
        hits = [r for r, line in enumerate(rows) if len(line) > col and line[col] == marker]
        assert hits, (marker, col, text)
        return hits[0]

    # left ("o") climbs from its first snapshot to its last (the run's best: "*"), right ("x") falls; up is a
    # smaller row number
    assert row_of("o", first) > row_of("*", last)
    assert row_of("x", first) < row_of("x", last)
    cpu_row = next(r for r, line in enumerate(rows) if line.rstrip().endswith(" cpu"))
    random_row = next(r for r, line in enumerate(rows) if line.rstrip().endswith(" random"))
    assert cpu_row < random_row and set(rows[cpu_row][first:last + 1]) <= {"-", "o", "x", ".", ":", "*"}
    assert "o left" in text and "x right" in text and "steps" in text and "100k" in text and "300k" in text


def test_braille_chart_fits_its_width(league: League) -> None:
    _two_learner_run(league)
    curves = run_curves(league, "r1")
    chart = curves_chart(curves, width=72, unicode=True)
    assert all(len(line) <= 72 for line in chart.plain.splitlines())
    assert any(ord(ch) in BRAILLE for ch in chart.plain)
    assert any(span.style for span in chart.spans)  # coloured
    summary = curves_summary(curves).plain
    assert "left: 3 rated snapshots\n  latest  r1/ep2-left (300k steps): " in summary
    assert "right: 3 rated snapshots" in summary and "highest r1/ep0-right (100k steps): " in summary
    assert "scripted players\n  cpu: " in summary


# --------------------------------------------------------------------------------------------------
# what a figure says it shows, it shows: the best snapshot, bounds, a team's equal curves
# --------------------------------------------------------------------------------------------------


def _twin_run(lg: League, run: str = "twin") -> None:
    """A team of two learners with the same record at every moment (as a team's members rated by the same team
    games): their curves are equal."""
    lg.roster.create_run(run, ENV, {})
    rnd, cpu = _bots(lg)
    _play(lg, cpu, rnd, 16, 4)
    for k, step in enumerate((100_000, 200_000, 300_000)):
        for side in ("left", "right"):
            snap = _snap(lg, run, f"s{k}-{side}", step, side)
            _play(lg, snap, rnd, 10 + 3 * k, 10 - 3 * k)
            _play(lg, snap, cpu, 2 + k, 8 - k)


def _bounded_run(lg: League, run: str = "clean") -> None:
    """ep0 scores 10-10 against random; ep1 wins every game (perfect), ep2 loses every game (zero): under --prior 0
    their maximum-likelihood ratings are infinite and the ones shown are bounds."""
    lg.roster.create_run(run, ENV, {})
    rnd, cpu = _bots(lg)
    _play(lg, cpu, rnd, 16, 4)
    for k, (wins, losses) in enumerate(((10, 10), (10, 0), (0, 10))):
        snap = _snap(lg, run, f"ep{k}", 100_000 * (k + 1), None)
        _play(lg, snap, rnd, wins, losses)
        _play(lg, snap, cpu, wins // 2, losses // 2)


def _figure(curves):
    from selfplay_cli.report.plots import run_figure  # inside the tests that need it: the others run without it

    return run_figure(curves).axes[0]


def _marks(ax) -> dict[str, object]:
    """The figure's marks by gid."""
    return {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}


def _legend(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_png_stars_the_snapshot_the_ladder_marks_best_and_its_legend_says_so(league: League) -> None:
    _two_learner_run(league)
    rows = ladder(league, ENV)
    (best,) = [r for r in rows if r.best]
    assert best.policy == "r1/ep2-left"
    ax = _figure(run_curves(league, "r1"))
    star = _marks(ax)["best"]
    assert star.get_marker() == "*" and star.get_markerfacecolor() == "gold"
    assert list(star.get_xdata()) == [300_000] and list(star.get_ydata()) == [best.elo]
    assert f"best snapshot of the run (ladder): r1/ep2-left, {best.elo:.0f}" in _legend(ax)
    assert "r1/ep2-left" in run_curves(league, "r1").to_json()["best"]

    # the ladder marks none (its candidates tied): nothing starred and nothing said about a best
    unmarked = run_curves(league, "r1", rows=[replace(r, best=False) for r in rows])
    ax = _figure(unmarked)
    assert "best" not in _marks(ax) and not any("best" in t for t in _legend(ax))
    assert unmarked.best is None and unmarked.to_json()["best"] is None
    text = curves_chart(unmarked, width=80, unicode=False).plain
    assert "*" not in text and "best" not in text
    assert "best" not in curves_summary(unmarked).plain


def test_terminal_chart_stars_the_best_snapshot_and_says_so(league: League) -> None:
    _two_learner_run(league)
    curves = run_curves(league, "r1")
    text = curves_chart(curves, width=80, unicode=False).plain
    rows, first, last = _plot_area(text)
    starred = [(r, c) for r, line in enumerate(rows) for c, ch in enumerate(line) if ch == "*"]
    assert len(starred) == 1 and starred[0][1] == last, text  # at the last step: r1/ep2-left
    assert "* best (ladder): r1/ep2-left" in text
    braille = curves_chart(curves, width=72, unicode=True).plain
    assert sum(line.count("*") for line in braille.splitlines()[1:15]) == 1
    assert "* best (ladder): r1/ep2-left" in braille
    summary = curves_summary(curves).plain
    assert summary.startswith("best snapshot of the run (ladder): r1/ep2-left (300k steps): ")
    assert "highest r1/ep0-right" in summary  # a learner's highest point is not called best: the ladder decides that


def test_a_figure_shows_bounds_only_where_there_are_some_and_then_says_so(league: League) -> None:
    _two_learner_run(league)
    ax = _figure(run_curves(league, "r1"))  # the default prior: every rating an estimate, no bound
    assert "bound" not in ax.get_title() and "open" not in ax.get_title()
    assert not any("bound" in t or "open" in t for t in _legend(ax))
    assert not any(gid.startswith(("bound:", "unanchored:")) for gid in _marks(ax))
    # every legend entry has its marks: a learner its line and points, the best its star
    assert _legend(ax) == ["left", "right", next(t for t in _legend(ax) if t.startswith("best snapshot"))]
    assert {"line:left", "points:left", "line:right", "points:right", "best"} <= set(_marks(ax))
    text = curves_chart(run_curves(league, "r1"), width=80, unicode=False).plain
    assert "bound" not in text and "^" not in text

    _bounded_run(league)
    curves = run_curves(league, "clean", prior=0)
    flags = {p.policy: p.flag for p in curves.curves[0].points}
    assert flags == {"clean/ep0": None, "clean/ep1": "perfect", "clean/ep2": "zero"}
    ax = _figure(curves)
    open_marks = _marks(ax)["bound:clean"]
    assert list(open_marks.get_xdata()) == [200_000, 300_000] and open_marks.get_markerfacecolor() == "white"
    assert list(_marks(ax)["points:clean"].get_xdata()) == [100_000]  # filled: the estimate only
    assert "open: a bound (perfect score: at least; zero: at most)" in _legend(ax)
    best = next(p for p in curves.curves[0].points if p.best)  # the perfect score, starred and said to be a bound
    assert best.policy == "clean/ep1"
    assert f"best snapshot of the run (ladder): clean/ep1, {best.elo:.0f} (at least: a bound)" in _legend(ax)
    assert "maximum likelihood" in ax.get_ylabel()
    text = curves_chart(curves, width=80, unicode=False).plain
    rows, first, last = _plot_area(text)
    middle = next(c for c in range(first, last) if any(len(line) > c and line[c] == "*" for line in rows))
    assert abs(middle - (first + last) / 2) <= 1, text  # ep1, the best: "*"
    assert any(len(line) > last and line[last] == "v" for line in rows), text  # ep2: at most this
    assert "v at most (a zero score: a bound)" in text and "* best (ladder): clean/ep1 (perfect: a bound)" in text
    assert "^" not in text, "no legend for a mark that does not show (the star covers ep1's ^)"
    assert "[perfect: a bound]" in curves_summary(curves).plain


def test_a_teams_equal_curves_are_both_drawn_and_both_named(league: League) -> None:
    _twin_run(league)
    curves = run_curves(league, "twin")
    left, right = curves.curves
    assert [p.elo for p in left.points] == pytest.approx([p.elo for p in right.points], abs=1.0)  # the premise
    ax = _figure(curves)
    marks = _marks(ax)
    a, b = marks["line:left"], marks["line:right"]
    xa, xb = list(a.get_xdata()), list(b.get_xdata())
    assert [y - x for x, y in zip(xa, xb, strict=True)] == [3000.0] * 3  # 1.5% of the 200k steps apart, not on top
    assert a.get_linestyle() != b.get_linestyle()
    assert marks["points:left"].get_marker() != marks["points:right"].get_marker()
    legend = _legend(ax)
    assert "left (same Elo as right at 3 of 3 snapshots; drawn -1.5k steps aside)" in legend, legend
    assert "right (same Elo as left at 3 of 3 snapshots; drawn +1.5k steps aside)" in legend, legend

    text = curves_chart(curves, width=80, unicode=False).plain
    rows, first, last = _plot_area(text)
    points = "".join(line[first] + line[(first + last) // 2] for line in rows if len(line) > last)
    assert points.count("=") == 2 and "x" not in points and "o" not in points, text  # both there, said so
    assert "= left = right (same point)" in text
    assert "* best (ladder): twin/s2-left (with right)" in text
    braille = curves_chart(curves, width=72, unicode=True).plain
    assert "= left = right (same point)" in braille


def test_curves_that_fall_near_each_other_are_not_called_the_same_elo() -> None:
    """Issue 48: left at 1998 and right at 2007 (3M steps) fall within the chart's 1% of each other and were said
    to have the 'same Elo'; the legend says how close they are instead, and 'same' only where the values printed
    are the same."""
    from selfplay_cli.report.plots import BotLevel, CurvePoint, LearnerCurve, RunCurves

    def curve(name: str, elos: tuple[float, ...]) -> LearnerCurve:
        return LearnerCurve(name, tuple(CurvePoint(f"r/s{k + 1}M-{name}", (k + 1) * 1_000_000, e, e - 40, e + 40,
                                                   None) for k, e in enumerate(elos)))

    near = RunCurves(ENV, "r", (curve("left", (1000.0, 1500.0, 1998.0)), curve("right", (1200.0, 1700.0, 2007.0))),
                     (BotLevel("random", 1000.0, 1000.0, 1000.0),), ("random", 1000.0))
    legend = _legend(_figure(near))
    assert not any("same Elo" in t for t in legend), legend
    assert "left (within 9 Elo of right at 1 of 3 snapshots; drawn -15k steps aside)" in legend, legend
    assert "right (within 9 Elo of left at 1 of 3 snapshots; drawn +15k steps aside)" in legend, legend
    equal = replace(near, curves=(curve("left", (1000.0, 1500.0, 2007.2)), curve("right", (1200.0, 1700.0, 2006.9))))
    assert "left (same Elo as right at 1 of 3 snapshots; drawn -15k steps aside)" in _legend(_figure(equal))


# --------------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------------




def _one_line_error(code: int, out: str, err: str, needle: str) -> None:
    assert code != 0 and out == "" and err.startswith("marl: error: ") and err.count("\n") == 1, (code, out, err)
    assert needle in err, err


def test_cli_plot_in_a_pipe_is_plain_text_at_80_columns(home: Path, capsys) -> None:
    with League.open(home=home) as lg:
        _two_learner_run(lg, "old")
        _two_learner_run(lg, "new")  # the newest run is the default
    code, out, err = run(capsys, "league", "plot")
    assert code == 0, err
    assert out.startswith("new (pong): fitted Elo by training step, 95% intervals")
    assert "\x1b" not in out and all(len(line) <= 80 for line in out.splitlines())
    assert "o left" in out and "x right" in out and " cpu" in out and " random" in out
    assert "latest  new/ep2-left" in out
    assert "* best (ladder): new/ep2-left" in out and "best snapshot of the run (ladder): new/ep2-left" in out
    code, out, err = run(capsys, "league", "plot", "--run", "old", "--env", "pong")
    assert code == 0 and out.startswith("old (pong)")


def test_cli_plot_out_and_json(home: Path, capsys, tmp_path: Path) -> None:
    import matplotlib.image

    with League.open(home=home) as lg:
        _two_learner_run(lg)
    png = tmp_path / "run.png"
    code, out, err = run(capsys, "league", "plot", "--out", str(png))
    assert code == 0 and out.strip() == f"wrote {png}"
    assert matplotlib.image.imread(png).shape[:2] == (550, 990)
    code, out, err = run(capsys, "league", "plot", "--json")
    data = json.loads(out, parse_constant=lambda c: pytest.fail(f"non-finite {c} in JSON"))
    assert data["run"] == "r1" and data["png"] is None
    assert [c["learner"] for c in data["learners"]] == ["left", "right"]
    assert [p["step"] for p in data["learners"][0]["points"]] == [100_000, 200_000, 300_000]
    assert data["best"] == "r1/ep2-left" and [p["best"] for p in data["learners"][0]["points"]] == [False, False, True]
    assert data["prior"] == 2


@pytest.mark.slow
def test_cli_plot_prior_0_draws_and_names_the_bounds(home: Path, capsys, tmp_path: Path) -> None:
    with League.open(home=home) as lg:
        _bounded_run(lg)
    code, out, err = run(capsys, "league", "plot", "--prior", "0")
    assert code == 0, err
    assert "v at most (a zero score: a bound)" in out and "[zero: a bound]" in out
    code, out, err = run(capsys, "league", "plot", "--prior", "0", "--json")
    data = json.loads(out)
    assert data["prior"] == 0 and [p["flag"] for p in data["learners"][0]["points"]] == [None, "perfect", "zero"]
    code, out, err = run(capsys, "league", "plot")  # the default prior: no bound, none named
    assert code == 0 and "bound" not in out
    _one_line_error(*run(capsys, "league", "plot", "--prior", "-1"), "--prior must be")


def test_cli_plot_errors_are_one_line(home: Path, capsys, tmp_path: Path) -> None:
    _one_line_error(*run(capsys, "league", "plot"), "no training runs in the league yet")
    with League.open(home=home) as lg:
        _two_learner_run(lg)
        lg.roster.create_run("fresh", ENV, {})
    _one_line_error(*run(capsys, "league", "plot"), "run 'fresh' has no rated snapshots yet")
    _one_line_error(*run(capsys, "league", "plot", "--run", "nope"), "no run named 'nope'")
    _one_line_error(*run(capsys, "league", "plot", "--run", "r1", "--out", str(tmp_path / "x" / "p.png")),
                    "no folder")
    _one_line_error(*run(capsys, "league", "plot", "--run", "r1", "--out", str(tmp_path / "p.svg")),
                    "must end in .png")
    _one_line_error(*run(capsys, "league", "plot", "--env", "chess"), "chess")
