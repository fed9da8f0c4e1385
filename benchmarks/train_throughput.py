"""Training throughput: game steps/s of PPO and DQN self-play in pong, two learners (one network per paddle), on
this machine's cores, through the real trainer (`marl train`'s loop: acting, game steps, updates, snapshots, the
training games into the ledger), with the evaluation games after each snapshot switched off.

Run: python benchmarks/train_throughput.py [--steps 1000000] [--games 256] [--only ppo|dqn]. Targets: PPO at least
100,000 game steps/s (issue 10; it was ~60,000-73,000), DQN at least 5,000 (issue 4), on 2 cores with nothing else
running (the two learners update side by side, one core each: another busy process halves that part); seed 000's DQN
loop does about 60.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from selfplay_cli.league.store import League
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.loop import Trainer


def steps_per_second(algo: str, steps: int, games: int) -> tuple[float, int]:
    with tempfile.TemporaryDirectory() as tmp:
        league = League.open(Path(tmp) / "league")
        cfg = TrainConfig(env="pong", agents=2, algo=algo, steps=steps, games=games, eval_games=0, run=f"bench-{algo}",
                          device="cpu")
        league.roster.create_run(cfg.run, "pong", cfg.to_dict(), algo=algo)
        report = Trainer(league, cfg).train()
        league.close()
    return report.steps_per_second, report.steps


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=1_000_000, help="game steps per algorithm (DQN: a fifth of it)")
    p.add_argument("--games", type=int, default=256, help="games at once (the `marl train` default)")
    p.add_argument("--only", choices=("ppo", "dqn"), help="run one algorithm")
    args = p.parse_args()
    print(f"{os.cpu_count()} cores; two learners, {args.games} games at once, no evaluation games")
    ok = True
    for algo, target, steps in (("ppo", 100_000, args.steps), ("dqn", 5_000, args.steps // 5)):
        if args.only not in (None, algo):
            continue
        rate, done = steps_per_second(algo, steps, args.games)
        ok &= rate >= target
        print(f"{algo.upper()} self-play: {rate:,.0f} game steps/s over {done:,} game steps (target >= {target:,}): "
              f"{'PASS' if rate >= target else 'FAIL'}")
    print("targets met" if ok else "targets NOT met")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
