"""Does the ladder tell the truth, on every game? Each of its claims about a pair, checked by a 200-game match.

For each game it runs README's own command for that game (kept if a finished run is in ``--keep``), reads what the
ladder and the run's summary claim, and plays each pair those claims are about 200 fresh games (not stored):

* **order**: every pair of the run's snapshots and the game's scripted players whose order the ladder claims (one
  above the other beyond doubt: what its ranks and tier boundaries say). The claim survives when the 200-game match
  goes the same way (a score above 50%);
* **margins**: every "A over B by +M [lo, hi] (...; 200 games would measure X to Y)" the ladder prints under its
  table (the top over the next, each run's best over the run's next best; the run's summary prints the same one)
  and each row's margin over the next row in its JSON: held when the 200-game Elo difference lies inside the range
  the margin says such a match measures, X to Y (a 0% or 100% result, whose Elo is only a bound, holds when the
  range reaches the bound). Reported beside it: how often [lo, hi], the interval of the pair's *expected*
  difference, holds the match's noisy measure of it;
* **summary**: each final snapshot against each scripted player, whose scores the run's summary prints;
* **predictions**: for every pair above, what ``marl league predict`` says of a 200-game match (95% interval), held
  when the measured score lies inside. Reported: the share held, and the median width of the open predictions (5 to
  95%) of pairs that met in rated games and of pairs that never met.

The same checks run on simulated leagues drawn from a run-like schedule (each snapshot against its predecessor, the
other learner, the best, older ones and two bots, which meet each other once; 8 games a pair, up to 32 where the
pair's record is still imprecise, as training's gauntlets; 64 for the finals against the bots), with pairs
scattered around their ratings by 0, 150 and 300 Elo (rock-paper-scissors between snapshots), where the truth is
known.

Games (README's commands): pong (the main job), tennis (against serve-bot too), the lander (FuPS teams, against the
heuristic), Kuhn poker (scored in chips), connect four (a PettingZoo AEC board game) and three-player Leduc poker (a
free-for-all). Targets per game: at least 90% of the 95% predictions held; median width of open predictions at most
30 points where the pair met and 45 where it did not; at least 90% of margins held.

Run: python benchmarks/ladder_truth.py [--games pong tennis ...] [--keep DIR] [--checks 200] [--max-pairs N]
     [--budget GAME=ARGS] [--simulated 20] [--parallel 1]

Writes ``benchmarks/results/ladder_truth.json``: what it printed, when, where and on what code, with the table and
every checked pair as data (the league page renders its table, the misses and the targets from them).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfplay_cli.envs import admit
from selfplay_cli.evaluation.gauntlet import prediction_width
from selfplay_cli.evaluation.match import run_match
from selfplay_cli.evaluation.match_jobs import MatchJob
from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.league.variants import variant_key, variant_options
from selfplay_cli.players.snapshots import run_options
from selfplay_cli.ratings.fit import fit_table
from selfplay_cli.ratings.forecast import Forecaster
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.ratings.ladder_rows import Margin
from selfplay_cli.stats.elo import score_to_elo

CHECK_SEEDS = 50_000_000  # the checking matches' seeds: far from every seed a run or a match of marl uses

GAMES: dict[str, list[str]] = {  # README's command for each game (after `marl train`)
    "pong": ["pong", "--agents", "2"],
    "tennis": ["tennis", "--agents", "2", "--minutes", "30"],
    "lander": ["lander", "--agents", "2", "--sharing", "fups"],
    "kuhn": ["openspiel:kuhn_poker", "--agents", "1", "--bots", "random=1", "--steps", "40000", "--games", "16"],
    "connect4": ["pettingzoo.classic.connect_four_v3", "--sharing", "fups", "--league-games", "0.5", "--bots",
                 "random=0.5", "--steps", "2000000"],
    "leduc3": ["openspiel:leduc_poker(players=3)", "--steps", "200000"],
}


@dataclass
class Claim:
    """A pair the ladder or the summary says something about (``a`` and ``b`` by full name) and what it says."""

    a: str
    b: str
    kinds: set[str] = field(default_factory=set)  # order, margin, summary
    margins: list[tuple[str, Margin, float]] = field(default_factory=list)  # (where, margin, sign: +1 as a over b)


def train(home: Path, args: list[str], seed: int) -> tuple[str, dict]:
    """README's run of a game in ``home`` (kept if it finished there before): its name and its JSON report."""
    report = home / "train.json"
    if report.exists():
        data = json.loads(report.read_text())
        return data["run"], data
    home.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, MARL_HOME=str(home), SDL_VIDEODRIVER="dummy")
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", "train", *args, "--seed", str(seed), "--quiet",
                          "--json"], env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"marl train {shlex.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    data = json.loads(out.stdout)
    tmp = report.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data))
    tmp.replace(report)  # a run killed before this line is trained again, whole
    print(f"  marl train {shlex.join(args)}: run {data['run']} in {time.perf_counter() - t0:.0f} s, "
          f"{data['steps']:,} steps, {data['rating_games']} rating games", flush=True)
    return data["run"], data


