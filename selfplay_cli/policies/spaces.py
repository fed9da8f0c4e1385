"""A seat's spaces as policies see them: JSON for snapshot files, and the action head a space calls for.

Observations are a Box (a Dict observation's ``observation`` part: the game contract hands policies that part and
the ``action_mask`` separately). Actions are ``Discrete(n)``, ``MultiDiscrete(nvec)`` or a bounded ``Box``. Policies
act on batches and return, for a batch of B observations:

=================  ==================================  ============================================================
action space       actions                             mask (optional)
=================  ==================================  ============================================================
Discrete(n)        ``(B,)`` int64 in ``0 .. n-1``      ``(B, n)`` bool, True = allowed
MultiDiscrete(v)   ``(B, k)`` int64, column j < v[j]   ``(B, sum(v))`` bool: each dimension's mask, side by side
Box(low, high)     ``(B, *shape)`` float32 in bounds   none
=================  ==================================  ============================================================

A space as JSON (``space_to_dict``): ``{"kind": "box", "shape": [8, 6], "dtype": "float32", "low": -1.0,
"high": 1.0}`` (bounds a number when uniform, else nested lists; ``null`` for an infinite bound),
``{"kind": "discrete", "n": 3}``, ``{"kind": "multidiscrete", "nvec": [3, 2], "dtype": "int64"}``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from ..envs.seat_spaces import SpaceError, describe_space

KINDS = ("discrete", "multidiscrete", "box")
MAX_BOUNDS = 65_536  # numbers of non-uniform bounds written out (larger observation bounds are written as unknown)


# ---------------------------------------------------------------------------------------------------------------
# JSON


def _bound_to_json(values: np.ndarray) -> Any:
    """A bound as JSON: one number when every entry is the same, else nested lists; infinities as null."""
    a = np.asarray(values, dtype=np.float64)
    if a.size and (a == a.flat[0]).all():
        x = float(a.flat[0])
        return x if math.isfinite(x) else None
    if a.size > MAX_BOUNDS:
        return None
    if np.isfinite(a).all():
        return a.tolist()
    return np.where(np.isfinite(a), a.astype(object), None).tolist()


def _bound_from_json(value: Any, shape: tuple[int, ...], what: str) -> float | None | np.ndarray:
    """A bound read from JSON: a number, None (no bound) or a float64 array of ``shape`` (NaN where unbounded).
    Only a bound written out as lists is turned into an array (its size is that of the JSON it came from)."""
    if value is None:
        return None
    if isinstance(value, bool):
        raise SpaceError(f"{what} must be a number, a list of numbers or null")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise SpaceError(f"{what} must be finite (null for no bound)")
        return float(value)
    if not isinstance(value, list):
        raise SpaceError(f"{what} must be a number, a list of numbers or null")
    try:
        a = np.array(value, dtype=np.float64)  # null entries (no bound) come back as NaN
    except (TypeError, ValueError):
        raise SpaceError(f"{what} must be a number, a list of numbers or null") from None
    if a.shape != shape:
        raise SpaceError(f"{what} has shape {list(a.shape)}, the space {list(shape)}")
    if np.isinf(a).any():
        raise SpaceError(f"{what} must be finite (null for no bound)")
    return a


def _full(bound: float | None | np.ndarray, shape: tuple[int, ...], default: float, dtype: np.dtype) -> np.ndarray:
    if bound is None:
        return np.full(shape, default, dtype=np.float64)
    if isinstance(bound, float):
        return np.full(shape, bound, dtype=np.float64)
    return np.where(np.isnan(bound), default, bound)


def space_to_dict(space: spaces.Space) -> dict[str, Any]:
    """``space`` as plain JSON (see the module docstring); :class:`SpaceError` for a space policies cannot play."""
    if isinstance(space, spaces.Discrete):
        _no_start(space)
        return {"kind": "discrete", "n": int(space.n)}
    if isinstance(space, spaces.MultiDiscrete):
        _no_start(space)
        return {"kind": "multidiscrete", "nvec": np.asarray(space.nvec).astype(int).tolist(),
                "dtype": str(np.dtype(space.dtype))}
    if isinstance(space, spaces.Box):
        return {"kind": "box", "shape": [int(d) for d in space.shape], "dtype": str(np.dtype(space.dtype)),
                "low": _bound_to_json(space.low), "high": _bound_to_json(space.high)}
    raise SpaceError(f"{describe_space(space)} spaces are not supported (Box, Discrete or MultiDiscrete)")


def _int_list(value: Any, what: str) -> list[int]:
    if not isinstance(value, list) or not all(isinstance(d, int) and not isinstance(d, bool) for d in value):
        raise SpaceError(f"{what} must be a list of integers")
    return value


def _parse(data: Any, limit: int) -> tuple[str, dict[str, Any]]:
    """Check a space's JSON without building anything big; returns its kind and its parsed fields."""
    if not isinstance(data, dict):
        raise SpaceError(f"a space must be an object, not {type(data).__name__}")
    kind = data.get("kind")
    if kind == "discrete":
        n = data.get("n")
        if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= limit:
            raise SpaceError(f"Discrete n must be an integer from 1 to {limit:,}")
        return kind, {"n": n}
    if kind == "multidiscrete":
        nvec = _int_list(data.get("nvec"), "MultiDiscrete nvec")
        if not 1 <= len(nvec) <= limit or any(not 1 <= d <= limit for d in nvec):
            raise SpaceError(f"MultiDiscrete nvec must hold 1 to {limit:,} integers from 1 to {limit:,}")
        return kind, {"nvec": nvec, "dtype": _dtype(data.get("dtype", "int64"), integer=True)}
    if kind == "box":
        shape = tuple(_int_list(data.get("shape"), "Box shape"))
        if not 1 <= len(shape) <= 8 or any(d < 1 for d in shape) or math.prod(shape) > limit:
            raise SpaceError(f"Box shape {list(shape)[:9]} is out of bounds (1 to 8 sizes >= 1, at most {limit:,} "
                             "numbers)")
        dtype = _dtype(data.get("dtype", "float32"))
        low = _bound_from_json(data.get("low"), shape, "Box low")
        high = _bound_from_json(data.get("high"), shape, "Box high")
        if low is not None and high is not None and bool(np.any(np.asarray(low) > np.asarray(high))):
            raise SpaceError("Box low exceeds high")
        return kind, {"shape": shape, "dtype": dtype, "low": low, "high": high}
    raise SpaceError(f"unknown space kind {str(kind)[:40]!r}; known: {', '.join(KINDS)}")


