"""Issue 15's figures for the tennis game: what the README's default tennis run learns in its budget.

For each algorithm (SAC, the default, then PPO) it trains `marl train tennis --agents 2 --algo ALGO --minutes M`
as a user types it (the game's own training defaults: `marl envs tennis`), then prints

* the Elo of every snapshot of the run against game steps, on the seed's convention (the serve bot fixed at 1200);
* how often the final snapshot returns the serve bot's randomized serves legally (serve_mode velocity and spin:
  of the serves that landed legally on its half, the share it sent back onto the bot's half; the target counts
  both modes together), and why the others were lost (not_returned: never touched);
* how many hits (serves included) a point of the final snapshot against itself lasts on average, and why: how
  many of its tosses it strikes, how many serves and returns land legally, how many rallies the game's time limit
  cut (a rally that never ends is counted as one point of the hits it lasted);

and finally SAC's final snapshot meets, in 200-game matches, PPO's final one (equal time) and PPO's snapshot at
SAC's steps (equal steps); seed 002 found SAC stronger.
Targets (issue 15): within 30 minutes on 2 cores the final snapshot returns at least 50% of randomized serves
legally, and self-play rallies average at least 4 hits.

Run: python benchmarks/tennis_skill.py [--minutes 30] [--algos sac ppo] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from selfplay_cli.envs import get_env
from selfplay_cli.envs.tennis.config import LIVE_OPTIONS, MISSED_SERVE, REASON_NAMES
from selfplay_cli.league.store import League
from selfplay_cli.players.load import load_player


def marl(home: Path, *args: str) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="140", SDL_VIDEODRIVER="dummy")
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    return out.stdout


def train(home: Path, algo: str, minutes: float, extra: list[str]) -> dict:
    t0 = time.perf_counter()
    report = json.loads(marl(home, "train", "tennis", "--agents", "2", "--algo", algo, "--minutes", str(minutes),
                             "--run", algo, "--quiet", "--json", *extra))
    report["wall"] = time.perf_counter() - t0
    return report


def policy(home: Path, name: str):
    league = League.open(home=home, readonly=True)
    from selfplay_cli.ratings.names import resolve

    return load_player(league, resolve(league, name, "tennis"), seed=1)


def rules_of(home: Path, run: str) -> dict:
    """The run's game options that change the play (its serve rule, the air...): not the shaping rewards, the bat
    size its curriculum drives, nor the serve bot's mode, which the measurements set."""
    options = json.loads((home / "runs" / run / "config.json").read_text()).get("env_options", {})
    return {k: v for k, v in options.items() if k not in (*LIVE_OPTIONS, "serve_mode")}


def serve_returns(home: Path, snapshot: str, mode: str, serves: int = 400, n: int = 64,
                  seed: int = 11, rules: dict | None = None) -> tuple[int, int, Counter]:
    """(returned legally, serves landed legally, why the others were lost) of the serve bot's serves
    (``serve_mode``) to ``snapshot`` under the game options ``rules``; the snapshot plays seat 0 in half the games
    and seat 1 in the others. Each game measures the bot's first serve (a new game follows once it is decided)."""
    spec = get_env("tennis")
    cfg = spec.config(**{**(rules or {}), "serve_mode": mode})
    core = spec.make_core(n, cfg)
    bot = spec.bots["serve-bot"].rule_for(cfg)
    rng = np.random.default_rng(seed)
    me = np.arange(n) % 2  # the snapshot's seat in each game
    rows = np.arange(n)
    core.reset(np.arange(n), seed * 100_000 + np.arange(n))
    player = policy(home, snapshot)
    pending = np.zeros(n, dtype=bool)
    returned = landed = 0
    lost: Counter = Counter()
    next_seed = n
    while landed < serves or pending.any():  # then the serves in flight are decided too
        obs = core.observe()
        mine = player.act(obs[me, rows])
        theirs = bot(obs[1 - me, rows], rng)
        actions = [np.where((me == s)[:, None], mine, theirs).astype(np.float32) for s in (0, 1)]
        before = (core.serves_in[1 - me, rows].copy(), core.returns_in[me, rows].copy(), core.score.sum(axis=0))
        core.step(actions)
        served = (core.serves_in[1 - me, rows] > before[0]) & (landed < serves)
        back = (core.returns_in[me, rows] > before[1]) & pending
        landed += int(served.sum())
        returned += int(back.sum())
        pending = (pending & ~back) | served
        ended = core.score.sum(axis=0) > before[2]  # a point ended: its serve was returned or not
        lost.update(REASON_NAMES[r] for r in core.reason[pending & ended])
        decided = back | (pending & ended)
        pending &= ~ended
        # A game whose serve is decided is done with (what follows cannot change it: two players who never miss
        # would rally to the time limit), and so is one where the snapshot is to serve: a new game, until the bot
        # serves first
        done = decided | core.terminated | core.truncated | (core.tossing & (core.server == me))
        while done.any():
            g = np.flatnonzero(done)
            core.reset(g, seed * 100_000 + next_seed + np.arange(len(g)))
            next_seed += len(g)
            pending[g] = False
            done = core.tossing & (core.server == me)
    return returned, landed, lost


