"""Where a rated match's time goes, and what a run waits for its rating games at its end.

1. A league of pong snapshots as the issue measured them: ``marl train pong --agents 2 --steps 1000000
   --eval-games 0`` (one core), then ``marl match RUN/s1M-left RUN/s1M-right --games 1000 --no-store --json`` on one
   core (``taskset``, torch at one thread), its wall time from start to exit (start-up included) and the game steps it
   played (its JSON). In the same run, on the same core: the batched core stepping 1,000 games (the match's games at
   once) with pre-drawn actions, game steps/s (the anchor), and so the time stepping the match's games takes; and the
   two networks alone, batched as a match runs them (:class:`~selfplay_cli.policies.bank.NetworkBank`), on the same
   rows for the same steps: the floor no match of these two networks goes below on this CPU.
   Target (the issue "speed where users feel it"): stepping at least 40% of the match's wall time.
2. ``marl train pong --agents 2 --minutes 0.5 --json`` (both cores, as a user runs it): training seconds, rating
   games, and the wait for the last ones once training ended. Target: the wait at most 10% of the training time.
   Where the rating games' time goes, read from the league the run wrote: their game steps beside the training's,
   the share cut at the game's step limit, the gauntlets' and the playoff's games, steps and units. A gauntlet
   matchup or a playoff round is a batch of games stepped together until its last game ends, so its wall time
   follows its longest game, not its number of games: the rounds played one after another are the wait's floor.
   The final moment's games (its gauntlet and the playoff), which every run plays once its training ended, priced
   at part 1's rates: the match's own (every game at once, one core) and the core's and the networks' alone. That
   is the least the wait can be with those games, however they are scheduled.
   Then the same run with ``--no-wait`` (its gauntlets not finished when training ends left on the league's queue),
   and ``marl worker --until-empty`` playing what it left: the wait it saves, and the games it leaves.

Run: python benchmarks/match_speed.py [--games 1000] [--cpu 0] [--no-train-wait]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np
from env_throughput import batched_core  # (pong's core with pre-drawn actions, games reset as they end)

ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "SDL_VIDEODRIVER": "dummy"}


def marl(home: Path, *args: str, cpu: int | None = None) -> tuple[str, float]:
    """``marl ARGS`` in the league ``home`` (on core ``cpu``): its stdout and wall seconds."""
    pin = ["taskset", "-c", str(cpu)] if cpu is not None else []
    env = {**os.environ, **(ONE_THREAD if cpu is not None else {"SDL_VIDEODRIVER": "dummy"}), "MARL_HOME": str(home)}
    began = time.perf_counter()
    out = subprocess.run([*pin, sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True)
    took = time.perf_counter() - began
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()[-2000:]}")
    return out.stdout, took


def network_floor(home: Path, names: list[str], games: int, steps: int) -> float:
    """Seconds the two snapshots' networks take, batched as a match runs them, to act ``steps`` times for ``games``
    rows each (observations drawn once; the forward and the sampling, nothing else)."""
    import torch

    from selfplay_cli.league.store import League
    from selfplay_cli.players import load_player
    from selfplay_cli.policies.bank import NetworkBank
    from selfplay_cli.ratings.names import resolve

    torch.set_num_threads(1)
    with League.open(home) as league:
        policies = [load_player(league, resolve(league, n, "pong")) for n in names]
    bank = NetworkBank(policies, seed=0)
    obs = [np.random.default_rng(k).normal(size=(games, bank.obs_dim)).astype(np.float32) for k in range(2)]
    bank.act(obs)
    began = time.perf_counter()
    for _ in range(steps):
        bank.act(obs)
    return time.perf_counter() - began


def rating_account(db: Path, run: str) -> tuple[dict[str, dict[str, float]], dict[str, float] | None]:
    """The rating games (kind ``eval``) of run ``run``'s snapshots (the bots' games among themselves left out) in the
    SQLite league at ``db``, by what played them (``gauntlet`` or ``playoff``): games, game steps, games cut at the
    step limit, units of work (a gauntlet's matchups; the playoff's rounds, each one batch) and, for the playoff,
    the seconds from the run's last gauntlet matchup stored to its last round stored. Beside them the same figures
    of the final moment alone (its gauntlet and playoff; None without gauntlets)."""
    import sqlite3

    with sqlite3.connect(db) as conn:
        rows = conn.execute(
            "SELECT m.work_key, m.created_at, COUNT(g.id), SUM(g.length), SUM(g.truncated) FROM matches m "
            "JOIN games g ON g.match_id = m.id WHERE m.kind = 'eval' AND m.id IN (SELECT g2.match_id FROM games g2 "
            "JOIN game_seats s ON s.game_id = g2.id JOIN players p ON p.id = s.player_id "
            "JOIN runs r ON r.id = p.run_id WHERE r.name = ?) GROUP BY m.id ORDER BY m.created_at", (run,)).fetchall()
    out: dict[str, dict[str, float]] = {}
    units: dict[str, set[str]] = {}
    ends: dict[str, list[datetime]] = {}
    for key, at, games, steps, truncated in rows:
        what = "playoff" if (key or "").startswith("playoff/") else "gauntlet"
        a = out.setdefault(what, {"games": 0, "steps": 0, "truncated": 0})
        a["games"] += games
        a["steps"] += steps
        a["truncated"] += truncated
        # (a playoff round's matchups are keyed playoff/<the run's final moment>/<the round's first seed>/...)
        units.setdefault(what, set()).add("/".join(key.split("/")[:3]) if what == "playoff" else key or at)
        ends.setdefault(what, []).append(datetime.fromisoformat(at))
    for what, a in out.items():
        a["units"] = len(units[what])
    # the final moment (the run's last gauntlet, keyed by its first snapshot's id, the largest) and its playoff: the
    # games a run always plays after its training ended, whatever it played beside training
    moments = [int(key.split("/")[1]) for key, *_ in rows if (key or "").startswith("gauntlet/")]
    final = None
    if moments:
        last = f"/{max(moments)}/"
        its = [r for r in rows if (r[0] or "").startswith(("gauntlet" + last, "playoff" + last))]
        final = {"games": sum(r[2] for r in its), "steps": sum(r[3] for r in its),
                 "truncated": sum(r[4] for r in its), "units": len(its)}
    if "playoff" in out and "gauntlet" in out:
        out["playoff"]["seconds"] = (max(ends["playoff"]) - max(ends["gauntlet"])).total_seconds()
    return out, final


def print_account(games: dict[str, dict[str, float]], train_steps: int) -> None:
    steps = sum(a["steps"] for a in games.values())
    total = sum(a["games"] for a in games.values())
    cut = sum(a["truncated"] for a in games.values())
    print(f"  the rating games of its snapshots: {total:,}, {steps / 1e6:.1f}M game steps ({steps / train_steps:.1f}x "
          f"the training's {train_steps / 1e6:.1f}M); {cut / total:.0%} of them cut at the step limit")
    for what, a in games.items():
        unit = "rounds" if what == "playoff" else "matchups"
        line = (f"    {what}: {a['games']:,} games, {a['steps'] / 1e6:.1f}M game steps ({a['steps'] / a['games']:,.0f} "
                f"a game), {a['truncated'] / a['games']:.0%} cut at the step limit, {a['units']} {unit}")
        if "seconds" in a:
            line += f"; {a['seconds']:.0f} s after the last gauntlet matchup, {a['seconds'] / a['units']:.1f} s a round"
        print(line)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--games", type=int, default=1000)
    ap.add_argument("--cpu", type=int, default=0, help="the core the match and its anchors run on")
    ap.add_argument("--no-train-wait", action="store_true", help="skip part 2")
    args = ap.parse_args()
    os.sched_setaffinity(0, {args.cpu})
    with tempfile.TemporaryDirectory() as tmp:
        home = Path(tmp) / "league"
        marl(home, "train", "pong", "--agents", "2", "--steps", "1000000", "--eval-games", "0", "--run", "p6",
             "--quiet", cpu=args.cpu)
        names = ["p6/s1M-left", "p6/s1M-right"]
        load = os.getloadavg()[0]
        out, wall = marl(home, "match", *names, "--games", str(args.games), "--no-store", "--json", cpu=args.cpu)
        m = json.loads(out)
        rate = batched_core(args.games, 5.0, observe=False)
        stepping = m["game_steps"] / rate
        per_step = m["game_steps"] / args.games  # the match's steps of all its games at once (they start together)
        floor = network_floor(home, names, args.games, int(round(per_step)))
        print(f"marl match {names[0]} {names[1]} --games {args.games:,} (one core, load {load:.2f}): {wall:.1f} s "
              f"wall ({m['seconds']:.1f} s playing), {m['game_steps']:,} game steps, {m['truncated_games']:,} games "
              "cut at the step limit")
        print(f"  anchor: the batched core, {args.games:,} games at once: {rate:,.0f} game steps/s, so "
              f"{stepping:.1f} s to step the match's games")
        print(f"  the two networks alone, batched, the same rows and steps: {floor:.1f} s (the floor: "
              f"stepping could be at most {100 * stepping / (stepping + floor):.0f}% of a match of these networks)")
        share = stepping / wall
        print(f"match stepping share: {100 * share:.1f}% of the wall time (target >= 40%: "
              f"{'met' if share >= 0.4 else 'not met'})")
        if args.no_train_wait:
            return
        os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
        load = os.getloadavg()[0]
        out, wall = marl(home, "train", "pong", "--agents", "2", "--minutes", "0.5", "--run", "wait", "--json")
        r = json.loads(out)
        wait, train = r["rating_wait_seconds"], r["session_train_seconds"]
        print(f"marl train pong --agents 2 --minutes 0.5 (both cores, load {load:.2f}): {wall:.0f} s wall, "
              f"{train:.1f} s training, {r['rating_games']:,} rating games ({r['rating_seconds']:.0f} s), "
              f"{wait:.1f} s waited for them at the end")
        print(f"end-of-run wait: {100 * wait / train:.0f}% of the training time (target <= 10%: "
              f"{'met' if wait <= 0.1 * train else 'not met'})")
        account, final = rating_account(home / "league.db", "wait")
        print_account(account, r["steps"])
        if final:  # what the games the final moment must play cost at the best rate measured above
            best = m["game_steps"] / m["seconds"]  # the 1,000-game match's own rate: every game at once, one core
            floor_rate = 1 / (1 / rate + 1 / (m["game_steps"] / floor))  # the core and the networks alone
            at_best, at_floor = final["steps"] / best, final["steps"] / floor_rate
            print(f"  the final moment (its gauntlet and playoff, played once training ended): {final['games']:,} "
                  f"games, {final['steps'] / 1e6:.1f}M game steps, {final['truncated'] / final['games']:.0%} cut at "
                  f"the step limit; at the match's rate above ({best:,.0f} game steps/s, one core) they take "
                  f"{at_best:.1f} s ({100 * at_best / train:.0f}% of the training time), at the core's and the "
                  f"networks' rate alone ({floor_rate:,.0f} game steps/s) {at_floor:.1f} s "
                  f"({100 * at_floor / train:.0f}%), on both cores at best half of that")
        out, wall = marl(home, "train", "pong", "--agents", "2", "--minutes", "0.5", "--run", "nowait", "--no-wait",
                         "--json")
        r = json.loads(out)
        wait, train = r["rating_wait_seconds"], r["session_train_seconds"]
        _, later = marl(home, "worker", "--until-empty")
        print(f"the same with --no-wait: {wall:.0f} s wall, {train:.1f} s training, {wait:.1f} s waited "
              f"({100 * wait / train:.0f}% of the training time), {r['rating_jobs_left']} gauntlets left on the "
              f"league's queue; marl worker --until-empty played them in {later:.0f} s")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
