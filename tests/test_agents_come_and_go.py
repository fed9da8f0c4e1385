"""Agents that come and go, a game's global state, and seats that differ (issue 34).

The suite's race (``tests/games/race.py``): runners leave the race as they finish, rewarded only then, and a
latecomer joins it at step 2; ``shifting`` has an agent that vanishes from ``agents`` without being done. A seat
whose agent left acts no more and keeps its score; its learner's last transition of that game is the one it left
on, marked done for that seat while the game goes on, with the finishing reward in it. A learner that declares
``wants_state`` is handed the game's global state row for row; none is read when no learner wants it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run, run_json

from selfplay_cli.algos.dqn import DQNConfig, DQNLearner
from selfplay_cli.algos.ppo import PPOConfig, PPOLearner
from selfplay_cli.envs import get_env
from selfplay_cli.errors import MarlError
from selfplay_cli.play.training_games import SelfPlayGames
from selfplay_cli.train.curriculum import Curriculum
from selfplay_cli.train.rollouts import Rollouts
from selfplay_cli.train.team import LearnerTeam

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

RACE, RACE_AEC = "tests.games.race:parallel_env", "tests.games.race:env"
LATE = 2  # the latecomer's seat
FORWARD = 2


@pytest.mark.parametrize("name", [RACE, RACE_AEC])
def test_runners_leave_as_they_finish_keep_their_score_and_the_latecomer_joins(name):
    spec = get_env(name)
    n = 4
    core = spec.core(n)
    core.reset(np.arange(n), np.arange(10, 10 + n))
    forward = [np.full(n, FORWARD)] * 3
    joined = np.zeros(n, dtype=bool)
    out = np.zeros((3, n), dtype=bool)  # seats that left their game
    final = np.zeros((3, n))  # each seat's reward on the step it left
    running = np.ones(n, dtype=bool)
    while running.any():
        obs, acting, in_game = core.observe(), core.to_act(), core.in_game
        g_out = ~in_game[LATE] & ~joined & running
        assert (obs[LATE][g_out] == 0).all() and not acting[LATE][g_out].any()  # zeros, no turn, before it joins
        joined |= in_game[LATE]
        assert not (acting & out).any(), "a seat that left its game acts again"
        score = core.score.copy()
        rewards = core.step(forward)
        final[core.seat_done] = rewards[core.seat_done]
        out |= core.seat_done
        assert np.array_equal(core.score[out & ~core.seat_done], score[out & ~core.seat_done]), "a score moved"
        running &= ~(core.terminated | core.truncated)
    assert joined.all() and out.all()  # every game: the latecomer joined, every seat's part ended
    finished = final > 1
    assert finished[:2].all(), "running forward, both runners finish (the latecomer may run out of time)"
    assert np.array_equal(core.score, final)  # a runner's only reward is its finish, and its score keeps it
    assert ((final[finished] > 1) & (final[finished] <= 2)).all()


def test_an_agent_that_vanishes_without_being_done_leaves_and_keeps_its_score():
    core = get_env("tests.games.shifting:parallel_env").core(2)  # b vanishes at step 3
    ones = [np.ones(2, dtype=np.int64)] * 2
    for t in range(1, 8):
        core.step(ones)
        assert core.seat_done[1].all() == (t == 3) and not core.seat_done[0].any(), t
    assert core.to_act().tolist() == [[True, True], [False, False]]
    assert core.score.tolist() == [[7, 7], [2, 2]]  # b's two points before it left stay its own
    assert not (core.terminated | core.truncated).any()  # a plays on


def _race_games(n: int = 2) -> SelfPlayGames:
    spec = get_env(RACE)
    return SelfPlayGames(spec, n, np.zeros((spec.n_seats, n), dtype=np.int64), ["runner"])


def _play_forward(games: SelfPlayGames, learner, steps: int) -> list[tuple]:
    """``steps`` steps where the learner records every slot (it acts; the runners all run forward); per step the
    slots that acted, the rewards, the dones and whether each slot's game ended."""
    history = []
    for _ in range(steps):
        obs, acting = games.observe(), games.acting()[0]
        learner.act(obs[0])
        started = games.games_started
        rewards, dones, finished = games.step([np.full(games.slots[0].size, FORWARD)])
        ended = np.zeros(games.slots[0].size, dtype=bool)
        for r in finished:
            ended[games.slots[0] % games.n == r.index] = True
        assert games.games_started == started + len(finished)
        cut = games.truncated[0] if games.truncated is not None else None
        learner.record(rewards[0], dones[0], truncated=cut, acting=acting,
                       final_obs=games.final_obs[0] if cut is not None else None)
        history.append((np.ones_like(dones[0]) if acting is None else acting, rewards[0], dones[0], ended))
    return history