def claims_of(league: League, env: str, variant: str, run: str, report: dict,
              forecast: Forecaster) -> dict[frozenset[str], Claim]:
    """Every pair the ladder and the run's summary make a claim about, with what they claim."""
    rows = ladder(league, env, variant=variant)
    mine = [r for r in rows if (r.run == run or r.kind == "bot") and r.copy_of is None and r.tier is not None]
    names = [r.policy for r in mine]
    out: dict[frozenset[str], Claim] = {}

    def claim(a: str, b: str, kind: str, margin: tuple[str, Margin] | None = None) -> None:
        c = out.setdefault(frozenset((a, b)), Claim(a, b))
        c.kinds.add(kind)
        if margin is not None:  # the claim as the pair's first names it
            c.margins.append((*margin, 1.0 if (c.a, c.b) == (a, b) else -1.0))

    idx = [forecast.names.index(forecast.aliases.get(n, n)) for n in names]
    below = forecast.model.below(idx)
    for i, j in itertools.permutations(range(len(names)), 2):
        if below[i, j] < 0.025:  # i above j beyond doubt: a rank, a tier boundary
            claim(names[i], names[j], "order")
    ranked = [r for r in rows if r.tier is not None and r.copy_of is None]
    if len(ranked) >= 2 and ranked[0].margin is not None:  # "top: A, +M [lo, hi] Elo over B"
        claim(ranked[0].policy, ranked[0].margin.over, "margin", ("top", ranked[0].margin))
    for r in rows:
        if r.best and r.run == run and r.best_margin is not None:  # "best of RUN: A, +M [lo, hi] over B"
            claim(r.policy, r.best_margin.over, "margin", ("best", r.best_margin))
    for r in mine:  # each row's margin over the next (JSON)
        if r.margin is not None and r.margin.over in names:
            claim(r.policy, r.margin.over, "row", ("row", r.margin))
    for final in report.get("final", []):  # the summary: each final snapshot against each scripted player
        for bot in final.get("vs", {}):
            if final["snapshot"] in names and bot in names:
                claim(final["snapshot"], bot, "summary")
    return out


def measured(round_points: list[list[float]]) -> tuple[float, float, int]:
    """A's score over the match (points per result), its Elo difference, and whether that is only a bound: a 0% or
    100% score (+1 above, -1 below, 0 an estimate) says the difference is beyond the one it would take to lose (win)
    every result with 2.5% chance, ``E(d)^n = 0.025``; that bound is the Elo returned."""
    pts = np.array([x for p in round_points for x in p])
    n = pts.size
    score = float(pts.mean()) if n else 0.5
    if n and score >= 1.0:
        return score, score_to_elo(0.025 ** (1.0 / n)), 1
    if n and score <= 0.0:
        return score, -score_to_elo(0.025 ** (1.0 / n)), -1
    return score, score_to_elo(score), 0


def margin_held(low: float, high: float, elo: float, bound: int) -> bool:
    """Whether an interval holds the 200-game difference (or, for a 0% or 100% score, reaches its bound)."""
    return bool(high >= elo if bound > 0 else low <= elo if bound < 0 else low <= elo <= high)


