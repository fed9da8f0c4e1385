"""A user's own PettingZoo games through every command, as README's "Your own game" does it: the suite's turn-based
board game (tic-tac-toe: AEC, action masks) and its simultaneous cooperative game (rendezvous: three seats, Box
actions) are trained with tiny budgets, land in the league as snapshots, play rated matches, show on the ladder and
are filmed; and every mapping of learners to seats that cannot work is one clear line."""

from __future__ import annotations

import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from cli_helpers import run, run_json
from gymnasium import spaces
from pettingzoo import ParallelEnv

from selfplay_cli.envs import get_env
from selfplay_cli.errors import MarlError
from selfplay_cli.play.seat_plan import OPPONENT, parse_seats, plan_layout, plan_seats

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.* (and this module's own, below)
    sys.path.insert(0, str(ROOT))

TICTACTOE = "tests.games.tictactoe:env"
RENDEZVOUS = "tests.games.rendezvous:parallel_env"





def _frames(path: Path) -> np.ndarray:
    return np.stack(list(iio.imiter(path)))


@pytest.mark.slow
def test_a_board_game_with_masks_trains_rates_plays_and_records(home, tmp_path, capsys):
    report = run_json(capsys, "train", TICTACTOE, "--steps", "6000", "--snapshot-steps", "3000", "--games", "16",
                      "--eval-games", "2", "--run", "ttt", "--seed", "3")
    finals = [f["snapshot"] for f in report["final"]]
    assert finals == ["ttt/s6k-x", "ttt/s6k-o"], finals  # one learner per side, named by its seat
    listed = [r["policy"] for r in run_json(capsys, "checkpoint", "list")]
    assert {"ttt/s0-x", "ttt/s0-o", "ttt/s6k-x", "ttt/s6k-o"} <= set(listed)
    shown = run_json(capsys, "checkpoint", "show", "ttt/s6k-x")
    assert shown["file"]["act_space"] == {"kind": "discrete", "n": 9}  # the spaces, not n_actions

    # every game legal to its end (the game refuses a forbidden move), won, drawn or lost (+1, 0 or -1)
    match = run_json(capsys, "match", "ttt/s6k-x", "random", "--games", "40", "--seed", "5")
    assert match["kind"] == "two-sides" and match["games"] == 40 and len(match["game_ids"]) == 40
    assert match["wins"] + match["draws"] + match["losses"] == 40 and match["points_for"] == -match["points_against"]
    by_name = {r["policy"]: r for r in run_json(capsys, "league", "ladder")}
    assert by_name["ttt/s6k-x"]["games"] >= 40 and by_name["ttt/s6k-x"]["vs"]["random"]["games"] >= 40

    out = tmp_path / "ttt.mp4"
    code, _, err = run(capsys, "record", "--ckpt", "ttt/s6k-x", "--out", str(out))
    assert code == 0, err
    frames = _frames(out)
    assert frames.shape[0] >= 5 and frames.shape[-1] == 3  # the game's own rgb_array frames, one or more per move


@pytest.mark.slow
def test_a_cooperative_game_with_box_actions_trains_rates_plays_and_records(home, tmp_path, capsys):
    report = run_json(capsys, "train", RENDEZVOUS, "--agents", "3", "--steps", "3000", "--snapshot-steps", "1500",
                      "--games", "8", "--eval-games", "2", "--run", "rv")
    assert [f["snapshot"] for f in report["final"]] == ["rv/s3k-a0", "rv/s3k-a1", "rv/s3k-a2"]
    shown = run_json(capsys, "checkpoint", "show", "rv/s3k-a1")
    assert shown["file"]["act_space"]["kind"] == "box" and shown["file"]["act_space"]["shape"] == [2]

    run_json(capsys, "match", "rv/s3k-a0", "random", "--games", "8")
    by_name = {r["policy"]: r for r in run_json(capsys, "league", "ladder")}
    # cooperative: the ladder shows each player's mean team return (rendezvous' returns are negative spreads)
    assert by_name["rv/s3k-a0"]["mean_return"] is not None and by_name["rv/s3k-a0"]["mean_return"] < 0
    assert by_name["random"]["mean_return"] < 0

    out = tmp_path / "rv.mp4"
    code, _, err = run(capsys, "record", "--ckpt", "rv/s3k-a0", "--out", str(out))
    assert code == 0, err
    assert _frames(out).shape[0] >= 50  # a 50-step game


def test_one_shared_network_flies_every_seat_with_fups(home, capsys):
    report = run_json(capsys, "train", RENDEZVOUS, "--agents", "3", "--sharing", "fups", "--steps", "1000",
                      "--snapshot-steps", "1000", "--games", "4", "--eval-games", "0", "--run", "shared")
    assert [f["snapshot"] for f in report["final"]] == ["shared/s1k"]


@pytest.mark.slow
def test_dqn_masks_a_board_game_and_refuses_box_actions_in_one_line(home, capsys):
    report = run_json(capsys, "train", TICTACTOE, "--algo", "dqn", "--steps", "3000", "--snapshot-steps", "3000",
                      "--games", "8", "--eval-games", "2", "--run", "dq")
    assert [f["snapshot"] for f in report["final"]] == ["dq/s3k-x", "dq/s3k-o"]
    code, out, err = run(capsys, "train", RENDEZVOUS, "--agents", "3", "--algo", "dqn", "--run", "dq2")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "DQN" in err and "Box" in err and "--algo ppo" in err
    assert not (home / "runs" / "dq2").exists()


# ----------------------------------------------------------------------------------------------- seat mapping


class Uneven(ParallelEnv):
    """Two seats that observe different things: one network cannot play both."""

    metadata = {"name": "uneven_v0", "kind": "two-sides"}

    def __init__(self, **options) -> None:
        self.possible_agents = ["big", "small"]
        self.agents = list(self.possible_agents)
        self._obs = {"big": spaces.Box(-1, 1, (4,), np.float32), "small": spaces.Box(-1, 1, (2,), np.float32)}

    def observation_space(self, agent):
        return self._obs[agent]

    def action_space(self, agent):
        return spaces.Discrete(2)

    def reset(self, seed=None, options=None):
        self.agents = list(self.possible_agents)
        self.t = 0
        return {a: np.zeros(self._obs[a].shape, np.float32) for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions):
        self.t += 1
        done = self.t >= 3
        obs = {a: np.zeros(self._obs[a].shape, np.float32) for a in self.agents}
        rew = {"big": float(actions["big"]), "small": float(actions["small"])}
        flags = {a: done for a in self.agents}
        if done:
            self.agents = []
        return obs, rew, flags, {a: False for a in flags}, {a: {} for a in flags}


def uneven(**options):
    return Uneven(**options)


@pytest.mark.parametrize("args, says", [
    (["pong", "--seats", "1,2,1"], "for each of the game's 2 seats, not '1,2,1'"),
    (["pong", "--seats", "1,3"], "learners must be numbered 1 to 2 without gaps"),
    (["pong", "--seats", "a,1"], "'a' is neither a learner number"),
    (["pong", "--seats", "-,-"], "gives no seat to a learner"),
    (["pong", "--agents", "3"], "pong has 2 seats: --agents must be between 1 and 2"),
    (["tests.test_your_own_game:uneven", "--sharing", "fups"], "seats big and small have different spaces"),
    (["tests.test_your_own_game:uneven", "--seats", "1,1"], "seats big and small have different spaces"),
])
def test_seats_that_cannot_be_mapped_are_one_line_and_nothing_is_written(home, capsys, args, says):
    code, out, err = run(capsys, "train", *args, "--run", "bad")
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    assert says in err, err
    assert not home.exists() or not (home / "runs" / "bad").exists()


def test_default_seat_mappings_by_kind():
    pong, coop = get_env("pong"), get_env(RENDEZVOUS)
    assert plan_seats(pong, 2).home == (0, 1)  # one learner a side
    one = plan_seats(pong, 1)
    assert plan_layout(one, 4, 1).tolist() == [[0, OPPONENT, 0, OPPONENT], [OPPONENT, 0, OPPONENT, 0]]
    assert plan_seats(coop, 3).home == (0, 1, 2) and plan_seats(coop, 1).home == (0, 0, 0)
    assert plan_seats(coop, 2).home == (0, 1, 0)  # seat s to learner s mod N
    assert plan_seats(coop, 3, "fups").home == (0, 0, 0)
    assert parse_seats("1,-", 2) == (0, OPPONENT)
    with pytest.raises(MarlError):
        parse_seats("0,1", 2)  # learners are numbered from 1


def test_new_match_seeds_give_new_games_of_a_deterministic_board_game(home, capsys):
    """Tic-tac-toe ignores its seed: only the players' sampling makes games differ, so it is seeded by the match's
    seed (and the player): the same seed replays the same games, another seed plays others."""
    from selfplay_cli.league.store import League

    run_json(capsys, "train", TICTACTOE, "--steps", "3000", "--snapshot-steps", "3000", "--games", "8",
             "--eval-games", "0", "--run", "d", "--sharing", "fups")

    def games(seed: str) -> list[bytes]:
        ids = run_json(capsys, "match", "d/s3k", "random", "--games", "20", "--seed", seed)["game_ids"]
        league = League.open(home=home)
        try:
            return [league.ledger.game(i).actions for i in ids]
        finally:
            league.close()

    first, again, other = games("7"), games("7"), games("8")
    assert first == again
    assert sum(a != b for a, b in zip(first, other, strict=True)) >= 10


class Race(ParallelEnv):
    """Three runners for themselves (free-for-all by default: more than two agents): each step a runner that
    sprints (action 1) gains a point; five steps."""

    metadata = {"name": "race_v0"}

    def __init__(self, **options) -> None:
        self.possible_agents = ["r0", "r1", "r2"]
        self.agents = list(self.possible_agents)

    def observation_space(self, agent):
        return spaces.Box(0, 1, (1,), np.float32)

    def action_space(self, agent):
        return spaces.Discrete(2)

    def reset(self, seed=None, options=None):
        self.agents, self.t = list(self.possible_agents), 0
        return {a: np.zeros(1, np.float32) for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions):
        self.t += 1
        obs = {a: np.full(1, self.t / 5, np.float32) for a in self.agents}
        rew = {a: float(actions[a]) for a in self.agents}
        done = {a: self.t >= 5 for a in self.agents}
        if self.t >= 5:
            self.agents = []
        return obs, rew, done, {a: False for a in done}, {a: {} for a in done}


def race(**options):
    return Race(**options)


@pytest.mark.slow
def test_every_opponent_seat_draws_its_own_opponent(home, capsys):
    """One learner in a three-seat free-for-all: it takes a seat in turn, and each of the two other seats of a game
    is drawn on its own by the matchmaker (here: random half the time, else the league's snapshots or the learner
    itself), so games with two different opponents exist; free-for-all results are pairwise."""
    from selfplay_cli.league.store import League

    report = run_json(capsys, "train", "tests.test_your_own_game:race", "--agents", "1", "--bots", "random=0.5",
                      "--steps", "2000", "--snapshot-steps", "1000", "--games", "16", "--eval-games", "2",
                      "--run", "ffa")
    assert [f["snapshot"] for f in report["final"]] == ["ffa/s2k"]
    league = League.open(home=home)
    try:
        seen = 0
        for gid in range(1, league.ledger.count_games() + 1):
            g = league.ledger.game(gid)
            if g.match_kind == "training":  # the learner and two opponents: random, or a snapshot, or itself
                seen += [league.roster.get_player(p).name for p in g.players].count("random") == 1
        # with one opponent a game, both opponent seats would be random or neither
        assert seen > 0, "two opponent seats of one game drawn apart"
        assert league.ledger.games(env="tests.test_your_own_game:race").games_played() > 0  # pairwise rated results
    finally:
        league.close()
