"""The command line as a user meets it: help, version, envs, errors, and README staying true."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from selfplay_cli import __version__
from selfplay_cli.cli import app

ROOT = Path(__file__).resolve().parents[1]


def marl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "selfplay_cli", *args], capture_output=True, text=True,
                          timeout=120, env={"COLUMNS": "160", "PATH": "/usr/bin:/bin", "TERM": "dumb"})


def registered_commands() -> set[str]:
    names = {c.name for c in app.registered_commands}
    names |= {g.name for g in app.registered_groups}
    return names


@pytest.mark.slow
def test_version_and_help_list_every_command_with_a_description():
    out = marl("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"marl {__version__}"
    out = marl("--help")
    assert out.returncode == 0
    for name in registered_commands():
        line = next(ln for ln in out.stdout.splitlines() if re.search(rf"\b{name}\b", ln))
        assert len(line.split(name, 1)[1].strip(" │")) > 10, f"{name} has no description"


def test_envs_json_is_json_alone_on_stdout():
    out = marl("envs", "--json")
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)
    pong = next(r for r in rows if r["name"] == "pong")
    assert pong["agents"] == ["left", "right"]
    assert pong["observation_space"] == "Box(-1, 1, (8, 6), float32)"
    assert pong["action_space"] == "Discrete(3)"
    assert set(pong["bots"]) == {"cpu", "random"}
    assert out.stderr == ""


@pytest.mark.slow
def test_envs_table_is_plain_when_not_a_tty():
    out = marl("envs")
    assert out.returncode == 0
    assert "pong" in out.stdout and "cpu" in out.stdout
    assert "\x1b[" not in out.stdout, "no colour codes in piped output"


@pytest.mark.slow
def test_unknown_command_and_bad_flag_fail_without_traceback():
    for args in (["frobnicate"], ["envs", "--no-such-flag"]):
        out = marl(*args)
        assert out.returncode != 0
        assert "Traceback" not in out.stderr + out.stdout


def test_readme_and_the_docs_document_exactly_the_registered_commands():
    """README's tour names every command, and the docs site has a section (a page, or a part of one) for each."""
    from cli_helpers import docs_text

    readme = (ROOT / "README.md").read_text()
    assert set(re.findall(r"\*\*`marl (\w+)`\*\*", readme)) == registered_commands()
    pages = "\n".join(p.read_text() for p in (ROOT / "docs").rglob("*.md") if p.parent.name != "reference")
    assert set(re.findall(r"^#{1,3} `marl (\w+)", pages, flags=re.M)) == registered_commands()
    assert "not built yet" not in docs_text().lower()


def test_ci_runs_the_readme_install_and_test_commands():
    ci = (ROOT / ".ci" / "run").read_text()
    assert "ci:install" in ci and "ci:test" in ci and "rm -rf .venv" in ci
    readme = (ROOT / "README.md").read_text()
    assert re.search(r"<!-- ci:install -->\n```sh\npython3 -m venv \.venv && .*pip install", readme)
    assert re.search(r"<!-- ci:test -->\n```sh\n\.venv/bin/pytest -n 2 -m \"not slow\"\n", readme)
    assert re.search(r"<!-- ci:test-slow -->\n```sh\n\.venv/bin/pytest -n 2 -m slow\n", readme)
    assert "test-slow" in ci


def test_readme_shows_what_marl_envs_prints_and_claims_no_missing_feature_that_exists(capsys):
    """The docs' sample of `marl envs` (the lines under the table: each game's training defaults) is what the command
    prints today; and the docs call nothing "not built yet" that a command offers (league roles and Nash opponents
    are `marl train --league alphastar` and `--opponents nash`)."""
    from cli_helpers import run

    readme = (ROOT / "docs" / "commands" / "envs.md").read_text()
    code, out, _ = run(capsys, "envs")
    assert code == 0
    for line in out.splitlines():
        if " trains with its own defaults " in line:
            game = line.split(" ", 1)[0]
            shown = [x for x in readme.splitlines() if x.startswith(f"{game} trains with its own defaults ")]
            assert shown and all(x == line for x in shown), (game, shown, line)