def check_margin(where: str, m: Margin, sign: float, elo: float, bound: int) -> dict:
    """One printed (or JSON) margin against the measured difference, oriented by ``sign``: ``held``, the range it
    says a 200-game match measures holds it; ``held_expected``, its interval of the expected difference does."""
    lo, hi = (m.low, m.high) if sign > 0 else (-m.high, -m.low)
    match = m.match or (None, None)  # (a flagged bound's margin has no range: unbounded)
    m_lo, m_hi = (match[0], match[1]) if sign > 0 else (
        None if match[1] is None else -match[1], None if match[0] is None else -match[0])
    m_lo, m_hi = -math.inf if m_lo is None else m_lo, math.inf if m_hi is None else m_hi
    return {"where": where, "elo": sign * m.elo, "low": lo, "high": hi, "match_low": m_lo, "match_high": m_hi,
            "held": margin_held(m_lo, m_hi, elo, bound), "held_expected": margin_held(lo, hi, elo, bound)}


def check_game(name: str, home: Path, trained: Future, games: int, max_pairs: int | None,
               rng: np.random.Generator) -> list[dict]:
    run, report = trained.result()
    records = []
    with League.open(home) as league:
        env = league.roster.get_run(run).env
        variant = variant_key(env, run_options(league, run))
        forecast = Forecaster.of_league(league, env, variant=variant)
        claims = list(claims_of(league, env, variant, run, report, forecast).values())
        if max_pairs is not None and len(claims) > max_pairs:  # the margins and the summary first, then a draw
            first = [c for c in claims if c.kinds - {"order"}]
            rest = [c for c in claims if not c.kinds - {"order"}]
            pick = rng.choice(len(rest), max(max_pairs - len(first), 0), replace=False) if rest else []
            claims = first + [rest[i] for i in sorted(pick)]
        rows = {p.full_name: p for p in league.roster.players(env=env, include_removed=True)}
        options = variant_options(variant)
        print(f"{name}: run {run} ({env}{', ' + variant if variant else ''}), {report['rating_games']} rating games; "
              f"spread around the ratings {forecast.spread:.0f} Elo; {len(claims)} pairs claimed about", flush=True)
        t0 = time.perf_counter()
        for k, c in enumerate(claims):
            pred = forecast.predict(c.a, c.b, games)
            _, met = forecast.met(c.a, c.b)
            first_seed = CHECK_SEEDS + 10_000 * k
            pa, pb, _ = MatchJob((rows[c.a],), rows[c.b]).load(league, first_seed, "cpu")
            r = run_match(pa[0], pb, games=games, first_seed=first_seed, env_options=options)
            score, elo, bound = measured(r.round_points)
            margins = [check_margin(where, m, sign, elo, bound) for where, m, sign in c.margins]
            for m in margins:
                if not m["held"]:
                    print(f"  margin did not hold: {c.a} over {c.b} {m['elo']:+.0f} [{m['low']:+.0f}, "
                          f"{m['high']:+.0f}], 200 games would measure {m['match_low']:+.0f} to "
                          f"{m['match_high']:+.0f} ({m['where']}); {r.n_results} results: {100 * score:.1f}%, "
                          f"{elo:+.0f} Elo", flush=True)
            rec = {"game": name, "a": c.a, "b": c.b, "kinds": sorted(c.kinds), "met": met, "results": r.n_results,
                   "predicted": pred.score, "low": pred.low, "high": pred.high, "measured": score,
                   "measured_elo": elo, "held": pred.holds(score), "margins": margins,
                   "order_held": score > 0.5 if "order" in c.kinds else None,
                   "truncated": r.truncated}
            records.append(rec)
            if not rec["held"]:
                print(f"  prediction did not hold: {c.a} vs {c.b}: {100 * pred.score:.1f}% [{100 * pred.low:.1f}, "
                      f"{100 * pred.high:.1f}], measured {100 * score:.1f}% (met before in {met})", flush=True)
            if rec["order_held"] is False:
                print(f"  order did not hold: {c.a} above {c.b}, measured {100 * score:.1f}%", flush=True)
        print(f"  {len(claims)} matches of {games} games in {time.perf_counter() - t0:.0f} s", flush=True)
    return records


def rate(flags: list[bool]) -> str:
    return f"{sum(flags)}/{len(flags)} = {100 * np.mean(flags):.1f}%" if flags else "-"


