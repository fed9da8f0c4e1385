"""``marl study team-size``: seed 001's method end to end on pursuit with tiny budgets, a study killed midway that
goes on where it stopped, and the refusals."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time

import imageio.v3 as iio
import procs
import pytest
from cli_helpers import ctrl_c_enabled, run, run_json

from selfplay_cli.league.store import League

PURSUIT = "pettingzoo.sisl.pursuit_v5"
PLAN = ["study", "team-size", PURSUIT, "--size-option", "n_pursuers", "--kind", "cooperative", "--train", "1,2",
        "--eval", "1-3", "--steps", "160", "--snapshots", "2", "--games", "2", "--eval-games", "3",
        "--env-option", "max_cycles=10", "--env-option", "x_size=8", "--env-option", "y_size=8",
        "--env-option", "n_evaders=3", "--name", "ts"]
RUNS = {"ts-n1", "ts-n2", "ts-n1-to2", "ts-n2-to1"}


@pytest.mark.slow
def test_a_study_trains_flies_adapts_and_measures(home, capsys):
    r = run_json(capsys, *PLAN, "--json")
    assert (r["train"], r["eval"], r["size_option"]) == ([1, 2], [1, 2, 3], "n_pursuers")
    cells = {(c["trained"], c["evaluated"]): c for c in r["returns"]}
    assert set(cells) == {(n, m) for n in (1, 2) for m in (1, 2, 3)}
    for c in cells.values():  # 3 episodes each, on the same seeds as the opponent's
        assert c["games"] == 3 and c["low"] <= c["mean"] <= c["high"] and c["vs"]["games"] == 3
    assert len({c["vs"]["mean"] for c in cells.values() if c["evaluated"] == 2}) == 1  # one opponent, one measure
    pairs = {(a["from"], a["to"]): a for a in r["adaptive"]}
    assert set(pairs) == {(1, 2), (2, 1)}
    a = pairs[(1, 2)]
    assert a["run"] == "ts-n1-to2" and a["fresh_run"] == "ts-n2" and a["return"]["games"] == 3
    assert a["fresh_return"] == {k: v for k, v in cells[(2, 2)].items() if k in a["fresh_return"]}
    assert a["fresh_steps"] == 160 and a["curve"][0][0] == 0 and a["curve"][-1][0] == 160  # its first and last
    state = json.loads((home / "studies" / "ts" / "study.json").read_text())
    target = a["fresh_return"]["mean"]  # the fresh run's final return: the table's, on the study's seeds
    flown = {int(k.rpartition(":")[2]): v["mean"] for k, v in state["evals"].items() if k.startswith("ts-n1-to2@2:")}
    flown[160] = a["return"]["mean"]  # its moments flown in order until one reached it, on the same seeds
    first = next((step for step, got in sorted(flown.items()) if got >= target), None)
    assert a["steps_to_reach"] == first  # the adapted run's first moment at or above it
    assert first is None or a["reached_return"] == flown[first] >= target
    assert state["evals"]["ts-n1-to2@2:0"]["team"] == "ts-n1-to2/s0"  # the parent flown at the new size
    figures = {x["run"]: x for x in r["runs"]}
    assert set(figures) == RUNS
    for x in figures.values():  # each run in its own process, measured
        assert x["steps"] == 160 and x["wall_seconds"] > 0 and x["cpu_seconds"] > 0 and x["peak_mb"] > 50
        assert 0 < x["mean_cpu"] <= os.cpu_count() + 0.5
    assert figures["ts-n1-to2"]["from"] == 1 and figures["ts-n2"]["from"] is None
    for png in r["plots"].values():
        assert iio.imread(png).ndim == 3  # a picture that decodes
    league = League.open(home=home)
    try:
        runs = {x.name: x for x in league.roster.list_runs()}
        assert set(runs) == RUNS and all(x.status == "finished" for x in runs.values())
        parent = league.roster.get_player(next(p for p in league.roster.players(kind="snapshot")
                                               if p.run == "ts-n1-to2" and p.step == 0).parent_id)
        assert parent.full_name == "ts-n1/s160"  # the adapted run started from the 1-team's final snapshot
    finally:
        league.close()
    saved = json.loads((home / "studies" / "ts" / "report.json").read_text())
    assert saved["returns"] == r["returns"]
    again = run_json(capsys, *PLAN, "--json")  # everything done: the same report, nothing trained again
    assert again["returns"] == r["returns"] and again["runs"] == r["runs"]
    code, out, _ = run(capsys, *PLAN)
    assert code == 0 and "mean team return by size trained" in out and "ts-n2-to1" in out
    code, _, err = run(capsys, *PLAN[:-2], "--name", "ts", "--eval-games", "5")  # the same name, other settings
    assert code == 2 and "exists with other settings" in err and err.count("\n") == 1, err


@pytest.mark.slow
def test_a_killed_study_goes_on_where_it_stopped(home, capsys):
    plan = [*PLAN[:PLAN.index("--train")], "--train", "1", "--eval", "1-2",
            *PLAN[PLAN.index("--steps"):]]  # one run, killed while it trains
    env = dict(os.environ, MARL_HOME=str(home), SDL_VIDEODRIVER="dummy")
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *plan, "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and not (home / "runs" / "ts-n1" / "config.json").exists():
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGKILL)  # the study and its training child, at once, mid-run
    proc.wait()
    assert (home / "runs" / "ts-n1").exists()
    r = run_json(capsys, *plan, "--json")  # the same command again
    assert [x["run"] for x in r["runs"]] == ["ts-n1"] and r["runs"][0]["steps"] == 160
    assert {(c["trained"], c["evaluated"]) for c in r["returns"]} == {(1, 1), (1, 2)}
    league = League.open(home=home)
    try:
        runs = league.roster.list_runs()
        assert [x.name for x in runs] == ["ts-n1"] and runs[0].status == "finished"  # resumed, not begun twice
    finally:
        league.close()


def test_refusals_are_one_line(home, capsys):
    code, _, err = run(capsys, "study", "team-size", PURSUIT, "--steps", "100")
    assert code == 2 and "names no team-size option" in err and err.count("\n") == 1, err
    code, _, err = run(capsys, "study", "team-size", "lander", "--steps", "100", "--minutes", "1")
    assert code == 2 and "--steps N or --minutes M" in err and err.count("\n") == 1, err
    code, _, err = run(capsys, "study", "team-size", "lander", "--steps", "100", "--train", "3-2")
    assert code == 2 and "team sizes run from 1 to 64" in err and err.count("\n") == 1, err
    code, _, err = run(capsys, "study", "team-size", "lander", "--steps", "100", "--env-option", "landers=3")
    assert code == 2 and "is the team size the study varies" in err and err.count("\n") == 1, err
    code, _, err = run(capsys, "study", "team-size", "lander", "--steps", "100", "--sharing", "sa")
    assert code == 2 and "fups or nops" in err and err.count("\n") == 1, err
    assert not (home / "runs").exists() or not any((home / "runs").iterdir())


def test_the_returns_figure_shows_only_the_team_sizes_studied(tmp_path, monkeypatch):
    """Issue 48: returns.png had team sizes 1.2, 1.4, ... on its x axis; a team size is a whole number of seats,
    and the axis shows the sizes flown, each labelled, and nothing between them."""
    from selfplay_cli.study import plots

    def cell(trained: int, flown: int, mean: float) -> dict:
        return {"trained": trained, "evaluated": flown, "games": 4, "mean": mean, "low": mean - 1, "high": mean + 1,
                "seating": None, "team": f"n{trained}/s1k", "vs": {"games": 4, "mean": 0.0, "low": -1, "high": 1,
                                                                  "player": "random"}}

    report = {"study": "t", "env": "pursuit", "size_option": "n_pursuers", "train": [1, 2], "eval": [1, 2, 3],
              "vs": "random", "returns": [cell(n, m, 10.0 * n + m) for n in (1, 2) for m in (1, 2, 3)]}
    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig) or path)
    plots.plot_returns(report, tmp_path / "returns.png")
    (ax,) = figures[0].axes
    lo, hi = ax.get_xlim()
    shown = [t for t in ax.get_xticks() if lo <= t <= hi]
    assert shown == [1, 2, 3], shown
    assert [t.get_text() for t in ax.get_xticklabels() if lo <= t.get_position()[0] <= hi] == ["1", "2", "3"]
    assert list(ax.get_xticks(minor=True)) == []


# --- issue 49: a study's training child dies with it ---

CHILD = """
import os, signal, sys
from pathlib import Path
out = Path(sys.argv[1])
def stop(sig, frame):
    out.write_text(signal.Signals(sig).name)
    sys.exit(0)
