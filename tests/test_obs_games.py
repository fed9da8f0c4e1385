"""Games whose observations are not a Box, through every command: the suite's cue (Discrete observations) and dash
(a nested Dict with a Tuple inside, MultiBinary, Discrete and Box leaves, and a top-level action mask). Each is
trained with a tiny budget and must learn to read what it is shown (a policy that ignores its observation cannot
beat random by the margin asserted), then matched, rated on the ladder and filmed."""

from __future__ import annotations

import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from cli_helpers import run, run_json

from selfplay_cli.envs import get_env

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

CUE = "tests.games.cue:parallel_env"
DASH = "tests.games.dash:parallel_env"


def test_dash_observation_is_read_in_the_stated_order_and_its_mask_is_the_seats():
    spec = get_env(DASH)
    (red, blue) = spec.seat_spaces()
    assert red.mask and red.observation.shape == (19,) and blue == red
    core = spec.make_core(1, spec.config())
    core.reset([0], [0])
    env = core.envs[0]
    env.cell[:] = (3, 5)
    env.left[:] = (0, 1)
    env.t = 3
    core._store(0, 0, env._observations()["red"])
    # Dict keys in gymnasium's sorted order: clock (Box), me (Dict: cell one-hot of 8, dash), rival (Tuple: cell
    # one-hot of 8, dash); action_mask is not read as observation but is red's mask (no dash left: 2 forbidden).
    want = np.zeros(19, dtype=np.float32)
    want[0] = 0.75
    want[1 + 3] = 1.0
    want[9] = 0.0
    want[10 + 5] = 1.0
    want[18] = 1.0
    np.testing.assert_array_equal(core.observe()[0][0], want)
    assert core.action_masks()[0][0].tolist() == [True, True, False]


@pytest.mark.slow
@pytest.mark.parametrize(("game", "steps", "seat"), [(CUE, 12000, "p0"), (DASH, 16000, "red")], ids=["cue", "dash"])
def test_a_game_with_discrete_or_dict_observations_learns_matches_rates_and_records(home, tmp_path, capsys, game,
                                                                                      steps, seat):
    report = run_json(capsys, "train", game, "--steps", str(steps), "--snapshot-steps", str(steps), "--games", "16",
                      "--eval-games", "0", "--run", "obs", "--seed", "1")
    final = f"obs/s{steps // 1000}k-{seat}"
    assert final in [f["snapshot"] for f in report["final"]]
    match = run_json(capsys, "match", final, "random", "--games", "100", "--seed", "7")
    # random answers its cue one round in four (cue) and wanders (dash): a policy that reads its observation wins
    # nearly every game (measured: 90% and 95%), one that does not, about half
    assert match["score"] > 0.75, match
    ladder = {r["policy"]: r for r in run_json(capsys, "league", "ladder")}
    assert ladder[final]["vs"]["random"]["games"] >= 100
    out = tmp_path / "game.mp4"
    code, _, err = run(capsys, "record", "--ckpt", final, "--out", str(out))
    assert code == 0, err
    frames = np.stack(list(iio.imiter(out)))
    assert frames.shape[0] >= 2 and frames.shape[-1] == 3



def test_marl_envs_shows_the_space_a_game_gives_how_it_is_read_and_its_global_state(capsys):
    cue, dash, race = run_json(capsys, "envs", CUE, DASH, "tests.games.race:parallel_env")
    assert cue["seats"][0]["given"] == "Discrete(4)" and cue["seats"][0]["observation"] == "Box(0, 1, (4,), float32)"
    assert dash["seats"][1]["given"].startswith("Dict(action_mask: MultiBinary(3), clock: Box(0, 1, (1,), float32), "
                                                "me: Dict(cell: Discrete(8), dash: MultiBinary(1)), rival: Tuple(")
    assert dash["state_space"] is None and race["state_space"] == "Box(0, 1, (4,), float32)"
    assert "given" not in race["seats"][0]  # a Box, read as it is
    code, out, _ = run(capsys, "envs", CUE)
    assert code == 0 and "p0, p1 observe Discrete(4), read as Box(0, 1, (4,), float32)" in out