def summary(label: str, records: list[dict]) -> dict:
    """One game's figures (printed, and returned for the table). The claims a reader meets, the ranks and tiers
    (order), the margins printed under the ladder and in the run's summary, the summary's scores against the bots,
    make the main figures; the JSON's margin of each row over the next is reported beside them."""
    shown = [r for r in records if set(r["kinds"]) - {"row"}]
    held = [r["held"] for r in shown]
    open_ = [r for r in shown if 0.05 < r["predicted"] < 0.95]
    met_w = [100 * (r["high"] - r["low"]) for r in open_ if r["met"]]
    new_w = [100 * (r["high"] - r["low"]) for r in open_ if not r["met"]]
    printed = [m["held"] for r in records for m in r["margins"] if m["where"] != "row"]
    expected = [m["held_expected"] for r in records for m in r["margins"] if m["where"] != "row"]
    rows = [m["held"] for r in records for m in r["margins"] if m["where"] == "row"]
    rows_expected = [m["held_expected"] for r in records for m in r["margins"] if m["where"] == "row"]
    order = [r["order_held"] for r in records if r["order_held"] is not None]
    out = {"label": label, "pairs": len(shown), "held": rate(held),
           "held_share": float(np.mean(held)) if held else None,
           "open_met": len(met_w), "width_met": float(np.median(met_w)) if met_w else None,
           "open_new": len(new_w), "width_new": float(np.median(new_w)) if new_w else None,
           "printed_margins": rate(printed), "row_margins": rate(rows), "order": rate(order),
           "printed_expected": rate(expected), "rows_expected": rate(rows_expected),
           "rows_predictions": rate([r["held"] for r in records if "row" in r["kinds"]])}
    w = (f"median width {out['width_met']:.0f} points of {len(met_w)} that met" if met_w else "none that met")
    w += f", {out['width_new']:.0f} of {len(new_w)} that never met" if new_w else ", none that never met"
    print(f"{label}: predictions held {out['held']}; open predictions: {w}; margins printed under the ladder and in "
          f"the summary held {out['printed_margins']} (their intervals of the expected difference "
          f"{out['printed_expected']}); order claims held {out['order']}; each row's margin over the next (JSON) held "
          f"{out['row_margins']} ({out['rows_expected']}), its pair's prediction {out['rows_predictions']}",
          flush=True)
    return out


def _expected(d: np.ndarray | float) -> np.ndarray:
    return 1.0 / (1.0 + 10.0 ** (-np.asarray(d) / 400.0))


def simulated(rng: np.random.Generator, tau: float, games: int, moments: int = 7, per_pair: int = 8) -> list[dict]:
    """One league drawn from the model: two learners whose ratings rise with the step, two bots, the run's schedule
    (each moment against its predecessors, the other learner, the best so far, two older snapshots and the bots,
    ``per_pair`` games each, more between snapshots whose record is still imprecise; the finals 64 against the bots),
    pairs scattered around their ratings by ``tau``; then every claim checked against ``games`` simulated games."""
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
        """k games of i against j, who play on (doubling, up to 4 times) until their record predicts a 200-game
        match within 30 points, as training's gauntlets do."""
        won = lost = played = 0
        while True:
            wins = rng.random(k - played) < p[i, j]
            a.extend([i] * (k - played))
            b.extend([j] * (k - played))
            s.extend(wins.astype(float).tolist())
            won, played = won + int(wins.sum()), k
            lost = played - won
            if k >= 4 * per_pair or prediction_width(won, 0, lost) <= 0.30:
                return
            k *= 2

    play(0, 1, per_pair)  # the run's first moment: its scripted players meet each other
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
                play(i, j, 64 if final else per_pair)
    f = Forecaster.of_games(names, np.array(a), np.array(b), np.array(s), anchor="random")
    rows = fit_table(names, a, b, s, "random", bootstrap=0)
    below = f.model.below(list(range(n)))
    claims: dict[tuple[int, int], list] = {}
    for i, j in itertools.permutations(range(n), 2):
        if below[i, j] < 0.025:
            claims.setdefault((min(i, j), max(i, j)), []).append(("order", i, j))
    for r in rows:
        if r.margin is not None:
            i, j = names.index(r.policy), names.index(r.margin.over)
            claims.setdefault((min(i, j), max(i, j)), []).append(("margin", i, j, r.margin))
    for i in (n - 2, n - 1):
        for j in (0, 1):
            claims.setdefault((j, i), []).append(("summary", i, j))
    out = []
    for (i, j), said in claims.items():
        pred = f.predict(names[i], names[j], games)
        k = rng.binomial(games, p[i, j])
        score, elo, bound = measured([[1.0] * k + [0.0] * (games - k)])
        margins = [check_margin("row", c[3], 1.0 if c[1] == i else -1.0, elo, bound) for c in said
                   if c[0] == "margin"]
        order = [c for c in said if c[0] == "order"]
        out.append({"kinds": sorted({"row" if c[0] == "margin" else c[0] for c in said}),
                    "predicted": pred.score, "low": pred.low, "high": pred.high, "measured": score,
                    "held": pred.holds(score), "met": f.met(names[i], names[j])[1], "margins": margins,
                    "order_held": ((score > 0.5) == (order[0][1] == i)) if order else None})
    return out


