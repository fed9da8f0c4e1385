"""A killed run loses nothing: `marl train` killed with SIGKILL at each step of writing a snapshot moment (after
its first file, after its pending state, during that state file, after its rows) resumes to completion, and every
row of the league then names a file whose weights are the row's; SIGTERM stops a run as cleanly as Ctrl-C. The kill
points that cut the league's own writes (before and after the rows) and SIGTERM run on PostgreSQL too (``MARL_DB``)."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from selfplay_cli.cli import main
from selfplay_cli.league.store import League
from selfplay_cli.policies.snapshot_format import weights_sha256
from selfplay_cli.policies.snapshot_reader import load_snapshot

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL")

ARGS = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps",
        "2048", "--steps", "8192", "--eval-games", "0", "--run", "r", "--quiet"]

KILL_POINTS = Path(__file__).with_name("kill_points.py")


def check_league(home: Path) -> list:
    """Every row names a file holding exactly its weights; nothing else is left in the run's folder."""
    with League.open(home) as league:
        snaps = league.roster.players("pong", kind="snapshot")
        for p in snaps:
            tensors, meta = load_snapshot(home / p.path, expect_env="pong")
            assert weights_sha256(tensors) == p.meta["weights_sha256"] == meta.weights_sha256, p.name
            assert p.sha256 in (meta.weights_sha256, hashlib.sha256((home / p.path).read_bytes()).hexdigest())
            assert meta.name == p.name and meta.step == p.step
        files = sorted(f.name for f in (home / "snapshots" / "r").iterdir())
        assert files == sorted(Path(p.path).name for p in snaps), files
        run_dir = home / "runs" / "r"
        assert not list(run_dir.glob("*.tmp-*")) and not (run_dir / "state.pt.pending").exists()
        return snaps


def league_in(request, monkeypatch, db: str) -> dict[str, str]:
    """The league of the test on ``db``: SQLite in the home (no ``MARL_DB``), or a fresh PostgreSQL database named by
    ``MARL_DB`` for this process and its children; the environment for a child."""
    if db == "sqlite":
        monkeypatch.delenv("MARL_DB", raising=False)
    else:
        monkeypatch.setenv("MARL_DB", request.getfixturevalue("pg_url"))
    return dict(os.environ)


@pytest.mark.slow
@pytest.mark.parametrize(("point", "db"), [
    ("after-first-file", "sqlite"), ("after-pending-state", "sqlite"), ("during-state-file", "sqlite"),
    ("after-rows", "sqlite"), ("after-pending-state", "postgresql"), ("after-rows", "postgresql")])
