"""Curricula driven by training progress (seed 002): schedules, their checks, and a run that follows one."""

from __future__ import annotations

import json

import pytest
from cli_helpers import run_json

from selfplay_cli.errors import MarlError
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.curriculum import Curriculum, parse_schedule


def test_ramp_holds_then_moves_linearly_then_holds():
    s = parse_schedule("bat_scale", {"start": 2.0, "end": 1.0, "from": 0.2, "until": 0.6})
    assert s.value(0.0) == 2.0
    assert s.value(0.2) == 2.0
    assert s.value(0.4) == pytest.approx(1.5)  # halfway through the ramp
    assert s.value(0.5) == pytest.approx(1.25)
    assert s.value(0.6) == 1.0
    assert s.value(1.0) == 1.0
    assert s.value(7.0) == 1.0  # progress is clipped to [0, 1]


def test_lessons_step_at_their_thresholds():
    s = parse_schedule("hit_reward", {"lessons": [[0.0, 0.5], [0.3, 0.25], [0.6, 0.0]]})
    assert [s.value(p) for p in (0.0, 0.29, 0.3, 0.59, 0.6, 1.0)] == [0.5, 0.5, 0.25, 0.25, 0.0, 0.0]


def test_a_plain_number_holds_for_the_whole_run():
    s = parse_schedule("bat_scale", 1)
    assert [s.value(p) for p in (0.0, 0.5, 1.0)] == [1.0, 1.0, 1.0]


@pytest.mark.parametrize("entry, words", [
    ({"start": 1.0}, "start, end"),
    ({"start": 1.0, "end": 0.0, "until": 1.5}, "until <= 1"),
    ({"start": 1.0, "end": 0.0, "from": 0.5, "until": 0.5}, "from < until"),
    ({"start": "big", "end": 0.0}, "finite number"),
    ({"start": 1.0, "end": float("nan")}, "finite number"),
    ({"lessons": [[0.2, 1.0]]}, "start at progress 0"),
    ({"lessons": [[0.0, 1.0], [0.5, 2.0], [0.4, 3.0]]}, "rise strictly"),
    ({"lessons": [[0.0, 1.0]], "start": 1.0}, "cannot be mixed"),
    ("3.0", "must be a table"),
    (True, "must be a table"),
    (float("inf"), "finite number"),
])
def test_bad_schedules_are_one_clear_error(entry, words):
    with pytest.raises(MarlError) as e:
        parse_schedule("bat_scale", entry)
    assert words in str(e.value) and "bat_scale" in str(e.value)


def test_only_live_options_may_follow_a_curriculum():
    with pytest.raises(MarlError, match="pong cannot change points_to_win during training"):
        Curriculum({"points_to_win": {"start": 5, "end": 21}}, "pong", ())
    c = Curriculum({"bat_scale": {"start": 2, "end": 1}}, "tennis", ("bat_scale", "hit_reward"))
    assert c.values(0.5) == {"bat_scale": 1.5}


def test_a_run_refuses_a_curriculum_its_game_cannot_follow():
    with pytest.raises(MarlError, match="cannot change"):
        TrainConfig(env="pong", curriculum={"paddle_speed": {"start": 1.0, "end": 2.0}})


def test_a_value_the_game_refuses_fails_before_the_run(tmp_path):
    pytest.importorskip("selfplay_cli.envs.tennis")
    with pytest.raises(MarlError, match=r"\[curriculum\]"):
        TrainConfig(env="tennis", curriculum={"bat_scale": {"start": 2.0, "end": 0.0}})  # a bat of size 0


@pytest.mark.slow
def test_training_follows_the_curriculum(tmp_path, home, capsys, monkeypatch):
    """A short tennis run: the metrics show each option as the schedule has it at that progress."""
    monkeypatch.setattr("selfplay_cli.train.loop.METRICS_STEPS", 1024)  # a metrics line each 1,024 steps, not 8,192
    config = tmp_path / "c.toml"
    config.write_text("[curriculum]\nbat_scale = { start = 3.0, end = 1.0, until = 0.5 }\n"
                      "hit_reward = { lessons = [[0.0, 0.5], [0.5, 0.0]] }\n[ppo]\nrollout_steps = 32\n")
    run_json(capsys, "train", "tennis", "--algo", "ppo", "--steps", "8192", "--games", "16", "--snapshot-steps", "0",
             "--snapshot-every", "1000000", "--eval-games", "0", "--config", str(config), "--run", "cur", "--seed", "3")
    lines = [json.loads(x) for x in (home / "runs" / "cur" / "metrics.jsonl").read_text().splitlines()]
    assert len(lines) >= 6  # the first update's, then one each 1,024 steps: both lessons, both sides of `until`
    for line in lines:
        # the values were set before the last step of the rollout: progress then was (step - games) / budget
        p = (line["step"] - 16) / 8192
        assert line["curriculum/bat_scale"] == pytest.approx(max(1.0, 3.0 - 4.0 * p), abs=0.01)
        assert line["curriculum/hit_reward"] == (0.5 if p < 0.5 else 0.0)
    assert lines[0]["curriculum/bat_scale"] > 2.5 and lines[-1]["curriculum/bat_scale"] == 1.0
