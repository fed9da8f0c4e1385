"""Skill on a user's turn-based board game: the suite's tic-tac-toe (tests/games/tictactoe.py, a PettingZoo AEC game
with action masks), trained through `marl train` as README's "Your own game" section does it.

Per seed it trains one shared network for both seats (`--sharing fups`) by self-play with half the games against
the league and the `random` player, then plays the final snapshot 200 fresh games (100 seat-swapped pairs, so it
moves first in half) against `random`, and prints the run's time, steps/s, the score with W/D/L, and the ladder.
Target (issue 13): the final snapshot scores at least 90% against random over 200 games.

Run from the repository's root: python benchmarks/board_game_skill.py [--seeds 0 1 2] [--steps 5000000]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GAME = "tests.games.tictactoe:env"
TRAIN = ["--sharing", "fups", "--league-games", "0.5", "--bots", "random=0.5", "--snapshot-steps", "1000000"]


def marl(home: Path, *args: str) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="140", SDL_VIDEODRIVER="dummy", MARL_GAMES=GAME)  # named
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True,
                         cwd=ROOT)  # the suite's games are tests.games.*, importable from the repository's root
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    return out.stdout


def one_seed(home: Path, seed: int, steps: int, games: int) -> float:
    t0 = time.perf_counter()
    report = json.loads(marl(home, "train", GAME, *TRAIN, "--steps", str(steps), "--seed", str(seed),
                             "--run", f"ttt-{seed}", "--quiet", "--json"))
    wall = time.perf_counter() - t0
    (final,) = report["final"]
    m = json.loads(marl(home, "match", final["snapshot"], "random", "--games", str(games),
                        "--seed", str(10**6 + seed), "--no-store", "--json"))
    print(f"seed {seed}: {wall:.0f} s wall, {report['steps']:,} moves at {report['steps_per_second']:,}/s, "
          f"{report['episodes']:,} games; {final['snapshot']} vs random: {100 * m['score']:.1f}% "
          f"({m['wins']} W {m['draws']} D {m['losses']} L over {m['games']} games), Elo {m['elo']:+.0f} "
          f"[{m['elo_low']:+.0f}, {m['elo_high']:+.0f}]")
    print("  " + marl(home, "league", "ladder", "--run", report["run"], "--top", "6").replace("\n", "\n  "))
    return float(m["score"])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--steps", type=int, default=5_000_000)
    p.add_argument("--games", type=int, default=200)
    p.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp) / "league"
        scores = {seed: one_seed(home, seed, args.steps, args.games) for seed in args.seeds}
    for seed, score in scores.items():
        verdict = "PASS" if score >= 0.9 else "FAIL"
        print(f"seed {seed}: final snapshot vs random {100 * score:.1f}% over {args.games} games (target >= 90%): "
              f"{verdict}")
    sys.exit(0 if all(s >= 0.9 for s in scores.values()) else 1)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
