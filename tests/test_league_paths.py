"""Paths read from the league database never reach outside the league, and removing a snapshot never kills a run
for good (issue 30, points 3 and 4). The league's rows are the point of the first part, which runs on SQLite and on
PostgreSQL (``league_db``); the second copies a trained league file, and stays on SQLite."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from cli_helpers import run
from sqlalchemy import create_engine, text
from sqlalchemy.exc import DataError

from selfplay_cli.errors import MarlError
from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.players.files import snapshot_relpath
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot
from selfplay_cli.train.loop import Trainer
from selfplay_cli.train.state import STATE_VERSION


def one_line_error(code: int, err: str) -> str:
    assert code == 2 and err.startswith("marl: error: ") and err.count("\n") == 1, (code, err)
    assert "Traceback" not in err
    return err


def make_league(home: Path, names=("s0-left", "s1M-left"), run_name: str = "r") -> None:
    """Run ``run_name`` (status finished, as an import leaves it) with one small snapshot per name, files in place."""
    with League.open(home) as league:
        rows = []
        for i, name in enumerate(names):
            rel = snapshot_relpath(run_name, name)
            save_snapshot(home / rel, build_network((8, 6), 3, Arch(hidden=(16,)), seed=i),
                          SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=Arch(hidden=(16,)),
                                       algo="ppo", run=run_name, name=name, step=1_000_000 * i))
            rows.append(dict(env="pong", run=run_name, name=name, path=rel, step=1_000_000 * i, algo="ppo"))
        league.roster.add_snapshots(rows, run_config={})
        league.roster.ensure_bots("pong", ["cpu", "random"])


@pytest.fixture(params=["sqlite", "postgresql"])
def league_db(request, monkeypatch) -> str:
    """The league of the test: SQLite in its home, or a fresh PostgreSQL database that ``MARL_DB`` names to every
    League and command of the test."""
    if request.param == "sqlite":
        monkeypatch.delenv("MARL_DB", raising=False)
    else:
        monkeypatch.setenv("MARL_DB", request.getfixturevalue("pg_url"))
    return request.param


def set_sql(home: Path, sql: str, **params) -> None:
    """Edit the league's database by hand (as something else than marl would): ``MARL_DB``'s, or the home's file."""
    engine = create_engine(os.environ.get("MARL_DB") or f"sqlite:///{home / 'league.db'}")
    with engine.begin() as conn:
        conn.execute(text(sql), params)
    engine.dispose()


def status(home: Path, run_name: str) -> str:
    with League.open(home, readonly=True) as league:
        return league.roster.get_run(run_name).status


def removed(home: Path, name: str) -> bool:
    with League.open(home, readonly=True) as league:
        return next(p for p in league.roster.players(env="pong", include_removed=True) if p.name == name).removed


# -- 1. a row's path never leads outside the league ------------------------------------------------------------------


def _bad_paths(tmp_path: Path, home: Path) -> dict[str, str]:
    """Row paths that leave the league, each naming a file outside it (or the database inside the home)."""
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious")
    (home / "snapshots" / "r" / "link.safetensors").symlink_to(victim)
    return {"dotdot": "../victim", "absolute": str(victim), "dotdot inside": "snapshots/../../victim",
            "symlink out": "snapshots/r/link.safetensors", "not under snapshots": "league.db",
            "nul byte": "snapshots/r/s1M-left.safetensors\0../../victim"}


@pytest.mark.parametrize("which", ["dotdot", "absolute", "dotdot inside", "symlink out", "not under snapshots",
                                   "nul byte"])