def canonical_space(data: Any, limit: int = 1 << 24) -> dict[str, Any]:
    """A space's JSON checked (:class:`SpaceError`) and in its one canonical form (what :func:`space_to_dict`
    writes), without building the space: a crafted description allocates nothing beyond its own size. ``limit``
    bounds a Box's numbers, a Discrete's n and a MultiDiscrete's entries."""
    if isinstance(data, spaces.Space):
        return space_to_dict(data)
    kind, f = _parse(data, limit)
    if kind == "discrete":
        return {"kind": kind, "n": f["n"]}
    if kind == "multidiscrete":
        return {"kind": kind, "nvec": f["nvec"], "dtype": str(f["dtype"])}
    bounds = {k: (f[k] if not isinstance(f[k], np.ndarray) else _bound_to_json(np.where(np.isnan(f[k]), default, f[k])))
              for k, default in (("low", -np.inf), ("high", np.inf))}
    return {"kind": kind, "shape": list(f["shape"]), "dtype": str(f["dtype"]), **bounds}


def space_from_dict(data: Any, limit: int = 1 << 24) -> spaces.Space:
    """Inverse of :func:`space_to_dict`; :class:`SpaceError` names what is wrong. ``limit`` bounds the numbers a
    Box holds and the entries of a MultiDiscrete (checked before anything is allocated)."""
    kind, f = _parse(data, limit)
    if kind == "discrete":
        return spaces.Discrete(f["n"])
    if kind == "multidiscrete":
        return spaces.MultiDiscrete(np.array(f["nvec"], dtype=f["dtype"]), dtype=f["dtype"])
    shape, dtype = f["shape"], f["dtype"]
    low = _full(f["low"], shape, -np.inf, dtype)
    high = _full(f["high"], shape, np.inf, dtype)
    if np.issubdtype(dtype, np.integer):  # integer Boxes cannot hold infinite bounds: the dtype's limits
        info = np.iinfo(dtype)
        low, high = np.clip(low, info.min, info.max), np.clip(high, info.min, info.max)
    return spaces.Box(low.astype(dtype), high.astype(dtype), shape=shape, dtype=dtype)


def _dtype(name: Any, integer: bool = False) -> np.dtype:
    allowed = ("int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64")
    if not integer:
        allowed += ("float16", "float32", "float64", "bool")
    if not isinstance(name, str) or name not in allowed:
        raise SpaceError(f"space dtype must be one of {', '.join(allowed)}, not {str(name)[:20]!r}")
    return np.dtype(name)


def _no_start(space: spaces.Space) -> None:
    start = np.asarray(getattr(space, "start", 0))
    if start.any():
        raise SpaceError(f"{describe_space(space)}: action spaces must start at 0 (start={start.tolist()})")


def box_of_shape(shape: tuple[int, ...]) -> spaces.Box:
    """An unbounded float32 Box of ``shape`` (what a snapshot written before spaces were recorded observes)."""
    return spaces.Box(-np.inf, np.inf, shape=tuple(int(d) for d in shape), dtype=np.float32)


# ---------------------------------------------------------------------------------------------------------------
# The action head a space calls for


