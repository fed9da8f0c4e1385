"""Training throughput: game steps/s of PPO and DQN self-play in pong (two learners, one network per paddle), the
learner loop alone (acting, game steps, updates; no evaluation games, no ledger), on this machine's cores.

Run: python benchmarks/train_throughput.py [--games 128 256 512] [--steps 400000]. Targets (issue 4): PPO at
least 50,000 game steps/s, DQN at least 5,000, on 2 cores; seed 000's DQN loop does about 60.
"""

from __future__ import annotations

import argparse
import time

import torch

from selfplay_cli.algos.dqn import DQNConfig, DQNLearner
from selfplay_cli.algos.ppo import PPOConfig, PPOLearner
from selfplay_cli.arena.selfplay import SelfPlayGames, seat_layout


def steps_per_second(algo: str, n_games: int, steps: int) -> float:
    torch.set_num_threads(1)
    layout = seat_layout(2, n_games, 2, "nops")
    games = SelfPlayGames("pong", n_games, layout, ["left", "right"])
    if algo == "ppo":
        learners = [PPOLearner((8, 6), 3, n_games, PPOConfig(), seed=i) for i in range(2)]
    else:
        learners = [DQNLearner((8, 6), 3, n_games, DQNConfig(), seed=i) for i in range(2)]
    obs = games.observe()
    done_steps = 0
    t0 = time.perf_counter()
    while done_steps < steps:
        rewards, dones, _ = games.step([learner.act(o) for learner, o in zip(learners, obs, strict=True)])
        obs = games.observe()
        due = [learner.record(r, d) for learner, r, d in zip(learners, rewards, dones, strict=True)]
        if all(due):
            for learner, o in zip(learners, obs, strict=True):
                learner.update(o, progress=done_steps / steps)
        done_steps += n_games
    return done_steps / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--games", type=int, nargs="+", default=[128, 256, 512])
    p.add_argument("--steps", type=int, default=400_000)
    args = p.parse_args()
    for algo, target in (("ppo", 50_000), ("dqn", 5_000)):
        for n in args.games:
            rate = steps_per_second(algo, n, args.steps)
            print(f"{algo.upper()} self-play, 2 learners, {n} games at once: {rate:,.0f} game steps/s "
                  f"(target >= {target:,})")


if __name__ == "__main__":
    main()
