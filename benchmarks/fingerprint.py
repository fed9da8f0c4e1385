"""Behaviour fingerprint: the same seeded runs, matches and records, reduced to hashes, to compare two commits.

A refactor should change no figure. This script trains small seeded runs of every learner on every built-in game
(rating games inline, so nothing depends on a second process's timing), then prints the sha256 of every snapshot
file (all of it but the time it was written), and the JSON that `marl match`, `marl elo fit`, `marl elo gate`,
`marl league ladder` and `marl checkpoint list` print about them (wall-clock fields removed), and the hash of a
recorded GIF. Run it on two commits and diff the output:

    python benchmarks/fingerprint.py > before.txt   # on the old commit
    python benchmarks/fingerprint.py > after.txt    # on the new one
    diff before.txt after.txt

Run: python benchmarks/fingerprint.py [--keep DIR] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

# Fields that measure time or place, not behaviour.
VOLATILE = {"seconds", "steps_per_second", "rating_seconds", "rating_wait_seconds", "created", "created_at",
            "path", "home", "db", "wall_seconds", "elapsed", "games_per_second", "file", "video", "at", "when",
            "training_seconds", "started", "ended", "time", "plot", "session_seconds", "session_train_seconds",
            "game_steps_per_second", "overrun_seconds",
            "sha256"}  # a file's sha256 covers its clock time; the snapshots are hashed without it

RUNS = {
    "pong-ppo": ["pong", "--agents", "2", "--steps", "40000", "--games", "16", "--snapshot-steps", "10000"],
    "pong-ppo-league": ["pong", "--agents", "1", "--steps", "30000", "--games", "16", "--snapshot-steps", "10000",
                        "--opponents", "pfsp", "--bots", "cpu=0.2,random=0.1"],
    "pong-dqn": ["pong", "--agents", "2", "--algo", "dqn", "--steps", "20000", "--games", "8",
                 "--snapshot-steps", "10000"],
    "pong-fups": ["pong", "--agents", "2", "--sharing", "fups", "--steps", "20000", "--games", "8",
                  "--snapshot-steps", "10000"],
    "lander-ppo": ["lander", "--agents", "2", "--steps", "6000", "--games", "4", "--snapshot-steps", "3000"],
    "lander-sac": ["lander", "--agents", "1", "--algo", "sac", "--steps", "3000", "--games", "4",
                   "--snapshot-steps", "1500", "--env-option", "continuous=true"],
    "tennis-ppo": ["tennis", "--agents", "2", "--steps", "8000", "--games", "8", "--snapshot-steps", "4000"],
    "tennis-sac": ["tennis", "--agents", "2", "--algo", "sac", "--steps", "3000", "--games", "4",
                   "--snapshot-steps", "1500"],
    "tictactoe-dqn": ["tests.games.tictactoe:env", "--agents", "2", "--algo", "dqn", "--steps", "3000", "--games",
                      "8", "--snapshot-steps", "1500"],
    "rendezvous-ppo": ["tests.games.rendezvous:parallel_env", "--agents", "2", "--steps", "3000", "--games", "8",
                       "--snapshot-steps", "1500"],
}


def marl(home: Path, *args: str, check: bool = True) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="140", SDL_VIDEODRIVER="dummy",
               MARL_GAMES=",".join(a[0] for a in RUNS.values() if ":" in a[0]))  # the users' games, named
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True)
    if check and out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    return out.stdout


def scrub(value):
    if isinstance(value, dict):
        return {k: scrub(v) for k, v in sorted(value.items()) if k not in VOLATILE}
    if isinstance(value, list):
        return [scrub(v) for v in value]
    if isinstance(value, float):
        return round(value, 9)
    return value


def snapshot_digest(path: Path) -> str:
    """A snapshot file's bytes, except the clock time it was written at (its metadata's ``created``)."""
    data = path.read_bytes()
    n = int.from_bytes(data[:8], "little")
    header = json.loads(data[8:8 + n])
    marl_meta = json.loads(header.get("__metadata__", {}).get("marl", "{}"))
    marl_meta.pop("created", None)
    header.get("__metadata__", {}).pop("marl", None)
    both = json.dumps([header, marl_meta], sort_keys=True).encode() + data[8 + n:]
    return hashlib.sha256(both).hexdigest()[:16]


def digest(value) -> str:
    return hashlib.sha256(json.dumps(scrub(value), sort_keys=True).encode()).hexdigest()[:16]


def one_run(home: Path, name: str, args: list[str]) -> None:
    report = json.loads(marl(home, "train", *args, "--run", name, "--seed", "7", "--eval-inline",
                             "--eval-games", "4", "--eval-playoff", "6", "--quiet", "--json"))
    print(f"[{name}] train report {digest(report)}")
    for snap in sorted((home / "snapshots" / name).iterdir()):
        print(f"  {snap.name} {snapshot_digest(snap)}")
    ladder = json.loads(marl(home, "league", "ladder", "--run", name, "--json"))
    print(f"  ladder {digest(ladder)}")
    finals = [f["snapshot"] for f in report["final"]]
    match = json.loads(marl(home, "match", finals[0], "random", "--games", "20", "--seed", "11", "--no-store",
                            "--quiet", "--json"))
    print(f"  match {finals[0]} vs random: {match['wins']}-{match['draws']}-{match['losses']} {digest(match)}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    p.add_argument("--only", nargs="+", choices=sorted(RUNS), help="these runs alone")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp)
        for name in args.only or RUNS:
            one_run(home, name, RUNS[name])
        for game in sorted({RUNS[name][0] for name in args.only or RUNS}):
            print(f"elo fit {game} {digest(json.loads(marl(home, 'elo', 'fit', '--env', game, '--json')))}")
        if "pong-ppo" in (args.only or RUNS):  # the gate and the GIF read its snapshots
            gate = json.loads(marl(home, "elo", "gate", "pong-ppo/s40k-left", "--vs", "pong-ppo/s0-left", "--json",
                                   check=False))
            print(f"gate {digest(gate)}")
            video = home / "fp.gif"
            marl(home, "record", "--ckpt", "pong-ppo/s40k-left", "--vs", "cpu", "--seed", "3", "--max-steps", "300",
                 "--out", str(video), "--quiet")
            print(f"record gif {hashlib.sha256(video.read_bytes()).hexdigest()[:16]}")
        print(f"checkpoints {digest(json.loads(marl(home, 'checkpoint', 'list', '--json')))}")


if __name__ == "__main__":
    main()
