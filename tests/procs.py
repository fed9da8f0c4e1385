"""This machine's processes as Linux's /proc shows them, read afresh at each call: the one walk over /proc of the
suite (its conftest and tests) and of ``benchmarks/fault_matrix.py`` (which imports it as ``tests.procs``, as it
imports ``tests.games``).

A command line is read whole, every argument however long: a CI clone lives at a deep path
(``/check/work/main/...``), and a match on the first 80 characters of a command line once missed what it looked for.
A process that ends while the walk reads it is left out. Linux only: elsewhere there is no /proc to read.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Proc", "children", "descendants", "gone", "holding", "naming", "processes", "ray_keeper", "read",
           "session", "stopped"]

PROC = Path("/proc")


@dataclass(frozen=True)
class Proc:
    """One process: its pid, parent, session, state (``R``, ``S``, ``T`` stopped, ``Z`` zombie...), start time (clock
    ticks since boot: with the pid, what tells it from a later process given the same pid) and command line."""

    pid: int
    ppid: int
    sid: int
    state: str
    start: str
    argv: tuple[str, ...]  # every argument, whole (a process that rewrote its title: that title, as one)

    @property
    def cmdline(self) -> str:
        """The command line as one string, its arguments joined by spaces (whole: nothing cut)."""
        return " ".join(self.argv)

    @property
    def zombie(self) -> bool:
        return self.state == "Z"


def _stat_fields(text: str) -> list[str]:
    """A stat line's fields after the command name (which may hold spaces and parentheses): state first."""
    return text[text.rfind(")") + 2:].split()


def read(pid: int) -> Proc | None:
    """Process ``pid`` now; None when there is no such process (or it ended while being read)."""
    d = PROC / str(pid)
    try:
        fields = _stat_fields((d / "stat").read_text())
        raw = (d / "cmdline").read_bytes()  # (all of it: read to its end, however long)
    except OSError:
        return None
    argv = tuple(a.decode(errors="replace") for a in raw.rstrip(b"\0").split(b"\0")) if raw.strip(b"\0") else ()
    return Proc(pid, int(fields[1]), int(fields[3]), fields[0], fields[19], argv)


def processes() -> list[Proc]:
    """Every process of this machine now, zombies included."""
    out = []
    for d in PROC.iterdir():
        if d.name.isdigit() and (p := read(int(d.name))) is not None:
            out.append(p)
    return out


def naming(text: str) -> list[Proc]:
    """The live processes (no zombie) whose command line holds ``text`` anywhere in it."""
    return [p for p in processes() if not p.zombie and text in p.cmdline]


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (a zombie child too)."""
    return [p.pid for p in processes() if p.ppid == pid]


def descendants(root: int) -> list[Proc]:
    """Every process descended from ``root`` now (children, theirs, and so on)."""
    table = processes()
    found: list[Proc] = []
    frontier = {root}
    while frontier:
        level = [p for p in table if p.ppid in frontier]
        found += level
        frontier = {p.pid for p in level}
    return found


def ray_keeper(p: Proc, pid: int) -> bool:
    """Whether ``p`` is the keeper of Ray started by process ``pid`` (``python -c KEEPER pid ...`` of
    :mod:`selfplay_cli.ray_support`, in a session of its own)."""
    a = p.argv
    return len(a) > 3 and a[1] == "-c" and "select.select" in a[2] and a[3] == str(pid)


def session(sid: int, keeper: bool = True) -> list[Proc]:
    """The live processes of session ``sid`` (a process started in a session of its own, and all it started that
    kept it: Ray's, for one), and (``keeper``) the keeper of Ray started by process ``sid`` (:func:`ray_keeper`)."""
    return [p for p in processes() if not p.zombie and (p.sid == sid or keeper and ray_keeper(p, sid))]


def gone(pid: int) -> bool:
    """No such process, or a zombie (dead, its exit not collected yet)."""
    p = read(pid)
    return p is None or p.zombie


def stopped(pid: int) -> bool:
    """Whether every thread of process ``pid`` is stopped (SIGSTOP: state ``T``, or ``t`` under a tracer): none of
    its code runs until SIGCONT. False for no such process."""
    states = []
    for stat in (PROC / str(pid) / "task").glob("*/stat"):
        try:
            states.append(_stat_fields(stat.read_text())[0])
        except OSError:  # (a thread that ended meanwhile)
            continue
    return bool(states) and all(s in "Tt" for s in states)


def holding(path: Path | str) -> list[int]:
    """The processes that have ``path`` open (readable only for this user's processes, or all as root)."""
    target = str(path)
    out = []
    for fd_dir in PROC.glob("[0-9]*/fd"):
        try:
            if any(os.readlink(fd) == target for fd in fd_dir.iterdir()):
                out.append(int(fd_dir.parent.name))
        except OSError:
            continue
    return out
