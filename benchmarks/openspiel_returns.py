"""OpenSpiel games through marl's adapter: returns equal to OpenSpiel's own over many random games, and the
adapter's speed against stepping pyspiel directly on the same games.

Run: python benchmarks/openspiel_returns.py [--games 10000] [--parallel 64]. For Kuhn poker, Leduc poker and
tic-tac-toe it plays ``--games`` games through the adapter's batched core by random legal actions, replays each on a
plain pyspiel state (the same chance outcomes, drawn as the adapter documents, and the same moves) and counts the
games whose ``returns()`` equal the adapter's final scores exactly. Then the speed, pinned to one core: those same
games (seeds and moves) played again through the adapter (``observe()``, ``action_masks()``, ``to_act()`` and
``step()`` each step, finished games reset) against a plain loop over pyspiel states that does what a player needs
at each move (its tensor and its legal actions, as OpenSpiel's lists, and again as the numpy arrays a network
reads); the ratio adapter / direct time is the adapter's cost per game step as a factor (target below 2), the
median of alternating rounds. The same check runs in the test suite
(tests/test_envs_openspiel.py), 10,000 games a game.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import pyspiel  # noqa: E402

from selfplay_cli.envs import get_env  # noqa: E402
from tests.test_envs_openspiel import random_games, replay  # noqa: E402

GAMES = ("kuhn_poker", "leduc_poker", "tic_tac_toe")


def through_adapter(name: str, played: list[tuple], parallel: int) -> float:
    """Seconds to play the games ``played`` (their seeds, their moves) again through the adapter's core, ``parallel``
    at once: each step ``observe()``, ``action_masks()``, ``to_act()`` and ``step()``, finished slots reset."""
    spec = get_env(f"openspiel:{name}")
    core = spec.core(parallel)
    todo = iter(played)
    moves: list[list[tuple[int, int]] | None] = [None] * parallel
    at = [0] * parallel
    actions = np.zeros((spec.n_seats, parallel), dtype=np.int64)

    def start(slots: list[int]) -> list[int]:
        seeds = []
        for g in slots:
            nxt = next(todo, None)
            moves[g], at[g] = (None, 0) if nxt is None else (nxt[1], 0)
            seeds.append(0 if nxt is None else nxt[0])
        core.reset(slots, seeds)
        return [g for g in slots if moves[g] is not None]

    t0 = time.perf_counter()
    live = start(list(range(parallel)))
    while live:
        core.observe()
        masks = core.action_masks()
        acting = core.to_act()
        if len(live) < parallel:  # the last games: slots without one play on, by their first legal move
            actions[:] = np.stack(masks).argmax(axis=2)
        for g in live:
            s, a = moves[g][at[g]]
            at[g] += 1
            actions[s, g] = a
        core.step(actions)
        done = np.flatnonzero(core.terminated).tolist()
        if done:
            gone = set(done)
            live = [g for g in live if g not in gone] + start(done)
        assert acting.any()
    return time.perf_counter() - t0


def directly(name: str, played: list[tuple], arrays: bool = False) -> float:
    """Seconds to play the same games on pyspiel states one by one, reading what a player needs at each move (as
    numpy arrays with ``arrays``)."""
    game = pyspiel.load_game(name)
    t0 = time.perf_counter()
    for seed, m, _, _, _ in played:
        replay(game, seed, m, observe=True, arrays=arrays)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--games", type=int, default=10_000, help="random games a game (default 10,000)")
    ap.add_argument("--parallel", type=int, default=64, help="games the adapter's core steps at once")
    ap.add_argument("--rounds", type=int, default=5, help="timed rounds each way, alternating (the median is shown)")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    for name in GAMES:
        game = pyspiel.load_game(name)
        played = random_games(f"openspiel:{name}", args.games, args.parallel, seed=1)
        equal = sum(score.tolist() == replay(game, seed, moves) for seed, moves, score, _, _ in played)
        moves = sum(len(m) for _, m, _, _, _ in played)
        print(f"{name}: {len(played):,} games, {moves:,} moves: returns equal to OpenSpiel's in {equal:,}, "
              f"different in {len(played) - equal:,}")
        adapter, direct, numpy = [], [], []
        for _ in range(args.rounds):
            adapter.append(through_adapter(name, played, args.parallel))
            direct.append(directly(name, played))
            numpy.append(directly(name, played, arrays=True))
        a, d, n = (float(np.median(x)) for x in (adapter, direct, numpy))
        print(f"  speed: adapter {moves / a:,.0f} steps/s, pyspiel directly {moves / d:,.0f} steps/s "
              f"(ratio {a / d:.2f}x), directly with numpy arrays {moves / n:,.0f} steps/s (ratio {a / n:.2f}x); "
              f"medians of {args.rounds} rounds")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
