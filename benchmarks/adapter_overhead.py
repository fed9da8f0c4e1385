"""The PettingZoo adapter's overhead: a PettingZoo game stepped directly in a loop, against the same game stepped as
N copies through the adapter's batched core (what rated play, training and recording play).

Run: python benchmarks/adapter_overhead.py [--seconds 0.5] [--rounds 5] [--copies 16]. Pinned to one CPU core.
For each game it prints game steps/s both ways and the ratio direct / adapter (the adapter's cost per game step as
a factor; the median of alternating rounds); the target is a ratio below 2 for every game. Games: pong's
PettingZoo view (parallel, the fastest game here, so the adapter's share is the largest), the test suite's
rendezvous (parallel, Box actions, 3 seats), tic-tac-toe (AEC, action masks), cue (Discrete observations, read
one-hot), dash (a nested Dict/Tuple observation flattened, with a top-level action mask), race (agents that leave
as they finish and one that joins late) and spot (16x16x3 uint8 image observations, kept as they are). OpenSpiel
games have their own figures: benchmarks/openspiel_returns.py.

Both ways play random legal actions drawn ahead of time, and both do what a player needs each step: the direct
loop reads the observations ``step`` returns (``last()`` for AEC) and resets finished games; through the adapter
each step is ``observe()``, ``action_masks()``, ``to_act()`` and ``step()``, and finished games are reset.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the test games live in tests/games

from selfplay_cli.envs import admit, get_env  # noqa: E402
from selfplay_cli.envs.adapters.pettingzoo import adapt  # noqa: E402
from selfplay_cli.envs.adapters.pettingzoo_core import PettingZooCore  # noqa: E402

GAMES = {
    "pong (parallel)": "pong",
    "rendezvous (parallel, Box)": "tests.games.rendezvous:parallel_env",
    "tictactoe (AEC, masks)": "tests.games.tictactoe:env",
    "cue (Discrete obs)": "tests.games.cue:parallel_env",
    "dash (Dict/Tuple obs, masks)": "tests.games.dash:parallel_env",
    "race (agents leave, join)": "tests.games.race:parallel_env",
    "spot (16x16x3 uint8 images)": "tests.games.spot:parallel_env",
}


def _random_actions(space, count: int, rng: np.random.Generator) -> list:
    if hasattr(space, "n"):
        return rng.integers(0, int(space.n), count).tolist()
    return list(rng.uniform(space.low, space.high, (count, *space.shape)).astype(space.dtype))


def direct(name: str, seconds: float) -> float:
    """Game steps/s of one env stepped in a plain loop."""
    spec = get_env(name)
    env = spec.make_parallel()
    rng = np.random.default_rng(0)
    agents = list(env.possible_agents)
    seat_of = {a: s for s, a in enumerate(agents)}
    spaces = [env.action_space(a) for a in agents]
    draws = [_random_actions(s, 4096, rng) for s in spaces]
    steps, t0 = 0, time.perf_counter()
    if spec.turns == "simultaneous":
        obs, _ = env.reset(seed=0)
        while time.perf_counter() - t0 < seconds:
            for i in range(256):
                j = (steps + i) & 4095
                act = {}
                for a in env.agents:  # the agents in the game now (some leave and join: race)
                    s = seat_of[a]
                    o = obs[a]
                    if isinstance(o, dict) and "action_mask" in o:  # the k-th legal action, k drawn ahead
                        legal = np.flatnonzero(o["action_mask"])
                        act[a] = int(legal[draws[s][j] % len(legal)])
                    else:
                        act[a] = draws[s][j]
                obs, *_ = env.step(act)
                if not env.agents:
                    obs, _ = env.reset()
            steps += 256
    else:
        env.reset(seed=0)
        seed = 1
        while time.perf_counter() - t0 < seconds:
            for _ in range(256):  # 256 moves (the dead agents' step(None) at a game's end are not moves)
                while True:
                    obs, _, term, trunc, _ = env.last()
                    if not (term or trunc):
                        break
                    env.step(None)
                    if not env.agents:
                        env.reset(seed=seed)
                        seed += 1
                legal = np.flatnonzero(obs["action_mask"])
                env.step(int(legal[draws[0][steps & 4095] % len(legal)]))
                steps += 1
    return steps / (time.perf_counter() - t0)


def adapted(name: str, seconds: float, copies: int) -> float:
    """Game steps/s (summed over the copies) of the same game as ``copies`` copies in the adapter's core."""
    spec = get_env(name)
    if spec.make_core is not PettingZooCore:  # a built-in game: its PettingZoo view through the adapter
        spec = adapt(f"{name} (PettingZoo view)", spec.make_parallel)
    core = spec.core(copies)
    rng = np.random.default_rng(0)
    seats = spec.seat_spaces()
    draws = []
    for seat in seats:
        if hasattr(seat.action, "n"):
            draws.append([rng.integers(0, int(seat.action.n), copies) for _ in range(64)])
        else:
            draws.append([rng.uniform(seat.action.low, seat.action.high, (copies, *seat.action.shape))
                          .astype(np.float32) for _ in range(64)])
    next_seed = copies
    played, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for i in range(32):
            core.observe()
            masks = core.action_masks()
            acting = core.to_act()
            actions = []
            for s, m in enumerate(masks):
                a = draws[s][i & 63]
                if m is not None:  # the k-th legal action, k drawn ahead
                    counts = m.sum(axis=1)
                    k = a % np.maximum(counts, 1)
                    a = (np.cumsum(m, axis=1) > k[:, None]).argmax(axis=1)
                actions.append(a)
            played += int(acting.any(axis=0).sum())
            core.step(actions)
            done = core.terminated | core.truncated
            if done.any():
                slots = np.flatnonzero(done)
                core.reset(slots, np.arange(next_seed, next_seed + slots.size))
                next_seed += slots.size
    return played / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=0.5, help="time per measurement")
    p.add_argument("--rounds", type=int, default=5, help="alternating direct/adapter measurements per game")
    p.add_argument("--copies", type=int, default=16, help="copies of the game in the adapter's core")
    args = p.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print(f"one core, {args.rounds} rounds of {args.seconds:g} s each way per game (alternating, so the machine's "
          f"speed drifting cancels in each round's ratio), {args.copies} copies through the adapter; medians")
    worst = 0.0
    for label, name in GAMES.items():
        admit(name)  # a game of your own: named here, as marl's --env names it
        d, a = [], []
        for _ in range(args.rounds):
            d.append(direct(name, args.seconds))
            a.append(adapted(name, args.seconds, args.copies))
        ratio = float(np.median(np.array(d) / np.array(a)))
        worst = max(worst, ratio)
        print(f"{label:<28} direct {np.median(d):>10,.0f} game steps/s   adapter {np.median(a):>10,.0f} game steps/s"
              f"   overhead x{ratio:.2f}")
    print(f"target: adapter overhead below 2x for every game: worst x{worst:.2f} -> {'PASS' if worst < 2 else 'FAIL'}")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
