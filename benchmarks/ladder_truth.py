"""Does the ladder tell the truth? Its predictions of pairs, checked by 200-game matches (issue 29).

For each seed it trains the README's default run (`marl train pong --agents 2`, its gauntlets and playoff as a user
gets them), takes the ladder's forecaster (`marl league predict`: the fitted difference with its uncertainty, how far
the league's pairs scatter around their ratings, the pair's own games), predicts the score of every pair of the run's
snapshots and the scripted players over 200 games with a 95% interval, then plays each pair 200 fresh games (not
stored) and counts how often the measured score fell inside. Target: at least 90% for the 95% intervals. It also
checks the run's best: is it separated, and does a 200-game match against the next agree?

The same check runs on simulated leagues drawn from the model itself (a run's schedule of gauntlets, its ratings
rising with the steps), with and without pairs that scatter around their ratings (rock-paper-scissors between
snapshots), so the real figure can be read against what the method gives where the model holds.

Run: python benchmarks/ladder_truth.py [--seeds 0 1] [--games 200] [--pairs N] [--keep DIR] [--simulated 20]
     [--out pairs.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from selfplay_cli.league.forecast import Forecaster
from selfplay_cli.league.ladder import ladder
from selfplay_cli.league.store import League
from selfplay_cli.rated.match import load_player, mix_seed, run_match

CHECK_SEEDS = 50_000_000  # the checking matches' seeds: far from every seed a run or a match of marl uses


def train(home: Path, seed: int) -> str:
    """The default run of ``seed`` in ``home`` (kept if it finished there before); its name."""
    if (home / "league.db").exists():
        with League.open(home) as league:
            runs = [r for r in league.list_runs() if r.status == "finished"]
        if runs:
            return runs[0].name
    env = dict(os.environ, MARL_HOME=str(home))
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", "train", "pong", "--agents", "2", "--seed", str(seed),
                          "--quiet", "--json"], env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"marl train failed ({out.returncode}): {out.stderr.strip()}")
    report = json.loads(out.stdout)
    print(f"seed {seed}: run {report['run']} trained and rated in {time.perf_counter() - t0:.0f} s, "
          f"{report['rating_games']} rating games", flush=True)
    return report["run"]


def check_run(home: Path, run: str, games: int, max_pairs: int | None, rng: np.random.Generator) -> list[dict]:
    """Predict, then play, every pair (or ``max_pairs`` of them, drawn at random) of the run's snapshots and the
    scripted players; one record per pair."""
    with League.open(home) as league:
        forecast = Forecaster.of_league(league, "pong")
        rows = {r.policy: r for r in ladder(league, "pong")}
        players = [p for p in league.players("pong") if p.is_bot or p.run == run]
        last = max(p.step for p in players if not p.is_bot)
        finals = {p.id for p in players if not p.is_bot and p.step == last}
        pairs = list(itertools.combinations(players, 2))
        if max_pairs is not None and len(pairs) > max_pairs:
            pairs = [pairs[i] for i in sorted(rng.choice(len(pairs), max_pairs, replace=False))]
        out = []
        for k, (a, b) in enumerate(pairs):
            pred = forecast.predict(a.full_name, b.full_name, games)
            first = CHECK_SEEDS + 10_000 * k
            pa = load_player(league, a, seed=mix_seed(first, 0))
            pb = load_player(league, b, seed=mix_seed(first, 1))
            r = run_match(pa, pb, games=games, first_seed=first)
            score = (r.wins + 0.5 * r.draws) / max(r.wins + r.draws + r.losses, 1)
            met_points, met = forecast.met(a.full_name, b.full_name)
            out.append({"a": a.full_name, "b": b.full_name, "final": a.id in finals or b.id in finals,
                        "measured_wdl": [r.wins, r.draws, r.losses], "predicted": pred.score, "low": pred.low,
                        "high": pred.high, "measured": score, "held": pred.holds(score), "met": met,
                        "ladder_diff": rows[a.full_name].elo - rows[b.full_name].elo})
            if not out[-1]["held"]:
                print(f"  did not hold: {a.full_name} vs {b.full_name}: predicted {100 * pred.score:.1f}% "
                      f"[{100 * pred.low:.1f}, {100 * pred.high:.1f}], measured {100 * score:.1f}% "
                      f"(met before: {met})", flush=True)
        print(f"  pairs' spread around their ratings (fitted from the ledger): {forecast.spread:.0f} Elo")
        best = next((r for r in rows.values() if r.best and r.run == run), None)
        if best is not None and best.best_margin is not None:
            m = best.best_margin
            b_row = next(p for p in players if p.full_name == m.over)
            a_row = next(p for p in players if p.full_name == best.policy)
            r = run_match(load_player(league, a_row, seed=1), load_player(league, b_row, seed=2), games=games,
                          first_seed=CHECK_SEEDS - 10_000)
            s = r.stats
            verdict = "separated" if m.separated else f"tied with {', '.join(best.tied)}"
            print(f"  best: {best.policy} ({verdict}), ladder {m.elo:+.0f} [{m.low:+.0f}, {m.high:+.0f}] over "
                  f"{m.over}; 200 games: {100 * s.score:.1f}%, Elo {s.elo:+.0f} [{s.elo_low:+.0f}, "
                  f"{s.elo_high:+.0f}]: the ladder's order " + ("held" if (s.score >= 0.5) == (m.elo >= 0) or
                                                                  not m.separated else "DID NOT hold"), flush=True)
    return out


def summary(label: str, records: list[dict]) -> None:
    def rate(rs: list[dict]) -> str:
        return f"{sum(r['held'] for r in rs)}/{len(rs)} = {100 * np.mean([r['held'] for r in rs]):.1f}%" if rs else "-"

    informative = [r for r in records if 0.05 < r["predicted"] < 0.95]
    widths = [r["high"] - r["low"] for r in informative]
    print(f"{label}: 95% predictions held for {rate(records)} of pairs; where the outcome was open (predicted "
          f"5-95%) {rate(informative)} (median width {100 * np.median(widths) if widths else 0:.0f} points); "
          f"pairs that met before {rate([r for r in records if r['met']])}, never met "
          f"{rate([r for r in records if not r['met']])}")


def _expected(d: np.ndarray | float) -> np.ndarray:
    return 1.0 / (1.0 + 10.0 ** (-np.asarray(d) / 400.0))


def simulated(rng: np.random.Generator, tau: float, games: int, moments: int = 7, per_pair: int = 8) -> list[dict]:
    """One league drawn from the model: two learners whose ratings rise with the step, two bots, the run's schedule
    (each moment against its predecessors, the other learner, the best so far, two older snapshots and the bots,
    ``per_pair`` games each; the finals 32 against the bots), pairs scattered around their ratings by ``tau``; then
    every pair predicted and checked by ``games`` simulated games."""
    bots = [1000.0, 1000.0 + rng.uniform(300, 600)]
    true = list(bots)
    names = ["random", "cpu"]
    for t in range(moments):
        for side in ("left", "right"):
            true.append(900.0 + 250.0 * t + rng.normal(0, 80))
            names.append(f"s{t}-{side}")
    n = len(names)
    effect = np.triu(rng.normal(0.0, tau, (n, n)), 1) if tau else np.zeros((n, n))
    effect = effect - effect.T
    p = _expected(np.subtract.outer(true, true) + effect)
    a, b, s = [], [], []

    def play(i: int, j: int, k: int) -> None:
        wins = rng.random(k) < p[i, j]
        a.extend([i] * k)
        b.extend([j] * k)
        s.extend(wins.astype(float).tolist())

    for t in range(moments):
        new = [2 + 2 * t, 3 + 2 * t]
        older = list(range(2, 2 + 2 * t))
        final = t == moments - 1
        for i in new:
            opponents = set(older[-2:]) | {x for x in new if x != i}
            if older:
                opponents |= {max(older, key=lambda x: true[x])}
                opponents |= {older[k] for k in np.linspace(0, len(older) - 1, 2).round().astype(int)}
            for j in sorted(opponents):
                play(i, j, per_pair)
            for j in (0, 1):
                play(i, j, 32 if final else per_pair)
    f = Forecaster.of_games(names, np.array(a), np.array(b), np.array(s), anchor="random")
    out = []
    for i in range(n):
        for j in range(i + 1, n):
            pred = f.predict(names[i], names[j], games)
            score = rng.binomial(games, p[i, j]) / games
            out.append({"predicted": pred.score, "low": pred.low, "high": pred.high, "measured": score,
                        "held": pred.holds(score), "met": f.met(names[i], names[j])[1]})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1])
    ap.add_argument("--games", type=int, default=200)
    ap.add_argument("--pairs", type=int, default=None, help="pairs to check per run (default: all)")
    ap.add_argument("--keep", type=Path, help="folder of the runs' leagues (kept; a finished run is reused)")
    ap.add_argument("--simulated", type=int, default=20, help="simulated leagues per spread")
    ap.add_argument("--out", type=Path, help="write every checked pair (prediction and measured score) as JSON")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        real: list[dict] = []
        for seed in args.seeds:
            home = root / f"seed{seed}"
            run = train(home, seed)
            records = check_run(home, run, args.games, args.pairs, rng)
            summary(f"seed {seed} ({run})", records)
            real += records
        if args.seeds:
            summary("all runs", real)
            summary("all runs, pairs with a run's final snapshot", [r for r in real if r["final"]])
        if args.out:
            args.out.write_text(json.dumps(real, indent=1))
    for tau in (0.0, 150.0):
        sim = [r for _ in range(args.simulated) for r in simulated(rng, tau, args.games)]
        summary(f"simulated leagues ({args.simulated}, pairs' true spread {tau:.0f} Elo)", sim)


if __name__ == "__main__":
    main()
