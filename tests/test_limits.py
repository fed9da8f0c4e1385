"""Issue 30's limits, users' games and recordings: sizes and numbers a config file can hold are refused in one line
before a run exists, error lines stay short whatever they quote, every game ends (at its declared length, else at
the loop's stated cap), an agent that is not one of the game's possible_agents is refused, and a full disk under
`marl record` is an I/O error (exit 4)."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run

from selfplay_cli.cli import MAX_LINE, MAX_WORD
from selfplay_cli.envs import get_env
from selfplay_cli.errors import EXIT_IO, EXIT_USAGE
from selfplay_cli.league.store import League
from selfplay_cli.play import Game, limits, play
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.policies.bots import ScriptedPolicy
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

ENDLESS = "tests.games.endless:env"  # never ends by itself; declares marl_max_steps = 30
UNDECLARED = "tests.games.endless:undeclared"  # never ends and declares no maximum
SHIFTING = "tests.games.shifting"


def _train(capsys, home: Path, config: str | bytes, *args: str, env: str = "pong", games: int | None = 4
           ) -> tuple[int, str]:
    """``marl train ENV --config FILE`` (FILE holding ``config``), tiny; ``games=None``: the file's own."""
    path = home.parent / "settings.toml"
    path.write_bytes(config.encode() if isinstance(config, str) else config)
    typed = ("--games", str(games)) if games is not None else ()
    code, _, err = run(capsys, "train", env, "--config", str(path), "--steps", "1000", *typed, "--eval-games", "0",
                       "--quiet", *args)
    return code, err


def _refused_before_a_run(code: int, err: str, home: Path, *needles: str) -> None:
    assert code == EXIT_USAGE, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    assert not home.exists(), "the league was opened (or a run created) before the settings were checked"


# --- 1. network sizes: the snapshot limits, before a run exists ----------------------------------------------------

@pytest.mark.parametrize(("config", "needles"), [
    ("[ppo.arch]\nhidden = [70000]\n", ("[ppo] network", "exceed 65,536")),  # wider than a snapshot may be
    ("[ppo.arch]\nhidden = [" + ", ".join(["8"] * 70) + "]\n", ("[ppo] network", "70 hidden layers", "(64)")),
])
def test_a_network_larger_than_a_snapshot_may_be_is_refused_before_the_run_exists(home, capsys, config, needles):
    code, err = _train(capsys, home, config)
    _refused_before_a_run(code, err, home, *needles)


def test_sac_critics_are_held_to_the_same_limits(home, capsys):
    code, err = _train(capsys, home, "[sac]\ncritic_hidden = [70000]\n", "--algo", "sac",
                       env="tests.games.rendezvous:parallel_env")
    _refused_before_a_run(code, err, home, "[sac] network", "exceed 65,536")


def test_a_teachers_states_are_counted_against_memory(home, capsys):
    code, err = _train(capsys, home, '[teacher]\nplayer = "cpu"\nstates = 9000000000000000000\n')
    _refused_before_a_run(code, err, home, "teacher's labelled states", "GB")


def test_more_games_at_once_than_memory_holds_are_refused_before_the_layout_is_built(home, capsys, monkeypatch):
    from selfplay_cli.train import bounds

    monkeypatch.setattr(bounds, "_machine_memory", lambda: 2**30)  # 1 GB: pong's 2 seats of 48 numbers a game
    code, err = _train(capsys, home, "games = 2_000_000\n", "--algo", "dqn", games=None)  # ~3.2 GB of observations
    _refused_before_a_run(code, err, home, "2,000,000 games at once would take 3.", "GB", "use fewer --games")


# --- 2. numbers and files that were internal errors ---------------------------------------------------------------