@pytest.mark.slow
def test_a_refused_command_leaves_no_league_behind(tmp_path, monkeypatch, capsys):
    """`marl match nosuch cpu` or `marl train --init-from ../../etc/passwd` in an empty folder is refused (exit 2)
    and creates no ./league; a command that plays creates it, and a later refused command leaves it, games and
    all; a refused command in a league that was there keeps it too."""
    from selfplay_cli.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MARL_HOME", raising=False)
    monkeypatch.delenv("MARL_DB", raising=False)
    assert main(["match", "nosuch", "cpu"]) == 2
    assert "no policy named 'nosuch'" in capsys.readouterr().err
    assert main(["train", "pong", "--init-from", "../../etc/passwd", "--steps", "100"]) == 2
    assert "no policy named '../../etc/passwd'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    assert main(["match", "cpu", "random", "--games", "2", "--quiet"]) == 0
    assert main(["match", "nosuch", "cpu"]) == 2
    import sqlite3

    con = sqlite3.connect(tmp_path / "league" / "league.db")
    try:
        assert con.execute("select count(*) from games").fetchone()[0] == 2  # the games the first match stored
    finally:
        con.close()


def test_ctrl_c_that_no_command_catches_says_interrupted_and_exits_130(monkeypatch, capsys):
    """typer turns an uncaught Ctrl-C into a silent exit 130 (an empty line on stderr); marl says what happened."""
    from selfplay_cli.cli import main
    from selfplay_cli.commands import envs

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(envs, "env_names", ctrl_c)
    assert main(["envs"]) == 130
    captured = capsys.readouterr()
    assert captured.err == "marl: interrupted\n" and captured.out == ""


def test_the_cli_imports_no_heavy_library_until_a_command_needs_it():
    """`marl --help`, `--version` and the CLI's building import neither torch nor scipy (1.3 s and more of every
    command's start): a command imports what it needs when it runs."""
    code = ("import sys; from selfplay_cli.cli import build_command; build_command(); "
            "print(sorted(m for m in ('torch', 'scipy', 'scipy.stats', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr[-500:]


@pytest.mark.slow
def test_reading_the_league_imports_no_torch(tmp_path):
    """Commands that read rows, snapshot headers and ratings (`league ladder`, `league matrix`, `league predict`,
    `checkpoint list`, `checkpoint show`) build no network, so they do not import torch (1.3 s and more of a
    command's start); nor does a `train --resume` that is refused (no such run, or one ended)."""
    home = str(tmp_path / "home")
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    for args in (["train", "pong", "--agents", "2", "--steps", "2000", "--games", "4", "--eval-games", "0", "--run",
                  "r", "--quiet"], ["match", "random", "cpu", "--env", "pong", "--games", "2"]):
        done = subprocess.run([sys.executable, "-m", "selfplay_cli", *args, "--home", home], capture_output=True,
                              text=True, timeout=300, env=env)
        assert done.returncode == 0, done.stderr[-500:]
    for args, exit_code in ((["league", "ladder"], 0), (["league", "matrix"], 0),
                            (["league", "predict", "random", "cpu", "--env", "pong"], 0), (["checkpoint", "list"], 0),
                            (["checkpoint", "show", "r/s2k-left"], 0),
                            (["train", "--resume", "nope"], 2)):  # no such run: refused before the trainer's imports
        code = ("import sys; from selfplay_cli.cli import main; "
                f"code = main({[*args, '--home', home]!r}); print(code, 'torch' in sys.modules)")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
        assert out.stdout.strip().splitlines()[-1] == f"{exit_code} False", (args, out.stdout[-500:],
                                                                             out.stderr[-500:])
