"""One training run of a study, as its own process, measured: wall time, CPU time and peak memory.

A study trains each of its runs with ``marl train`` in a child process (``python -m selfplay_cli train ...``), so
that each run's figures are its own: the CPU time is the child's and its descendants' (``os.wait4``'s resource
usage), the peak memory the largest resident size its process tree reached (``/proc``'s ``VmRSS``, summed over the
tree and sampled every half second; where there is no ``/proc``, the child's own ``ru_maxrss``). The run's progress
is read from its ``metrics.jsonl`` as it grows. A run killed with its study is resumed with ``marl train --resume``:
each piece of a run is a :class:`Segment`, and a run's figures add its segments up (peak memory: their largest).

The child dies with its study: Ctrl-C or SIGTERM of the study is handed to the child, which stops its run (kept,
resumable) and is waited for; the child runs in a process group of its own, so a Ctrl-C at the terminal reaches it
once, through the study. A study killed outright (SIGKILL) cannot hand anything on: on Linux the kernel sends the
child SIGTERM when its study dies (:func:`~selfplay_cli.signals.dies_with_parent`), so no training outlives it.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ..errors import MarlError
from ..signals import dies_with_parent, stop_child

__all__ = ["Segment", "last_line", "summed", "train_process", "tree_rss_kb"]


@dataclass(frozen=True)
class Segment:
    """One process of a run: its wall time and CPU time (seconds) and the peak memory of its process tree (MB)."""

    wall: float
    cpu: float
    peak_mb: float

    def to_json(self) -> dict[str, float]:
        return {k: round(v, 3) for k, v in asdict(self).items()}


def _children(pid: int) -> list[int]:
    out: list[int] = []
    with contextlib.suppress(OSError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            with contextlib.suppress(OSError):
                out += [int(c) for c in (task / "children").read_text().split()]
    return out


def tree_rss_kb(pid: int) -> int:
    """The resident memory (kB) of a process and all its descendants now; 0 once gone (or without ``/proc``)."""
    total, todo, seen = 0, [pid], set()
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.add(p)
        with contextlib.suppress(OSError, ValueError):
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
                    break
        todo += _children(p)
    return total


def train_process(args: Sequence[str], env: dict[str, str], log: Path,
                  on_tick: Callable[[], None] | None = None, *, program: Sequence[str] | None = None,
                  patience: float = 120.0) -> tuple[int, Segment]:
    """Run ``python -m selfplay_cli`` (or ``program``) with ``args`` (stdout and stderr to ``log``), measured;
    returns its exit code and its :class:`Segment`. ``on_tick`` is called about every half second while it runs.
    Ctrl-C or SIGTERM (:class:`~selfplay_cli.signals.Terminated`) stops the child too, with the same signal (it
    saves its run, which the study resumes next time), and waits for it up to ``patience`` seconds (then, or on a
    second signal, kills it) before going on; the child dies with this process even when that is killed outright."""
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    peak = 0
    with open(log, "ab") as out:
        try:
            proc = subprocess.Popen([*(program or (sys.executable, "-m", "selfplay_cli")), *args], env=env,
                                    stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                    process_group=0, preexec_fn=dies_with_parent())
        except OSError as e:
            raise MarlError(f"cannot start marl train: {e}") from None
        try:
            while True:
                waited = os.wait4(proc.pid, os.WNOHANG)
                if waited[0] == proc.pid:
                    break
                peak = max(peak, tree_rss_kb(proc.pid))
                if on_tick is not None:
                    on_tick()
                time.sleep(0.5)
        except BaseException as stop:
            stop_child(proc, signal.SIGINT if isinstance(stop, KeyboardInterrupt) else signal.SIGTERM, patience)
            raise
    _, status, usage = waited
    proc.returncode = os.waitstatus_to_exitcode(status)  # so Popen does not wait for it again
    cpu = usage.ru_utime + usage.ru_stime
    peak_mb = max(peak, usage.ru_maxrss) / 1024  # ru_maxrss: kB on Linux (the largest one process reached)
    return proc.returncode, Segment(time.perf_counter() - start, cpu, peak_mb)


def last_line(metrics: Path) -> dict[str, Any]:
    """A run's last metrics line (``step``, ``steps_per_second``, ...); empty before its first."""
    try:
        with open(metrics, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 4096))
            lines = f.read().decode(errors="replace").strip().splitlines()
    except OSError:
        return {}
    for line in reversed(lines):
        with contextlib.suppress(ValueError, TypeError):
            out = json.loads(line)
            if isinstance(out, dict) and "step" in out:
                return out
    return {}


def summed(segments: Sequence[dict[str, Any]]) -> dict[str, float]:
    """A run's figures from its segments: wall and CPU time added up, mean CPU use (cores busy: CPU time over wall
    time), the largest peak memory."""
    wall = sum(float(s["wall"]) for s in segments)
    cpu = sum(float(s["cpu"]) for s in segments)
    return {"wall_seconds": round(wall, 1), "cpu_seconds": round(cpu, 1),
            "mean_cpu": round(cpu / wall, 2) if wall > 0 else 0.0,
            "peak_mb": round(max((float(s["peak_mb"]) for s in segments), default=0.0), 1)}
