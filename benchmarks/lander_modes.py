"""Seed 001's comparison of control modes on the 2-lander game: SA (one agent, joint actions), NoPS (one network a
lander) and FuPS (one shared network), each trained by `marl train lander` for the same wall-clock budget.

Per mode it prints the mean return per lander of every snapshot against training steps and wall time (from the
run's rating games and metrics), the mean return per lander over fresh games of the final snapshot and of the run's
best (by fitted rating, as its ladder marks it), and the peak memory of the run's processes; then a FuPS policy
trained with 2 landers flown with 1 to 4 landers (the game's own steps/s are ``lander_env_speed.py``'s). A PNG of
mean return per lander against game steps and wall time goes to --png. Target (issue 36): each mode's final
snapshot (not only its best) scores a mean return per lander of at least 200 within 30 minutes on 2 cores, measured
on fresh games.

Run: python benchmarks/lander_modes.py [--minutes 30] [--modes sa nops fups] [--algo ppo] [--png lander_modes.png]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def marl(home: Path, *args: str) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="140", SDL_VIDEODRIVER="dummy")
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    return out.stdout


def peak_kb(pid: int) -> int:
    """The peak resident memory (VmHWM, kB) of a process and its children, 0 once gone."""
    total = 0
    for p in [pid, *_children(pid)]:
        with contextlib.suppress(OSError):  # a process that ended since it was listed has no status to read
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    total += int(line.split()[1])
    return total


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def train(home: Path, mode: str, minutes: float, algo: str, snapshot_steps: int) -> dict:
    """``marl train lander`` as a user types it (the game's own training defaults: marl envs lander)."""
    args = [sys.executable, "-m", "selfplay_cli", "train", "lander", "--agents", "2", "--sharing", mode, "--algo",
            algo, "--minutes", str(minutes), "--snapshot-steps", str(snapshot_steps), "--run", mode, "--quiet",
            "--json"]
    env = dict(os.environ, MARL_HOME=str(home), SDL_VIDEODRIVER="dummy")
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = 0
    while proc.poll() is None:
        peak = max(peak, peak_kb(proc.pid))
        time.sleep(1.0)
    out, err = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"marl train lander --sharing {mode} failed: {err.strip()}")
    report = json.loads(out)
    report["wall"] = time.perf_counter() - t0
    report["peak_mb"] = peak / 1024
    return report


def curve(home: Path, run: str) -> list[tuple[int, float, float]]:
    """(step, wall seconds, mean return per lander) of every snapshot of the run, from its rating games."""
    rows = json.loads(marl(home, "league", "ladder", "--run", run, "--env", "lander", "--json"))
    seconds = {}
    metrics = home / "runs" / run / "metrics.jsonl"
    for line in metrics.read_text().splitlines():
        m = json.loads(line)
        seconds[m["step"]] = m["seconds"]
    steps = sorted(seconds)
    out = []
    seen = set()
    for r in rows:
        if r["kind"] != "snapshot" or r.get("mean_return") is None or int(r["step"]) in seen:
            continue  # (a NoPS moment's members fly as one team: the same figure, once)
        step = int(r["step"])
        seen.add(step)
        near = min(steps, key=lambda s: abs(s - step)) if steps else 0
        out.append((step, seconds.get(near, 0.0) if step else 0.0, r["mean_return"] / 2))
    return sorted(out)


def best_of(home: Path, run: str) -> str:
    """The run's best snapshot, as its ladder marks it (by fitted rating; a NoPS member stands for its team)."""
    rows = json.loads(marl(home, "league", "ladder", "--run", run, "--env", "lander", "--json"))
    best = next(r["policy"] for r in rows if r.get("best"))
    return best.rsplit("-", 1)[0] if run == "nops" else best


def fly(home: Path, snapshot: str, landers: int, games: int) -> float:
    """Mean return per lander of ``snapshot`` over ``games`` fresh games with ``landers`` landers."""
    m = json.loads(marl(home, "match", snapshot, "heuristic", "--games", str(2 * games), "--env-option",
                        f"landers={landers}", "--seed", "777", "--no-store", "--json"))
    return m["points_for"] / games / landers


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=30.0)
    p.add_argument("--modes", nargs="+", default=["sa", "nops", "fups"])
    p.add_argument("--algo", default="ppo")
    p.add_argument("--games", type=int, default=50, help="fresh games for each final figure")
    p.add_argument("--png", type=Path, default=Path("lander_modes.png"))
    p.add_argument("--snapshot-steps", type=int, default=2_000_000, help="game steps between snapshots (the curve)")
    p.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp) / "league"
        results = {}
        for mode in args.modes:
            r = train(home, mode, args.minutes, args.algo, args.snapshot_steps)
            finals = [f["snapshot"] for f in r["final"]]
            team = finals[0].rsplit("-", 1)[0] if mode == "nops" else finals[0]  # nops: the team flies together
            final = fly(home, team, 2, args.games)
            best = best_of(home, mode)
            best_return = fly(home, best, 2, args.games) if best != team else final
            results[mode] = {"curve": curve(home, mode), "final": final, "report": r, "snapshot": team,
                             "best": best, "best_return": best_return}
            print(f"{mode}: {r['steps']:,} steps in {r['wall'] / 60:.1f} min ({r['steps_per_second']:,} steps/s), "
                  f"peak memory {r['peak_mb']:,.0f} MB; final {team}: mean return per lander {final:.1f}, the run's "
                  f"best ({best}) {best_return:.1f}, over {args.games} fresh games")
            for step, sec, ret in results[mode]["curve"]:
                print(f"    step {step:>10,}  {sec / 60:5.1f} min  mean return per lander {ret:8.1f}")
        if "fups" in results:
            snap = results["fups"]["best"]
            print(f"{snap} (trained with 2 landers) flown with M landers, mean return per lander over "
                  f"{args.games} games:")
            for m in (1, 2, 3, 4):
                print(f"    M = {m}: {fly(home, snap, m, args.games):8.1f}")
        _plot(results, args.png)
        print(f"plot: {args.png}")
        for mode, f in results.items():
            ok = f["final"] >= 200 and args.minutes <= 30
            print(f"target: {mode} {args.algo}'s final snapshot scores a mean return per lander >= 200 within 30 "
                  f"minutes: {f['snapshot']} {f['final']:.1f} (the run's best, {f['best']}, {f['best_return']:.1f}) "
                  f"over {args.games} fresh games -> {'PASS' if ok else 'FAIL'}")


def _plot(results: dict, path: Path) -> None:
    """Mean return per lander of every snapshot against game steps (left) and wall time (right), one line a mode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_steps, by_time) = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for mode, r in results.items():
        pts = r["curve"]
        by_steps.plot([step / 1e6 for step, _, _ in pts], [v for _, _, v in pts], marker="o", label=mode)
        by_time.plot([sec / 60 for _, sec, _ in pts], [v for _, _, v in pts], marker="o", label=mode)
    for ax, label in ((by_steps, "game steps (millions)"), (by_time, "wall time (minutes)")):
        ax.axhline(200, color="grey", linestyle=":", label="200 (solved)")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    by_steps.set_ylabel("mean return per lander")
    by_steps.legend()
    fig.suptitle("lander, 2 landers: control modes (PPO)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
