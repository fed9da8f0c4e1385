"""What the commands that read a league cost to run: CPU and wall seconds of each, and the heavy libraries it loaded.

A user types `marl league ladder`, `marl checkpoint list` or `marl league predict` many times a day; none of them
builds a network, so none should pay for torch (about 1.3 s of every start on this machine) or for libraries it does
not use. This builds a small league once (a 2,000-step pong run, `--run r`, and 4 rated games of the scripted
players), then runs each command ``--rounds`` times, each a fresh process as a user's shell starts it, and prints
the median CPU seconds (user + system) and wall seconds, with the libraries of torch, scipy, matplotlib, Ray and
OpenSpiel that its process imported. ``marl --version`` is the floor: the interpreter, typer and the CLI's table.

Run: python benchmarks/command_start.py [--rounds 5] [--before DIR]

``--before DIR``: a checkout of another commit, whose commands are run alternately with this one's on the same
league (each command: this tree, then DIR's, ``--rounds`` times), and printed beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("torch", "scipy", "matplotlib", "ray", "pyspiel")
COMMANDS = [
    ["--version"],
    ["checkpoint", "list"],
    ["checkpoint", "show", "r/s2k-left"],
    ["league", "ladder"],
    ["league", "matrix"],
    ["league", "predict", "random", "cpu", "--env", "pong"],
    ["elo", "fit", "--env", "pong"],
    ["elo", "gate", "random", "--vs", "cpu", "--env", "pong", "--games", "4"],  # its 4 games stored: none played
    ["train", "--resume", "nope"],
]
PROBE = "HEAVY = " + repr(HEAVY) + """
import json, resource, sys
from selfplay_cli.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as e:
    code = e.code
u = resource.getrusage(resource.RUSAGE_SELF)
print("\\n" + json.dumps({"code": code, "cpu": u.ru_utime + u.ru_stime,
                          "heavy": [m for m in HEAVY if m in sys.modules]}), file=sys.stderr)
"""


def once(tree: Path, home: Path, args: list[str]) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "MARL_HOME": str(home), "SDL_VIDEODRIVER": "dummy"}
    began = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=env, cwd=tree,
                         timeout=600)
    return {**json.loads(out.stderr.strip().splitlines()[-1]), "wall": time.perf_counter() - began}


def marl(home: Path, *args: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MARL_HOME": str(home), "SDL_VIDEODRIVER": "dummy"}
    done = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed: {done.stderr.strip()[-1000:]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--before", type=Path, help="a checkout of another commit, run alternately with this one")
    args = ap.parse_args()
    trees = {"this": ROOT, **({"before": args.before.resolve()} if args.before else {})}
    with tempfile.TemporaryDirectory(prefix="marl-command-start-") as tmp:
        home = Path(tmp) / "league"
        marl(home, "train", "pong", "--agents", "2", "--steps", "2000", "--games", "4", "--eval-games", "0", "--run",
             "r", "--quiet")
        marl(home, "match", "random", "cpu", "--env", "pong", "--games", "4")
        before = ""
        if args.before:
            commit = subprocess.run(["git", "-C", str(args.before), "rev-parse", "--short", "HEAD"],
                                    capture_output=True, text=True).stdout.strip() or "?"
            before = f"; before: {args.before} at commit {commit}"
        print(f"each command {args.rounds} times, a fresh process each (median; CPU: user + system seconds){before}")
        width = max(len(" ".join(c)) for c in COMMANDS) + 6
        head = f"  {'command':<{width}}" + "".join(f"{name + ' CPU s':>14}{name + ' wall s':>14}" for name in trees)
        print(head + "  exit  heavy libraries loaded")
        for command in COMMANDS:
            runs: dict[str, list[dict]] = {name: [] for name in trees}
            for _ in range(args.rounds):
                for name, tree in trees.items():
                    runs[name].append(once(tree, home, command))
            cells = "".join(f"{statistics.median(r['cpu'] for r in runs[n]):>14.2f}"
                            f"{statistics.median(r['wall'] for r in runs[n]):>14.2f}" for n in trees)
            heavy = " | ".join(", ".join(runs[n][-1]["heavy"]) or "none" for n in trees)
            print(f"  {'marl ' + ' '.join(command):<{width}}{cells}  {runs['this'][-1]['code']!s:>4}  {heavy}")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
