"""The docs: README is the front door (at most 300 lines, every link landing), the site in docs/ builds under
`mkdocs build --strict` (no broken link, no page left out of its navigation), and the command reference is what the
CLI itself says."""

from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_command_reference_is_the_clis_own():
    """docs/reference/cli.md is generated from typer's metadata (every command, argument, option and default): the
    file and the CLI differ nowhere. Regenerate it with `python -m selfplay_cli.reference --write`."""
    from typer._click import Context

    from selfplay_cli.cli import build_command
    from selfplay_cli.reference import render

    text = render()
    assert (ROOT / "docs" / "reference" / "cli.md").read_text() == text, \
        "regenerate: python -m selfplay_cli.reference --write"

    def walk(command, path):
        for name, sub in command.commands.items():
            yield [*path, name], sub
            if hasattr(sub, "commands"):
                yield from walk(sub, [*path, name])

    for path, command in walk(build_command(), ["marl"]):
        assert f"`{' '.join(path)}`" in text
        for p in command.params:
            record = p.get_help_record(Context(command))
            if record is not None:
                assert f"| `{record[0]}` |" in text, (path, record[0])
    assert "| `--steps N` | Budget in game steps. [default: 6,000,000; 1 to 1,000,000,000,000] |" in text


def test_figures_quoted_in_the_docs_are_their_benchmarks_output():
    """A block of figures in a page (`<!-- figures:NAME -->`) is rendered from its benchmark's output file, with the
    date and machine it was measured on: typed by hand nowhere."""
    from selfplay_cli.reference import FIGURES, with_figures

    quoted = set()
    for page in (ROOT / "docs").rglob("*.md"):
        text = page.read_text()
        quoted |= set(re.findall(r"<!-- figures:(\w+)(?:/\w+)? -->", text))
        blocks = re.findall(r"<!-- figures:\w+(?:/\w+)? -->\n.*?<!-- /figures -->", text, flags=re.S)
        assert len(blocks) == text.count("<!-- figures:") == text.count("<!-- /figures -->"), \
            f"{page}: a figures block not closed (or not opened) escapes its check"
        assert with_figures(text, ROOT) == text, f"{page}: regenerate: python -m selfplay_cli.reference --write"
    assert set(FIGURES) <= quoted
    for name in quoted - set(FIGURES):  # what a benchmark printed, with when, where and on what code it ran
        r = json.loads((ROOT / "benchmarks" / "results" / f"{name}.json").read_text())
        assert r["printed"] and r["command"].startswith("python benchmarks/"), name
        assert datetime.date.fromisoformat(r["date"]) and "cores" in r["machine"] and len(r["load_start"]) == 3, name


def test_a_benchmark_run_leaves_its_figures_in_a_file_only_when_it_ends_well(tmp_path, monkeypatch, capsys):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import results_file
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    monkeypatch.setattr(results_file, "RESULTS", tmp_path)
    monkeypatch.setattr(sys, "argv", ["benchmarks/speed.py", "--rounds", "3"])
    with results_file.recorded() as data:
        print("pong view: 41,000 steps/s")
        print("core: 120,000 steps/s")
        data["table"] = [{"label": "pong", "steps_per_second": 41000}]  # figures as data, for a page's table
    assert capsys.readouterr().out == "pong view: 41,000 steps/s\ncore: 120,000 steps/s\n"  # (the terminal's too)
    r = json.loads((tmp_path / "speed.json").read_text())
    assert r["printed"] == ["pong view: 41,000 steps/s", "core: 120,000 steps/s"]
    assert r["table"] == [{"label": "pong", "steps_per_second": 41000}]
    assert r["command"] == "python benchmarks/speed.py --rounds 3" and r["benchmark"] == "speed"
    assert f"{os.cpu_count()} cores" in r["machine"] and r["started"].startswith(r["date"])
    with pytest.raises(RuntimeError), results_file.recorded("speed"):
        print("half a run")
        raise RuntimeError("stopped")
    assert json.loads((tmp_path / "speed.json").read_text())["printed"] == r["printed"]  # the good run's stays
    assert [p.name for p in tmp_path.iterdir()] == ["speed.json"]  # (no temporary file left)


