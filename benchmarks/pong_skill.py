"""Skill of the README's default training: `marl train pong --agents 2`, then 200-game matches of its final
snapshots against `random` and `cpu`. Prints the wall time, the match results and the ladder.

Run: python benchmarks/pong_skill.py [--games 200] [--keep DIR]. Targets (issue 4): a final snapshot scores at
least 95% against random and at least 60% against cpu over 200 games.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def marl(home: Path, *args: str) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="140")
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, check=True, capture_output=True,
                         text=True)
    return out.stdout


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--games", type=int, default=200)
    p.add_argument("--keep", type=Path, help="league home to keep (default: a temporary directory)")
    p.add_argument("--train-args", default="", help="extra `marl train` options, e.g. \"--seed 1 --config x.toml\"")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp) / "league"
        t0 = time.perf_counter()
        report = json.loads(marl(home, "train", "pong", "--agents", "2", *shlex.split(args.train_args), "--json"))
        wall = time.perf_counter() - t0
        print(f"marl train pong --agents 2 {args.train_args}: {report['steps']:,} game steps, "
              f"{report['episodes']} episodes, {wall:.0f} s wall ({report['steps_per_second']:,} game steps/s "
              "incl. evaluation games)")
        finals = [s for s in report["snapshots"] if s.split("/")[1].split("-")[0] ==
                  report["snapshots"][-1].split("/")[1].split("-")[0]]
        best = {}
        for snap in finals:
            for opp in ("random", "cpu"):
                m = json.loads(marl(home, "match", snap, opp, "--games", str(args.games), "--json"))
                best[opp] = max(best.get(opp, 0.0), m["score"])
                print(f"  {snap} vs {opp}: {m['wins']} W {m['draws']} D {m['losses']} L, score {100 * m['score']:.1f}%"
                      f", Elo {m['elo']:+.0f} [{m['elo_low']:+.0f}, {m['elo_high']:+.0f}], points "
                      f"{m['points_for']}-{m['points_against']}")
        print(marl(home, "league", "ladder", "--bootstrap", "100"))
        ok = best.get("random", 0) >= 0.95 and best.get("cpu", 0) >= 0.60
        print(f"best final snapshot: {100 * best['random']:.1f}% vs random (target >= 95%), "
              f"{100 * best['cpu']:.1f}% vs cpu (target >= 60%): {'PASS' if ok else 'FAIL'}")


if __name__ == "__main__":
    main()
