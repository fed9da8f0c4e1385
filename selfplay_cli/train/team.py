"""The learners of a run, acting and learning side by side.

With one network per seat (``--agents 2 --sharing nops``) a run has several learners, each with its own network,
optimiser and buffer, none touching another's tensors. Torch releases Python's GIL inside its kernels, so one
thread per learner runs their updates on separate cores (measured here: two PPO updates side by side take ~0.65x
the time of two in a row). Each thread keeps torch's intra-op pool at one thread. Acting stays on the calling
thread: a forward pass over one step's slots is too short to win back a thread hand-over.

Learner i always gets observation list i and returns action array i, and draws only from its own generator, so a
run is as reproducible with threads as without.

An update allocates and frees the same few megabytes of activations and gradients every minibatch. glibc's malloc
hands freed blocks of that size back to the kernel (and trims its heaps), so each minibatch page-faulted its memory
in again: ~20,000 faults per update of two learners, with both threads queueing on the kernel's lock of the
address space. A team therefore asks malloc to keep freed memory for reuse (:func:`keep_freed_memory`); measured
on 2 cores, the two updates side by side went from ~0.28 s to ~0.15 s, the time of one update alone.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import torch

from ..errors import NonFiniteError


def _single_torch_thread() -> None:
    torch.set_num_threads(1)


_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt parameters (glibc's malloc.h)


def keep_freed_memory() -> bool:
    """Have glibc's malloc keep freed blocks of up to 32 MB in the heap (not ``munmap`` them) and trim a heap only
    when 64 MB lie free at its top (process-wide; the memory stays the process's peak). Speed only: where there is
    no glibc (macOS, musl) it does nothing. Returns whether malloc took the settings."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, 32 << 20)) & bool(mallopt(_M_TRIM_THRESHOLD, 64 << 20))


class LearnerTeam:
    """Every learner's ``act``, ``record`` and ``update``; the updates in parallel threads when there are several."""

    def __init__(self, learners: Sequence[Any], threads: bool = True) -> None:
        self.learners = list(learners)
        keep_freed_memory()
        use = threads and len(self.learners) > 1
        self._pool = (ThreadPoolExecutor(len(self.learners), thread_name_prefix="learner",
                                         initializer=_single_torch_thread) if use else None)

    def act(self, obs: Sequence[np.ndarray], masks: Sequence[np.ndarray | None] | None = None) -> list[np.ndarray]:
        """Each learner's actions for its observations (and action masks, where the game has them), one after the
        other (measured: threads make acting slower)."""
        if masks is None:
            return [learner.act(o) for learner, o in zip(self.learners, obs, strict=True)]
        return [learner.act(o, m) for learner, o, m in zip(self.learners, obs, masks, strict=True)]

    def take(self, obs: Sequence[np.ndarray], taken: Sequence[dict[str, Any]]) -> None:
        """Each learner keeps a step it did not act on itself: its observations and the decisions a rollout actor
        made for them (``learner.take``), as ``act`` would have kept them."""
        for learner, o, t in zip(self.learners, obs, taken, strict=True):
            learner.take(o, t)

    def record(self, rewards: Sequence[np.ndarray], dones: Sequence[np.ndarray],
               truncated: Sequence[np.ndarray] | None = None, acting: Sequence[np.ndarray | None] | None = None,
               final_obs: Sequence[np.ndarray] | None = None,
               final_masks: Sequence[np.ndarray | None] | None = None) -> bool:
        """Store each learner's outcome; True when every learner's update is due (they run in lockstep).
        ``truncated`` and ``final_obs`` (games cut short on this step, and their final observations, per learner),
        ``acting`` (turn-based games: the slots that acted) as the learner interface takes them."""
        due = []
        for i, (learner, r, d) in enumerate(zip(self.learners, rewards, dones, strict=True)):
            extra: dict[str, Any] = {}
            if truncated is not None:
                extra.update(truncated=truncated[i], final_obs=final_obs[i] if final_obs is not None else None,
                             final_mask=final_masks[i] if final_masks is not None else None)
            if acting is not None and acting[i] is not None:
                extra["acting"] = acting[i]
            due.append(learner.record(r, d, **extra))
        return all(due)

    def update(self, obs: Sequence[np.ndarray], progress: float) -> list[dict[str, float]]:
        """Every learner's update, side by side; returns their statistics in learner order. A learner whose update
        met a number that is not finite raises its :class:`NonFiniteError` with ``learner`` set to its index."""
        pairs = list(zip(self.learners, obs, strict=True))
        if self._pool is None:
            calls = [lambda learner=learner, o=o: learner.update(o, progress) for learner, o in pairs]
        else:
            calls = [self._pool.submit(learner.update, o, progress).result for learner, o in pairs]
        out = []
        for i, call in enumerate(calls):
            try:
                out.append(call())
            except NonFiniteError as e:
                e.learner = i
                raise
        return out

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self) -> LearnerTeam:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