def test_a_runner_that_finishes_is_done_for_its_seat_and_its_learner_gets_the_finish_reward():
    games = _race_games()
    steps = 16
    learner = PPOLearner(games.spaces[0], games.slots[0].size, PPOConfig(rollout_steps=steps), seed=0)
    history = _play_forward(games, learner, steps)
    acting, rewards, dones, ended = (np.stack(x) for x in zip(*history, strict=True))
    finishes = np.argwhere(dones & ~ended & (rewards > 1))  # (step, slot): a runner finished, its race goes on
    assert len(finishes) >= 4, finishes
    for t, slot in finishes:
        assert learner.dones[t, slot] == 1 and learner.rewards[t, slot] == rewards[t, slot] > 1  # the buffer has it
        rest = t + 1 + np.argmax(ended[t + 1:, slot]) if ended[t + 1:, slot].any() else steps
        assert not acting[t + 1:rest + 1, slot].any()  # no decisions for the seat until its game restarts
    # GAE over the seat's decisions: the finish is terminal, its return exactly its reward (nothing bootstrapped)
    values = learner.values.cpu().numpy()
    zero = np.zeros((1, learner.n_slots))
    adv, learn, _, _ = learner._turn_advantages(
        np.concatenate((zero, learner.rewards.cpu().numpy())), np.concatenate((zero, learner.dones.cpu().numpy())) > 0,
        np.zeros((steps + 1, learner.n_slots), np.float32), np.concatenate((zero > 0, learner.acting.cpu().numpy())),
        np.concatenate((zero, values)).astype(np.float32))
    for t, slot in finishes:
        assert learn[t + 1, slot] and adv[t + 1, slot] + values[t, slot] == pytest.approx(rewards[t, slot])
    assert not (learn[1:] & ~acting).any()  # a seat out of its game has no transitions

    dqn = DQNLearner(games.spaces[0], games.slots[0].size, DQNConfig(n_step=1, learning_starts=10**6), seed=0)
    history = _play_forward(_race_games(), dqn, steps)
    rewards, dones, ended = (np.stack([h[k] for h in history]) for k in (1, 2, 3))
    buf = dqn.buffer
    stored = np.sort(buf.rewards[:len(buf)][buf.rewards[:len(buf)] > 1])
    assert np.array_equal(stored, np.sort(rewards[dones & (rewards > 1)]))  # every finish, once
    assert (buf.dones[:len(buf)][buf.rewards[:len(buf)] > 1] == 1).all()  # each the end of its seat's game


class _StateReader(PPOLearner):
    """A PPO learner that declares it reads the game's global state, and keeps what it was handed."""

    wants_state = True

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.seen: list[np.ndarray] = []

    def see_state(self, rows: np.ndarray) -> None:
        self.seen.append(np.array(rows))


@pytest.mark.parametrize("wants", [True, False])
def test_a_learner_that_wants_the_global_state_gets_its_games_rows_and_none_is_read_otherwise(wants, monkeypatch):
    games = _race_games(3)
    calls: list[np.ndarray] = []
    state = games.core.state

    def counted() -> np.ndarray:
        calls.append(state())
        return calls[-1]

    monkeypatch.setattr(games.core, "state", counted)
    kind = _StateReader if wants else PPOLearner
    learner = kind(games.spaces[0], games.slots[0].size, PPOConfig(rollout_steps=4), seed=0)
    rollouts = Rollouts(games, [learner], Curriculum({}, "race", ()), None, None)
    team = LearnerTeam([learner], threads=False)
    obs = rollouts.observe()
    for _ in range(6):
        step = rollouts.step(team, obs, 0.5)
        rollouts.learn(team, step, 0.5)
        obs = step.obs
    if not wants:
        assert calls == [] and step.state is None
        return
    assert len(calls) == 7  # the first state, then one after each step (handed again to the update)
    games_of = games.slots[0] % games.n
    seen_calls = [0, 1, 2, 3, 4, 4, 5]  # before each step; after step 4, the update (rollout_steps 4) sees it too
    assert len(learner.seen) == len(seen_calls)
    for rows, k in zip(learner.seen, seen_calls, strict=True):
        assert np.array_equal(rows, calls[k][games_of])  # each slot: its own game's state
    assert calls[0][:, -1].tolist() == [0.0] * 3 and calls[1][:, -1].tolist() == pytest.approx([1 / 12] * 3)


