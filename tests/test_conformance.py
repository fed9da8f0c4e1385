"""Every game against its own declaration: the registered games (pong, unchanged) and the suite's three PettingZoo games
through the adapter.

What a game declares (seats, per-seat spaces, turns, kind, time limit) is what the rest of marl builds on, so each
game is played and held to it: observations, masks, actions and rewards have the declared shapes, dtypes and
bounds; an acting seat always has a legal action; the same seed and the same actions give the same game; scores
are finite floats; random play ends within the declared limit. In a game whose agents come and go (the core says who
is in each game: ``in_game``, ``seat_done``) the seats in a game are the ones that act (simultaneous games), a seat's
part ends once, when it leaves or with its game, and a game that ended has nobody in it. The checks live in
:func:`check_game`, and the last tests feed it games that break one rule each, so a check that cannot fail would
show here.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.test import api_test, parallel_api_test

from selfplay_cli.envs import EnvSpec, env_names, get_env
from selfplay_cli.envs.adapters.pettingzoo import adapt
from selfplay_cli.envs.bots import random_rule
from selfplay_cli.envs.obs_spaces import image_layout

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

TEST_GAMES = ["tests.games.tictactoe:env", "tests.games.rendezvous:parallel_env", "tests.games.chase:parallel_env",
              "tests.games.reach:parallel_env", "tests.games.cue:parallel_env", "tests.games.dash:parallel_env",
              "tests.games.race:parallel_env", "tests.games.race:env", "tests.games.spot:parallel_env",
              "tests.games.duet:parallel_env", "tests.games.relay:parallel_env"]
# OpenSpiel's games are played through marl's own core (they have no PettingZoo view)
OPENSPIEL_GAMES = ["openspiel:kuhn_poker", "openspiel:leduc_poker", "openspiel:tic_tac_toe",
                   "openspiel:goofspiel(imp_info=True,num_cards=5)"]
GAMES = sorted(set(env_names())) + TEST_GAMES


def _random_actions(spec: EnvSpec, core, rngs, rules) -> list[np.ndarray]:
    obs, masks = core.observe(), core.action_masks()
    return [rules[s](obs[s], rngs[s], masks[s]) for s in range(spec.n_seats)]


def _play(spec: EnvSpec, n: int, seeds, steps: int, action_seed: int) -> list[tuple]:
    """A record of ``steps`` steps of ``n`` games under random legal actions (finished games restart with the next
    seeds), for comparing two plays."""
    cfg = spec.config()
    seats = spec.seat_spaces(cfg)
    core = spec.make_core(n, cfg)
    core.reset(np.arange(n), seeds)
    rules = [random_rule(seat.action) for seat in seats]
    rngs = [np.random.default_rng(action_seed + s) for s in range(spec.n_seats)]
    next_seed = int(max(seeds)) + 1
    out = []
    for _ in range(steps):
        obs, masks, acting = core.observe(), core.action_masks(), core.to_act()
        actions = _random_actions(spec, core, rngs, rules)
        rewards = core.step(actions)
        out.append(([np.array(o) for o in obs], [None if m is None else m.copy() for m in masks], acting,
                     rewards, core.score.copy(), core.terminated.copy(), core.truncated.copy()))
        done = np.flatnonzero(core.terminated | core.truncated)
        if done.size:
            core.reset(done, np.arange(next_seed, next_seed + done.size))
            next_seed += done.size
    return out


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if a is None or b is None:
        return a is None and b is None
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=False)


def check_game(spec: EnvSpec, n: int = 6, max_play: int = 20_000) -> None:
    """Play ``spec`` and assert it keeps its declaration (the conformance test's one definition)."""
    cfg = spec.config()
    seats = spec.seat_spaces(cfg)
    S = spec.n_seats
    assert len(seats) == S == len(spec.agents) >= 1
    limit = spec.max_steps(cfg)
    core = spec.make_core(n, cfg)
    assert core.n == n and core.n_seats == S
    core.reset(np.arange(n), np.arange(100, 100 + n))
    rules = [random_rule(seat.action) for seat in seats]
    rngs = [np.random.default_rng(s) for s in range(S)]
    ended = np.zeros(n, dtype=bool)
    length = np.zeros(n, dtype=np.int64)
    total = np.zeros((S, n))
    steps = 0
    while not ended.all():
        # --- what the players see
        obs = core.observe()
        masks = core.action_masks()
        acting = core.to_act()
        assert isinstance(acting, np.ndarray) and acting.shape == (S, n) and acting.dtype == bool, "to_act()"
        assert len(masks) == S, "action_masks(): one entry per seat"
        running = ~ended
        in_game = getattr(core, "in_game", None)  # a core whose agents may come and go says who is in each game
        if in_game is not None:
            assert in_game.shape == (S, n) and in_game.dtype == bool, "in_game"
            assert not (acting & ~in_game)[:, running].any(), "only seats in their game act"
            if spec.turns == "simultaneous":
                assert (acting[:, running] == in_game[:, running]).all(), "every seat in a game acts (simultaneous)"
            was_in = in_game.copy()
        if spec.turns == "sequential":
            assert (acting[:, running].sum(axis=0) == 1).all(), "one seat acts at a time in a sequential game"
        else:
            assert acting[:, running].any(axis=0).all(), "every running game has seats to act"
            if steps == 0 and in_game is None:
                assert acting.all(), "all seats act at the start of a simultaneous game"
        for s, seat in enumerate(seats):
            o = obs[s]
            assert isinstance(o, np.ndarray) and o.dtype == seat.observation.dtype, \
                f"seat {s}: observations are of the seat's dtype"
            assert o.dtype == np.float32 or image_layout(seat.observation) is not None, \
                f"seat {s}: observations are float32 (an image's own dtype, uint8)"
            assert o.shape == (n, *seat.observation.shape), f"seat {s}: observation shape {o.shape}"
            box = seat.observation
            live = o[running]
            assert np.isfinite(live).all(), f"seat {s}: observations are finite"
            assert (live >= box.low - 1e-6).all() and (live <= box.high + 1e-6).all(), \
                f"seat {s}: observations within {box}"
            if seat.mask:
                m = masks[s]
                assert isinstance(m, np.ndarray) and m.dtype == bool and m.shape == (n, seat.action.n), \
                    f"seat {s}: mask shape/dtype"
                assert m[acting[s]].any(axis=1).all(), f"seat {s}: an acting seat has a legal action"
            else:
                assert masks[s] is None, f"seat {s}: a seat without masks gives None"
        # --- what they do
        actions = [rules[s](obs[s], rngs[s], masks[s]) for s in range(S)]
        for s, seat in enumerate(seats):
            for g in range(n) if steps < 50 else ():
                if acting[s, g] and not ended[g]:
                    a = actions[s][g]
                    assert seat.action.contains(np.asarray(a, dtype=seat.action.dtype)
                                                if not isinstance(seat.action, spaces.Discrete) else int(a)), \
                        f"seat {s}: the random player's action {a} is in {seat.action}"
                    if seat.mask:
                        assert masks[s][g, int(a)]
        rewards = core.step(actions)
        steps += 1
        assert isinstance(rewards, np.ndarray) and rewards.shape == (S, n) and rewards.dtype == np.float32
        assert np.isfinite(rewards).all(), "rewards are finite"
        score = core.score
        assert isinstance(score, np.ndarray) and score.shape == (S, n), "score is (n_seats, n)"
        assert np.issubdtype(score.dtype, np.floating) and np.isfinite(score).all(), "score: finite floats"
        total[:, running] += rewards[:, running]
        length[running] += 1
        assert (core.steps[running] == length[running]).all(), "steps counts the steps of each game"
        done = (core.terminated | core.truncated) & running
        assert not (core.terminated & core.truncated).any(), "a game ends either terminated or truncated"
        if in_game is not None:
            seat_done, seat_cut, now_in = core.seat_done, core.seat_cut, core.in_game
            assert not (seat_cut & ~seat_done).any(), "a seat cut short is done"
            assert not (seat_done & ~was_in).any(), "only a seat in its game is done in it"
            assert not (seat_done & now_in).any(), "a seat done in its game is out of it"
            assert not now_in[:, done].any(), "a game that ended has nobody in it"
            assert (seat_done[:, done] == was_in[:, done]).all(), "a game's end ends the part of everyone in it"
            left = (was_in & ~now_in)[:, running & ~done]
            assert (left == seat_done[:, running & ~done]).all(), "a seat that leaves a running game is done in it"
        ended |= done
        if limit is not None:
            assert (length[running] <= limit).all(), f"a game ran past its declared limit of {limit} steps"
        assert steps <= (limit or max_play), f"random play did not end within {limit or max_play} steps"
    if spec.make_core.__name__ == "PettingZooCore":  # the adapter's score is the summed rewards
        assert np.allclose(core.score, total), "score = summed rewards"
    # --- reset by seed reproduces the game
    seeds = np.arange(7, 7 + n)
    a = _play(spec, n, seeds, 40, action_seed=3)
    b = _play(spec, n, seeds, 40, action_seed=3)
    assert _same(a, b), "same seeds and actions must give the same observations, masks and scores"


@pytest.mark.slow
@pytest.mark.parametrize("name", GAMES + OPENSPIEL_GAMES)
def test_every_game_keeps_its_declaration(name):
    check_game(get_env(name))


@pytest.mark.parametrize("name", GAMES)
def test_every_games_pettingzoo_env_passes_pettingzoo_api_tests(name):
    env = get_env(name).make_parallel()
    if isinstance(env, AECEnv):
        api_test(env, num_cycles=100)
    else:
        assert isinstance(env, ParallelEnv)
        parallel_api_test(env, num_cycles=100)


def test_different_seeds_give_different_games():
    for name in ("pong", "tests.games.rendezvous:parallel_env"):
        spec = get_env(name)
        a = _play(spec, 2, np.array([1, 2]), 20, 0)
        b = _play(spec, 2, np.array([3, 4]), 20, 0)
        assert not _same(a, b), name


# ---------------------------------------------------------------------------------------------------------------
# The checks can fail: games that break one rule each
class _Walk(ParallelEnv):
    """A 1-seat game that walks a counter; ``flaw`` breaks one rule of the contract."""

    metadata = {"name": "walk", "marl_kind": "cooperative", "marl_max_steps": 5}

    def __init__(self, flaw: str = "") -> None:
        self.flaw = flaw
        self.possible_agents = ["w"]
        self._o = spaces.Box(0.0, 1.0, (2,), dtype=np.float32)
        self._a = spaces.Discrete(2)
        self.agents: list[str] = []
        self.t, self.rng = 0, np.random.default_rng()

    def observation_space(self, agent):
        return self._o

    def action_space(self, agent):
        return self._a

    def _obs(self):
        x = np.array([self.t / 10, self.rng.random() if self.flaw == "unseeded" else 0.5], dtype=np.float32)
        if self.flaw == "out of bounds":
            x[0] = 2.0
        if self.flaw == "wrong shape":
            x = np.zeros(3, dtype=np.float32)
        return {"w": x}

    def reset(self, seed=None, options=None):
        if seed is not None and self.flaw != "unseeded":
            self.rng = np.random.default_rng(seed)
        self.t = 0
        self.agents = ["w"]
        return self._obs(), {"w": {}}

    def step(self, actions):
        self.t += 1
        if self.flaw == "stranger" and self.t == 2:
            self.agents = ["w", "x"]
        end = self.t >= (50 if self.flaw == "too long" else 5)
        reward = float("nan") if self.flaw == "nan reward" else 1.0
        out = self._obs(), {"w": reward}, {"w": end}, {"w": False}, {"w": {}}
        if end:
            self.agents = []
        return out


@pytest.mark.parametrize("flaw, why", [
    ("", None),
    ("out of bounds", "within"),
    ("wrong shape", "observ"),
    ("nan reward", "finite"),
    ("too long", "limit"),
    ("unseeded", "same seeds"),
    ("stranger", "'x' is in the game of seed 100 at its step 2 but is not one of its possible_agents"),
])
def test_the_conformance_check_catches_a_game_that_breaks_its_declaration(flaw, why):
    spec = adapt(f"walk-{flaw or 'ok'}", lambda: _Walk(flaw))
    if why is None:
        check_game(spec)
        return
    with pytest.raises(Exception, match=why):
        check_game(spec)