def test_rm_never_deletes_a_file_a_row_points_outside(tmp_path, capsys, league_db, which):
    home = tmp_path / "home"
    make_league(home)
    if league_db == "postgresql":
        (home / "league.db").write_bytes(b"a file of the home's that is no snapshot")  # what "league.db" points at
    path = _bad_paths(tmp_path, home)[which]
    if league_db == "postgresql" and "\0" in path:  # PostgreSQL's text holds no NUL: no such row can be
        with pytest.raises(DataError, match="cannot contain NUL"):
            set_sql(home, "update players set path = :path where name = 's1M-left'", path=path)
        return
    set_sql(home, "update players set path = :path where name = 's1M-left'", path=path)
    before = {p: p.read_bytes() for p in (tmp_path / "victim", home / "league.db")}
    err = one_line_error(*run(capsys, "checkpoint", "rm", "r/s1M-left", "--home", str(home))[::2])
    assert "r/s1M-left" in err and "leaves the league" in err and "--keep-file" in err
    assert (tmp_path / "victim").read_bytes() == b"precious" and (home / "league.db").exists()
    assert not removed(home, "s1M-left")
    # --keep-file touches no file: the row alone goes
    code, _, err = run(capsys, "checkpoint", "rm", "r/s1M-left", "--keep-file", "--home", str(home))
    assert code == 0, err
    assert removed(home, "s1M-left") and (tmp_path / "victim").read_bytes() == before[tmp_path / "victim"]


def test_no_command_reads_a_copy_outside_the_league(tmp_path, capsys, league_db):
    """An absolute path to an exact copy of the registered file (its sha256 matches) outside the home: show, export,
    match and record refuse it, naming the snapshot."""
    home = tmp_path / "home"
    make_league(home)
    outside = tmp_path / "outside.safetensors"
    shutil.copy(home / snapshot_relpath("r", "s1M-left"), outside)
    (home / snapshot_relpath("r", "s1M-left")).unlink()
    set_sql(home, "update players set path = :path where name = 's1M-left'", path=str(outside))
    for args in (("checkpoint", "show", "r/s1M-left"), ("checkpoint", "export", "r/s1M-left", str(tmp_path / "x")),
                 ("match", "r/s1M-left", "cpu", "--games", "2"),
                 ("record", "--ckpt", "r/s1M-left", "--vs", "cpu", "--max-steps", "5")):
        err = one_line_error(*run(capsys, *args, "--home", str(home))[::2])
        assert "r/s1M-left" in err and "leaves the league" in err, args
    assert not (tmp_path / "x").exists()


def test_snapshot_file_is_the_one_check(tmp_path, league_db):
    home = tmp_path / "home"
    make_league(home)
    with League.open(home) as league:
        row = next(p for p in league.roster.players(env="pong", kind="snapshot") if p.name == "s1M-left")
        assert league.snapshot_file(row) == home.resolve() / "snapshots" / "r" / "s1M-left.safetensors"
        snapshots_elsewhere = tmp_path / "disk2"  # snapshots/ itself a symlink to another disk: still the league's
        shutil.move(home / "snapshots", snapshots_elsewhere)
        (home / "snapshots").symlink_to(snapshots_elsewhere)
        assert league.snapshot_file(row).read_bytes()
    with League("sqlite://") as by_url:  # a league opened by URL without a home: no file is anywhere
        assert by_url.home is None
        with pytest.raises(LeagueError, match="no home directory"):
            by_url.snapshot_file(row)