@pytest.mark.parametrize(("config", "needle"), [
    ("[ppo]\nlr = 1e300\n", "[ppo] lr must be more than 0 and at most 1, not 1e+300"),
    ("minutes = 1e-300\n", "--minutes must be at least 0.001"),
    ("[dqn]\nlr = 1e300\n", "[dqn] lr must be"),
    ("[ppo]\nreward_scale = 1e308\n", "[ppo] reward_scale must be"),
    ("[sac]\nalpha = 1e300\n", "[sac] alpha must be"),
    ("[dqn]\nbatch_size = 1_000_000_000_000\n", "[dqn] batch_size must be at most buffer_size (100,000)"),
])
def test_number_settings_outside_their_range_are_one_line(home, capsys, config, needle):
    code, err = _train(capsys, home, config)
    _refused_before_a_run(code, err, home, needle)


def test_the_range_table_names_settings_that_exist():
    from selfplay_cli.train.bounds import RANGES
    from selfplay_cli.train.config import TrainConfig

    cfg = TrainConfig(env="pong", run="x", steps=1000, games=2)
    for path in RANGES:  # a typo in the table would check nothing
        value = cfg
        for part in path.split("."):
            value = getattr(value, part)


def test_a_config_nested_5000_deep_or_of_random_bytes_is_one_line(home, capsys):
    deep = "a = " + "{b = " * 5000 + "1" + "}" * 5000 + "\n"
    code, err = _train(capsys, home, deep)
    _refused_before_a_run(code, err, home, "settings.toml", "nested too deeply")
    junk = bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8))
    code, err = _train(capsys, home, b"\xb2" + junk)
    _refused_before_a_run(code, err, home, "settings.toml", "not UTF-8")


def test_a_10_mb_name_is_named_not_echoed(home, capsys):
    code, err = _train(capsys, home, "x" * 10_000_000 + " = 1\n")
    _refused_before_a_run(code, err, home, "unknown training setting(s) xxx")
    assert len(err) < MAX_LINE + 100, len(err)  # the whole line at most MAX_LINE, the name at most MAX_WORD
    assert "x" * MAX_WORD not in err and "x" * (MAX_WORD - 3) + "..." in err


def test_a_snapshot_whose_step_the_league_cannot_store_is_refused(home, tmp_path, capsys):
    arch = Arch(hidden=(8,))
    path = tmp_path / "big.safetensors"
    save_snapshot(path, build_network((8, 6), 3, arch, seed=0),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="r", name="s", algo="ppo",
                               step=2**70))
    code, _, err = run(capsys, "checkpoint", "import", str(path))
    assert code == EXIT_USAGE and err.count("\n") == 1, err
    assert "field 'step' must lie between 0 and 9,223,372,036,854,775,807" in err


# --- 3. every game ends --------------------------------------------------------------------------------------------

def _play_in_time(env: str, seconds: float = 60) -> list:
    """``play`` one game of random against random, in a thread: [results], or [] if it did not end in time."""
    out: list = []
    policy = ScriptedPolicy(env, "random", seed=1)
    worker = threading.Thread(target=lambda: out.extend(play(env, [policy], [Game(seed=3, seats=(0, 0))])),
                              daemon=True)
    worker.start()
    worker.join(seconds)
    return out


def test_a_game_that_never_ends_stops_at_its_declared_length_in_a_match():
    results = _play_in_time(ENDLESS)
    assert len(results) == 1, "the game declared marl_max_steps = 30 and was still playing after a minute"
    assert results[0].length == 30 and results[0].truncated


def test_a_game_that_never_ends_stops_at_its_declared_length_in_training():
    spec = get_env(ENDLESS)
    games = SelfPlayGames(spec, 3, np.array([[0, 0, 0], [1, 1, 1]]), ["a", "b"])
    finished = []
    for _ in range(31):
        _, dones, ended = games.step([np.ones(3, dtype=np.int64), np.zeros(3, dtype=np.int64)])
        finished += ended
    assert [r.length for r in finished] == [30, 30, 30] and all(r.truncated for r in finished)
    assert all(r.scores == (30.0, -30.0) for r in finished)  # a's 1 against b's 0, every step
    assert games.truncated is None  # step 31 ended nothing: the new games had started at step 30


def test_a_game_that_declares_no_length_stops_at_the_stated_cap_with_one_warning(monkeypatch, capsys):
    monkeypatch.setattr(limits, "UNDECLARED_MAX_STEPS", 50)
    monkeypatch.setattr(limits, "_warned", set())
    results = _play_in_time(UNDECLARED) + _play_in_time(UNDECLARED)
    assert [r.length for r in results] == [50, 50] and all(r.truncated for r in results)
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "declares no maximum game length" in err and "50 steps" in err, err


