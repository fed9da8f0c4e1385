"""The tennis game's speed, and what its scripted player does.

1. Game steps/s of the batched core (one step of one game: both bats, 4 physics substeps) at 1, 16, 256 and 1024
   games, random actions drawn ahead, ``observe()`` every step, games reset as they end.
2. Steps/s of the PettingZoo view (one game).
3. The serve-bot: its time per call, games played by it on both seats (steps/s), how many of its serves land
   legally in each ``serve_mode`` (the receiver standing still), and its own rallies (hits per point, returns in).
4. The targets, each a line ``name: value (target ...)`` with its anchor beside it, measured in the same run:
   things compared are run alternately, ``--rounds`` times, and the medians are shown (the machine may be shared).

   ``tennis serve-bot 1 row``: ms per call of the rule on one observation, the mean over 256 observations in which
   it plans a stroke (serving, or receiving a ball), taken from its games against itself; anchor: ms per step of
   the core at one game (observe and step). ``tennis serve-bot 1024 rows``: ms per call on 1,024 observations of
   games 25 steps in (half receiving a serve, half having served), the median of 20 calls (a call the machine's
   other work interrupts counts once); anchor: ms per step of the core at 1,024 games.
   ``tennis view / core at 1 game``: the view's steps/s over the core's at one game under random actions; the
   anchors are the two rates.

    .venv/bin/python benchmarks/tennis_env_speed.py [--seconds 3] [--rounds 5] [--targets-only]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from core_runs import core_rate

from selfplay_cli.envs.tennis.bots import serve_bot_for
from selfplay_cli.envs.tennis.config import TennisConfig
from selfplay_cli.envs.tennis.core import TennisCore
from selfplay_cli.envs.tennis.view import TennisParallelEnv


def core_speed(games: int, seconds: float) -> float:
    """Game steps per second of the batched core under random actions (drawn ahead, observe() every step)."""
    actions = np.random.default_rng(0).uniform(-1, 1, (64, 2, games, 3)).astype(np.float32)
    return core_rate(TennisCore(games), actions, seconds)


def view_speed(seconds: float) -> float:
    env = TennisParallelEnv()
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        if not env.agents:
            env.reset()
        env.step({a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents})
        steps += 1
    return steps / (time.perf_counter() - start)


def bot_call_ms(rows: int, calls: int = 40) -> float:
    """Milliseconds per call of the serve-bot's rule on ``rows`` observations of games in play."""
    core = TennisCore(rows)
    rule = serve_bot_for(TennisConfig())
    for _ in range(25):  # into the serves
        core.step(np.stack([rule(o) for o in core.observe()]))
    obs = core.observe()
    start = time.perf_counter()
    for _ in range(calls):
        rule(obs[0])
    return (time.perf_counter() - start) / calls * 1000


def core_step_ms(games: int, steps: int) -> float:
    """Milliseconds per step of the batched core at ``games`` games (observe and step, random actions)."""
    core = TennisCore(games)
    actions = np.random.default_rng(1).uniform(-1, 1, (16, 2, games, 3)).astype(np.float32)
    start = time.perf_counter()
    for i in range(steps):
        core.observe()
        core.step(actions[i % 16])
    return (time.perf_counter() - start) / steps * 1000


def planning_rows(count: int = 256) -> np.ndarray:
    """``count`` single observations ``(1, 25)`` in which the serve-bot plans a stroke (it serves, or a ball comes
    to it), from its games against itself (8 games, both seats, spaced through 1,500 steps)."""
    from selfplay_cli.envs.tennis.config import I_SERVE, INCOMING, MY_TURN

    core = TennisCore(8)
    core.reset(np.arange(8), np.arange(500, 508))
    rule = serve_bot_for(core.config)
    rows = []
    for _ in range(1500):
        obs = core.observe()
        plan = (obs[..., I_SERVE] > 0.5) | (obs[..., INCOMING] > 0.5) | (obs[..., MY_TURN] > 0.5)
        rows.extend(obs[plan])
        core.step(np.stack([rule(obs[0]), rule(obs[1])]))
        done = np.flatnonzero(core.over)
        if done.size:
            core.reset(done, done + 10_000 + core.steps[done])
    pick = np.linspace(0, len(rows) - 1, count).astype(np.int64)
    return np.stack([rows[i] for i in pick])[:, None, :]


def bot_rows_ms(rule, rows: np.ndarray) -> float:
    """Mean milliseconds per call of ``rule`` over single observations ``rows`` ``(k, 1, 25)``."""
    start = time.perf_counter()
    for row in rows:
        rule(row)
    return (time.perf_counter() - start) / len(rows) * 1000


def served_batch(rows: int = 1024) -> np.ndarray:
    """Seat 0's observations of ``rows`` games 25 steps in, played by the serve-bot (benchmark's bot_call_ms)."""
    core = TennisCore(rows)
    rule = serve_bot_for(TennisConfig())
    for _ in range(25):
        core.step(np.stack([rule(o) for o in core.observe()]))
    return core.observe()[0]


