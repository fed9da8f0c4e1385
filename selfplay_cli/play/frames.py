"""Frame stacking: a policy that reads the last K observations of its seat, kept here, in the game loop, so that
training, matches, gauntlets, ladders and recordings all give it the same input.

A policy's ``frame_stack`` (K, 1 when it has none: scripted players) says how many observations it reads: an image's
K frames side by side on its channel axis (HxWxC becomes HxWx(K*C), CxHxW becomes (K*C)xHxW), any other observation's
K rows one after the other (a flat ``(K * size,)`` vector), the oldest first. A game's first observation stands for
the K - 1 before it (the stack is filled with it at each game's start); in a turn-based game a seat's stack moves on
only when the seat acts (the observations it acted on). A snapshot records its K, so it plays as it learned.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from ..envs.obs_spaces import image_layout, stacked_space
from ..errors import MarlError
from ..policies.arch import MAX_FRAME_STACK

__all__ = ["MAX_FRAME_STACK", "FrameStacks", "check_frame_stack", "stacked_space"]


def check_frame_stack(k: object, what: str = "--frame-stack") -> int:
    """``k`` as a frame count from 1 to :data:`MAX_FRAME_STACK`, or a :class:`MarlError` naming ``what``."""
    if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or not 1 <= k <= MAX_FRAME_STACK:
        raise MarlError(f"{what} must be a whole number from 1 (no stacking) to {MAX_FRAME_STACK}, not {k!r}")
    return int(k)


class FrameStacks:
    """The last ``k`` observations of each of ``rows`` positions (a seat of a game slot), kept in the stacked layout
    (:func:`stacked_space` of ``k``), so a policy's input is one gather of its rows' newest frames.

    :meth:`restart` marks rows whose game starts anew; :meth:`see` gives the observations of this step (each row moves
    on at most once per ``step``, a fresh row is filled with its first observation); :meth:`read` the stacks."""

    def __init__(self, box: spaces.Box, k: int, rows: int) -> None:
        self.box, self.k = box, int(k)
        self.layout = image_layout(box)
        self.frame = box.shape[-1] if self.layout == "hwc" else box.shape[0] if self.layout == "chw" else math.prod(
            box.shape)  # a frame's width on the stacking axis
        self.buf = np.zeros((rows, *stacked_space(box, self.k).shape), dtype=box.dtype)
        self.fresh = np.ones(rows, dtype=bool)
        self.last = np.full(rows, -1, dtype=np.int64)  # the step each row last moved on

    def _view(self, a: np.ndarray) -> np.ndarray:
        """``a`` (rows, *stacked) with the stacking axis second: (rows, k * frame, ...)."""
        return np.moveaxis(a, -1, 1) if self.layout == "hwc" else a.reshape(a.shape[0], a.shape[1], -1) \
            if self.layout == "chw" else a[:, :, None]

    def restart(self, rows: np.ndarray) -> None:
        self.fresh[rows] = True

    def see(self, rows: np.ndarray, obs: np.ndarray, step: int) -> None:
        """This step's observations ``obs`` (one per row of ``rows``) join their rows' stacks."""
        rows = np.asarray(rows, dtype=np.int64)
        pick = self.fresh[rows] | (self.last[rows] != step)
        due = rows[pick]
        if not due.size:
            return
        o = np.asarray(obs)[pick]
        o = self._view(o) if self.layout is not None else o.reshape(due.size, -1)[:, :, None]
        stack = self.buf[due]
        v = self._view(stack)
        f = self.frame
        fresh = self.fresh[due]
        v[~fresh, :-f] = v[~fresh, f:]
        v[~fresh, -f:] = o[~fresh]
        v[fresh] = np.concatenate([o[fresh]] * self.k, axis=1)
        self.buf[due] = stack
        self.fresh[due] = False
        self.last[due] = step

    def read(self, rows: np.ndarray | slice, k: int) -> np.ndarray:
        """The stacks of the newest ``k`` observations of ``rows``: ``(len(rows), *stacked_space(box, k).shape)``."""
        cut = self.frame * (self.k - int(k))
        if self.layout == "hwc":
            return self.buf[rows][..., cut:]
        return self.buf[rows][:, cut:]

    def grow(self, k: int) -> None:
        """Keep ``k`` observations from now on (more than before: the oldest kept stands for the ones before it)."""
        if k <= self.k:
            return
        v = self._view(self.buf)
        oldest = v[:, :self.frame]
        wider = np.concatenate([oldest] * (k - self.k) + [v], axis=1)
        self.k = int(k)
        buf = np.zeros((self.buf.shape[0], *stacked_space(self.box, self.k).shape), dtype=self.box.dtype)
        self._view(buf)[:] = wider
        self.buf = buf
