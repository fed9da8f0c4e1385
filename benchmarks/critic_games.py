"""What a team's critic buys on the suite's two credit-assignment games (``tests/games``), per algorithm and sharing.

* The duet (``tests/games/duet.py``): a round pays only when both singers name their own targets, and each sees luck
  of its own that moves the team's reward. Figure: the chance both are right (the final snapshots' policies, sampling
  as they trained, averaged over targets and lucks).
* The relay (``tests/games/relay.py``): the scout answers once and leaves; whether it was right is paid to the
  runner at the game's end. Figure: the chance the scout answers its signal (0.5 is a guess).

Each set-up: ``marl train GAME --algo ALGO --agents 2 --sharing SHARING --steps 10000 --games 32 --eval-games 0
--seed S`` with 16-step rollouts (as ``tests/test_mappo.py`` and ``tests/test_poca.py`` train them), seeds 0-2; PPO
FuPS on the duet also at 40,000 steps.

Run: python benchmarks/critic_games.py [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # the suite's games, and its measures of what they learned
from team_helpers import DUET, RELAY, ROLLOUT, duet_together, relay_scout_right  # noqa: E402

SETUPS = [  # (game, algo, sharing, steps)
    ("duet", "ppo", "fups", 10_000), ("duet", "ppo", "fups", 40_000), ("duet", "mappo", "fups", 10_000),
    ("duet", "mappo", "nops", 10_000), ("duet", "poca", "fups", 10_000), ("duet", "poca", "nops", 10_000),
    ("relay", "ppo", "fups", 10_000), ("relay", "ppo", "nops", 10_000), ("relay", "mappo", "fups", 10_000),
    ("relay", "poca", "fups", 10_000), ("relay", "poca", "nops", 10_000),
]


def train(tmp: Path, game: str, algo: str, sharing: str, steps: int, seed: int) -> list[Path]:
    """One run (a fresh league): the final snapshots' files, one per learner in seat order."""
    home, config = tmp / f"{game}-{algo}-{sharing}-{steps}-{seed}", tmp / "rollout.toml"
    config.write_text(ROLLOUT)
    env = dict(os.environ, MARL_GAMES=f"{DUET},{RELAY}", PYTHONPATH=str(ROOT), MARL_HOME=str(home))
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", "train", DUET if game == "duet" else RELAY, "--algo",
                          algo, "--agents", "2", "--sharing", sharing, "--steps", str(steps), "--games", "32",
                          "--eval-games", "0", "--seed", str(seed), "--run", "r", "--config", str(config), "--json",
                          "--quiet"], env=env, cwd=ROOT, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"marl train {game} --algo {algo} failed: {out.stderr.strip()[-2000:]}")
    report = json.loads(out.stdout)
    return [next((home / "snapshots" / "r").glob(f"{f['snapshot'].split('/')[-1]}.*")) for f in report["final"]]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args()
    from selfplay_cli.envs import admit, get_env

    for game in (DUET, RELAY):  # (named here and loaded: their snapshots are read as theirs)
        admit(game)
        get_env(game)
    print(f"each: 2 agents, 32 games, 16-step rollouts, no rating games; seeds {', '.join(map(str, args.seeds))}")
    print("| game | figure | algo | sharing | steps | " + " | ".join(f"seed {s}" for s in args.seeds) + " |")
    print("|---|---|---|---|---|" + "---|" * len(args.seeds))
    with tempfile.TemporaryDirectory(prefix="marl-critic-games-") as tmp:
        for game, algo, sharing, steps in SETUPS:
            measure = duet_together if game == "duet" else relay_scout_right
            figures = [measure(train(Path(tmp), game, algo, sharing, steps, s)) for s in args.seeds]
            what = "both right" if game == "duet" else "scout right"
            print(f"| {game} | {what} | {algo} | {sharing} | {steps:,} | "
                  + " | ".join(f"{f:.3f}" for f in figures) + " |", flush=True)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
