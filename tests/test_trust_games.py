"""A game's code comes only from the user of this machine (issue 49, part 1).

In a shared league every row was written by someone else: a run, a player, a job, a run's saved configuration. A row
whose game is ``evilmod:env`` (or ``os:abort``) must not make the owner's marl import ``evilmod.py`` from the
current folder. A game of your own is imported only when you name it: the game argument of ``marl train``, any
``--env``, or this machine's ``MARL_GAMES``. Every command here runs in a folder holding ``evilmod.py``, whose import
writes a marker file; none may create it. A refused row is one line on stderr (exit 2) or a row shown as not
playable here, and the command goes on where it can.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest
from cli_helpers import run
from test_hostile import _tictactoe_file, make_league

from selfplay_cli.envs import GameNotAdmittedError, admit, get_env, known_env
from selfplay_cli.envs.loading import is_admitted, not_named_here
from selfplay_cli.league.job_rows import NewJob
from selfplay_cli.league.store import League
from selfplay_cli.results import GameResult
from selfplay_cli.train.config import TrainConfig

ROOT = Path(__file__).resolve().parents[1]
EVIL = "evilmod:env"


def _module(marker: Path) -> str:
    """A user's game module (tic-tac-toe) whose import writes ``marker``."""
    return textwrap.dedent(f"""
        from pathlib import Path
        Path({str(marker)!r}).write_text("this module ran")
        from tests.games.tictactoe import env
    """)