def self_play(home: Path, snapshot: str, points: int = 400, n: int = 64, seed: int = 12,
              rules: dict | None = None, max_games: int = 256) -> dict[str, int]:
    """``snapshot`` playing itself (game options ``rules``) until ``points`` points are over, or ``max_games`` games
    have been played: points, points lost by a missed toss, rallies cut by the game's time limit (each counted as a
    point that lasted at least its hits: two players who never miss would otherwise never finish a point), serves
    struck, serves landed legally, returns, returns landed legally (hits = serves + returns)."""
    spec = get_env("tennis")
    core = spec.make_core(n, spec.config(**(rules or {})))
    core.reset(np.arange(n), seed * 100_000 + np.arange(n))
    player = policy(home, snapshot)
    counts = dict.fromkeys(("points", "missed", "cut", "games", "serves", "serves_in", "returns", "returns_in"), 0)
    next_seed = n
    while counts["points"] < points and counts["games"] < max_games:
        obs = core.observe()
        actions = [player.act(obs[s]).astype(np.float32) for s in (0, 1)]
        before = {key: getattr(core, key).sum() for key in ("serves", "serves_in", "returns", "returns_in")}
        score = core.score.sum(axis=0)
        core.step(actions)
        for key, value in before.items():  # before a reset (which zeroes the counters)
            counts[key] += int(getattr(core, key).sum() - value)
        ended = core.score.sum(axis=0) > score
        counts["points"] += int(ended.sum())
        counts["missed"] += int((ended & (core.reason == MISSED_SERVE)).sum())
        cut = core.truncated & ~ended & ~core.tossing  # a rally the time limit ended (not a toss in the air)
        counts["cut"] += int(cut.sum())
        counts["points"] += int(cut.sum())
        done = np.flatnonzero(core.terminated | core.truncated)
        if len(done):
            counts["games"] += len(done)
            core.reset(done, seed * 100_000 + next_seed + np.arange(len(done)))
            next_seed += len(done)
    return counts


def elo_curve(home: Path, run: str) -> list[tuple[int, str, float, float, float]]:
    rows = json.loads(marl(home, "league", "ladder", "--env", "tennis", "--run", run, "--anchor", "serve-bot=1200",
                           "--json"))
    return sorted((int(r["step"]), r["policy"], r["elo"], r["ci_low"], r["ci_high"]) for r in rows
                  if r["kind"] == "snapshot" and r.get("elo") is not None)


def main() -> None:
    sys.stdout.reconfigure(line_buffering=True)  # each figure as it is measured, also into a file or a pipe
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=30.0)
    p.add_argument("--algos", nargs="+", default=["sac", "ppo"])
    p.add_argument("--games", type=int, default=200, help="games of the SAC vs PPO match")
    p.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    p.add_argument("train_args", nargs="*", help="extra `marl train` arguments (after --)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp) / "league"
        finals: dict[str, str] = {}
        curves: dict[str, list] = {}
        verdicts = []
        for algo in args.algos:
            r = train(home, algo, args.minutes, args.train_args)
            final = r["final"][0]["snapshot"]
            finals[algo] = final
            print(f"{algo}: {r['steps']:,} game steps in {r['wall'] / 60:.1f} min ({r['steps_per_second']:,} steps/s); "
                  f"final snapshot {final}")
            print("    Elo against steps (serve-bot = 1200, 95% interval):")
            curves[algo] = elo_curve(home, algo)
            for step, name, elo, lo, hi in curves[algo]:
                print(f"    {step:>12,}  {elo:7.1f}  [{lo:7.1f} .. {hi:7.1f}]  {name}")
            rules = rules_of(home, algo)
            if rules:
                print(f"    measured under the run's game options {rules}")
            back_all = landed_all = 0
            for mode in ("velocity", "spin"):
                back, landed, lost = serve_returns(home, final, mode, rules=rules)
                back_all, landed_all = back_all + back, landed_all + landed
                why = ", ".join(f"{k} {v}" for k, v in lost.most_common())
                print(f"    returns of the serve bot's {mode} serves: {back} of {landed} legal serves "
                      f"({back / max(landed, 1):.1%}); the others lost by: {why or '-'}")
            share = back_all / max(landed_all, 1)
            c = self_play(home, final, rules=rules)
            hits = (c["serves"] + c["returns"]) / max(c["points"], 1)
            print(f"    self-play: {hits:.2f} hits per point (serve included) over {c['points']} points "
                  f"({c['games']} games finished): {c['missed']} tosses missed, {c['cut']} rallies cut by the "
                  f"2-minute time limit (counted as points), {c['serves']} serves struck, {c['serves_in']} landed "
                  f"legally; {c['returns']} returns, {c['returns_in']} landed legally")
            ok = share >= 0.5 and hits >= 4 and args.minutes <= 30
            verdicts.append(f"{algo}: returns {share:.1%} of randomized serves (>= 50%), rallies "
                            f"{hits:.2f} hits (>= 4) within {args.minutes:g} min: {'PASS' if ok else 'FAIL'}")
        if "sac" in finals and "ppo" in finals:
            # equal time (both final snapshots), then equal game steps (PPO's snapshot nearest SAC's steps, not
            # past them): on a CPU PPO makes several times SAC's steps in the same minutes
            sac_steps = max(step for step, *_ in curves["sac"])
            ppo_at = max((c for c in curves["ppo"] if c[0] <= sac_steps), key=lambda c: c[0])[1]
            for budget, ppo in (("equal time", finals["ppo"]), ("equal steps", ppo_at)):
                m = json.loads(marl(home, "match", finals["sac"], ppo, "--games", str(args.games), "--seed", "5",
                                    "--json"))
                print(f"{budget}: {finals['sac']} vs {ppo} over {m['games']} games: {m['wins']} W {m['draws']} D "
                      f"{m['losses']} L, score {m['score']:.1%}, Elo difference {m['elo']:+.0f} "
                      f"[{m['elo_low']:+.0f} .. {m['elo_high']:+.0f}], points {m['points_for']}-{m['points_against']}")
        for line in verdicts:
            print("target: " + line)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
