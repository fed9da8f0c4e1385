"""README's main job as a new user runs it: ``marl train pong --agents 2`` in a fresh league home, its summary as it
prints it (stdout, not a terminal: plain lines), and the wall time of the whole command. README quotes what this
printed (its figures block), so the example there is a real run's, with its date, machine and load.

The run is seeded (``--seed 0``, the default): on one machine the same command gives the very same snapshots, rating
games and figures at any speed; the times in its first line are what changes with the machine's load.

Run: python benchmarks/main_job.py [--keep DIR] [-- extra marl train arguments]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    ap.add_argument("train_args", nargs="*", help="extra `marl train` arguments (after --)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="marl-main-job-") as tmp:
        home = args.keep or Path(tmp) / "league"
        env = dict(os.environ, MARL_HOME=str(home), COLUMNS="120")
        command = ["train", "pong", "--agents", "2", *args.train_args]
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "selfplay_cli", *command], env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if out.returncode != 0:
            raise SystemExit(f"marl {' '.join(command)} failed ({out.returncode}): {out.stderr.strip()[-2000:]}")
        print(f"$ marl {' '.join(command)}    # {wall:.0f} s of wall time, start-up included")
        for line in out.stdout.splitlines():
            print(line.replace(str(home), "league"))  # (the league's folder as a user's default, ./league)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