signal.signal(signal.SIGTERM, stop)
signal.signal(signal.SIGINT, stop)
(out.parent / "ready").write_text(str(os.getpid()))
while True:
    signal.pause()
"""

PARENT = """
import os, sys
from pathlib import Path
from selfplay_cli.signals import Terminated, stop_on_sigterm
from selfplay_cli.study.measure import train_process
here = Path(sys.argv[1])
try:
    with stop_on_sigterm():
        train_process([str(here / "got")], dict(os.environ), here / "log", program=[sys.executable, sys.argv[2]])
except Terminated:
    sys.exit(143)
except KeyboardInterrupt:
    sys.exit(130)
"""


def _wait_for(what, seconds: float = 120.0):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        got = what()
        if got:
            return got
        time.sleep(0.05)
    return what()


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL])
def test_the_training_child_of_a_study_ends_with_it(tmp_path, sig):
    """SIGTERM or Ctrl-C of the study are handed to its child, which the study waits for before it exits; a study
    killed outright (SIGKILL: nothing of it runs) has the kernel send its child SIGTERM. The child here is a stand-in
    for marl train that writes the signal it got."""
    child = tmp_path / "child.py"
    child.write_text(CHILD)
    parent = subprocess.Popen([sys.executable, "-c", PARENT, str(tmp_path), str(child)], preexec_fn=ctrl_c_enabled)
    pid = int(_wait_for(lambda: (tmp_path / "ready").exists() and (tmp_path / "ready").read_text() or None))
    assert not procs.gone(pid) and os.getpgid(pid) == pid  # in a group of its own: a terminal's Ctrl-C reaches it once
    parent.send_signal(sig)
    code = parent.wait(timeout=120)
    if sig == signal.SIGKILL:
        assert code == -signal.SIGKILL
        assert _wait_for(lambda: (tmp_path / "got").exists()) and _wait_for(lambda: procs.gone(pid))
    else:  # the study waited for it: it had ended when the study did
        assert code == (143 if sig == signal.SIGTERM else 130) and procs.gone(pid)
    assert (tmp_path / "got").read_text() == ("SIGINT" if sig == signal.SIGINT else "SIGTERM")


LANDER = ["study", "team-size", "lander", "--train", "1", "--eval", "1", "--games", "2", "--eval-games", "2",
          "--snapshots", "1", "--name", "t"]


def _trainer(home) -> int | None:
    """The live process training the study's run, once it has claimed the run."""
    from selfplay_cli.train.lock import live_trainer

    return live_trainer(home / "runs" / "t-n1" / "lock")