def test_a_page_quotes_a_worked_examples_section_or_its_summary_lines_alone(tmp_path):
    from selfplay_cli.reference import figures

    (tmp_path / "benchmarks" / "results").mkdir(parents=True)
    run = {"command": "python benchmarks/doc_examples.py pong", "date": "2026-11-30", "machine": "2 cores",
           "load_start": [0.5, 0, 0], "load_end": [1.5, 0, 0], "commit": "abc1234", "seconds": 30.0,
           "printed": ["$ marl train pong", "run pong-1: 6,000,128 game steps", "  pong-1/s6M-left: Elo 2161",
                       "$ marl league predict a b", "a against b: 50.1%"],
           "sections": {"predict": ["$ marl league predict a b", "a against b: 50.1%"]}}
    (tmp_path / "benchmarks" / "results" / "example_pong.json").write_text(json.dumps(run))
    stamp = ("From `benchmarks/results/example_pong.json`: `python benchmarks/doc_examples.py pong`, run 2026-11-30 on "
             "2 cores (load 0.5 at its start, 1.5 at its end, code abc1234; 30 s):\n\n```text\n")
    assert figures("example_pong/predict", tmp_path) == stamp + "$ marl league predict a b\na against b: 50.1%\n```\n"
    assert figures("example_pong/top", tmp_path) == stamp + "\n".join(
        x for x in run["printed"] if not x.startswith(" ")) + "\n```\n"
    assert figures("example_pong", tmp_path) == stamp + "\n".join(run["printed"]) + "\n```\n"
    with pytest.raises(ValueError, match="has no section 'plot' \\(its sections: predict\\)"):
        figures("example_pong/plot", tmp_path)


def test_the_games_page_reads_the_recipes_table_from_its_run():
    """The games page's reading of ``benchmarks/other_libraries.py``'s table (in one process against 2 workers; the
    bare view against the recipe in one process) is computed from the printed rows, here two rows worked by hand."""
    from selfplay_cli.reference import _other_libraries

    run = {"command": "python benchmarks/other_libraries.py", "date": "2026-11-30", "machine": "m", "seconds": 10,
           "load_start": [0.5], "load_end": [1.0], "commit": "abc1234",
           "printed": ["SuperSuit recipe ..., 8 games",
                       "game                 2 workers  in-process   bare view   2 workers / in-process",
                       "pong                     1,000       4,000      30,000                    0.25x",
                       "lander landers=4         2,000       2,200       3,520                    0.91x",
                       "load average 1.0, 1.0, 1.0"]}
    text = _other_libraries(run)
    assert "pong                     1,000" in text  # the table as printed
    assert ("in one process the recipe runs 1.1 to 4.0 times as fast as with 2 worker processes" in text)  # 2200/2000
    assert "the bare view plays 1.6 to 7.5 times as many game steps" in text  # 3520/2200, 30000/4000


def test_the_teams_page_reads_its_tables_from_the_study_report():
    """What the teams page says of a study's tables (where a team beats the scripted player beyond doubt, its
    steepest fall, the adapted runs against the fresh ones, the runs' cost) is computed from the report, checked here
    against a two-size study worked by hand."""
    from selfplay_cli.reference import _team_study

    def cell(mean: float, half: float = 1.0) -> dict:
        return {"mean": mean, "low": mean - half, "high": mean + half}

    bot = {1: cell(-5.0), 2: cell(-9.0), 3: cell(-20.0)}
    trained = {(1, 1): 2.0, (1, 2): 1.5, (1, 3): -8.0, (2, 1): -4.5, (2, 2): 3.0, (2, 3): 4.0}
    report = {"study": "s", "env": "g", "size_option": "n", "train": [1, 2], "eval": [1, 2, 3],
              "budget": {"minutes": 5.0, "steps": None}, "sharing": "fups", "algo": None, "vs": "random",
              "eval_games": 50,
              "returns": [{"trained": n, "evaluated": m, **cell(v), "vs": {**bot[m]}} for (n, m), v in trained.items()],
              "adaptive": [{"from": 1, "to": 2, "return": cell(6.5), "fresh_return": cell(3.0), "steps_to_reach": 0,
                            "minutes_to_reach": 0.0, "reached_return": 1.5, "fresh_steps": 900_000,
                            "fresh_minutes": 5.0},
                           {"from": 2, "to": 1, "return": cell(1.0), "fresh_return": cell(2.0),
                            "steps_to_reach": None, "fresh_steps": 1_500_000, "fresh_minutes": 5.0}],
              "runs": [{"size": 1, "from": None, "steps": 1_500_000, "wall_seconds": 300.0, "mean_cpu": 0.98,
                        "peak_mb": 700.4},
                       {"size": 2, "from": None, "steps": 900_000, "wall_seconds": 318.0, "mean_cpu": 1.0,
                        "peak_mb": 650.0}]}
    text = _team_study("docs/s.json")(report)
    reading = text[text.index("Read from the tables"):].splitlines()[2:]
    assert reading == [
        # 1 at 1: 2.0 [1, 3] above -5.0 [-6, -4]; at 3: -8.0 [-9, -7] above -20 [-21, -19]
        "- trained with 1: above `random` beyond doubt flown with 1, 2 and 3; at its best flown with 1; its steepest "
        "fall, 1.5 at 2 to -8.0 at 3",
        # 2 at 1: -4.5 [-5.5, -3.5] overlaps -5.0 [-6, -4]
        "- trained with 2: above `random` beyond doubt flown with 2 and 3; at its best flown with 3; it never falls "
        "from one size to the next",
        "- adapted minus fresh, the returns each reached: -1.0 to +3.5; above beyond doubt: 1 -> 2; below beyond "
        "doubt: none; at the fresh run's final return from its start (its parent flown at the new size): 1 -> 2",
        "- each of the 2 runs: 5.0 to 5.3 min of wall time, mean CPU 0.98 to 1.00 cores, 650 to 700 MB at its peak, "
        "900k to 1.5M game steps (trained afresh, by size: 1: 1.5M, 2: 900k)"]