def one_line(code: int, err: str) -> str:
    assert code == 2, (code, err)
    assert err.startswith("marl: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


def _games_job(env: str, a: list[int], b: int) -> NewJob:
    return NewJob(kind="games", env=env, spec={"a": a, "b": b, "rounds": 1, "first_seed": 0, "round": 0,
                                              "match_seed": 0, "env_options": {}, "match_kind": "match",
                                              "params": {}, "team_name": None}, max_tries=2)


@pytest.fixture
def evil(tmp_path, monkeypatch):
    """The owner's league (pong run ``r``: snapshots ``s0`` and ``s146k``, rated games) into which a second member
    wrote run ``evil1`` of game ``evilmod:env``: a snapshot named like the owner's, ``s146k``, with a real file, a
    scripted player row of that game, its games, a saved configuration naming it (the run's row and its
    ``runs/evil1/config.json``), and queued jobs of its players; the owner's folder holds ``evilmod.py``."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MARL_GAMES", raising=False)
    monkeypatch.delenv("MARL_HOME", raising=False)
    monkeypatch.delenv("MARL_DB", raising=False)
    marker = tmp_path / "EVIL_RAN"
    (tmp_path / "evilmod.py").write_text(_module(marker))
    home = tmp_path / "league"
    league = make_league(home, names=("s0", "s146k"))
    admit("tests.games.tictactoe:env")  # (the test's own game, to write a valid file that says it plays evilmod)
    _tictactoe_file(tmp_path / "evil.safetensors", EVIL, seed=5)
    config = TrainConfig.defaults("pong", run="evil1") | {"env": EVIL}
    league.roster.create_run("evil1", EVIL, config)
    rel = "snapshots/evil1/s146k.safetensors"
    (home / "snapshots" / "evil1").mkdir(parents=True)
    (home / rel).write_bytes((tmp_path / "evil.safetensors").read_bytes())
    snap = league.roster.add_snapshot(env=EVIL, run="evil1", name="s146k", path=rel, step=146_000, algo="ppo")
    league.roster.ensure_bots(EVIL, ["random"])
    bot = next(p for p in league.roster.players(kind="bot") if p.env == EVIL)
    league.ledger.create_match_with_games(EVIL, "match", {}, [
        GameResult(env=EVIL, players=(snap.id, bot.id)[::1 - 2 * (k % 2)], seed=k, scores=(1, -1),
                   outcome=(1.0, 0.0), length=9, truncated=False) for k in range(4)])
    (home / "runs" / "evil1").mkdir(parents=True)
    (home / "runs" / "evil1" / "config.json").write_text(json.dumps(config))
    mine = league.roster.find_players("s146k", env="pong")[0]
    cpu = next(p for p in league.roster.players(kind="bot") if p.env == "pong" and p.name == "cpu")
    league.queue.enqueue("evil", [_games_job(EVIL, [snap.id], bot.id), _games_job(EVIL, [bot.id], bot.id)])
    league.queue.enqueue("mine", [_games_job("pong", [mine.id], cpu.id)])
    league.close()
    assert not is_admitted(EVIL)
    yield type("Evil", (), {"root": tmp_path, "home": home, "marker": marker, "args": ("--home", str(home))})
    assert not marker.exists(), "a row made marl import evilmod.py"


def test_a_module_a_row_names_is_refused_without_importing_it(evil):
    with pytest.raises(GameNotAdmittedError) as e:
        get_env(EVIL)
    assert str(e.value).count("\n") == 0 and "--env evilmod:env" in str(e.value) and "MARL_GAMES" in str(e.value)
    assert known_env(EVIL) is None and not_named_here(EVIL) and not not_named_here("pong")
    assert "evilmod" not in sys.modules


def test_names_that_resolve_two_ways_say_so_without_importing_either(evil, capsys):
    """The issue's case: s146k names the owner's snapshot and the other member's; looking for teams of every game
    the league's runs play imported evilmod before reporting the ambiguity."""
    for args in (("checkpoint", "show", "s146k"), ("match", "s146k", "random", "--games", "2")):
        code, _, err = run(capsys, *args, *evil.args)
        assert "'s146k' is ambiguous: r/s146k, evil1/s146k" in one_line(code, err)


@pytest.mark.slow
def test_the_rows_of_a_module_nobody_here_named_cannot_play_and_the_rest_goes_on(evil, capsys):
    code, _, err = run(capsys, "match", "evil1/s146k", "random", "--games", "2", *evil.args)
    assert "game 'evilmod:env' is not imported" in one_line(code, err)
    code, out, err = run(capsys, "match", "r/s146k", "random", "--games", "2", "--json", *evil.args)
    assert code == 0 and json.loads(out)["games"] == 2, err  # the owner's own snapshot plays as before

    code, out, err = run(capsys, "checkpoint", "show", "evil1/s146k", "--json", *evil.args)
    assert code == 0, err
    shown = json.loads(out)
    assert shown["env"] == EVIL and shown["playable_here"] is False and shown["file"]["env"] == EVIL

    code, out, err = run(capsys, "checkpoint", "list", "--json", *evil.args)
    assert code == 0, err
    playable = {r["policy"]: r["playable_here"] for r in json.loads(out)}
    assert playable == {"r/s0": True, "r/s146k": True, "evil1/s146k": False}
    assert err.count("\n") == 1 and err.startswith("not imported here: evilmod:env"), err
    code, out, err = run(capsys, "checkpoint", "list", *evil.args)
    assert code == 0 and "evilmod:env (not imported)" in out, out

    code, _, err = run(capsys, "league", "ladder", *evil.args)
    assert "several envs in the league (pong, evilmod:env): pass --env" in one_line(code, err)
    code, out, err = run(capsys, "league", "ladder", "--env", "pong", "--json", *evil.args)
    assert code == 0 and {r["policy"] for r in json.loads(out)} >= {"r/s146k", "cpu"} and err == "", err
    code, out, err = run(capsys, "league", "ladder", "--run", "evil1", "--json", *evil.args)
    assert code == 0 and [r["policy"] for r in json.loads(out)] == ["evil1/s146k", "random"], err
    assert err.startswith("not imported here: evilmod:env") and err.count("\n") == 1, err


@pytest.mark.slow
def test_a_worker_fails_the_jobs_of_a_module_nobody_here_named_and_plays_the_rest(evil, capsys):
    code, out, err = run(capsys, "worker", "--until-empty", "--json", *evil.args)
    assert code == 0, err
    report = json.loads(out)
    assert report["done"] == 1 and report["failed"] == 4, report  # the owner's job; two tries of each of the two
    code, out, err = run(capsys, "queue", "--json", *evil.args)
    jobs = {j["id"]: j for j in json.loads(out)["jobs"]}
    assert [jobs[i]["state"] for i in sorted(jobs)] == ["dead", "dead", "done"], jobs
    for i in sorted(jobs)[:2]:
        assert "game 'evilmod:env' is not imported" in jobs[i]["error"], jobs[i]


def test_resuming_a_run_whose_record_names_a_module_is_refused_in_one_line(evil, capsys):
    code, _, err = run(capsys, "train", "--resume", "evil1", *evil.args)
    line = one_line(code, err)
    assert "run 'evil1' trains 'evilmod:env', a game of your own" in line
    assert "marl train 'evilmod:env' --resume evil1" in line and "MARL_GAMES" in line
    # a run of pong whose saved configuration was changed to name the module: refused by the run's own game
    league = League.open(evil.home)
    league.roster.create_run("tampered", "pong", TrainConfig.defaults("pong", run="tampered") | {"env": EVIL})
    league.close()
    code, _, err = run(capsys, "train", "--resume", "tampered", *evil.args)
    assert "its saved configuration names another game ('evilmod:env')" in one_line(code, err)


def _marl(cwd: Path, *args: str, games: str | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("MARL_GAMES", "MARL_HOME", "MARL_DB")}
    env |= {"PYTHONPATH": str(ROOT), "SDL_VIDEODRIVER": "dummy"} | ({"MARL_GAMES": games} if games else {})
    return subprocess.run([sys.executable, "-m", "selfplay_cli", *args], cwd=cwd, capture_output=True, text=True,
                          env=env, timeout=600)


@pytest.mark.slow
@pytest.mark.parametrize("named", ["os:abort", "signal:pause"])
def test_a_row_naming_os_abort_neither_aborts_nor_hangs(tmp_path, named):
    home = tmp_path / "league"
    league = League.open(home)
    league.roster.create_run("boom", named, {})
    league.roster.add_snapshot(env=named, run="boom", name="x", path="snapshots/boom/x.safetensors", sha256="0" * 64)
    league.close()
    for args in (("match", "boom/x", "random", "--games", "2"), ("checkpoint", "show", "boom/x"),
                 ("train", "--resume", "boom")):
        p = _marl(tmp_path, *args, "--home", str(home))
        assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, (args, p)


@pytest.mark.slow
def test_a_game_you_name_is_imported_and_played(tmp_path):
    """`marl train mygame:env` (typed) imports and trains it, its rating worker too; later commands play it once
    named again (--env, or MARL_GAMES, which `marl worker` and `marl train --resume` read as well; `marl record
    --game ID --env mygame:env` replays one of its stored games)."""
    marker = tmp_path / "MINE_RAN"
    (tmp_path / "mygame.py").write_text(_module(marker))
    home = ("--home", str(tmp_path / "league"))
    p = _marl(tmp_path, "train", "mygame:env", "--steps", "200", "--games", "4", "--snapshot-steps", "100",
              "--eval-games", "2", "--run", "mine", "--json", *home)
    assert p.returncode == 0, p.stderr
    assert marker.exists() and json.loads(p.stdout)["final"][0]["snapshot"] == "mine/s200-x"
    marker.unlink()

    p = _marl(tmp_path, "match", "mine/s200-x", "random", "--games", "4", *home)
    assert p.returncode == 2 and "MARL_GAMES=mygame:env" in p.stderr and p.stderr.count("\n") == 1, p.stderr
    assert not marker.exists()
    p = _marl(tmp_path, "train", "--resume", "mine", *home)
    assert p.returncode == 2 and "marl train 'mygame:env' --resume mine" in p.stderr, p.stderr
    assert not marker.exists()

    p = _marl(tmp_path, "match", "mine/s200-x", "random", "--games", "4", "--json", *home, games="mygame:env")
    assert p.returncode == 0 and json.loads(p.stdout)["games"] == 4, p.stderr
    p = _marl(tmp_path, "match", "mine/s200-x", "random", "--games", "4", "--json", "--env", "mygame:env", *home)
    assert p.returncode == 0 and json.loads(p.stdout)["games"] == 4, p.stderr
    p = _marl(tmp_path, "train", "mygame:env", "--resume", "mine", "-q", *home)
    assert p.returncode == 0, p.stderr
    gif = str(tmp_path / "game1.gif")  # a stored game replayed: its game named with --env
    p = _marl(tmp_path, "record", "--game", "1", "--out", gif, *home)
    assert p.returncode == 2 and "MARL_GAMES=mygame:env" in p.stderr, p.stderr
    p = _marl(tmp_path, "record", "--game", "1", "--out", gif, "--env", "mygame:env", *home)
    assert p.returncode == 0 and Path(gif).stat().st_size > 0, p.stderr

    league = League.open(tmp_path / "league")
    (snap,) = league.roster.find_players("mine/s200-x")
    rnd = next(q for q in league.roster.players(kind="bot") if q.env == "mygame:env" and q.name == "random")
    league.queue.enqueue("mine", [_games_job("mygame:env", [snap.id], rnd.id)])
    league.close()
    p = _marl(tmp_path, "worker", "--until-empty", "--json", *home, games="mygame:env")
    assert p.returncode == 0 and json.loads(p.stdout)["done"] == 1, p.stderr


def test_admit_and_marl_games_let_a_library_user_name_a_game(tmp_path, monkeypatch):
    module = f"admitted_game_{uuid.uuid4().hex[:8]}"
    marker = tmp_path / "RAN"
    (tmp_path / f"{module}.py").write_text(_module(marker))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("MARL_GAMES", raising=False)
    try:
        with pytest.raises(GameNotAdmittedError):
            get_env(f"{module}:env")
        assert not marker.exists()
        monkeypatch.setenv("MARL_GAMES", f"other:env, {module}:env")
        assert get_env(f"{module}:env").agents == ("x", "o") and marker.exists()
        monkeypatch.delenv("MARL_GAMES")
        with pytest.raises(GameNotAdmittedError):  # exactly the names listed: the variable is read at each lookup
            get_env(f"{module}:env")
        assert known_env(f"{module}:env") is None
        admit(f"{module}:env")
        assert get_env(f"{module}:env").agents == ("x", "o") and known_env(f"{module}:env") is not None
        with pytest.raises(GameNotAdmittedError):  # another factory of the same module is another name
            get_env(f"{module}:TicTacToe")
    finally:
        sys.modules.pop(module, None)
