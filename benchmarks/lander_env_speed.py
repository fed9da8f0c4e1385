"""The lander game's speed and the heuristic's returns.

1. Env steps/s of the batched core (game steps per second: one step of one game, all its landers) with 1, 2, 4
   and 8 landers, games played by the heuristic (its time included) and reset as they end.
2. The heuristic's mean return per lander with 1, 2, 3 and 4 landers in the parallel view and in the AEC view
   (engines scaled by the number of landers, as the AEC view does by default).
3. The targets (issue 51), each a line ``name: value (target ...)`` with its anchor beside it, measured in the same
   run: gymnasium's ``LunarLander-v3`` (``gym.make``, as its users make it), random actions, reset as it ends. The
   things compared take turns, ``--slices`` turns of ``--slice-seconds`` each, each keeping its games between turns,
   so both sides of a ratio are measured over the same stretch of the machine's time (a shared machine's speed
   drifts over seconds: gymnasium's own rate has moved between 13,000 and 24,000 steps/s within minutes here); each
   ratio is from the summed steps and seconds, with the range of the turns' own ratios beside it (run it on one core,
   ``taskset -c 1``).

   ``lander view / gymnasium per lander step, N landers``: the parallel view's game steps/s times N over
   gymnasium's steps/s (one lander each), random actions (drawn ahead for both), games reset as they end.
   ``lander core at 64 games / gymnasium per lander step, 2 landers``: the batched core's game steps/s at 64 games
   times 2 over gymnasium's, random actions drawn ahead, ``observe()`` every step, games reset as they end.

    .venv/bin/python benchmarks/lander_env_speed.py [--games 16] [--seconds 3] [--episodes 10] [--slices 40]
        [--slice-seconds 0.25]
        [--targets-only]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from core_runs import Runner, core_runner, sliced

from selfplay_cli.envs.lander.bots import heuristic_rule
from selfplay_cli.envs.lander.config import LanderConfig
from selfplay_cli.envs.lander.core import LanderCore
from selfplay_cli.envs.lander.view import LanderAECEnv, LanderParallelEnv

VIEW_LANDERS = (1, 2, 4)


def core_speed(landers: int, games: int, seconds: float) -> float:
    """Game steps per second of the batched core, the heuristic playing ``games`` at once (its time included)."""
    core = LanderCore(games, LanderConfig(landers=landers))
    next_seed, steps = games, 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        obs = core.observe()
        core.step(heuristic_rule(obs.reshape(-1, 8)).reshape(landers, games))
        steps += games  # every slot steps: finished games are reset at once
        done = np.flatnonzero(core.over)
        if done.size:
            core.reset(done, np.arange(next_seed, next_seed + done.size))
            next_seed += done.size
    return steps / (time.perf_counter() - start)


def gym_runner() -> Runner:
    """gymnasium's ``LunarLander-v3`` under random actions (drawn ahead), reset as it ends, :func:`sliced`."""
    import gymnasium as gym

    env = gym.make("LunarLander-v3")
    actions = np.random.default_rng(0).integers(0, 4, 4096).tolist()
    env.reset(seed=0)
    total = [0]

    def step() -> int:
        _, _, term, trunc, _ = env.step(actions[total[0] % 4096])
        total[0] += 1
        if term or trunc:
            env.reset()
        return 1

    return sliced(step)


def view_runner(landers: int) -> Runner:
    """The parallel view under random actions (drawn ahead), reset as its games end, :func:`sliced` (game steps)."""
    env = LanderParallelEnv(landers=landers)
    actions = np.random.default_rng(1).integers(0, 4, (4096, landers)).tolist()
    seats = list(enumerate(env.possible_agents))
    env.reset(seed=0)
    total = [0]

    def step() -> int:
        if not env.agents:
            env.reset()
        row = actions[total[0] % 4096]
        env.step({a: row[i] for i, a in seats if a in env.agents})
        total[0] += 1
        return 1

    return sliced(step)


