"""Training on Ray actors (``marl train --executor ray``) against training in one process, on this machine.

For pong (two learners, PPO), the lander (2 landers, one shared network: ``--agents 2 --sharing fups``, PPO) and
tennis (its defaults: SAC, a shared network, the serve-bot teacher, its curriculum, half its games against the
league), each trained with the game's own settings (``marl envs GAME`` shows them) and no rating games:

* **steps/s**: game steps per second of training (Ray's start and the actors' building left out: the run's own
  clock starts after them), and the speed-up over the local run;
* **peak memory**: of the trainer's process, and of each actor (their peak resident set, read as the run ends);
* **moving data**: the time per update (one fragment, a PPO rollout) spent neither in the actors' stepping nor in
  the learner: waiting for the pieces beyond the slowest actor's own time (serialising, the object store, the
  network) plus putting them back in the learners' slot order, against the whole update's time (the fragment's
  wall time, the learning included). Target: under 10%.

Each configuration runs in a process of its own (so its peak memory is its own). Run with
``python benchmarks/ray_rollouts.py`` (``--games pong,lander,tennis --actors 1,2 --seconds 40``); ``--seconds`` is
roughly how long each local run trains (its steps are measured once and used for every executor).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

GAMES = {  # the options each game trains with here, as marl train would take them
    "pong": {"agents": 2},
    "lander": {"agents": 2, "sharing": "fups"},
    "tennis": {},
}
RATE_GUESS = {"pong": 60_000, "lander": 15_000, "tennis": 6_000}  # steps/s of a local run, to size the budget


def one(game: str, executor: str, actors: int, steps: int) -> dict:
    """Train ``game`` for ``steps`` game steps in this process (``executor``, ``actors``) and return its figures."""
    from selfplay_cli.league.store import League
    from selfplay_cli.train.loop import Trainer
    from selfplay_cli.train.settings import new_settings, start_run

    home = Path(tempfile.mkdtemp(prefix="marl-bench-ray-"))
    league = League.open(home)
    flags = {**GAMES[game], "steps": steps, "eval_games": 0, "snapshot_steps": 0, "snapshot_every": 10**9,
             "executor": executor, "actors": actors}
    settings = new_settings(game, flags)
    cfg = start_run(league, settings, None)
    trainer = Trainer(league, cfg)
    report = trainer.train()
    out = {"game": game, "executor": executor, "actors": actors if executor == "ray" else 0, "steps": report.steps,
           "seconds": report.train_seconds, "steps_per_second": report.steps / report.train_seconds,
           "driver_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    rollouts = trainer.rollouts
    if executor == "ray":
        fragments = max(rollouts._fragments, 1)
        moving = max(rollouts.wait_seconds - rollouts.actor_seconds, 0.0) + rollouts.merge_seconds
        out.update(actor_peaks_mb=[m / 2**20 for m in rollouts.actor_peaks], fragments=fragments,
                   fragment_steps=rollouts.fragment_steps,
                   update_ms=1000 * report.train_seconds / fragments, moving_ms=1000 * moving / fragments,
                   actor_ms=1000 * rollouts.actor_seconds / fragments)
    league.close()
    shutil.rmtree(home, ignore_errors=True)  # (the run's league: nothing of it is kept)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--games", default="pong,lander,tennis")
    parser.add_argument("--actors", default="1,2")
    parser.add_argument("--seconds", type=float, default=40.0, help="about how long each local run trains")
    parser.add_argument("--one", nargs=4, metavar=("GAME", "EXECUTOR", "ACTORS", "STEPS"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        game, executor, actors, steps = args.one
        print(json.dumps(one(game, executor, int(actors), int(steps))))
        return
    print(f"marl training rollouts on Ray actors; {os.cpu_count()} cores; each local run ~{args.seconds:.0f} s")
    for game in args.games.split(","):
        steps = int(RATE_GUESS[game] * args.seconds)
        rows = []
        for executor, actors in [("local", 1)] + [("ray", int(a)) for a in args.actors.split(",")]:
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, __file__, "--one", game, executor, str(actors), str(steps)],
                                  capture_output=True, text=True, cwd=ROOT)
            if done.returncode:
                print(f"{game} {executor} {actors}: failed\n{done.stderr[-2000:]}")
                continue
            row = json.loads(done.stdout.strip().splitlines()[-1])
            row["wall"] = time.perf_counter() - t0
            rows.append(row)
        if not rows:
            continue
        base = rows[0]["steps_per_second"] if rows[0]["executor"] == "local" else None
        print(f"\n{game} ({', '.join(f'{k} {v}' for k, v in GAMES[game].items()) or 'its defaults'}; "
              f"{steps:,} steps)")
        print(f"  {'run':<14}{'steps/s':>10}{'x local':>9}{'driver MB':>11}{'actors MB':>14}"
              f"{'update ms':>11}{'actors ms':>11}{'moving ms':>11}{'moving %':>10}")
        for r in rows:
            name = "local" if r["executor"] == "local" else f"ray, {r['actors']} actor{'s' * (r['actors'] > 1)}"
            speed = f"{r['steps_per_second'] / base:.2f}" if base else "-"
            if r["executor"] == "ray":
                peaks = "/".join(f"{m:.0f}" for m in r["actor_peaks_mb"])
                extra = (f"{peaks:>14}{r['update_ms']:>11.1f}{r['actor_ms']:>11.1f}{r['moving_ms']:>11.2f}"
                         f"{100 * r['moving_ms'] / r['update_ms']:>9.1f}%")
            else:
                extra = f"{'-':>14}{'-':>11}{'-':>11}{'-':>11}{'-':>10}"
            print(f"  {name:<14}{r['steps_per_second']:>10,.0f}{speed:>9}{r['driver_peak_mb']:>11.0f}{extra}")
        one_actor = next((r for r in rows if r["actors"] == 1), None)
        if one_actor is not None:
            print("  " + project(one_actor))


def project(r: dict) -> str:
    """Steps/s with more actors (a core each), projected from the one-actor run: an update's time is the actors'
    stepping, shared N ways, plus what does not shrink with N (the learner, the trainer's bookkeeping, moving)."""
    per_fragment = r["steps"] / r["fragments"]
    stepping = r["actor_ms"] / 1000
    fixed = (r["update_ms"] - r["actor_ms"]) / 1000
    rates = {n: per_fragment / (stepping / n + fixed) for n in (2, 4, 8, 16)}
    return (f"projected from 1 actor (stepping {1000 * stepping:.0f} ms, the rest {1000 * fixed:.0f} ms an "
            "update): " + ", ".join(f"{n} actors {v:,.0f}" for n, v in rates.items())
            + f"; at most {per_fragment / fixed:,.0f} steps/s however many")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