# -- 2. removing a snapshot a run needs ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A real run 'r' of 2,000 steps (snapshots s0-* and s2k-*, its state.pt), trained once for the module."""
    home = tmp_path_factory.mktemp("trained") / "home"
    code = os.spawnvpe(os.P_WAIT, sys.executable, [  # a process of its own: torch threads, signal handlers
        sys.executable, "-m", "selfplay_cli", "train", "pong", "--agents", "2", "--steps", "2000", "--games", "4",
        "--eval-games", "0", "--run", "r", "--home", str(home), "--quiet"],
        {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    assert code == 0
    return home


@pytest.fixture
def stopped(trained, tmp_path) -> Path:
    """A copy of the trained run, stopped (as Ctrl-C leaves it): resumable."""
    home = tmp_path / "home"
    shutil.copytree(trained, home)
    set_sql(home, "update runs set status = 'stopped'")
    return home


@pytest.mark.slow
def test_rm_refuses_the_snapshot_a_stopped_run_resumes_from_and_force_ends_it(stopped, capsys):
    home = stopped
    err = one_line_error(*run(capsys, "checkpoint", "rm", "r/s2k-left", "--home", str(home))[::2])
    assert "run 'r'" in err and "--resume continues from it" in err and "--force" in err
    assert not removed(home, "s2k-left") and (home / snapshot_relpath("r", "s2k-left")).exists()
    code, out, err = run(capsys, "checkpoint", "rm", "r/s2k-left", "--force", "--home", str(home))
    assert code == 0, err
    assert "ended run 'r'" in out
    assert removed(home, "s2k-left") and not (home / snapshot_relpath("r", "s2k-left")).exists()
    assert status(home, "r") == "ended"
    err = one_line_error(*run(capsys, "train", "--resume", "r", "--home", str(home))[::2])
    assert "run 'r' was ended" in err and "r/s2k-left" in err and "cannot be resumed" in err
    assert status(home, "r") == "ended"


@pytest.mark.slow
def test_rm_of_a_snapshot_no_run_needs_lets_the_run_go_on(stopped, capsys):
    home = stopped
    code, _, err = run(capsys, "checkpoint", "rm", "r/s0-left", "--home", str(home))
    assert code == 0, err
    assert status(home, "r") == "stopped"
    code, _, err = run(capsys, "train", "--resume", "r", "--home", str(home), "--quiet")
    assert code == 0, err
    assert status(home, "r") == "finished"


@pytest.mark.slow
def test_rm_refuses_a_snapshot_whose_gauntlet_a_run_owes(stopped, capsys):
    home = stopped
    state = torch.load(home / "runs" / "r" / "state.pt", weights_only=True)
    assert state["version"] == STATE_VERSION
    state["jobs"] = [[["r/s0-left", "r/s0-right"], 10_000_000, False]]
    torch.save(state, home / "runs" / "r" / "state.pt")
    err = one_line_error(*run(capsys, "checkpoint", "rm", "r/s0-right", "--home", str(home))[::2])
    assert "run 'r'" in err and "rating gauntlet" in err
    assert not removed(home, "s0-right")


@pytest.mark.slow
def test_a_run_states_names_are_read_without_torch_and_without_running_its_pickle(trained, tmp_path):
    """`marl checkpoint rm` reads which snapshots a run needs from its state without importing torch: the plain
    values come out as torch.load gives them (a tensor as None), and a class or function the pickle names is never
    imported nor called."""
    from selfplay_cli.train.state_file import plain_state

    path = trained / "runs" / "r" / "state.pt"
    plain, loaded = plain_state(path), torch.load(path, weights_only=True)
    assert plain["version"] == loaded["version"] == STATE_VERSION
    for key in ("latest", "snapshots", "jobs", "steps", "next_seed"):
        assert plain[key] == loaded[key], key
    assert plain["latest"] == ["r/s2k-left", "r/s2k-right"]
    weights = loaded["learners"][0]["net"]  # a state dict: an OrderedDict of tensors
    assert isinstance(next(iter(weights.values())), torch.Tensor)
    assert list(plain["learners"][0]["net"]) == list(weights)
    assert all(v is None for v in plain["learners"][0]["net"].values())
    assert plain["learners"][0]["updates"] == loaded["learners"][0]["updates"]

    class Planted:
        def __reduce__(self):
            return (os.system, (f"touch {tmp_path / 'ran'}",))

    planted = tmp_path / "state.pt"
    torch.save({"version": STATE_VERSION, "latest": Planted(), "jobs": []}, planted, pickle_protocol=2)
    assert plain_state(planted) == {"version": STATE_VERSION, "latest": None, "jobs": []}
    assert not (tmp_path / "ran").exists()


@pytest.mark.slow
def test_a_state_the_plain_reader_cannot_read_is_read_by_torch_and_its_snapshot_stays_needed(stopped, capsys,
                                                                                             monkeypatch):
    import selfplay_cli.train.needs as needs

    def cannot(path):
        raise ValueError("a layout of another torch")

    monkeypatch.setattr(needs, "plain_state", cannot)
    err = one_line_error(*run(capsys, "checkpoint", "rm", "r/s2k-left", "--home", str(stopped))[::2])
    assert "--resume continues from it" in err
    assert not removed(stopped, "s2k-left")


@pytest.mark.slow
def test_rm_of_a_needed_snapshot_is_refused_without_importing_torch(stopped):
    code = ("import sys; from selfplay_cli.cli import main; "
            f"code = main(['checkpoint', 'rm', 'r/s2k-left', '--home', {str(stopped)!r}]); "
            "print(code, sorted(m for m in ('torch', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == "2 []", out.stdout + out.stderr[-500:]
    assert "--resume continues from it" in out.stderr


@pytest.mark.slow
def test_rm_refuses_a_stopped_runs_teacher(tmp_path, capsys, league_db):
    home = tmp_path / "home"
    make_league(home, run_name="t")
    with League.open(home) as league:
        league.roster.create_run("pupil", "pong", {"env": "pong", "run": "pupil", "teacher": {"player": "t/s1M-left"}},
                                 status="stopped")
        league.roster.create_run("done", "pong", {"env": "pong", "run": "done", "teacher": {"player": "t/s0-left"}},
                                 status="finished")
    err = one_line_error(*run(capsys, "checkpoint", "rm", "t/s1M-left", "--home", str(home))[::2])
    assert "run 'pupil'" in err and "teacher" in err
    code, _, err = run(capsys, "checkpoint", "rm", "t/s0-left", "--home", str(home))  # a finished run needs nothing
    assert code == 0, err
    code, _, err = run(capsys, "checkpoint", "rm", "t/s1M-left", "--force", "--home", str(home))
    assert code == 0, err
    assert status(home, "pupil") == "ended" and status(home, "done") == "finished"


@pytest.mark.slow
def test_rm_is_refused_even_with_force_while_the_runs_trainer_lives(stopped, capsys):
    home = stopped
    set_sql(home, "update runs set status = 'running'")
    (home / "runs" / "r" / "lock").write_text(str(os.getpid()))  # a live process holds the run
    for extra in ((), ("--force",)):
        err = one_line_error(*run(capsys, "checkpoint", "rm", "r/s0-left", *extra, "--home", str(home))[::2])
        assert f"process {os.getpid()}" in err and "stop that training first" in err
    assert not removed(home, "s0-left") and status(home, "r") == "running"


@pytest.mark.slow
def test_a_run_whose_needed_snapshot_was_removed_before_is_ended_at_resume(stopped, capsys):
    """A league where an older marl removed the snapshot a run resumes from: --resume says so in one line and the
    run is no longer left 'stopped' or 'running'."""
    home = stopped
    set_sql(home, "update players set removed = true where name = 's2k-right'")
    err = one_line_error(*run(capsys, "train", "--resume", "r", "--home", str(home))[::2])
    assert "r/s2k-right" in err and "cannot be resumed" in err
    assert status(home, "r") == "ended"


@pytest.mark.slow
@pytest.mark.parametrize("failure", [MarlError("a snapshot went missing"), SystemExit(3)])
def test_a_resumed_trainer_that_dies_is_not_left_running(stopped, capsys, monkeypatch, failure):
    home = stopped

    def dies(self):
        raise failure

    monkeypatch.setattr(Trainer, "train", dies)
    code, _, err = run(capsys, "train", "--resume", "r", "--home", str(home))
    assert code != 0
    assert status(home, "r") == "failed"
