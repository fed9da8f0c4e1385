"""What the help texts claim of their commands holds (issue 48): every --flag an option's or a command's help
mentions is an option of that command (unless the text names another command: marl train --resume), a --env
that speaks of "the policies" is on a command given some, and the default anchor is said as the ladder takes it."""

from __future__ import annotations

import re
from typing import Any

import pytest
from cli_helpers import run_json

from selfplay_cli.cli import build_command

FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
CLAUSE = re.compile(r"[^.;:(,]*$")  # the text from the clause's start up to a flag
ANOTHER_PROGRAM = re.compile(r"\b(marl|ray|pip|python)\s")  # marl train --resume, ray start --head: not its own


def commands() -> list[tuple[str, Any]]:
    """Every command of `marl` (``"league ladder"``) and its click command."""
    out = []

    def walk(cmd: Any, path: list[str]) -> None:
        if hasattr(cmd, "commands"):
            for name, sub in cmd.commands.items():
                walk(sub, [*path, name])
        else:
            out.append((" ".join(path), cmd))

    walk(build_command(), [])
    return out


def _helps(cmd: Any) -> list[tuple[str, str]]:
    return [("the command", cmd.help or "")] + [(p.opts[0], getattr(p, "help", None) or "") for p in cmd.params]


def test_the_walk_sees_every_command():
    names = {name for name, _ in commands()}
    assert {"train", "elo fit", "league ladder", "checkpoint list", "queue cancel"} <= names, names


def test_every_flag_a_help_mentions_is_an_option_of_its_command():
    wrong = []
    for name, cmd in commands():
        own = {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)}
        for where, text in _helps(cmd):
            for m in FLAG.finditer(text):
                if m.group() not in own and not ANOTHER_PROGRAM.search(CLAUSE.search(text[:m.start()]).group()):
                    wrong.append(f"marl {name} ({where}): {m.group()} in ...{text[max(0, m.start() - 50):m.end()]}")
    assert wrong == [], "\n".join(wrong)


def test_an_env_help_that_speaks_of_the_policies_is_on_a_command_given_some():
    wrong = []
    for name, cmd in commands():
        env = next((p for p in cmd.params if "--env" in p.opts), None)
        if env is None or "polic" not in (env.help or ""):
            continue
        given = any(p.param_type_name == "argument" for p in cmd.params) or any(
            o in ("--vs", "--ckpt") for p in cmd.params for o in p.opts)
        if not given:
            wrong.append(f"marl {name}: --env {env.help!r}")
    assert wrong == [], "\n".join(wrong)


@pytest.mark.parametrize("name", ["league ladder", "elo fit"])
def test_the_default_anchor_is_the_games_declared_one(name):
    cmd = dict(commands())[name]
    texts = " ".join(text for _, text in _helps(cmd))
    assert "random bot at 1000" not in texts  # a game declares its anchor: tennis's serve-bot, the lander's heuristic
    anchor = next(p for p in cmd.params if "--anchor" in p.opts).help
    assert "declares" in anchor and "1000" in anchor, anchor


def test_elo_fit_on_a_file_anchors_at_its_first_player_as_its_help_says(tmp_path, capsys):
    anchor = next(p for p in dict(commands())["elo fit"].params if "--anchor" in p.opts).help
    assert "--results: the file's first player" in anchor, anchor
    f = tmp_path / "results.csv"
    f.write_text("player_a,player_b,result\n" + "b,a,0\n" * 3 + "b,a,1\n" * 7)
    rows = run_json(capsys, "elo", "fit", "--results", str(f), "--bootstrap", "0")
    assert {r["policy"]: r["elo"] for r in rows}["b"] == 1000.0
