"""`marl envs NAME`: a game's options (--env-option NAME=VALUE) with their types, defaults and which a curriculum
drives, for the built-in games (their config dataclass) and users' PettingZoo games (their factory's signature)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from cli_helpers import run, run_json

from selfplay_cli.envs import game_options, get_env

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

TYPED_GAME = '''
from typing import Literal

from tests.games.tictactoe import TicTacToe


def env(size: int = 3, swap: bool = False, mode: Literal["easy", "hard"] = "easy", render_mode=None, seed=7,
        **extra):
    return TicTacToe(render_mode=render_mode)
'''


def test_the_built_in_games_list_every_option_with_its_type_and_default():
    pong = {o.name: o for o in game_options(get_env("pong")).options}
    assert (pong["points_to_win"].type, pong["points_to_win"].default) == ("int", 21)
    assert (pong["rules"].type, pong["rules"].default, pong["rules"].choices) == ("str", "classic", ("classic", "seed"))
    assert (pong["speedup"].type, pong["speedup"].default) == ("float", 0.5)
    lander = {o.name: o for o in game_options(get_env("lander")).options}
    assert (lander["continuous"].type, lander["continuous"].default, lander["landers"].default) == ("bool", False, 2)
    tennis = game_options(get_env("tennis"))
    assert {o.name for o in tennis.options if o.live} == set(get_env("tennis").live_options) == {
        "hit_reward", "return_reward", "point_reward", "bat_scale"}
    assert tennis.source == "config" and not tennis.open


def test_marl_envs_name_shows_the_options_and_json_carries_them(capsys):
    (row,) = run_json(capsys, "envs", "tennis")  # the named game alone
    options = {o["name"]: o for o in row["options"]}
    assert options["serve_mode"] == {"name": "serve_mode", "type": "str", "default": "fixed",
                                      "choices": ["fixed", "velocity", "spin", "mixed"], "required": False,
                                      "live": False, "train_default": "mixed"}  # marl train tennis plays mixed
    assert options["bat_scale"]["live"] and not options["points_to_win"]["live"]
    every = run_json(capsys, "envs")
    assert {r["name"] for r in every} >= {"pong", "lander", "tennis"}
    assert all(r["options"] for r in every if r["name"] in ("pong", "lander", "tennis"))
    code, out, err = run(capsys, "envs", "pong")
    assert code == 0 and "pong: options, --env-option NAME=VALUE" in out
    assert any(line.split() == ["│", "points_to_win", "│", "int", "│", "21", "│"] for line in out.splitlines()), out
    assert "lander" not in out  # only the game named
    code, out, err = run(capsys, "envs")
    assert code == 0 and "marl envs NAME shows a game's options" in out
    lander = next(line for line in out.splitlines() if line.startswith("lander trains with its own defaults"))
    assert "[ppo] lr=0.001" in lander and lander.endswith("its [ppo] is also where [mappo] and [poca] start")


def test_a_pettingzoo_factorys_keyword_arguments_are_its_options(tmp_path, monkeypatch, capsys):
    (tmp_path / "typed_game_mod.py").write_text(TYPED_GAME)
    monkeypatch.syspath_prepend(str(tmp_path))
    (row,) = run_json(capsys, "envs", "typed_game_mod:env")
    assert row["options_from"] == "factory" and row["options_open"]  # **extra: it takes options it does not name
    assert [(o["name"], o["type"], o["default"], o["choices"]) for o in row["options"]] == [
        ("size", "int", 3, []), ("swap", "bool", False, []), ("mode", "str", "easy", ["easy", "hard"]),
        ("seed", "int", 7, [])]  # render_mode is marl's to set; seed's type read from its default
    code, out, err = run(capsys, "envs", "typed_game_mod:env")
    assert code == 0 and "one of easy, hard" in out and "keyword options it does not name" in out


def test_pettingzoos_own_games_show_their_raw_env_options(capsys):
    (row,) = json.loads(run(capsys, "envs", "pettingzoo.classic.connect_four_v3", "--json")[1])
    assert row["options_from"] == "raw_env"  # env(**kwargs) passes them on to raw_env(render_mode, screen_scaling)
    assert [(o["name"], o["type"], o["default"]) for o in row["options"]] == [
        ("screen_scaling", "int", 9), ("kind", "str", "two-sides")]  # kind: marl's, the game does not declare it
    assert row["kind"] == "two-sides" and row["kind_from"] == "agents"


def test_train_help_points_at_the_listing_that_exists(capsys):
    code, out, err = run(capsys, "train", "--help")
    assert code == 0 and "marl envs NAME lists" in " ".join(out.split())


WRAPPER = '''
def wrapper_fn(env_fn):  # as pettingzoo.utils.conversions.parallel_wrapper_fn: a closure in another module
    def par_fn(**kwargs):
        return env_fn(**kwargs)

    return par_fn
'''

CONVENTION_GAME = '''
from convention_pkg.wrappers import wrapper_fn as parallel_wrapper_fn

from tests.games.tictactoe import TicTacToe


class raw_env(TicTacToe):
    def __init__(self, size: int = 3, swap: bool = False, render_mode=None):
        super().__init__(render_mode=render_mode)


def env(**kwargs):
    return raw_env(**kwargs)


parallel_env = parallel_wrapper_fn(env)
'''


def _options(capsys, name: str) -> list[tuple[str, object]]:
    (row,) = run_json(capsys, "envs", name)
    return [(o["name"], o["default"]) for o in row["options"]]


def test_a_module_lists_the_options_its_env_form_lists(tmp_path, monkeypatch, capsys):
    """Issue 48: `marl envs MODULE` reads the module's parallel_env, PettingZoo's wrapper of env (**kwargs, a
    closure of pettingzoo.utils.conversions; here one of the same shape), and listed no option where `marl envs
    MODULE:env` listed raw_env's: both forms name the same game, and list the same options."""
    (tmp_path / "convention_pkg").mkdir()
    (tmp_path / "convention_pkg" / "__init__.py").write_text("")
    (tmp_path / "convention_pkg" / "game_v1.py").write_text(CONVENTION_GAME)
    (tmp_path / "convention_pkg" / "wrappers.py").write_text(WRAPPER)
    monkeypatch.syspath_prepend(str(tmp_path))
    expected = [("size", 3), ("swap", False)]  # (tic-tac-toe declares its kind: no kind option)
    assert _options(capsys, "convention_pkg.game_v1:env") == expected  # the premise: raw_env's, as before
    assert _options(capsys, "convention_pkg.game_v1") == expected
    assert _options(capsys, "convention_pkg.game_v1:parallel_env") == expected


def test_pursuit_lists_its_options_as_the_readme_uses_them(capsys):
    """README: `marl envs pettingzoo.sisl.pursuit_v5`, then `--env-option n_pursuers=3`: its raw_env(*args,
    **kwargs) hands them on to the SISL Pursuit class, whose keyword arguments they are."""
    for name in ("pettingzoo.sisl.pursuit_v5", "pettingzoo.sisl.pursuit_v5:env",
                 "pettingzoo.sisl.pursuit_v5:parallel_env"):
        options = dict(_options(capsys, name))
        assert {"n_pursuers": 8, "n_evaders": 30, "x_size": 16, "max_cycles": 500}.items() <= options.items(), name
        assert "render_mode" not in options and "kind" in options


def test_pistonball_lists_the_same_options_in_either_form(capsys):
    module = _options(capsys, "pettingzoo.butterfly.pistonball_v6")
    assert ("n_pistons", 20) in module and module == _options(capsys, "pettingzoo.butterfly.pistonball_v6:env")