# --- 4. an agent from nowhere --------------------------------------------------------------------------------------

def test_an_agent_that_is_not_one_of_possible_agents_is_refused_in_one_line(home, capsys):
    code, _, err = run(capsys, "train", f"{SHIFTING}:stranger", "--steps", "200", "--games", "2", "--eval-games",
                       "0", "--quiet")
    assert code == EXIT_USAGE, err
    assert err.count("\n") == 1 and "agent 'c' is in the game of seed" in err, err
    assert "at its step 3 but is not one of its possible_agents (a, b)" in err, err


# --- 5. a full disk under marl record ------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["mp4", "gif"])
def test_a_file_size_limit_under_marl_record_is_an_io_error(home, tmp_path, capsys, fmt):
    League.open(home=home).close()  # the league exists before the limit
    out = tmp_path / "videos" / f"game.{fmt}"

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (256 * 1024, 256 * 1024))

    env = {**os.environ, "PYTHONPATH": str(ROOT), "MARL_HOME": str(home)}
    p = subprocess.run([sys.executable, "-m", "selfplay_cli", "record", "--ckpt", "cpu", "--vs", "random", "--env",
                        "pong", "--out", str(out)], capture_output=True, text=True, env=env, preexec_fn=limit,
                       timeout=300)
    assert p.returncode == EXIT_IO, p.stderr
    assert p.stderr.count("\n") == 1 and str(out) in p.stderr and "File too large" in p.stderr, p.stderr
    assert list(out.parent.iterdir()) == []  # no video, no partial file


# --- memory is counted for the run's own settings (issue 48) -------------------------------------------------------

SPOT = "tests.games.spot:parallel_env"  # two seats of 16x16x3 uint8 images: 768 bytes an observation


def test_the_memory_check_counts_the_games_and_rollout_the_run_will_use(monkeypatch, tmp_path):
    """Issue 48: an image game was refused at any --games, its check made on the defaults (256 games) before the
    options typed and the config file's were applied."""
    from selfplay_cli.errors import MarlError
    from selfplay_cli.train import bounds
    from selfplay_cli.train.settings import new_settings

    monkeypatch.setattr(bounds, "_machine_memory", lambda: 3 * 2**20)  # 3 MB: 0.8 of it may be taken
    with pytest.raises(MarlError, match="256 games at once would take"):  # the defaults: 256 x 2 x ~12 kB > 2.4 MB
        new_settings(SPOT, {})
    assert new_settings(SPOT, {"games": 4})["games"] == 4  # 8 seats x 128 steps x 768 B = 0.8 MB
    rollout = tmp_path / "rollout.toml"
    rollout.write_text("games = 8\n[ppo]\nrollout_steps = 16\n")
    assert new_settings(SPOT, {}, config=rollout)["games"] == 8  # the file's games and rollout
    # where the real settings are too big, the refusal names them: 64 games, 32-step rollouts, 3 MB > 2.4 MB
    rollout.write_text("[ppo]\nrollout_steps = 32\n")
    with pytest.raises(MarlError, match=r"PPO's rollouts \(32 steps of 128 seats\) of 16x16x3 observations"):
        new_settings(SPOT, {"games": 64}, config=rollout)


def test_an_image_game_trains_with_few_games_where_its_defaults_would_not_fit(home, capsys, monkeypatch):
    from selfplay_cli.train import bounds

    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setattr(bounds, "_machine_memory", lambda: 3 * 2**20)
    code, _, err = run(capsys, "train", SPOT, "--games", "4", "--steps", "64", "--eval-games", "0", "--quiet")
    assert code == 0, err
    code, _, err = run(capsys, "train", SPOT, "--steps", "64", "--eval-games", "0", "--quiet", "--run", "big")
    assert code == EXIT_USAGE and err.count("\n") == 1 and "256 games at once" in err, err  # the defaults: too many