def test_a_learner_that_wants_the_state_of_a_game_that_gives_none_is_one_line():
    spec = get_env("pong")
    assert spec.state_space() is None and get_env(RACE).state_space().shape == (4,)
    games = SelfPlayGames(spec, 1, np.zeros((2, 1), dtype=np.int64), ["p"])
    learner = _StateReader(games.spaces[0], 2, PPOConfig(rollout_steps=4), seed=0)
    with pytest.raises(MarlError, match="cannot train on pong: the game gives none"):
        Rollouts(games, [learner], Curriculum({}, "race", ()), None, None)


def test_fups_on_seats_that_differ_names_the_seats_and_their_spaces(home, capsys):
    code, out, err = run(capsys, "train", "tests.games.chase:parallel_env", "--agents", "2", "--sharing", "fups",
                         "--steps", "100")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert ("seats hunter and runner have different spaces (hunter: observation (3,), actions Discrete(3); "
            "runner: observation (5,), actions Discrete(5))") in err, err


@pytest.mark.slow
def test_the_race_trains_beats_random_rates_and_records(home, capsys, tmp_path):
    report = run_json(capsys, "train", RACE, "--steps", "6000", "--games", "16", "--eval-games", "20",
                      "--eval-inline", "--run", "r", "--seed", "1")
    final = report["final"][0]
    assert final["vs"]["random"]["score"] > 0.6, final  # it learned to run: its only reward is the finish
    m = run_json(capsys, "match", final["snapshot"], "random", "--games", "12")
    assert m["results"] == 12 and m["points_for"] > m["points_against"], m
    out = tmp_path / "race.gif"
    (rec,) = run_json(capsys, "record", "--ckpt", final["snapshot"], "--vs", "random", "--seconds", "0", "--out",
                      str(out))
    assert rec["players"][0] == final["snapshot"] and out.stat().st_size > 0 and rec["frames"] >= 2
    (replay,) = run_json(capsys, "record", "--game", "1", "--out", str(tmp_path / "game1.gif"))  # a training game
    assert replay["frames"] >= 2 and replay["length"] <= 12
    code, text, err = run(capsys, "league", "ladder", "--bootstrap", "0")
    assert code == 0 and final["snapshot"] in text and "random (anchor)" in text, err


def test_one_agent_for_the_whole_team_ends_its_game_when_everyone_in_it_is_done():
    from selfplay_cli.algos.joint import JointLearner

    seat = get_env(RACE).seat_spaces()[0]
    joint = JointLearner(PPOLearner, seat, 3, 2, PPOConfig(rollout_steps=4), seed=0)  # 3 seats of 2 games
    obs = np.zeros((6, *seat.observation.shape), dtype=np.float32)  # slots seat by seat: seat * 2 + game
    for dones, acting in [
        ([0, 0, 1, 0, 0, 0], None),  # seat 1 of game 0 leaves; game 0 goes on
        ([0, 0, 0, 0, 0, 0], [1, 1, 0, 1, 1, 1]),
        ([1, 0, 0, 0, 1, 0], [1, 1, 0, 1, 1, 1]),  # the others of game 0 are done: it ended
        ([1, 1, 1, 1, 1, 1], None),  # both games end
    ]:
        joint.act(obs)
        joint.record(np.zeros(6, np.float32), np.array(dones, np.float32),
                     acting=None if acting is None else np.array(acting, bool))
    assert joint.inner.dones.cpu().numpy().tolist() == [[0, 0], [0, 0], [1, 0], [1, 1]]