def main(data: dict) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--games", nargs="*", default=list(GAMES), choices=list(GAMES))
    ap.add_argument("--checks", type=int, default=200,
                    help="games of each checking match (the ranges the margins print are for 200)")
    ap.add_argument("--max-pairs", type=int, default=None, help="pairs to check per game (default: all claimed)")
    ap.add_argument("--budget", action="append", default=[], metavar="GAME=ARGS",
                    help="replace the budget of a game's README command, e.g. tennis='--minutes 5'")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, help="folder of the runs' leagues (kept; a finished run is reused)")
    ap.add_argument("--simulated", type=int, default=20, help="simulated leagues per spread")
    ap.add_argument("--parallel", type=int, default=1,
                    help="games' runs trained at once (each a process; a game is checked once its run is done)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    budgets = dict(b.split("=", 1) for b in args.budget)
    table, real = [], []
    print(f"ladder_truth: {time.strftime('%Y-%m-%d %H:%M')}, {platform.node()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}", flush=True)
    if args.parallel < 1:
        raise SystemExit(f"--parallel must be at least 1, not {args.parallel}")
    commands = {}
    for game in args.games:
        cmd = list(GAMES[game])
        admit(cmd[0])  # its game named here, for the ladder and the checking matches (a user's game: connect four)
        if game in budgets:  # the budget flags replaced
            for flag in ("--minutes", "--steps"):
                if flag in cmd:
                    k = cmd.index(flag)
                    del cmd[k:k + 2]
            cmd += shlex.split(budgets[game])
        commands[game] = cmd
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.parallel) as pool:
        root = args.keep or Path(tmp)  # (each run is its own process: the pool's threads only wait on them)
        runs = {game: pool.submit(train, root / game, cmd, args.seed) for game, cmd in commands.items()}
        for game in args.games:
            try:
                records = check_game(game, root / game, runs[game], args.checks, args.max_pairs, rng)
            except LeagueError as e:
                print(f"{game}: {e}", flush=True)
                continue
            table.append(summary(game, records))
            real += records
    for tau in (0.0, 150.0, 300.0) if args.simulated else ():
        sim = [r for _ in range(args.simulated) for r in simulated(rng, tau, args.checks)]
        table.append(summary(f"simulated, spread {tau:.0f}", sim))
    print("\n| game | pairs | 95% predictions held | open, met: median width (pairs) | open, never met | "
          "printed margins held (their expected-difference intervals) | order claims held | row margins (JSON) held "
          "(intervals) |")
    print("|---|---|---|---|---|---|---|---|")
    for t in table:
        wm = f"{t['width_met']:.0f} ({t['open_met']})" if t["width_met"] is not None else "-"
        wn = f"{t['width_new']:.0f} ({t['open_new']})" if t["width_new"] is not None else "-"
        print(f"| {t['label']} | {t['pairs']} | {t['held']} | {wm} | {wn} | {t['printed_margins']} "
              f"({t['printed_expected']}) | {t['order']} | {t['row_margins']} ({t['rows_expected']}) |")
    data.update(table=table, pairs=real)


if __name__ == "__main__":
    from results_file import recorded

    with recorded() as figures:
        main(figures)
