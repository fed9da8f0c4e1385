"""Every gymnasium observation space as what a policy reads: one flat float32 vector, in a stated order.

:class:`FlatObs` reads observations of one space into a float32 row of :attr:`FlatObs.size` numbers:

* **Box** (any shape, any dtype): its numbers in C order, as float32;
* **Discrete(n, start)**: one-hot, n numbers (a 1 at ``x - start``);
* **MultiDiscrete(nvec, start)**: a one-hot per entry (in C order), side by side;
* **MultiBinary(n)** (any shape): its zeros and ones, in C order;
* **Tuple**: its parts in order; **Dict**: its entries in the Dict's own key order (gymnasium sorts the keys of a
  plain dict), nested spaces read the same way all the way down.

The bounds of the row (:meth:`FlatObs.box`) are the parts' bounds (0 and 1 for one-hots and binaries), so a policy's
input is checked as any Box observation is. A game's ``action_mask`` is not read here: the adapter takes it out of
a top-level Dict first (:func:`~selfplay_cli.envs.seat_spaces.seat_space_of`).

**Images** are the one exception to the flat float32 row (:func:`image_layout`): a Box of three axes whose numbers
lie in 0..255 (uint8, or any dtype with those bounds) and whose channel axis holds 1 to 4 channels is read as it is,
its shape and dtype kept, so a uint8 frame stays one byte a number from the game to the network (which scales it to
[0, 1] itself) and a convolutional encoder reads it.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["FlatObs", "SeatObs", "image_layout", "stacked_space"]

MAX_CHANNELS = 4  # an image's channels (grey, grey+alpha, RGB, RGBA); a bigger axis is a side, not the channels
MIN_SIDE = 4  # an image's smaller side: below it there is nothing for a convolution to slide over


def image_layout(space: spaces.Space) -> str | None:
    """``"hwc"`` or ``"chw"`` for an image observation, else None.

    An image is a Box of three axes with numbers in 0..255 (dtype uint8, or bounds 0 and 255 of any dtype) whose
    channel axis holds 1 to 4 channels: the last axis when it holds at most 4 (HxWxC, what PettingZoo's butterfly
    and Atari games give), else the first (CxHxW); its other two sides hold at least 4 pixels each."""
    if not isinstance(space, spaces.Box) or len(space.shape) != 3:
        return None
    if space.dtype != np.uint8:
        low, high = np.asarray(space.low), np.asarray(space.high)
        if not (np.all(low == 0) and np.all(high == 255)):
            return None
    h, w, c = space.shape
    if 1 <= c <= MAX_CHANNELS and min(h, w) >= MIN_SIDE:
        return "hwc"
    c, h, w = space.shape
    if 1 <= c <= MAX_CHANNELS and min(h, w) >= MIN_SIDE:
        return "chw"
    return None


class FlatObs:
    """Reads observations of ``space`` as flat float32 rows (see the module docstring); :class:`ValueError` for a
    space it cannot read (Text, Graph, Sequence: no fixed size), naming it."""

    def __init__(self, space: spaces.Space) -> None:
        self.space = space
        self._parts: list[tuple[str, Any, int, int]] = []  # (kind, space, offset, size), leaves in reading order
        lows: list[np.ndarray] = []
        highs: list[np.ndarray] = []
        self.size = self._plan(space, lows, highs)
        if self.size == 0:
            raise ValueError(f"observation space {space} holds no numbers")
        self.low = np.concatenate(lows).astype(np.float32)
        self.high = np.concatenate(highs).astype(np.float32)
        self._one_hot = any(kind in ("discrete", "multidiscrete") for kind, *_ in self._parts)
        self._writers = _writers(self._parts, _paths(space))

    def _plan(self, space: spaces.Space, lows: list[np.ndarray], highs: list[np.ndarray], offset: int = 0) -> int:
        """Lay out the leaves of ``space`` from ``offset``; returns the numbers they take."""
        if isinstance(space, spaces.Box):
            n = math.prod(space.shape)
            kind = "box"
            lows.append(np.asarray(space.low, dtype=np.float64).reshape(-1))
            highs.append(np.asarray(space.high, dtype=np.float64).reshape(-1))
        elif isinstance(space, spaces.Discrete):
            n = int(space.n)
            kind = "discrete"
        elif isinstance(space, spaces.MultiDiscrete):
            n = int(np.sum(space.nvec))
            kind = "multidiscrete"
        elif isinstance(space, spaces.MultiBinary):
            n = math.prod(np.atleast_1d(space.n).tolist())
            kind = "binary"
        elif isinstance(space, (spaces.Tuple, spaces.Dict)):
            at = offset
            for sub in (space.spaces if isinstance(space, spaces.Tuple) else space.spaces.values()):
                at += self._plan(sub, lows, highs, at)
            return at - offset
        else:
            raise ValueError(f"observation space {space} ({type(space).__name__}) has no fixed size: marl reads Box, "
                             "Discrete, MultiDiscrete, MultiBinary, and Tuples and Dicts of them")
        if kind != "box":
            lows.append(np.zeros(n))
            highs.append(np.ones(n))
        self._parts.append((kind, space, offset, n))
        return n

    def box(self) -> spaces.Box:
        """The flat float32 Box a policy reads."""
        return spaces.Box(self.low, self.high, dtype=np.float32)

    def read(self, x: Any, out: np.ndarray | None = None) -> np.ndarray:
        """One observation as a flat float32 row (into ``out`` when given)."""
        row = np.empty(self.size, dtype=np.float32) if out is None else out
        if self._one_hot:
            row.fill(0.0)
        for path, write in self._writers:
            value = x
            for key in path:
                value = value[key]
            write(row, value)
        return row


def _writers(parts: list[tuple[str, Any, int, int]], paths: list[tuple[Any, ...]]) -> list[tuple[tuple[Any, ...], Any]]:
    """Per leaf, where it sits in an observation (its keys and indices) and a function that writes its value into a
    row: the per-step work of :meth:`FlatObs.read` planned once, so a step costs a few Python operations a leaf."""
    out = []
    for (kind, space, offset, n), path in zip(parts, paths, strict=True):
        end = offset + n
        if kind in ("box", "binary"):
            flat = len(space.shape) <= 1

            def write(row: np.ndarray, v: Any, o: int = offset, e: int = end, flat: bool = flat) -> None:
                row[o:e] = v if flat else np.ravel(v)
        elif kind == "discrete":
            def write(row: np.ndarray, v: Any, at: int = offset - int(space.start)) -> None:
                row[at + int(v)] = 1.0
        else:
            nvec = np.asarray(space.nvec).reshape(-1)
            base = offset + np.concatenate(([0], np.cumsum(nvec)[:-1])) - np.asarray(space.start).reshape(-1)

            def write(row: np.ndarray, v: Any, base: np.ndarray = base) -> None:
                row[base + np.ravel(v)] = 1.0
        out.append((path, write))
    return out


def _paths(space: spaces.Space, at: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """The keys and indices that reach each leaf of ``space``, in :class:`FlatObs`'s reading order."""
    if isinstance(space, spaces.Tuple):
        return [p for i, sub in enumerate(space.spaces) for p in _paths(sub, (*at, i))]
    if isinstance(space, spaces.Dict):
        return [p for key, sub in space.spaces.items() for p in _paths(sub, (*at, key))]
    return [at]


