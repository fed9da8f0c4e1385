"""The run's lock: which processes are training a run, so that one run is trained by one process at a time.

``runs/<run>/lock`` names the training process and, once it has one, its rating worker, each by pid and start
time (JSON ``{"trainer": [pid, start], "worker": [pid, start]}``; an older marl's lock holds the trainer's pid
alone). A process is recognised by both, so a pid the system has given to another process since is never taken
for the run's, nor killed. A run killed with SIGKILL leaves a stale lock, which the next claim takes over. The Ray
actors of ``--eval ray`` are not named: Ray ends them with the trainer that owns them
(:mod:`selfplay_cli.evaluation.executors.ray_actors`).
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

from ..errors import MarlError
from ..files import pid_alive, write_atomic

__all__ = ["claim", "live_trainer", "process_start", "read_lock", "write_lock"]


def claim(lock: Path, run: str) -> None:
    """Claim the run for this process: refused while the process that holds the lock lives; a stale lock is taken
    over, and a rating worker of that run still alive (where the kernel did not end it with its trainer) is ended
    first, so that nothing of the old session plays on beside the new one."""
    holder = read_lock(lock)
    trainer = holder.get("trainer")
    if trainer is not None and trainer[0] != os.getpid() and same_process(*trainer):
        raise MarlError(f"run '{run}' is being trained by process {trainer[0]}; stop it before resuming")
    worker = holder.get("worker")
    if worker is not None and worker[1] is not None and same_process(*worker) and worker[0] != os.getpid():
        end_process(worker[0])
    write_lock(lock, None)


def write_lock(lock: Path, worker: int | None) -> None:
    """The lock naming this process and its rating ``worker`` (if any), written to a temporary name and renamed."""
    me = os.getpid()
    holder = {"trainer": [me, process_start(me)]}
    if worker is not None:
        holder["worker"] = [worker, process_start(worker)]
    write_atomic(lock, json.dumps(holder))


def live_trainer(lock: Path) -> int | None:
    """The pid of the live process the lock names as training the run; None for no lock or a stale one."""
    trainer = read_lock(lock).get("trainer")
    return trainer[0] if trainer is not None and trainer[0] > 0 and same_process(*trainer) else None


def process_start(pid: int) -> str | None:
    """When process ``pid`` started, in the kernel's clock ticks since boot (``/proc/<pid>/stat``, field 22): with
    the pid, what tells a process from a later one given the same pid. None where there is no ``/proc``, or no such
    process."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2:].split()  # after the command name, which may hold spaces and parentheses
    return fields[19] if len(fields) > 19 else None


def same_process(pid: int, start: str | None) -> bool:
    """Whether ``pid`` is alive and, where its start time was recorded and can be read, still the same process."""
    if not pid_alive(pid):
        return False
    now = process_start(pid)
    return start is None or now is None or now == start


def read_lock(lock: Path) -> dict[str, tuple[int, str | None]]:
    """The processes a run's lock names: ``{"trainer": (pid, start), "worker": (pid, start)}`` (an older marl's
    lock holds the trainer's pid alone); empty for no lock, or one that cannot be read."""
    try:
        text = lock.read_text().strip()
    except OSError:
        return {}
    if text.isdigit():  # an older marl's lock
        return {"trainer": (int(text), None)}
    try:
        raw = json.loads(text)
        return {role: (int(v[0]), None if v[1] is None else str(v[1])) for role, v in raw.items()
                if role in ("trainer", "worker")}
    except (ValueError, TypeError, KeyError, IndexError, AttributeError):
        return {}


def end_process(pid: int, timeout: float = 10.0) -> None:
    """SIGKILL ``pid`` and wait (up to ``timeout`` s) until it is gone."""
    try:
        os.kill(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        return
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and _running(pid):
        time.sleep(0.05)


def _running(pid: int) -> bool:
    """Whether ``pid`` is alive and not a zombie (dead, its exit not yet collected by its parent)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    except OSError:
        return pid_alive(pid)
    return stat[stat.rfind(")") + 2:].split()[:1] != ["Z"]
