"""The lander game's speed and the heuristic's returns.

1. Env steps/s of the batched core (game steps per second: one step of one game, all its landers) with 1, 2, 4
   and 8 landers, games played by the heuristic (its time included) and reset as they end.
2. The heuristic's mean return per lander with 1, 2, 3 and 4 landers in the parallel view and in the AEC view
   (engines scaled by the number of landers, as the AEC view does by default).

    .venv/bin/python benchmarks/lander_env_speed.py [--games 16] [--seconds 3] [--episodes 10]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from selfplay_cli.envs.lander.bots import heuristic_rule
from selfplay_cli.envs.lander.config import LanderConfig
from selfplay_cli.envs.lander.core import LanderCore
from selfplay_cli.envs.lander.view import LanderAECEnv, LanderParallelEnv


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
    args = ap.parse_args()
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


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
