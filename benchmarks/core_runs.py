"""Games played in slices of time, for the speed benchmarks of the built-in games (``lander_env_speed.py``,
``tennis_env_speed.py``)."""

from __future__ import annotations

import time
from collections.abc import Callable, Generator
from typing import Any

import numpy as np

Runner = Generator[tuple[int, float], float, None]


def sliced(step: Callable[[], int]) -> Runner:
    """``step()`` (plays one step, returns the game steps it played) in slices: primed with ``next()``; then sent a
    number of seconds, it steps that long and yields the game steps played and the seconds they took. What ``step``
    plays goes on from slice to slice."""
    seconds = yield (0, 0.0)
    while True:
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            steps += step()
        seconds = yield steps, time.perf_counter() - start


def core_runner(core: Any, actions: np.ndarray) -> Runner:
    """``core`` (a :class:`~selfplay_cli.envs.contract.BatchedCore` of ``core.n`` games) played :func:`sliced` with the
    pre-drawn ``actions`` (``(K, *one step's shape)``, taken in turn), ``observe()`` every step, its games reset as they
    end (on fresh seeds); every slot steps a game each step."""
    state = {"seed": core.n, "i": 0}

    def step() -> int:
        core.observe()
        core.step(actions[state["i"] % len(actions)])
        state["i"] += 1
        done = np.flatnonzero(core.over)
        if done.size:
            core.reset(done, np.arange(state["seed"], state["seed"] + done.size))
            state["seed"] += done.size
        return core.n

    return sliced(step)


def core_rate(core: Any, actions: np.ndarray, seconds: float) -> float:
    """Game steps per second of :func:`core_runner` over one slice of ``seconds``."""
    runner = core_runner(core, actions)
    next(runner)
    steps, took = runner.send(seconds)
    return steps / took
