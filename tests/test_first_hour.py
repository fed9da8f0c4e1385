"""A new user's first hour (issue 11) and the exit codes (issue 12, point 4): every help text rendered whole, every
mistake one line with its fix and exit code 2, names meaning the same in every command, recordings of a length a
person watches, and an exit code per kind of failure."""

from __future__ import annotations

import errno
import json
import math
import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from cli_helpers import run

from selfplay_cli.cli import build_command, main
from selfplay_cli.commands._output import finite
from selfplay_cli.errors import EXIT_CODES, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_IO, EXIT_USAGE
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

ROOT = Path(__file__).resolve().parents[1]



def one_line_error(code: int, out: str, err: str, needle: str, want: int = EXIT_USAGE) -> None:
    assert code == want, (code, err)
    assert err.startswith("marl: ") and err.count("\n") == 1, err
    assert needle in err, err
    assert "Traceback" not in err + out



def snapshot_file(path: Path, run: str, name: str, seed: int) -> Path:
    arch = Arch(hidden=(16, 16))
    save_snapshot(path, build_network((8, 6), 3, arch, seed=seed),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run=run, name=name, algo="ppo",
                               step=1000 * seed, episode=seed))
    return path


@pytest.fixture
def team_home(home, tmp_path, capsys) -> Path:
    """A league with one run that trained a network per seat: r2/s6M-left and r2/s6M-right, and r2/s5M-left."""
    for i, name in enumerate(("s5M-left", "s6M-left", "s6M-right"), start=1):
        f = snapshot_file(tmp_path / f"{name}.safetensors", "r2", name, seed=i)
        assert main(["checkpoint", "import", str(f)]) == 0
    capsys.readouterr()
    return home


# ---------------------------------------------------------------------------------------------------------------
# Help texts, rendered as a user sees them


def command_paths(command=None, path=()) -> list[tuple[tuple[str, ...], object]]:
    """Every command and subcommand of the tree, found by walking it (a new command is covered without a list)."""
    command = command or build_command()
    found = [(path, command)]
    for name, sub in sorted(getattr(command, "commands", {}).items()):
        found += command_paths(sub, (*path, name))
    return found


def squash(text: str) -> str:
    """Whitespace collapsed, and a line broken after a hyphen joined again (``ML-\\nAgents`` -> ``ML-Agents``)."""
    return re.sub(r"-\s+", "-", " ".join(text.split()))


PATHS = [p for p, _ in command_paths()]


def test_the_walk_finds_every_command_and_subcommand():
    names = {" ".join(p) for p in PATHS}
    assert {"", "envs", "train", "match", "record", "checkpoint", "checkpoint show", "elo", "elo fit", "elo gate",
            "league", "league ladder", "league matrix", "league plot", "league tournament"} <= names


