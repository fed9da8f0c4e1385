"""Benchmarks of the league: the Bradley-Terry rating fit, its bootstrap, `marl match`, and the game runner.

Generates 200 players with known ratings and 100,000 random games between them (logistic Elo model
with draws), then times ``fit_bradley_terry`` (best of 3) and ``bootstrap_ci`` with 200 resamples,
and reports the error against the true ratings. Targets: fit < 0.3 s, bootstrap(200) < 30 s.

Then runs the real ``marl match`` (a subprocess, wall clock including start-up) between two network snapshots
(64x64 tanh MLPs, untrained: games of ~6,000 steps) in pong over ``--match-games`` games in a scratch league.
Target (issue 10): 1,000 games in at most 15 s on 2 cores (it was ~26 s).

Then the runner as a gauntlet drives it: ``play()`` with 4 network players (64x64 relu MLPs, the architecture
``marl train`` gives PPO, hand-set to track the ball as the scripted ``cpu`` player does, so they rally as
strong players do: games of 15,000 steps up to the 18,000-step time limit) over ``--runner-games`` games in
seat-swapped pairs of every pairing, all at once. Reported as game steps per second (no target; measured on 2 idle
cores: ~210,000 before issue 10's work, ~430,000 after it, the networks batched in one forward and the game core and
runner trimmed).

Run with ``python benchmarks/ratings.py`` (optional: ``--players``, ``--games``, ``--boot``, ``--seed``,
``--match-games``, ``--runner-games``, ``--only fit|match|runner``).
If scipy happens to be installed, the ML solution is also cross-checked against a generic
optimiser (scipy is not a dependency of the project; the check is skipped without it).
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
from typing import TYPE_CHECKING

import numpy as np

from selfplay_cli.stats.bradley_terry import fit_bradley_terry
from selfplay_cli.stats.elo import NAT_TO_ELO
from selfplay_cli.stats.intervals import bootstrap_ci

if TYPE_CHECKING:
    from selfplay_cli.policies.network import MLPNet

FIT_TARGET_S = 0.3
BOOT_TARGET_S = 30.0
MATCH_TARGET_S = 15.0  # for 1,000 games, start-up included


def simulate(
    n_players: int, n_games: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """True ratings ~ N(1000, 200^2) (player 0 pinned at 1000) and uniformly random pairings.

    Each game: P(win) = E(d) - q/2, P(draw) = q, P(loss) = 1 - E(d) - q/2 with draw rate
    ``q = 0.3 * 4 E(d) (1 - E(d))``, so A's expected score is exactly ``E(d) = 1 / (1 + 10**(-d/400))``.
    """
    rng = np.random.default_rng(seed)
    true = rng.normal(1000.0, 200.0, n_players)
    true[0] = 1000.0
    a = rng.integers(0, n_players, n_games)
    b = (a + rng.integers(1, n_players, n_games)) % n_players
    p = 1.0 / (1.0 + 10.0 ** (-(true[a] - true[b]) / 400.0))
    q = 0.3 * 4.0 * p * (1.0 - p)
    u = rng.random(n_games)
    score = np.where(u < p - q / 2, 1.0, np.where(u < p + q / 2, 0.5, 0.0))
    return a, b, score, true


def scipy_check(a: np.ndarray, b: np.ndarray, s: np.ndarray, n: int, ratings: np.ndarray) -> float | None:
    """Max |difference| (Elo) between our fit and scipy's L-BFGS on the same likelihood, or None."""
    try:
        from scipy.optimize import minimize  # type: ignore[import-not-found, import-untyped]
    except ImportError:
        return None
    w = np.zeros((n, n))
    g = np.zeros((n, n))
    np.add.at(w, (a, b), s)
    np.add.at(w, (b, a), 1.0 - s)
    np.add.at(g, (a, b), 1.0)
    np.add.at(g, (b, a), 1.0)

    def negll(x: np.ndarray) -> tuple[float, np.ndarray]:
        theta = np.concatenate([[0.0], x])
        d = theta[:, None] - theta[None, :]
        p = 1.0 / (1.0 + np.exp(-d))
        value = float(np.sum(w * np.logaddexp(0.0, -d)))
        grad = -np.sum(w - g * p, axis=1)[1:]
        return value, grad

    options = {"gtol": 1e-10, "maxiter": 10000}
    res = minimize(negll, np.zeros(n - 1), jac=True, method="L-BFGS-B", options=options)
    theirs = 1000.0 + np.concatenate([[0.0], res.x]) * NAT_TO_ELO
    return float(np.max(np.abs(theirs - ratings)))


def match_throughput(n_games: int) -> tuple[float, dict]:
    """Wall time of `marl match A B --games n` between two untrained 64x64 network snapshots in pong."""
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, MARL_HOME=str(Path(tmp) / "league"))
        marl = [sys.executable, "-m", "selfplay_cli"]
        for i in (1, 2):
            f = Path(tmp) / f"net{i}.safetensors"
            save_snapshot(f, build_network((8, 6), 3, Arch(), seed=i),
                          SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, run="bench", name=f"net{i}"))
            subprocess.run([*marl, "checkpoint", "import", str(f)], env=env, check=True, capture_output=True)
        t0 = time.perf_counter()
        out = subprocess.run([*marl, "match", "bench/net1", "bench/net2", "--games", str(n_games), "--json"],
                             env=env, check=True, capture_output=True, text=True)
        return time.perf_counter() - t0, json.loads(out.stdout)


