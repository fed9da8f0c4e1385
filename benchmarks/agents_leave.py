"""Agents that leave mid-game in a real PettingZoo game: butterfly's knights-archers-zombies (v11, its vector
observations: (27, 5) per agent, a (26, 4) global state), where an archer or a knight that a zombie touches is removed
from ``agents`` while the others fight on, until all are dead, a zombie reaches the bottom or 900 cycles pass.

It trains one shared network for the four seats (the game is declared cooperative here: the team's kills are its
score) with `marl train --minutes`, counting on the way how many agents left a game that went on (the core's
``seat_done`` on a step whose game did not end), then plays the final snapshot against ``random`` (both flying the
whole team on the same seeds) and prints the run's steps/s, the departures, and the match.

Measured (2 cores shared with other work): seed 0, 63,072 steps in 2 minutes (526 steps/s), 189 agents left a game
that went on (0.53 a game); seed 1, 97,760 steps (815 steps/s), 300 left (0.53 a game). Both final snapshots against
random over 40 seeds: 63.7% (21 W 9 D 10 L), 2.95 team kills a game against 2.20, Elo +98 [+6, +207] (the same
games: the two greedy policies played alike). With marl's default learning rate (2e-3, 16 games) the snapshot
scored 27.5% (kills 1.65 against 2.70).

Run from the repository's root: python benchmarks/agents_leave.py [--minutes 2] [--games 32] [--match 80] [--lr 5e-4]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
GAME = "benchmarks.agents_leave:kaz"


def kaz(**options):
    """Knights-archers-zombies as a parallel env, declared cooperative (every agent kills zombies for the team)."""
    from pettingzoo.butterfly import knights_archers_zombies_v11

    env = knights_archers_zombies_v11.parallel_env(**options)
    env.metadata = {**env.metadata, "marl_kind": "cooperative"}
    return env


class Departures:
    """Counts, over every PettingZoo core stepped in this process, the agents that left a game that went on."""

    def __init__(self) -> None:
        self.left = 0
        self.games = 0

    @contextlib.contextmanager
    def counting(self):
        from selfplay_cli.envs.adapters.pettingzoo_core import PettingZooCore

        step = PettingZooCore.step

        def counted(core, actions):
            rewards = step(core, actions)
            ended = core.terminated | core.truncated
            self.left += int(core.seat_done[:, ~ended].sum())
            self.games += int(ended.sum())
            return rewards

        PettingZooCore.step = counted
        try:
            yield self
        finally:
            PettingZooCore.step = step


def marl(*args: str) -> dict:
    from selfplay_cli.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([*args, "--json"])
    if code != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({code}): {err.getvalue().strip()}")
    return json.loads(out.getvalue())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=2.0)
    p.add_argument("--games", type=int, default=32, help="training games played at once")
    p.add_argument("--match", type=int, default=80, help="games of the final snapshot against random (each seed "
                                                       "flown by both teams)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--lr", type=float, default=5e-4, help="PPO's learning rate (marl's default 2e-3 learned "
                                                          "nothing here in two minutes)")
    p.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    args = p.parse_args()
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp) / "league"
        os.environ["MARL_HOME"] = str(home)
        os.environ.pop("MARL_DB", None)
        t0 = time.perf_counter()
        with Departures().counting() as training:
            report = marl("train", GAME, "--minutes", str(args.minutes), "--games", str(args.games),
                          "--agents", "1", "--eval-games", "0", "--seed", str(args.seed), "--run", "kaz", "--quiet",
                          "--lr", str(args.lr))
        wall = time.perf_counter() - t0
        (final,) = report["final"]
        with Departures().counting() as played:
            m = marl("match", final["snapshot"], "random", "--games", str(args.match), "--seed", "1000000",
                     "--no-store")
    print(f"knights_archers_zombies_v11 (4 agents, vector observations), {args.games} games at once, one network:")
    print(f"  trained {report['steps']:,} steps in {report['session_train_seconds']:.0f} s of training "
          f"({wall:.0f} s wall): {report['steps_per_second']:,} steps/s; {report['episodes']:,} games")
    per_game = training.left / max(training.games, 1)
    print(f"  agents that left a game that went on: {training.left:,} in training ({per_game:.2f} a game over "
          f"{training.games:,} games), {played.left:,} in the match ({played.games:,} games)")
    episodes = max(m["games"] // 2, 1)  # each seed flown once by each team
    print(f"  {final['snapshot']} vs random, {episodes} seeds each flown by both teams: score {100 * m['score']:.1f}% "
          f"({m['wins']} W {m['draws']} D {m['losses']} L), team kills {m['points_for'] / episodes:.2f} against "
          f"{m['points_against'] / episodes:.2f} a game, Elo {m['elo']:+.0f} "
          f"[{m['elo_low']:+.0f}, {m['elo_high']:+.0f}]")
    sys.exit(0 if training.left > 0 else 1)  # the point: agents left games that went on, and training went on


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