@pytest.mark.parametrize("columns", [80, 120])
@pytest.mark.parametrize("path", PATHS, ids=lambda p: " ".join(p) or "marl")
def test_every_help_is_whole_and_plain(path, columns, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", str(columns))
    code, out, err = run(capsys, *path, "--help")
    assert code == 0 and err == "", err
    assert "Traceback" not in out
    assert not re.search(r"\[\s*\]|\(\s*\)|\(\s*[,;]|,\s*,|,\s*\)", out), "an empty bracket pair: markup ate its text"
    assert not re.search(r"<(bool|int|float|str|path|list)[^>]*>", out), "a type column (<bool> on a flag...)"
    assert "\x1b[" not in out and "…" not in out
    assert max(len(line) for line in out.splitlines()) <= columns
    command = dict(command_paths())[path]
    text = squash(out)
    for param in command.params:  # every option's and argument's help, word for word
        if getattr(param, "help", None) and not getattr(param, "hidden", False):
            assert squash(param.help) in text, (param.name, param.help)
    if command.help:
        assert squash(command.help.split("\f")[0]) in text
    for name, sub in getattr(command, "commands", {}).items():  # a group lists each command's whole first line
        assert squash(sub.short_help or "") in text, name
    for param in command.params:
        if getattr(param, "is_flag", False):
            assert re.search(rf"{re.escape(param.opts[-1])}(\s|,|/)", out), param.opts
            assert not re.search(rf"{re.escape(param.opts[-1])} [A-Z<]", out), f"{param.opts} shown taking a value"


def test_config_help_keeps_its_bracketed_sections(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")
    code, out, err = run(capsys, "train", "--help")
    sections = ("(top-level options, [ppo], [dqn], [sac], [mappo], [poca], [opponents], [env_options], [curriculum], "
                "[teacher], [league])")
    assert sections in squash(out)
    assert re.search(r"--json\s+Print JSON alone on stdout", out)
    assert "--config FILE" in out and "--env-option KEY=VALUE" in out and "[default: 6,000,000; 1 to" in out


def test_the_root_help_gives_the_exit_codes(capsys):
    code, out, err = run(capsys, "--help")
    text = squash(out)
    for code_, meaning in ((3, "SPRT undecided"), (4, "I/O or resource error"), (5, "internal error"),
                           (130, "interrupted"), (143, "stopped by SIGTERM")):
        assert f"{code_} {meaning}" in text


def test_no_arguments_prints_the_help(capsys):
    for path in ((), ("elo",), ("league",), ("checkpoint",)):
        code, out, err = run(capsys, *path)
        assert code == 0 and out.startswith("Usage: marl") and "Commands:" in out and err == ""


# ---------------------------------------------------------------------------------------------------------------
# Mistakes: one line on stderr, the fix in it, exit code 2


@pytest.mark.parametrize("path", [p for p in PATHS if p], ids=lambda p: " ".join(p))
def test_an_unknown_option_is_one_line_everywhere(path, capsys):
    one_line_error(*run(capsys, *path, "--no-such-option"), f"see marl {' '.join(path)} --help")


def test_a_missing_option_is_one_line_that_says_what_it_is_for(capsys):
    code, out, err = run(capsys, "elo", "gate", "latest")
    one_line_error(code, out, err, "Missing option '--vs': the baseline policy")
    assert "usage: marl elo gate [OPTIONS] CANDIDATE" in err and "see marl elo gate --help" in err
    one_line_error(*run(capsys, "match", "cpu"), "Missing argument 'B'")
    one_line_error(*run(capsys, "trian"), "Did you mean 'train'?")


def write(tmp_path: Path, text: str) -> str:
    f = tmp_path / "c.toml"
    f.write_text(text)
    return str(f)


@pytest.mark.parametrize(("args", "needle"), [
    (["train", "pong", "--seed", "-1"], "--seed must be at least 0, not -1"),
    (["match", "cpu", "random", "--seed", "-1"], "--seed must be at least 0, not -1"),
    (["record", "--ckpt", "cpu", "--seed", "-1"], "--seed must be at least 0, not -1"),
    (["train", "pong", "--minutes", "nan"], "--minutes must be a finite number, not nan"),
    (["train", "pong", "--minutes", "inf"], "--minutes must be"),
    (["match", "cpu", "random", "--k", "nan"], "--k must be"),
    (["match", "cpu", "random", "--k", "-100"], "--k must be at least 0"),
    (["match", "cpu", "random", "--games", "99999999999999999999"], "--games must be at most 10,000,000"),
    (["match", "cpu", "random", "--games", "1e3"], "--games must be a whole number, not 1e3"),
    (["elo", "fit", "--anchor", "alice=nan"], "--anchor alice=nan: the rating must be a finite number"),
    (["elo", "gate", "cpu", "--vs", "random", "--min-diff", "nan", "--json"], "--min-diff must be"),
    (["checkpoint", "show", "99999999999999999999"], "no player with id 99999999999999999999"),
    (["checkpoint", "show", "#²"], "no policy named '#²'"),
    (["train", "pong", "--env-option", "points_to_win=abc"],
     "pong's points_to_win wants a whole number, not 'abc' (e.g. points_to_win=21"),
    (["train", "pong", "--env-option", "points_to_win=2.5"], "points_to_win wants a whole number, not '2.5'"),
    (["train", "pong", "--env-option", "r_for_hit=nan"], "r_for_hit wants a finite number"),
    (["train", "pong", "--env-option", "rules=fancy"], "rules wants one of 'classic', 'seed', not 'fancy'"),
    (["train", "pong", "--config", "{tmp}/steps.toml"], "setting steps wants a whole number, not 'many'"),
    (["train", "pong", "--config", "{tmp}/lr.toml"], "[ppo] lr wants a number, not 'fast'"),
    (["train", "pong", "--config", "{tmp}/seed.toml"], "--seed must lie between 0 and 4294967295, not -1"),
    (["train", "pong", "--config", "{tmp}/hidden.toml"], "[ppo] arch.hidden wants a list of whole numbers"),
    (["train", "pong", "--config", "{tmp}/points.toml"], "points_to_win wants a whole number"),
    (["train", "pong", "--config", "{tmp}/bool.toml"], "setting eval_inline wants true or false, not 1"),
])
def test_bad_values_are_one_line_with_exit_code_2(args, needle, home, tmp_path, capsys):
    configs = {"steps": 'steps = "many"', "lr": '[ppo]\nlr = "fast"', "seed": "seed = -1",
               "hidden": '[ppo.arch]\nhidden = [64, "x"]', "points": "[env_options]\npoints_to_win = 2.5",
               "bool": "eval_inline = 1"}
    for name, text in configs.items():
        (tmp_path / f"{name}.toml").write_text(text + "\n")
    args = [a.format(tmp=tmp_path) for a in args]
    one_line_error(*run(capsys, *args), needle)
    assert not (home / "runs").exists(), "nothing was started"


def test_a_whole_float_in_a_config_is_the_whole_number(home, tmp_path, capsys):
    from selfplay_cli.train.config import TrainConfig

    cfg = TrainConfig.from_dict({**TrainConfig(env="pong", run="x").to_dict(), "steps": 5e6})
    assert cfg.steps == 5_000_000 and isinstance(cfg.steps, int)


def test_json_never_holds_nan():
    data = finite({"elo": math.nan, "bounds": [math.inf, 1.5, -math.inf], "n": 3, "name": "x"})
    assert json.loads(json.dumps(data, allow_nan=False)) == {"elo": None, "bounds": [None, 1.5, None], "n": 3,
                                                            "name": "x"}


def test_tensorboard_hint_names_the_extra(monkeypatch):
    import tomllib

    from selfplay_cli.errors import MarlError
    from selfplay_cli.train.config import tensorboard_writer

    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)
    with pytest.raises(MarlError, match=re.escape('pip install -e ".[tensorboard]"')):
        tensorboard_writer(None)
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert any(dep.startswith("tensorboard") for dep in extras["tensorboard"])
    assert 'pip install -e ".[tensorboard]"' in (ROOT / "docs" / "commands" / "train.md").read_text()


# ---------------------------------------------------------------------------------------------------------------
# Names: the same in every command


@pytest.mark.slow
def test_a_team_name_means_its_members_in_every_command(team_home, tmp_path, capsys):
    members = ["r2/s6M-left", "r2/s6M-right"]
    code, out, err = run(capsys, "checkpoint", "show", "s6M", "--json")
    assert code == 0, err
    shown = json.loads(out)
    assert shown["team"] == "r2/s6M" and [m["policy"] for m in shown["members"]] == members

    code, out, err = run(capsys, "match", "r2/s6M", "cpu", "-n", "2", "--no-store", "--json", "-q")
    assert code == 0, err
    played = json.loads(out)
    assert played["team"] == "r2/s6M" and [m["a"] for m in played["matches"]] == members
    assert [m["b"] for m in played["matches"]] == ["cpu", "cpu"]

    code, out, err = run(capsys, "record", "--ckpt", "s6M", "--max-steps", "3", "--size", "64x32", "--hold", "0",
                         "--out", str(tmp_path / "v"), "--json", "-q")
    assert code == 0, err
    assert json.loads(out)[0]["players"] == members
    code, out, err = run(capsys, "record", "--ckpt", "s6M", "--vs", "cpu", "--max-steps", "3", "--size", "64x32",
                         "--hold", "0", "--out", str(tmp_path / "w"), "--json", "-q")
    assert code == 0, err
    assert [r["players"] for r in json.loads(out)] == [[members[0], "cpu"], ["cpu", members[1]]]

    code, out, err = run(capsys, "league", "tournament", "s6M", "cpu", "--games-per-pair", "2", "--json", "-q")
    assert code == 0, err
    assert set(members) <= {row["policy"] for row in json.loads(out) if row["games"]}

    # one verdict, one policy: the gate, tags, exports refuse a team in one line that names its members
    for args in (["elo", "gate", "s6M", "--vs", "cpu"], ["elo", "gate", "cpu", "--vs", "r2/s6M"],
                 ["checkpoint", "tag", "s6M", "champ"], ["checkpoint", "export", "s6M", str(tmp_path / "x.st")],
                 ["match", "s6M", "cpu", "--sprt"]):
        one_line_error(*run(capsys, *args), "r2/s6M-left, r2/s6M-right")
    one_line_error(*run(capsys, "match", "s6M", "s6M"), "both teams")


def test_an_unknown_name_lists_the_closest_then_the_newest(team_home, capsys):
    code, out, err = run(capsys, "match", "s7M", "cpu")
    one_line_error(code, out, err, "no policy named 's7M'")
    assert "..." not in err
    closest = re.search(r"closest: ([^;]*)", err).group(1).split(", ")
    assert closest[0] in ("s6M", "s5M") and "s6M" in closest
    newest = re.search(r"newest: ([^;]*)", err).group(1).split(", ")
    assert newest[0] == "r2/s6M-right", "the newest snapshot first"
    assert "latest, best" in err


def test_the_same_player_twice_says_what_happened(team_home, capsys):
    code, out, err = run(capsys, "match", "latest", "r2/s6M-right")
    one_line_error(code, out, err, "'latest' and 'r2/s6M-right' are the same player, r2/s6M-right")
    assert "two different players" in err and "marl match r2/s6M-right cpu" in err
    one_line_error(*run(capsys, "match", "cpu", "cpu"), "'cpu' on both sides")


# ---------------------------------------------------------------------------------------------------------------
# Recordings: a length a person watches, and the reason a game ended


@pytest.mark.slow
def test_a_recording_stops_at_60_seconds_by_default_and_says_so(home, tmp_path, capsys):
    args = ["record", "--ckpt", "cpu", "--vs", "cpu", "--env", "pong", "--fps", "10", "--size", "64x32", "--hold",
            "0", "-q", "--out"]
    code, out, err = run(capsys, *args, str(tmp_path / "a.mp4"))
    assert code == 0, err
    assert "stopped at 1:00 by --seconds 60; the default cap: --seconds 0 records the whole game" in out
    assert "600 steps, 1:00 of video" in out
    code, out, err = run(capsys, *args, str(tmp_path / "b.mp4"), "--max-steps", "20", "--json")
    (rec,) = json.loads(out)
    assert rec["ended"] == "stopped" and rec["stopped_by"] == "--max-steps 20" and rec["length"] == 20
    one_line_error(*run(capsys, *args, str(tmp_path / "c.mp4"), "--seconds", "5", "--max-steps", "3"),
                   "--seconds and --max-steps exclude each other")


def test_only_a_limit_of_the_recording_is_called_stopped(tmp_path):
    from selfplay_cli.play import Game
    from selfplay_cli.policies import ScriptedPolicy
    from selfplay_cli.record import VideoSettings, record_game, stop_rule
    from selfplay_cli.record.recorder import ENDED_RESULT, ENDED_STOPPED, ENDED_TIME_LIMIT

    settings = VideoSettings(fps=30, size=(64, 32), hold=0)
    players = [ScriptedPolicy("pong", "cpu", seed=0), ScriptedPolicy("pong", "random", seed=1)]
    won = record_game("pong", players, Game(0, (0, 1)), tmp_path / "won.mp4", settings,
                      env_options={"points_to_win": 1})
    assert won.ended == ENDED_RESULT and won.stopped_by is None and not won.result.truncated
    timed = record_game("pong", players, Game(0, (0, 1)), tmp_path / "timed.mp4", settings,
                        env_options={"max_steps": 25})
    assert timed.ended == ENDED_TIME_LIMIT and timed.result.length == 25 and timed.stopped_by is None
    cut = record_game("pong", players, Game(0, (0, 1)), tmp_path / "cut.mp4", settings,
                      stop_when=stop_rule("pong", {}, max_steps=10), stop_label="--max-steps 10")
    assert cut.ended == ENDED_STOPPED and cut.stopped_by == "--max-steps 10" and cut.result.length == 10


# ---------------------------------------------------------------------------------------------------------------
# Exit codes: one per kind of outcome


@pytest.mark.slow
def test_exit_codes_of_verdicts(home, capsys):
    assert run(capsys, "envs")[0] == 0
    code, out, err = run(capsys, "elo", "gate", "cpu", "--vs", "random", "--env", "pong", "-n", "20")
    assert code == 0 and out.startswith("PASS"), err
    code, out, err = run(capsys, "elo", "gate", "random", "--vs", "cpu", "--env", "pong", "-n", "20")
    assert code == 1 and out.startswith("FAIL") and err == ""
    sprt = ["--env", "pong", "--sprt", "--elo0", "0", "--elo1", "50", "--no-store", "-q", "--json"]
    code, out, err = run(capsys, "match", "cpu", "random", *sprt, "--max-games", "400")
    assert code == 0 and json.loads(out)["sprt"]["decision"] == "H1"
    code, out, err = run(capsys, "match", "random", "cpu", *sprt, "--max-games", "400")
    assert code == 1 and json.loads(out)["sprt"]["decision"] == "H0"
    code, out, err = run(capsys, "match", "cpu", "random", *sprt, "--max-games", "2")
    assert code == 3 and json.loads(out)["sprt"]["decision"] is None
    one_line_error(*run(capsys, "match", "nobody", "cpu"), "no policy named 'nobody'", EXIT_USAGE)


def test_an_io_error_is_one_line_naming_the_path_and_cause(capsys, monkeypatch):
    from selfplay_cli.commands import envs as envs_cmd

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", "/data/league/videos/x.mp4")

    monkeypatch.setattr(envs_cmd, "env_rows", full)
    one_line_error(*run(capsys, "envs"), "marl: I/O error: /data/league/videos/x.mp4: No space left on device "
                   "(ENOSPC); free some space", EXIT_IO)

    def torch_save(*a, **k):  # torch's own words for a failed write, the path only in its frame
        f = "/data/league/runs/r/state.pt"  # noqa: F841
        raise RuntimeError("[enforce fail at inline_container.cc:603] . PytorchStreamWriter failed writing file "
                           "data/3: file write failed")

    monkeypatch.setattr(envs_cmd, "env_rows", torch_save)
    one_line_error(*run(capsys, "envs"), "/data/league/runs/r/state.pt", EXIT_IO)

    def gone(*a, **k):  # a path that is not there is a mistake to fix, not a broken disk
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", "/no/such/file")

    monkeypatch.setattr(envs_cmd, "env_rows", gone)
    one_line_error(*run(capsys, "envs"), "marl: error: /no/such/file: No such file or directory", EXIT_USAGE)

    def huge(*a, **k):
        raise RuntimeError("[enforce fail at alloc_cpu.cpp:127] DefaultCPUAllocator: can't allocate memory: you tried "
                           "to allocate 125829120000 bytes")

    monkeypatch.setattr(envs_cmd, "env_rows", huge)
    one_line_error(*run(capsys, "envs"), "out of memory: use fewer games at once", EXIT_IO)


@pytest.mark.slow
def test_a_full_disk_is_an_io_error(home, capsys):
    """A file size limit stands in for a full disk: the database cannot grow past it."""
    assert main(["match", "cpu", "random", "--env", "pong", "-n", "2", "-q"]) == 0
    limit = (home / "league.db").stat().st_size + 20_000

    def small_disk() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    proc = subprocess.run([sys.executable, "-m", "selfplay_cli", "match", "cpu", "random", "--env", "pong", "-n",
                           "2000", "-q"], capture_output=True, text=True, timeout=300, preexec_fn=small_disk,
                          env={**os.environ, "MARL_HOME": str(home)})
    assert proc.returncode == EXIT_IO, proc.stderr
    assert proc.stderr.startswith("marl: I/O error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert str(home / "league.db") in proc.stderr and "Traceback" not in proc.stderr


def test_a_crash_is_one_line_saying_it_is_a_bug_with_the_traceback_in_a_file(capsys, monkeypatch, tmp_path):
    import tempfile

    from selfplay_cli.commands import envs as envs_cmd

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))

    def bug(*a, **k):
        return {}["no such key"]

    monkeypatch.setattr(envs_cmd, "env_rows", bug)
    code, out, err = run(capsys, "envs")
    one_line_error(code, out, err, "internal error (a bug in marl, please report it): KeyError", EXIT_INTERNAL)
    path = Path(re.search(r"the traceback is in (\S+)", err).group(1))
    assert path.parent == tmp_path
    report = path.read_text()
    assert "Traceback" in report and "command: marl envs" in report and "no such key" in report