def stacked_space(box: spaces.Box, k: int) -> spaces.Box:
    """What a policy stacking ``k`` observations of ``box`` reads (``box`` itself for k = 1): an image's frames on
    its channel axis (HxWx(k*C), (k*C)xHxW), any other observation's k rows one after the other, flat (the oldest
    first; :mod:`selfplay_cli.play.frames` keeps them)."""
    if k == 1:
        return box
    layout = image_layout(box)
    axis = -1 if layout == "hwc" else 0
    if layout is None:
        low, high = np.asarray(box.low).reshape(-1), np.asarray(box.high).reshape(-1)
        return spaces.Box(np.tile(low, k), np.tile(high, k), dtype=box.dtype)
    return spaces.Box(np.concatenate([box.low] * k, axis=axis), np.concatenate([box.high] * k, axis=axis),
                      dtype=box.dtype)


class SeatObs:
    """A seat's observation as a game gives it, and as a policy reads it: an ``action_mask`` entry of a top-level
    Dict is the seat's action mask (not read as observation); what remains is ``observation`` alone where the Dict
    holds only that (PettingZoo's classic games), else the rest of the Dict; it is read as it is where it is a Box,
    else flattened by :class:`FlatObs`. :attr:`box` is what the policy reads, :attr:`mask` whether there is a mask."""

    def __init__(self, space: spaces.Space) -> None:
        self.raw = space
        self.mask_space: spaces.Space | None = None
        self._key: str | None = None  # the entry read as the observation (None: the rest of the Dict, or all)
        inner = space
        if isinstance(space, spaces.Dict):
            rest = OrderedDict((k, v) for k, v in space.spaces.items() if k != "action_mask")
            self.mask_space = space.spaces.get("action_mask")
            if set(rest) == {"observation"}:
                self._key, inner = "observation", rest["observation"]
            elif self.mask_space is not None:  # the reader reads the other entries from the whole observation
                inner = spaces.Dict(rest)
        self.reader = None if isinstance(inner, spaces.Box) else FlatObs(inner)
        self.box: spaces.Space = inner if self.reader is None else self.reader.box()
        self.split = self._splitter(isinstance(space, spaces.Dict))

    @property
    def mask(self) -> bool:
        return self.mask_space is not None

    def _splitter(self, is_dict: bool) -> Callable[[Any], tuple[Any, Any]]:
        """``split(x)``: one observation as the game gives it -> (what the policy reads, the action mask or None),
        made once for this seat's space (it runs for every seat of every game at every step)."""
        key = self._key
        read = None if self.reader is None else self.reader.read
        if not is_dict:
            return (lambda x: (x, None)) if read is None else (lambda x: (read(x), None))
        if key is None:  # a Dict read whole (its action_mask aside: the reader reads only its own entries)
            assert read is not None
            return lambda x: (read(x), x.get("action_mask"))
        if read is None:
            return lambda x: (x[key], x.get("action_mask"))
        return lambda x: (read(x[key]), x.get("action_mask"))
