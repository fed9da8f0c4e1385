"""A batched core played in slices, for the speed benchmarks of the built-in games (``lander_env_speed.py``,
``tennis_env_speed.py``)."""

from __future__ import annotations

import time
from collections.abc import Generator
from typing import Any

import numpy as np


def core_runner(core: Any, actions: np.ndarray) -> Generator[tuple[int, float], float, None]:
    """``core`` (a :class:`~selfplay_cli.envs.contract.BatchedCore` of ``core.n`` games) played with the pre-drawn
    ``actions`` (``(K, *one step's shape)``, taken in turn), ``observe()`` every step, its games reset as they end (on
    fresh seeds). Primed with ``next()``; then sent a number of seconds, it plays that long and yields the game steps
    it played (every slot steps a game each step) and the seconds they took. Its games go on from slice to slice."""
    games = core.n
    next_seed, i = games, 0
    seconds = yield (0, 0.0)
    while True:
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            core.observe()
            core.step(actions[i % len(actions)])
            i += 1
            steps += games
            done = np.flatnonzero(core.over)
            if done.size:
                core.reset(done, np.arange(next_seed, next_seed + done.size))
                next_seed += done.size
        seconds = yield steps, time.perf_counter() - start


def core_rate(core: Any, actions: np.ndarray, seconds: float) -> float:
    """Game steps per second of :func:`core_runner` over one slice of ``seconds``."""
    runner = core_runner(core, actions)
    next(runner)
    steps, took = runner.send(seconds)
    return steps / took