@dataclass(frozen=True)
class ActionHead:
    """What a network's action head outputs for an action space, and how its outputs become actions.

    ``kind`` is ``discrete`` (``n`` logits), ``multidiscrete`` (``sum(nvec)`` logits, one block per dimension) or
    ``box`` (a Gaussian: ``prod(shape)`` means and a learned state-independent log-std per dimension).
    ``outputs`` is the width of the head's Linear layer; ``mask_width`` the width of a mask (0: no masks).
    """

    kind: str
    nvec: tuple[int, ...] = ()  # discrete: (n,); multidiscrete: nvec
    shape: tuple[int, ...] = ()  # box: the action shape
    low: tuple[float, ...] = ()  # box: flat bounds
    high: tuple[float, ...] = ()

    @classmethod
    def of(cls, space: spaces.Space | int) -> ActionHead:
        """The head for an action space (an int ``n`` means ``Discrete(n)``); :class:`SpaceError` otherwise."""
        if isinstance(space, (int, np.integer)) and not isinstance(space, bool):
            if int(space) < 1:
                raise SpaceError(f"a discrete action space needs at least one action, not {int(space)}")
            return cls("discrete", (int(space),))
        if isinstance(space, spaces.Discrete):
            _no_start(space)
            return cls("discrete", (int(space.n),))
        if isinstance(space, spaces.MultiDiscrete):
            _no_start(space)
            nvec = np.asarray(space.nvec)
            if nvec.ndim != 1:
                raise SpaceError(f"{describe_space(space)}: MultiDiscrete actions must be one-dimensional")
            return cls("multidiscrete", tuple(int(v) for v in nvec))
        if isinstance(space, spaces.Box):
            low = np.asarray(space.low, dtype=np.float64).reshape(-1)
            high = np.asarray(space.high, dtype=np.float64).reshape(-1)
            if not (np.isfinite(low).all() and np.isfinite(high).all()):
                raise SpaceError(f"{describe_space(space)}: Box actions need finite bounds")
            if not np.issubdtype(space.dtype, np.floating):
                raise SpaceError(f"{describe_space(space)}: Box actions must be floating point")
            return cls("box", shape=tuple(int(d) for d in space.shape), low=tuple(low.tolist()),
                       high=tuple(high.tolist()))
        raise SpaceError(f"{describe_space(space)} actions are not supported (Discrete, MultiDiscrete or Box)")

    @property
    def outputs(self) -> int:
        return math.prod(self.shape) if self.kind == "box" else sum(self.nvec)

    @property
    def mask_width(self) -> int:
        return 0 if self.kind == "box" else sum(self.nvec)

    @property
    def action_shape(self) -> tuple[int, ...]:
        """The shape of one action: ``()`` Discrete, ``(k,)`` MultiDiscrete, the Box's shape."""
        return {"discrete": (), "multidiscrete": (len(self.nvec),)}.get(self.kind, self.shape)

    def describe(self) -> str:
        if self.kind == "discrete":
            return f"Discrete({self.nvec[0]})"
        if self.kind == "multidiscrete":
            return f"MultiDiscrete({list(self.nvec)})"
        return f"Box({min(self.low):g}, {max(self.high):g}, {self.shape})"

    def check_mask(self, mask: Any, batch: int) -> np.ndarray | None:
        """``mask`` as a ``(batch, mask_width)`` bool array, or None; ValueError for a mask that does not fit."""
        if mask is None:
            return None
        if self.kind == "box":
            raise ValueError("Box actions take no action mask")
        m = np.asarray(mask, dtype=bool)
        if m.shape != (batch, self.mask_width):
            raise ValueError(f"mask has shape {tuple(m.shape)}; expected {(batch, self.mask_width)}")
        return m


def uniform_allowed(mask: np.ndarray, u: np.ndarray) -> np.ndarray:
    """For each row of ``mask`` ``(B, n)`` the allowed action of rank ``floor(u * allowed)`` (``u`` in [0, 1), one
    per row): uniform over the allowed actions. ValueError when a row allows nothing."""
    counts = mask.sum(axis=1)
    if not counts.all():
        raise ValueError("the action mask allows no action in some rows")
    rank = np.minimum((u * counts).astype(np.int64), counts - 1)
    return (np.cumsum(mask, axis=1) > rank[:, None]).argmax(axis=1)


def pad_index(nvec: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """For a MultiDiscrete head: ``(k, max(nvec))`` indices into the ``sum(nvec)`` logits (0 where padded) and the
    matching validity mask. ``logits[:, index]`` lays the dimensions out as rows of one padded tensor."""
    k, width = len(nvec), max(nvec)
    index = np.zeros((k, width), dtype=np.int64)
    valid = np.zeros((k, width), dtype=bool)
    offset = 0
    for j, n in enumerate(nvec):
        index[j, :n] = np.arange(offset, offset + n)
        valid[j, :n] = True
        offset += n
    return index, valid