def _study(home, *args: str) -> subprocess.Popen:
    env = dict(os.environ, MARL_HOME=str(home), SDL_VIDEODRIVER="dummy")
    return subprocess.Popen([sys.executable, "-m", "selfplay_cli", *LANDER, *args, "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)


def _end_session(study: subprocess.Popen) -> None:
    """Whatever is left of the study's session (nothing, when it held)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(study.pid, signal.SIGKILL)


@pytest.mark.slow
def test_sigterm_stops_a_study_and_its_training_run(home):
    """Issue 49: SIGTERM ended the study (143) while its marl train ran on for its whole budget."""
    study = _study(home, "--minutes", "30")
    try:
        trainer = _wait_for(lambda: _trainer(home))
        assert trainer is not None
        study.send_signal(signal.SIGTERM)
        _, err = study.communicate(timeout=300)
    finally:
        _end_session(study)
    assert study.returncode == 143 and procs.gone(trainer)
    assert err.count("\n") == 1 and "study t stopped (SIGTERM)" in err and "type the same command again" in err, err
    log = (home / "studies" / "t" / "logs" / "t-n1.log").read_text()
    assert "stopped t-n1 at step" in log and "(SIGTERM)" in log  # the run stopped itself, kept to be resumed
    league = League.open(home=home)
    try:
        assert league.roster.get_run("t-n1").status == "stopped"
    finally:
        league.close()


@pytest.mark.slow
def test_a_study_killed_outright_takes_its_run_down_and_resumes_when_typed_again(home, capsys):
    """Issue 49: SIGKILL of the study left its marl train running, and the study typed again was refused while that
    orphan lived. Now the kernel stops the child with its study, and the study typed again at once waits for it to
    end, then resumes the run."""
    study = _study(home, "--minutes", "0.1")
    try:
        trainer = _wait_for(lambda: _trainer(home))
        assert trainer is not None
        study.kill()
        study.wait(timeout=60)
        r = run_json(capsys, *LANDER, "--minutes", "0.1", "--json")  # at once: the child may still be stopping
    finally:
        _end_session(study)
    assert procs.gone(trainer) and [x["run"] for x in r["runs"]] == ["t-n1"]
    log = (home / "studies" / "t" / "logs" / "t-n1.log").read_text()
    assert "stopped t-n1 at step" in log and "(SIGTERM)" in log  # told by the kernel, it stopped its run itself
    league = League.open(home=home)
    try:
        runs = league.roster.list_runs()
        assert [x.name for x in runs] == ["t-n1"] and runs[0].status == "finished"  # resumed, not begun again
    finally:
        league.close()