def test_killed_at_any_step_of_a_snapshot_moment_resumes_to_completion(tmp_path, capsys, request, monkeypatch, point,
                                                                       db):
    home = tmp_path / "h"
    env = league_in(request, monkeypatch, db)
    child = subprocess.run([sys.executable, str(KILL_POINTS), point, str(home), *ARGS], capture_output=True,
                           text=True, timeout=300, env=env)
    assert child.returncode == -signal.SIGKILL, (child.returncode, child.stderr[-2000:])
    with League.open(home) as league:
        before = {p.name: p.sha256 for p in league.roster.players("pong", kind="snapshot")}
        assert league.roster.get_run("r").status == "running"
    assert (home / "league.db").exists() == (db == "sqlite")  # the league is where MARL_DB says
    committed = point == "after-rows"
    assert sorted(before) == (["s0-left", "s0-right", "s2.05k-left", "s2.05k-right"] if committed
                              else ["s0-left", "s0-right"])

    code = main(["train", "--resume", "r", "--home", str(home), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    snaps = check_league(home)
    names = [p.name for p in snaps]
    assert names == ["s0-left", "s0-right", "s2.05k-left", "s2.05k-right", "s4.1k-left", "s4.1k-right",
                     "s6.14k-left", "s6.14k-right", "s8.19k-left", "s8.19k-right"]
    assert all(before[n] == next(p.sha256 for p in snaps if p.name == n) for n in before), "registered files kept"
    for learner in ("left", "right"):
        chain = [p for p in snaps if p.name.endswith(learner)]
        assert [p.parent_id for p in chain] == [None] + [p.id for p in chain[:-1]]
        assert [p.step for p in chain] == sorted(p.step for p in chain)
    if committed:
        assert "registered as it was killed" in err
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"


@pytest.mark.slow
@pytest.mark.parametrize("db", ["sqlite", "postgresql"])
def test_sigterm_stops_a_run_cleanly_and_it_resumes(tmp_path, capsys, request, monkeypatch, db):
    home = tmp_path / "h"
    env = league_in(request, monkeypatch, db)
    args = [*ARGS[:ARGS.index("--steps")], "--steps", "100000", *ARGS[ARGS.index("--steps") + 2:]]
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *args, "--home", str(home)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    metrics = home / "runs" / "r" / "metrics.jsonl"  # its first line: the first update is done, training under way
    deadline = time.time() + 120
    while time.time() < deadline and not (metrics.exists() and "\n" in metrics.read_text()):
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, (proc.returncode, err[-2000:])
    assert "stopped r at step" in err and "marl train --resume r" in err and "Traceback" not in err
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "stopped"
    check_league(home)
    code = main(["train", "--resume", "r", "--home", str(home), "--json"])
    assert code == 0, capsys.readouterr().err
    check_league(home)
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"


# --- issue 49: a disk that fills during a snapshot moment leaves no file that no row names ---

DISK_FULL = """
import resource, sys
import torch
import selfplay_cli.train.state as run_state
from selfplay_cli.cli import main
from selfplay_cli.league.roster import Roster

point, home, args = sys.argv[1], sys.argv[2], sys.argv[3:]
calls = {}

def full():  # from here on no file of this process may grow: the disk is full
    resource.setrlimit(resource.RLIMIT_FSIZE, (1, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))

def nth(what):
    calls[what] = calls.get(what, 0) + 1
    return calls[what]

real_file, real_state, real_rows = run_state.save_snapshot, torch.save, Roster.add_snapshots

def save_file(*a, **k):
    if point == "second-file" and nth("file") == 4:  # the second moment's second file (its first is written)
        full()
    return real_file(*a, **k)

def save_state(*a, **k):
    if point == "pending-state" and nth("state") == 2:  # the second moment's pending state (its files written)
        full()
    return real_state(*a, **k)

def add_rows(self, *a, **k):
    if point == "rows" and nth("rows") == 2:  # the second moment's rows (its files and pending state written)
        full()
    return real_rows(self, *a, **k)

run_state.save_snapshot, torch.save, Roster.add_snapshots = save_file, save_state, add_rows
sys.exit(main([*args, "--home", home]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("point", ["second-file", "pending-state", "rows"])
def test_a_snapshot_moment_cut_by_a_full_disk_leaves_no_file_without_its_row(tmp_path, capsys, point):
    """Issue 49: a run whose disk filled left two snapshot files with no rows (the files written, the rows' insert
    failed). The disk fills (RLIMIT_FSIZE 1: no file may grow) at each write of the second snapshot moment after its
    first file; the run ends in one line (exit 4), the first moment whole and nothing of the second left; resumed
    with room again, it runs to its end."""
    home = tmp_path / "h"
    child = subprocess.run([sys.executable, "-c", DISK_FULL, point, str(home), *ARGS], capture_output=True, text=True,
                           timeout=300)
    lines = child.stderr.splitlines()
    assert child.returncode == 4 and len(lines) == 1 and "Traceback" not in child.stderr, child.stderr[-2000:]
    snaps = check_league(home)  # every file named by a row, no pending state, no temporary file
    assert [p.name for p in snaps] == ["s0-left", "s0-right"]  # the first moment, committed, kept
    code = main(["train", "--resume", "r", "--home", str(home), "--json"])
    assert code == 0, capsys.readouterr().err
    snaps = check_league(home)
    assert len(snaps) == 10 and snaps[-1].name == "s8.19k-right"
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"
