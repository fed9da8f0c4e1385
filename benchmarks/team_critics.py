"""The team critics' cost where users feel it: `marl train lander --agents 2 --sharing fups --algo ppo|mappo|poca
--minutes 1 --eval-games 0`, each run on one core (``taskset``) with torch at one thread, the three alternated round
after round (each round starts with the next algorithm), so a machine shared with other work slows them alike.

Prints each run's game steps/s (the anchor) and CPU seconds per 1,000 game steps with the load average beside
them, then per target the median over the rounds of the ratio of wall time per game step within a round (PPO's
steps/s over the algorithm's) and the same ratio in CPU time (start-up included: it moves least when other work
shares the machine), and one learner update of the lander's rollout (256 steps of 64 games, two landers each:
32,768 decisions, 10 epochs of 8 minibatches of 4,096) measured in-process on the same core: its milliseconds per
4,096-row gradient step (the whole update, the critic's pass over the rollout included, over its 80 steps).

Targets (the issue "speed where users feel it"): MAPPO at most 1.25x PPO's wall time per game step, MA-POCA at most
2.5x, each learning the lander at least as well (docs/teams.md).

Run: python benchmarks/team_critics.py [--minutes 1] [--rounds 3] [--cpu 0] [--no-train] [--no-update]
(PYTHONPATH chooses the checkout measured).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ALGOS = ("ppo", "mappo", "poca")
TARGETS = {"mappo": 1.25, "poca": 2.5}
ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "SDL_VIDEODRIVER": "dummy"}


def load() -> str:
    return f"load {os.getloadavg()[0]:.2f}"


def train(home: Path, algo: str, minutes: float, cpu: int, run: str) -> tuple[float, float]:
    """Game steps/s of one `marl train lander` run on core ``cpu``, and its CPU seconds (user and system, start-up
    included) per 1,000 game steps: what it costs whatever else the machine runs."""
    args = ["taskset", "-c", str(cpu), sys.executable, "-m", "selfplay_cli", "train", "lander", "--agents", "2",
            "--sharing", "fups", "--algo", algo, "--minutes", str(minutes), "--eval-games", "0", "--run", run,
            "--home", str(home), "--quiet", "--json"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(args, env={**os.environ, **ONE_THREAD}, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise SystemExit(f"marl train --algo {algo} failed ({out.returncode}): {out.stderr.strip()[-2000:]}")
    report = json.loads(out.stdout)
    used = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return float(report["steps_per_second"]), 1000 * used / max(1, int(report["steps"]))


def update_ms(algo: str, repeats: int) -> tuple[float, float, int]:
    """One learner update of the lander's rollout, filled through the learner's interface with the shapes (and the
    two seats of a game sharing its team rows) the trainer gives: (median ms per gradient step, median ms of the
    whole update, gradient steps an update)."""
    import numpy as np
    import torch

    from selfplay_cli.algos import get_learner
    from selfplay_cli.envs import get_env
    from selfplay_cli.envs.team import TeamStep, TeamView, team_spec
    from selfplay_cli.train.settings import game_defaults

    torch.set_num_threads(1)
    spec = get_env("lander")
    game_cfg = spec.config()
    seats = spec.seat_spaces(game_cfg)
    defaults = game_defaults(spec)
    n_games, n_seats = int(defaults.get("games", 64)), len(seats)
    layout = np.zeros((n_seats, n_games), dtype=np.int64)
    cls = get_learner(algo)
    cfg = cls.config_class(**defaults.get(algo, {}))
    team = {} if algo == "ppo" else {"team": team_spec(spec, game_cfg, seats, layout, 0)}
    learner = cls(seats[0], n_seats * n_games, cfg, seed=0, **team)
    rng = np.random.default_rng(0)
    games = np.arange(n_seats * n_games) % n_games  # a slot's game (seat-major slots, as the trainer lays them)
    width = int(np.prod(seats[0].observation.shape))
    n_actions = int(seats[0].action.n)

    def view() -> TeamView:
        return TeamView(rng.normal(size=(n_games, n_seats, width)).astype(np.float32),
                        np.ones((n_games, n_seats), dtype=bool), None)

    times = []
    for _ in range(repeats + 1):
        now = view()
        for _ in range(cfg.rollout_steps):
            obs = now.obs.transpose(1, 0, 2).reshape(n_seats * n_games, width)
            actions = learner.act(obs)
            acts = np.eye(n_actions, dtype=np.float32)[actions.reshape(n_seats, n_games).T]
            reward = rng.normal(size=n_games).astype(np.float32)
            done = rng.random(n_games) < 0.004
            after = view()
            if team:
                learner.see_team(TeamStep(now.rows(games), acts[games], reward[games], done[games],
                                          np.zeros(len(games), dtype=bool), after.rows(games), None))
            learner.record(reward[games] / n_seats, done[games])
            now = after
        t0 = time.perf_counter()
        learner.update(now.obs.transpose(1, 0, 2).reshape(n_seats * n_games, width), 0.5)
        times.append(time.perf_counter() - t0)
    steps = cfg.update_epochs * cfg.minibatches
    whole = statistics.median(times[1:]) * 1e3  # the first warms up
    return whole / steps, whole, steps


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=1.0, help="each training run's budget")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--cpu", type=int, default=0, help="the core the runs are pinned to")
    p.add_argument("--no-train", action="store_true", help="skip the training runs")
    p.add_argument("--no-update", action="store_true", help="skip the in-process update timing")
    p.add_argument("--update-repeats", type=int, default=3)
    p.add_argument("--update-child", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.update_child:
        print(json.dumps(update_ms(args.update_child, args.update_repeats)))
        return
    print(f"{os.cpu_count()} cores; each run on core {args.cpu}, torch at 1 thread; {load()}")
    if not args.no_train:
        rates: dict[str, list[float]] = {a: [] for a in ALGOS}
        costs: dict[str, list[float]] = {a: [] for a in ALGOS}
        tmp = Path(tempfile.mkdtemp(prefix="poca-bench-", dir="/tmp"))
        try:
            for r in range(args.rounds):
                order = ALGOS[r % 3:] + ALGOS[:r % 3]
                for algo in order:
                    before = load()
                    sps, cost = train(tmp / f"{algo}-{r}", algo, args.minutes, args.cpu, f"{algo}-{r}")
                    rates[algo].append(sps)
                    costs[algo].append(cost)
                    print(f"round {r + 1} {algo:5}: {sps:8,.0f} game steps/s, {cost:6.3f} CPU s per 1,000 game steps "
                          f"({before} before, {load()} after)", flush=True)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        for algo, target in TARGETS.items():
            ratios = [p / a for p, a in zip(rates["ppo"], rates[algo], strict=True)]
            ratio = statistics.median(ratios)
            print(f"{algo} / ppo wall time per game step: {ratio:.2f} (target <= {target}) -> "
                  f"{'PASS' if ratio <= target else 'FAIL'}; rounds {', '.join(f'{x:.2f}' for x in ratios)}; anchor "
                  f"ppo {statistics.median(rates['ppo']):,.0f} and {algo} {statistics.median(rates[algo]):,.0f} game "
                  f"steps/s (medians)")
        for algo, target in TARGETS.items():  # the same, in CPU time: what a busy machine moves least
            ratios = [a / p for p, a in zip(costs["ppo"], costs[algo], strict=True)]
            print(f"{algo} / ppo CPU time per game step: {statistics.median(ratios):.2f} (the wall time's target "
                  f"<= {target}); rounds {', '.join(f'{x:.2f}' for x in ratios)}")
    if not args.no_update:
        for algo in ALGOS:
            before = load()
            out = subprocess.run(["taskset", "-c", str(args.cpu), sys.executable, __file__, "--update-child", algo,
                                  "--update-repeats", str(args.update_repeats)], env={**os.environ, **ONE_THREAD},
                                 capture_output=True, text=True)
            if out.returncode != 0:
                raise SystemExit(f"the {algo} update timing failed: {out.stderr.strip()[-2000:]}")
            step, whole, steps = json.loads(out.stdout)
            print(f"{algo} update of the lander's rollout: {step:.1f} ms per 4,096-row gradient step ({whole:,.0f} "
                  f"ms for {steps} steps, the critic's pass over the rollout included; {before})", flush=True)


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
