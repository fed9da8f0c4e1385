"""Kill `marl train` at a chosen point of writing a snapshot moment: SIGKILL, no clean-up of any kind.

Run as ``python tests/kill_points.py POINT HOME <marl train arguments>``. The chosen function kills the process the
second time a snapshot moment reaches that point, so the first moment (s0) is complete and the second is cut:

* ``after-first-file``: the second moment's first snapshot file is written, nothing else;
* ``after-pending-state``: its files and its pending run state are written, its rows are not;
* ``during-state-file``: half of its pending run state is written;
* ``after-rows``: its rows are committed, the pending state not yet renamed into place.

One point is in the rating worker instead (a process of its own, started by spawn, which imports this file as
``__mp_main__`` with the same arguments, so the point is armed there too):

* ``worker-mid-job``: the worker has stored two games' batches of the second moment's gauntlet and is storing a
  third: it kills the trainer, then itself (SIGKILL both), before that third batch is committed.

Used by tests/test_kill_resume.py, tests/test_worker.py and benchmarks/fault_matrix.py.
"""

from __future__ import annotations

import os
import signal
import sys

import torch

import selfplay_cli.train.state as run_state
from selfplay_cli.cli import main
from selfplay_cli.league.roster import Roster

POINTS = ("after-first-file", "after-pending-state", "during-state-file", "after-rows", "worker-mid-job")
SECOND_MOMENT = range(10_010_000, 10_030_000)  # the seeds of the second snapshot moment's gauntlet (state.py: a
# moment's seeds start 10,000 a snapshot taken before it above 10,000,000: with one learner or two)


def arm_worker() -> None:
    """In the rating worker: kill the trainer and the worker as the second moment's third batch is being stored."""
    from selfplay_cli.league.ledger import Ledger

    real = Ledger._insert_games
    stores = []

    def insert(self, s, match, games, pids):
        if int((match.params or {}).get("first_seed", -1)) in SECOND_MOMENT:
            stores.append(match.id)
            if len(stores) == 3:
                os.kill(os.getppid(), signal.SIGKILL)
                os.kill(os.getpid(), signal.SIGKILL)
        return real(self, s, match, games, pids)

    Ledger._insert_games = insert


def arm(point: str) -> None:
    """Wrap the function that writes at ``point`` so that its call of the second moment kills the process."""
    calls: dict[str, int] = {}

    def nth(what: str) -> int:
        calls[what] = calls.get(what, 0) + 1
        return calls[what]

    def die() -> None:
        os.kill(os.getpid(), signal.SIGKILL)

    real_file, real_state, real_rows = run_state.save_snapshot, torch.save, Roster.add_snapshots

    def save_file(*args, **kwargs):
        out = real_file(*args, **kwargs)
        if nth("file") == 3:  # the first moment wrote s0-left and s0-right: this is the second moment's first
            die()
        return out

    def save_state(obj, f, *args, **kwargs):
        if nth("state") == 2:
            f.write(b"half a state file")
            f.flush()
            die()
        return real_state(obj, f, *args, **kwargs)

    def rows_first(self, items):
        if nth("rows") == 2:
            die()
        return real_rows(self, items)

    def rows_then(self, items):
        out = real_rows(self, items)
        if nth("rows") == 2:
            die()
        return out

    if point not in POINTS:
        raise SystemExit(f"kill point must be one of {', '.join(POINTS)}, not {point!r}")
    if point == "worker-mid-job":
        return  # armed in the worker (below)
    if point == "after-first-file":
        run_state.save_snapshot = save_file
    elif point == "during-state-file":
        torch.save = save_state
    elif point == "after-pending-state":
        Roster.add_snapshots = rows_first
    else:
        Roster.add_snapshots = rows_then


if __name__ == "__mp_main__" and sys.argv[1:2] == ["worker-mid-job"]:  # this file, imported by the worker
    arm_worker()

if __name__ == "__main__":
    arm(sys.argv[1])
    sys.exit(main([*sys.argv[3:], "--home", sys.argv[2]]))
