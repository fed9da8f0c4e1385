"""The learners of a run, acting and learning side by side.

With one network per seat (``--agents 2 --sharing nops``) a run has several learners, each with its own network,
optimiser and buffer, none touching another's tensors. Torch releases Python's GIL inside its kernels, so one
thread per learner runs their updates on separate cores (measured here: two PPO updates side by side take ~0.65x
the time of two in a row). Each thread keeps torch's intra-op pool at one thread. Acting stays on the calling
thread: a forward pass over one step's slots is too short to win back a thread hand-over.

Learner i always gets observation list i and returns action array i, and draws only from its own generator, so a
run is as reproducible with threads as without.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import torch


def _single_torch_thread() -> None:
    torch.set_num_threads(1)


class LearnerTeam:
    """Every learner's ``act``, ``record`` and ``update``; the updates in parallel threads when there are several."""

    def __init__(self, learners: Sequence[Any], threads: bool = True) -> None:
        self.learners = list(learners)
        use = threads and len(self.learners) > 1
        self._pool = (ThreadPoolExecutor(len(self.learners), thread_name_prefix="learner",
                                         initializer=_single_torch_thread) if use else None)

    def act(self, obs: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Each learner's actions for its observations, one after the other (measured: threads make acting slower)."""
        return [learner.act(o) for learner, o in zip(self.learners, obs, strict=True)]

    def record(self, rewards: Sequence[np.ndarray], dones: Sequence[np.ndarray]) -> bool:
        """Store each learner's outcome; True when every learner's update is due (they run in lockstep)."""
        due = [learner.record(r, d) for learner, r, d in zip(self.learners, rewards, dones, strict=True)]
        return all(due)

    def update(self, obs: Sequence[np.ndarray], progress: float) -> list[dict[str, float]]:
        """Every learner's update, side by side; returns their statistics in learner order."""
        pairs = list(zip(self.learners, obs, strict=True))
        if self._pool is None:
            return [learner.update(o, progress) for learner, o in pairs]
        futures = [self._pool.submit(learner.update, o, progress) for learner, o in pairs]
        return [f.result() for f in futures]

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self) -> LearnerTeam:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