def test_the_ladder_truth_page_says_each_miss_and_which_game_falls_short_of_a_target():
    """The league page's account of ladder_truth.json: a game below a target is named with the figure that falls
    short, every missed prediction of a claimed pair is listed (a row-only pair's is not: nobody reads it), and a
    margin printed in two places (the ladder's top is the run's best) is listed once."""
    from selfplay_cli.reference import _ladder_truth

    margin = {"elo": 9.3, "low": -52.8, "high": 72.3, "match_low": -70.4, "match_high": 88.7, "held": True,
              "held_expected": False}
    pair = {"game": "lander", "met": 100, "results": 100, "measured_elo": -63.2, "held": True, "kinds": ["margin"],
            "a": "lander-1/s5M", "b": "lander-1/s4M", "predicted": 0.51, "low": 0.4, "high": 0.62, "measured": 0.41,
            "margins": [{**margin, "where": "top"}, {**margin, "where": "best"}, {**margin, "where": "row"}]}
    miss = {**pair, "game": "pong", "a": "pong-1/s5M-left", "b": "cpu", "kinds": ["order"], "met": 0, "results": 200,
            "predicted": 0.863, "low": 0.532, "high": 0.99, "measured": 1.0, "held": False, "margins": []}
    unread = {**miss, "a": "pong-1/s1M-left", "kinds": ["row"]}
    row = {"pairs": 1, "held": "1/1 = 100.0%", "held_share": 1.0, "open_met": 1, "width_met": 22.0, "open_new": 0,
           "width_new": None, "printed_margins": "2/2 = 100.0%", "order": "-", "row_margins": "1/1 = 100.0%"}
    data = {"command": "python benchmarks/ladder_truth.py", "date": "2026-11-30", "machine": "2 cores",
            "load_start": [1.0, 1.0, 1.0], "load_end": [1.2, 1.0, 1.0], "commit": "abc1234", "seconds": 5400.0,
            "table": [{**row, "label": "lander"}, {**row, "label": "pong", "held": "9/11 = 81.8%", "held_share": 0.818,
                                                    "width_met": 31.5}],
            "pairs": [pair, miss, unread]}
    text = _ladder_truth(data)
    assert text.startswith("From `benchmarks/results/ladder_truth.json`: `python benchmarks/ladder_truth.py`, run "
                           "2026-11-30 on 2 cores (load 1.0 at its start, 1.2 at its end, code abc1234; 90 minutes)")
    assert ("Held on lander. Missed on pong (predictions held 9/11 = 81.8%; open predictions of pairs that met 32 "
            "points wide).") in text
    assert ("- pong: `pong-1/s5M-left` against `cpu` predicted 86.3% [53.2, 99.0] (they had never met); measured "
            "100.0% over 200 results") in text
    assert "s1M-left" not in text
    assert text.count("lander-1/s5M") == 1
    assert ("`lander-1/s5M` over `lander-1/s4M` +9 [-53, +72] (the ladder's top over the next and the run's best over "
            "its next best; 200 games would measure -70 to +89); measured -63: inside the range, outside the "
            "interval") in text


def test_the_sites_home_is_the_readme():
    from selfplay_cli.reference import home_page

    assert (ROOT / "docs" / "index.md").read_text() == home_page((ROOT / "README.md").read_text()), \
        "regenerate: python -m selfplay_cli.reference --write"


def test_readme_is_a_front_door_whose_links_land():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 300
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", readme)
    local = [x for x in links if not x.startswith(("http://", "https://"))]
    assert len(local) >= 15 and all((ROOT / x).is_file() for x in local), [x for x in local if not (ROOT / x).is_file()]


@pytest.mark.slow
def test_the_site_builds_strictly(tmp_path):
    """`mkdocs build --strict` (the Material theme): every page in the navigation, every link and anchor found."""
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent))
    assert mkdocs is not None, 'mkdocs is part of the dev install: pip install -e ".[dev]"'
    out = subprocess.run([mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, env={"NO_MKDOCS_2_WARNING": "1",
                                                                           "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr[-2000:]
    pages = {p.relative_to(tmp_path / "site").as_posix() for p in (tmp_path / "site").rglob("index.html")}
    assert {"index.html", "commands/train/index.html", "reference/cli/index.html", "safety/index.html"} <= pages