def tracker(sharpness: float, seed: int) -> MLPNet:
    """A 64x64 relu MLP that plays as the scripted ``cpu`` player does, a strong player without training: from the
    newest frame, two hidden units carry the ball's height above and below the paddle's centre (pixels), and the
    logits of down and up are ``sharpness`` times them (sampled from, as PPO snapshots play)."""
    import torch

    from selfplay_cli.policies.network import Arch, build_network

    net = build_network((8, 6), 3, Arch(hidden=(64, 64), activation="relu", value_head=True), seed=seed)
    first, second = net.trunk[0], net.trunk[2]
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
        below = torch.zeros(48)
        below[43], below[44] = 200.0, -165.0  # newest frame: ball y and own paddle y, each scaled to [-1, 1]
        first.weight[0], first.weight[1] = below, -below
        second.weight[0, 0] = second.weight[1, 1] = 1.0
        net.action_head.weight[2, 0] = net.action_head.weight[1, 1] = sharpness  # 2: down, 1: up
    return net


def runner_throughput(n_games: int) -> tuple[float, list[int], int]:
    """``play()`` of ``n_games`` games among 4 tracking network players in seat-swapped pairs of every pairing:
    (wall seconds, game lengths, batched steps)."""
    import torch

    from selfplay_cli.play import Game, play
    from selfplay_cli.policies.network import NetworkPolicy

    torch.set_num_threads(1)  # as marl match and the gauntlet run networks
    players = [NetworkPolicy(tracker(s, i), f"tracker{s:g}", "pong", greedy=False, seed=i)
               for i, s in enumerate((0.25, 0.5, 1.0, 2.0))]
    pairs = itertools.cycle(itertools.combinations(range(len(players)), 2))
    games = []
    for seed in range((n_games + 1) // 2):
        a, b = next(pairs)
        games += [Game(seed, (a, b)), Game(seed, (b, a))]
    steps = [0]
    t0 = time.perf_counter()
    results = play("pong", players, games[:n_games], on_step=lambda n: steps.__setitem__(0, steps[0] + 1),
                   record_actions=True)
    return time.perf_counter() - t0, [r.length for r in results], steps[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--players", type=int, default=200)
    parser.add_argument("--games", type=int, default=100_000)
    parser.add_argument("--boot", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--match-games", type=int, default=1000)
    parser.add_argument("--runner-games", type=int, default=200)
    parser.add_argument("--only", choices=("fit", "match", "runner"), help="run one part")
    args = parser.parse_args()
    ok = True
    if args.only in (None, "fit"):
        ok &= ratings_fit(args)
    if args.only in (None, "match"):
        ok &= match_part(args.match_games)
    if args.only in (None, "runner"):
        runner_part(args.runner_games)
    print("targets met" if ok else "TARGETS MISSED")


def ratings_fit(args: argparse.Namespace) -> bool:
    a, b, s, true = simulate(args.players, args.games, args.seed)
    times = []
    fit = None
    for _ in range(3):
        t0 = time.perf_counter()
        fit = fit_bradley_terry(a, b, s, args.players, anchor=0, anchor_rating=1000.0)
        times.append(time.perf_counter() - t0)
    assert fit is not None
    fit_s = min(times)
    err = np.abs(fit.ratings - true)
    flagged = sum(f is not None for f in fit.flags)
    print(f"fit {args.players} players / {args.games} games: {fit_s:.3f} s (target < {FIT_TARGET_S} s)")
    print(f"  newton iterations: {fit.iterations}, converged: {fit.converged}, flagged players: {flagged}")
    print(f"  error vs true ratings: max {err.max():.1f} Elo, mean {err.mean():.1f} Elo")

    t0 = time.perf_counter()
    low, high = bootstrap_ci(a, b, s, args.players, anchor=0, anchor_rating=1000.0, n_boot=args.boot, seed=1)
    boot_s = time.perf_counter() - t0
    covered = np.mean((low[1:] <= true[1:]) & (true[1:] <= high[1:]))
    print(f"bootstrap_ci {args.boot} resamples: {boot_s:.2f} s (target < {BOOT_TARGET_S:.0f} s)")
    print(f"  mean 95% CI width {np.mean(high[1:] - low[1:]):.1f} Elo, true rating covered for {covered:.1%}")

    diff = scipy_check(a, b, s, args.players, fit.ratings)
    if diff is None:
        print("scipy not installed: L-BFGS cross-check skipped")
    else:
        print(f"scipy L-BFGS cross-check: max |difference| {diff:.2e} Elo")
    return fit_s < FIT_TARGET_S and boot_s < BOOT_TARGET_S


def match_part(n_games: int) -> bool:
    wall, rep = match_throughput(n_games)
    points = rep["points_for"] + rep["points_against"]
    print(f"marl match (two 64x64 tanh network snapshots, pong): {rep['games']} games in {wall:.1f} s wall "
          f"({rep['games_per_second']:.1f} games/s while playing, {points} points) "
          f"(target: 1,000 games <= {MATCH_TARGET_S:.0f} s)")
    return wall * 1000 / max(rep["games"], 1) <= MATCH_TARGET_S


def runner_part(n_games: int) -> None:
    wall, lengths, batched = runner_throughput(n_games)
    lengths.sort()
    print(f"runner, 4 tracking network players (64x64 relu), {len(lengths)} games in seat-swapped pairs: "
          f"{sum(lengths):,} game steps ({batched:,} batched) in {wall:.1f} s = {sum(lengths) / wall:,.0f} game "
          f"steps/s; game lengths {lengths[0]:,} to {lengths[-1]:,} (median {lengths[len(lengths) // 2]:,})")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
