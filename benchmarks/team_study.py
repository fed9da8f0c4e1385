"""Seed 001's team-size study, as `marl study team-size` runs it, on pursuit (PettingZoo SISL) and on the lander;
and the team critics (MAPPO, MA-POCA) against PPO FuPS on the lander.

Parts (``--parts``, default all three):

- ``pursuit``: ``marl study team-size pettingzoo.sisl.pursuit_v5 --size-option n_pursuers --kind cooperative`` on a
  small grid (8x8, 5 evaders, 100 steps a game), teams of 2, 3 and 4 pursuers (FuPS), each flown with 1 to 6, each
  adapted to the other sizes; ``--minutes`` per run (5: 9 runs, about an hour on 2 cores).
- ``lander``: ``marl study team-size lander``, teams of 1, 2 and 3 landers (FuPS, the game's PPO defaults), flown
  with 1 to 4; ``--minutes`` per run.
- ``critics``: ``marl train lander --agents 2 --sharing fups --algo ALGO --minutes M`` for ppo, mappo and poca, each
  final snapshot flown over ``--games`` fresh games (mean return per lander, the most likely action).

Each study prints its three tables (returns by trained x flown size, adapted vs fresh, each run's wall time, CPU use
and peak memory); its report and PNGs are copied to ``--docs`` (``docs/team-study-<part>.json``,
``-returns.png``, ``-curves.png``). A study killed midway goes on when the script is run again with the same
``--keep`` folder.

Run: python benchmarks/team_study.py [--parts pursuit lander critics] [--minutes 5] [--critic-minutes 30]
     [--critic-algos ppo mappo poca]
     [--keep DIR] [--docs docs]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PURSUIT = ["pettingzoo.sisl.pursuit_v5", "--size-option", "n_pursuers", "--kind", "cooperative",
           "--env-option", "x_size=8", "--env-option", "y_size=8", "--env-option", "n_evaders=5",
           "--env-option", "max_cycles=100", "--train", "2,3,4", "--eval", "1-6", "--games", "16"]
LANDER = ["lander", "--train", "1,2,3", "--eval", "1-4", "--vs", "heuristic"]


def marl(home: Path, *args: str, capture: bool = True) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="160", SDL_VIDEODRIVER="dummy")
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, text=True,
                         capture_output=capture)
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {(out.stderr or '').strip()}")
    return out.stdout or ""


def study(home: Path, part: str, args: list[str], minutes: float, docs: Path) -> None:
    name = f"bench-{part}"
    common = ["study", "team-size", *args, "--minutes", f"{minutes:g}", "--sharing", "fups", "--name", name]
    print(f"== {part}: marl {' '.join(common)}", flush=True)
    report = json.loads(marl(home, *common, "--json"))
    print(marl(home, *common, "--quiet"), flush=True)  # the same study: its tables, nothing trained again
    docs.mkdir(parents=True, exist_ok=True)
    (docs / f"team-study-{part}.json").write_text(json.dumps(report, indent=1))
    for key, path in (report.get("plots") or {}).items():
        shutil.copy(path, docs / f"team-study-{part}-{key}.png")
    print(f"{part}: report and PNGs in {docs}/team-study-{part}*", flush=True)


def critics(home: Path, minutes: float, games: int, algos: list[str]) -> None:
    print(f"== critics: marl train lander --agents 2 --sharing fups --algo ALGO --minutes {minutes:g}", flush=True)
    rows = []
    for algo in algos:
        run = f"critic-{algo}"
        r = json.loads(marl(home, "train", "lander", "--agents", "2", "--sharing", "fups", "--algo", algo,
                            "--minutes", f"{minutes:g}", "--run", run, "--quiet", "--json"))
        final = r["final"][0]["snapshot"]
        m = json.loads(marl(home, "match", final, "heuristic", "--games", str(2 * games), "--seed", "777",
                            "--no-store", "--json"))
        per_lander = m["points_for"] / games / 2
        rows.append((algo, r["steps"], r["steps_per_second"], per_lander, final))
        print(f"{algo}: {r['steps']:,} steps; final {final}: mean return per lander {per_lander:.1f} over {games} "
              "fresh games", flush=True)
    print("| algo | game steps | steps/s | final snapshot: mean return per lander |")
    print("|---|---|---|---|")
    for algo, steps, rate, ret, _ in rows:
        print(f"| {algo} | {steps:,} | {rate:,.0f} | {ret:.1f} |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--parts", nargs="+", default=["pursuit", "lander", "critics"],
                   choices=["pursuit", "lander", "critics"])
    p.add_argument("--minutes", type=float, default=5.0, help="minutes per study run")
    p.add_argument("--critic-minutes", type=float, default=30.0, help="minutes per lander critic run")
    p.add_argument("--games", type=int, default=50, help="fresh games for the critics' final figures")
    p.add_argument("--critic-algos", nargs="+", default=["ppo", "mappo", "poca"], choices=["ppo", "mappo", "poca"])
    p.add_argument("--keep", type=Path, help="league folder to keep (and to go on with a study killed midway)")
    p.add_argument("--docs", type=Path, default=ROOT / "docs")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp) / "league"
        if "pursuit" in args.parts:
            study(home, "pursuit", PURSUIT, args.minutes, args.docs)
        if "lander" in args.parts:
            study(home, "lander", LANDER, args.minutes, args.docs)
        if "critics" in args.parts:
            critics(home, args.critic_minutes, args.games, args.critic_algos)


if __name__ == "__main__":
    from itertools import takewhile

    from results_file import recorded

    after = sys.argv[sys.argv.index("--parts") + 1:] if "--parts" in sys.argv else []
    parts = list(takewhile(lambda a: not a.startswith("-"), after))  # (a study of some parts: a file of its own)
    with recorded("_".join(["team_study", *parts])):
        main()