def targets(slices: int, seconds: float) -> None:
    """The issue's targets, each beside its anchor (gymnasium's rate, measured in the same slices). Every runner
    keeps its games between slices; the runners take turns, ``slices`` slices of ``seconds`` each, the order
    rotating from slice to slice, so each ratio compares the two over the same stretch of the machine's time (a
    shared machine's speed drifts over seconds). A ratio is the summed steps over the summed seconds of each;
    beside it the range of the slices' own ratios."""
    runners: dict[str, Runner] = {
        "gym": gym_runner(), **{f"view{n}": view_runner(n) for n in VIEW_LANDERS}, "core": core_runner(
        LanderCore(64, LanderConfig(landers=2)), np.random.default_rng(2).integers(0, 4, (64, 2, 64)))}
    for r in runners.values():
        next(r)  # (built, its first game reset: outside the timed slices)
    names = list(runners)
    steps = dict.fromkeys(names, 0)
    took = dict.fromkeys(names, 0.0)
    per_slice: dict[str, list[float]] = {name: [] for name in names}
    for k in range(slices):
        for name in names[k % len(names):] + names[: k % len(names)]:
            n, t = runners[name].send(seconds)
            steps[name] += n
            took[name] += t
            per_slice[name].append(n / t)
    rate = {name: steps[name] / took[name] for name in names}
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\ntargets ({slices} slices of {seconds:g} s each, taking turns; random actions; load average {load})")

    def spread(name: str, seats: int) -> str:
        ratios = [x * seats / g for x, g in zip(per_slice[name], per_slice["gym"], strict=True)]
        return f"slices {min(ratios):.2f}x to {max(ratios):.2f}x"

    for n in VIEW_LANDERS:
        ratio = rate[f"view{n}"] * n / rate["gym"]
        print(f"lander view / gymnasium per lander step, {n} lander{'s' if n > 1 else ''}: {ratio:.2f}x (target >= "
              f"1.0x); view {rate[f'view{n}']:,.0f} game steps/s, gymnasium {rate['gym']:,.0f} steps/s; "
              f"{spread(f'view{n}', n)}")
    ratio = rate["core"] * 2 / rate["gym"]
    print(f"lander core at 64 games / gymnasium per lander step, 2 landers: {ratio:.2f}x (target >= 2.0x); core "
          f"{rate['core']:,.0f} game steps/s, gymnasium {rate['gym']:,.0f} steps/s; {spread('core', 2)}")


def parallel_heuristic(landers: int, episodes: int) -> float:
    env = LanderParallelEnv(landers=landers)
    total = 0.0
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        while env.agents:
            acts = {a: int(heuristic_rule(obs[a][None])[0]) for a in env.agents}
            obs, rewards, _, _, _ = env.step(acts)
            total += sum(rewards.values())
    return total / (episodes * landers)


def aec_heuristic(landers: int, episodes: int) -> float:
    env = LanderAECEnv(landers=landers)
    total = 0.0
    for seed in range(episodes):
        env.reset(seed=seed)
        for _agent in env.agent_iter():
            obs, reward, term, trunc, _ = env.last()
            total += reward
            env.step(None if term or trunc else int(heuristic_rule(obs[None])[0]))
    return total / (episodes * landers)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--games", type=int, default=16, help="games in the batched core")
    ap.add_argument("--seconds", type=float, default=3.0, help="seconds of play per lander count")
    ap.add_argument("--episodes", type=int, default=10, help="heuristic episodes per lander count and view")
    ap.add_argument("--slices", type=int, default=40, help="turns each target's runner takes")
    ap.add_argument("--slice-seconds", type=float, default=0.25, help="seconds of one turn")
    ap.add_argument("--targets-only", action="store_true", help="only the target lines")
    args = ap.parse_args()
    if args.targets_only:
        targets(args.slices, args.slice_seconds)
        return
    print(f"batched core, {args.games} games, heuristic play, games reset as they end")
    print(f"{'landers':>8} {'game steps/s':>13} {'lander steps/s':>15}")
    for landers in (1, 2, 4, 8):
        rate = core_speed(landers, args.games, args.seconds)
        print(f"{landers:>8} {rate:>13,.0f} {rate * landers:>15,.0f}")
    print(f"\nheuristic mean return per lander over {args.episodes} seeds (0..{args.episodes - 1})")
    print(f"{'landers':>8} {'parallel':>9} {'AEC':>9}")
    for landers in (1, 2, 3, 4):
        print(f"{landers:>8} {parallel_heuristic(landers, args.episodes):>9.1f} "
              f"{aec_heuristic(landers, args.episodes):>9.1f}")
    targets(args.slices, args.slice_seconds)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
