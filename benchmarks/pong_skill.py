"""Skill and time of the README's default run, `marl train pong --agents 2`, on several seeds.

Per seed it prints the wall time (all of it; training alone; the rating games, which run beside training, and how
long the run waited for the last of them), both learners' final snapshots' scores over 200 games against `cpu` and
`random` (fresh games, not stored), and the top 10 of the run's ladder. Targets (issue 10): the whole run within 4
minutes on 2 cores; both learners' final snapshots at least 60% against cpu, on seeds 0, 1 and 2.

Run: python benchmarks/pong_skill.py [--seeds 0 1 2] [--games 200] [--keep DIR] [--train-args "..."]
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
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    return out.stdout


def one_seed(home: Path, seed: int, games: int, extra: list[str]) -> dict:
    t0 = time.perf_counter()
    report = json.loads(marl(home, "train", "pong", "--agents", "2", "--seed", str(seed), "--quiet", *extra, "--json"))
    wall = time.perf_counter() - t0
    train_s = report["seconds"] - report["rating_wait_seconds"]
    print(f"seed {seed}: {wall:.0f} s wall (training {train_s:.0f} s at {report['steps_per_second']:,} steps/s; "
          f"{report['rating_games']} rating games took {report['rating_seconds']:.0f} s beside training, "
          f"{report['rating_wait_seconds']:.0f} s waited for at the end; the rest is start-up)")
    scores = {}
    for final in report["final"]:
        snap = final["snapshot"]
        for opp in ("cpu", "random"):
            m = json.loads(marl(home, "match", snap, opp, "--games", str(games), "--seed", str(10**6 + seed),
                                "--no-store", "--json"))
            scores[(snap, opp)] = m["score"]
            print(f"  {snap} vs {opp}: {100 * m['score']:.1f}% ({m['wins']} W {m['draws']} D {m['losses']} L), Elo "
                  f"{m['elo']:+.0f} [{m['elo_low']:+.0f}, {m['elo_high']:+.0f}], points {m['points_for']}-"
                  f"{m['points_against']}")
    print("  " + marl(home, "league", "ladder", "--run", report["run"], "--top", "10").replace("\n", "\n  "))
    return {"wall": wall, "scores": scores}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--games", type=int, default=200)
    p.add_argument("--keep", type=Path, help="folder to keep the leagues in (default: a temporary one)")
    p.add_argument("--train-args", default="", help="extra `marl train` options, e.g. \"--steps 3000000\"")
    args = p.parse_args()
    extra = shlex.split(args.train_args)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        for seed in args.seeds:
            results[seed] = one_seed(root / f"league-seed{seed}", seed, args.games, extra)
    ok = True
    for seed, r in results.items():
        cpu = [s for (snap, opp), s in r["scores"].items() if opp == "cpu"]
        good = r["wall"] <= 240 and len(cpu) == 2 and min(cpu) >= 0.60
        ok &= good
        print(f"seed {seed}: {r['wall']:.0f} s (target <= 240 s); both learners vs cpu "
              f"{', '.join(f'{100 * s:.1f}%' for s in cpu)} (target >= 60%): {'PASS' if good else 'FAIL'}")
    print("targets met" if ok else "targets NOT met")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
