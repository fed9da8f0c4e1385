"""Run `marl` marking where it has got to, for a test to wait on rather than guess how long the way there takes.

Run as ``python tests/marks.py MARKS <marl arguments>``: `marl` as ``python -m selfplay_cli <marl arguments>`` runs
it, appending a line to the file MARKS each time it reaches one of these points:

* ``update``: a PPO learner (MAPPO and POCA too) is beginning its update's first minibatch; written from the
  thread that runs the update (a run of several learners updates them side by side, one thread each), so a line
  per learner says that every one of them is in its update.

The rating worker (a process of its own, started by spawn, which imports this file as ``__mp_main__``) is not
marked. Used by tests/test_worker.py.
"""

from __future__ import annotations

import sys
from pathlib import Path


def mark(marks: Path, what: str) -> None:
    """Append the line ``what`` to ``marks`` (one write in append mode: lines of two threads never mix)."""
    with open(marks, "a") as f:
        f.write(what + "\n")


def arm(marks: Path) -> None:
    """Wrap the learner code at each point so that reaching it writes its mark."""
    from selfplay_cli.algos.ppo import PPOLearner

    real = PPOLearner._minibatch_step
    marked: dict[int, int] = {}  # learner (by id) -> the update it last marked (its count of updates done)

    def minibatch_step(self, *args, **kwargs):
        if marked.get(id(self)) != self.updates:
            marked[id(self)] = self.updates
            mark(marks, "update")
        return real(self, *args, **kwargs)

    PPOLearner._minibatch_step = minibatch_step


if __name__ == "__main__":
    arm(Path(sys.argv[1]))
    del sys.argv[1]
    from selfplay_cli.cli import run

    run()  # (as `python -m selfplay_cli` runs marl, exit code and all)