def targets(rounds: int, seconds: float) -> None:
    """The issue's targets, each beside its anchor, alternating what is compared; medians of ``rounds`` rounds."""
    rule = serve_bot_for(TennisConfig())
    one, batch = planning_rows(), served_batch()
    bot1, bot1024, core1, core1024, view, core = [], [], [], [], [], []
    for _ in range(rounds):
        core1.append(core_step_ms(1, 300))
        bot1.append(bot_rows_ms(rule, one))
        core1024.append(core_step_ms(1024, 20))
        calls = []
        for _ in range(20):
            start = time.perf_counter()
            rule(batch)
            calls.append((time.perf_counter() - start) * 1000)
        bot1024.append(statistics.median(calls))
        core.append(core_speed(1, seconds))
        view.append(view_speed(seconds))
    med = statistics.median
    ratio = med(v / c for v, c in zip(view, core, strict=True))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\ntargets (medians of {rounds} rounds, alternated; load average {load})")
    print(f"tennis serve-bot 1 row: {med(bot1):.3f} ms (target < 1 ms); anchor: core step at 1 game "
          f"{med(core1):.3f} ms")
    print(f"tennis serve-bot 1024 rows: {med(bot1024):.3f} ms (target < 5 ms); anchor: core step at 1024 games "
          f"{med(core1024):.3f} ms")
    print(f"tennis view / core at 1 game: {ratio:.2f} (target >= 0.8); anchors: view {med(view):,.0f} steps/s, "
          f"core {med(core):,.0f} steps/s")


def bot_games(games: int, steps: int, mode: str = "fixed") -> tuple[float, TennisCore]:
    core = TennisCore(games, TennisConfig(serve_mode=mode))
    rule = serve_bot_for(core.config)
    start = time.perf_counter()
    for _ in range(steps):
        obs = core.observe()
        core.step(np.stack([rule(obs[0]), rule(obs[1])]))
    return games * steps / (time.perf_counter() - start), core


def serves_in(mode: str, games: int = 32, steps: int = 1500, bounce: bool = False) -> tuple[int, int]:
    """The serve-bot on seat 0 against a receiver standing still: its serves (those decided: not still in the air
    when the run stops), and those that landed legally (``bounce``: table tennis's serve, ``serve_bounce=true``)."""
    core = TennisCore(games, TennisConfig(serve_mode=mode, serve_bounce=bounce))
    core.reset(np.arange(games), np.arange(1000, 1000 + games))
    rule = serve_bot_for(core.config)
    served = landed = 0
    next_seed = 2000
    for _ in range(steps):
        a = np.zeros((2, games, 3), dtype=np.float32)
        a[0] = rule(core.observe()[0])
        s, i = core.serves[0].sum(), core.serves_in[0].sum()
        core.step(a)
        served += core.serves[0].sum() - s
        landed += core.serves_in[0].sum() - i
        done = np.flatnonzero(core.over)
        if done.size:
            core.reset(done, np.arange(next_seed, next_seed + done.size))
            next_seed += done.size
    flying = (~core.tossing & core.serve_shot & ~core.landed & (core.hitter == 0)).sum()  # not decided yet
    return int(served - flying), int(landed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=3.0, help="seconds of play per measurement")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of the alternated target measurements")
    ap.add_argument("--targets-only", action="store_true", help="only the target lines")
    args = ap.parse_args()
    if args.targets_only:
        targets(args.rounds, min(args.seconds, 1.0))
        return
    print("batched core, random actions, observe() every step, games reset as they end")
    print(f"{'games':>6} {'game steps/s':>13}")
    for games in (1, 16, 256, 1024):
        print(f"{games:>6} {core_speed(games, args.seconds):>13,.0f}")
    print(f"\nPettingZoo view (one game): {view_speed(args.seconds):,.0f} steps/s")
    print("\nserve-bot: ms per call of its rule (games in play)")
    for rows in (1, 16, 256, 1024):
        print(f"{rows:>6} rows {bot_call_ms(rows):>8.2f} ms")
    rate, core = bot_games(64, 1500)
    hits = core.serves.sum() + core.returns.sum()
    points = core.score.sum()
    print(f"\nserve-bot vs serve-bot, 64 games x 1500 steps: {rate:,.0f} game steps/s (bot time included); "
          f"{hits / max(points, 1):.1f} hits per point, {core.returns_in.sum() / max(core.returns.sum(), 1):.1%} "
          "of returns landed")
    print("\nserve-bot's serves against a receiver standing still (32 games x 1500 steps)")
    for mode in ("fixed", "velocity", "spin"):
        served, landed = serves_in(mode)
        print(f"{mode:>9}: {landed}/{served} landed legally ({landed / max(served, 1):.1%})")
    print("the same with table tennis's serve (serve_bounce=true: on the server's own half first)")
    for mode in ("fixed", "velocity", "spin"):
        served, landed = serves_in(mode, bounce=True)
        print(f"{mode:>9}: {landed}/{served} landed legally ({landed / max(served, 1):.1%})")
    targets(args.rounds, min(args.seconds, 1.0))


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
