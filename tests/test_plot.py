"""A run's rating curves (report.plots), their terminal chart (report.terminal) and `marl league plot`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_helpers import run

from selfplay_cli.errors import MarlError
from selfplay_cli.league.ladder import ladder
from selfplay_cli.league.store import League, PlayerRow
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
    m = lg.create_match(ENV, "match")
    lg.record_games(m, [_game(a.id, b.id, s, k) if k % 2 == 0 else _game(b.id, a.id, 1.0 - s, k)
                        for k, s in enumerate(results)])


def _snap(lg: League, run: str, name: str, step: int, learner: str | None) -> PlayerRow:
    return lg.add_snapshot(env=ENV, run=run, name=name, path=f"/snaps/{run}/{name}.safetensors", sha256="0" * 64,
                           step=step, meta={"learner": learner} if learner else {})


def _bots(lg: League) -> tuple[PlayerRow, PlayerRow]:
    lg.ensure_bots(ENV, ["random", "cpu"])
    by_name = {p.name: p for p in lg.players(env=ENV, kind="bot")}
    return by_name["random"], by_name["cpu"]


def _two_learner_run(lg: League, run: str = "r1") -> None:
    """``left`` gets better with training (10-10, 14-6, 18-2 against random), ``right`` worse (13-7, 10-10, 7-13);
    cpu beats random."""
    lg.create_run(run, ENV, {})
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
    league.create_run("solo", ENV, {})
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
    league.create_run("empty", ENV, {})
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

    # left ("o") climbs from its first snapshot to its last, right ("x") falls; up is a smaller row number
    assert row_of("o", first) > row_of("o", last)
    assert row_of("x", first) < row_of("x", last)
    cpu_row = next(r for r, line in enumerate(rows) if line.rstrip().endswith(" cpu"))
    random_row = next(r for r, line in enumerate(rows) if line.rstrip().endswith(" random"))
    assert cpu_row < random_row and set(rows[cpu_row][first:last + 1]) <= {"-", "o", "x", ".", ":"}
    assert "o left" in text and "x right" in text and "steps" in text and "100k" in text and "300k" in text


def test_braille_chart_fits_its_width(league: League) -> None:
    _two_learner_run(league)
    curves = run_curves(league, "r1")
    chart = curves_chart(curves, width=72, unicode=True)
    assert all(len(line) <= 72 for line in chart.plain.splitlines())
    assert any(ord(ch) in BRAILLE for ch in chart.plain)
    assert any(span.style for span in chart.spans)  # coloured
    summary = curves_summary(curves).plain
    assert "left: 3 rated snapshots\n  latest r1/ep2-left (300k steps): " in summary
    assert "right: 3 rated snapshots" in summary and "best   r1/ep0-right (100k steps): " in summary
    assert "scripted players\n  cpu: " in summary


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
    assert "latest new/ep2-left" in out
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


def test_cli_plot_errors_are_one_line(home: Path, capsys, tmp_path: Path) -> None:
    _one_line_error(*run(capsys, "league", "plot"), "no training runs in the league yet")
    with League.open(home=home) as lg:
        _two_learner_run(lg)
        lg.create_run("fresh", ENV, {})
    _one_line_error(*run(capsys, "league", "plot"), "run 'fresh' has no rated snapshots yet")
    _one_line_error(*run(capsys, "league", "plot", "--run", "nope"), "no run named 'nope'")
    _one_line_error(*run(capsys, "league", "plot", "--run", "r1", "--out", str(tmp_path / "x" / "p.png")),
                    "no folder")
    _one_line_error(*run(capsys, "league", "plot", "--run", "r1", "--out", str(tmp_path / "p.svg")),
                    "must end in .png")
    _one_line_error(*run(capsys, "league", "plot", "--env", "chess"), "chess")