def test_an_interrupt_exits_130(capsys, monkeypatch):
    from selfplay_cli.commands import envs as envs_cmd

    def stop(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(envs_cmd, "env_rows", stop)
    code, out, err = run(capsys, "envs")
    assert code == EXIT_INTERRUPTED and "Traceback" not in err


def test_the_docs_document_the_exit_codes():
    readme = (ROOT / "docs" / "getting-started.md").read_text()
    table = dict(re.findall(r"^\| (\d+) \| ([^|]+) \|$", readme, flags=re.M))
    assert set(map(int, table)) == set(EXIT_CODES)


def test_options_that_a_resumed_run_would_ignore_are_refused(home, capsys):
    code, out, err = run(capsys, "train", "pong", "--steps", "512", "--games", "4", "--eval-games", "0",
                         "--env-option", "points_to_win=1", "--run", "r", "-q")
    assert code == 0, err
    one_line_error(*run(capsys, "train", "--resume", "r", "--minutes", "0.1", "--games", "8"),
                   "--resume continues run 'r' under the configuration it was started with: --games, --minutes "
                   "cannot change it")


@pytest.mark.slow
def test_scripted_players_named_alone_find_their_game(home, capsys):
    """With several games registered, `marl match A B` of scripted players finds the one game that has them both;
    names several games share ask for --env in one line."""
    code, out, err = run(capsys, "match", "random", "heuristic", "--games", "2", "--no-store", "--json")
    assert code == 0, err
    assert json.loads(out)["env"] == "lander"
    code, out, err = run(capsys, "match", "cpu", "random", "--games", "2", "--no-store", "--json")
    assert code == 0 and json.loads(out)["env"] == "pong", err
    one_line_error(*run(capsys, "match", "random", "random", "--no-store"),
                   "several games (lander, pong, tennis): say which with --env")
    one_line_error(*run(capsys, "match", "heuristic", "cpu", "--no-store"), "heuristic plays lander but cpu plays pong")
