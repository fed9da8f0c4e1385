"""Actions to replay a game: a compact encoding for the ledger, the log both game loops keep them in, and a policy
that plays them back.

A game core is deterministic given its seed, its options and every step's actions (randomness is counter-based,
see :mod:`selfplay_cli.envs.pong`), so the actions are all the ledger needs to re-render a game exactly as it
was played, whoever played it: networks, sampling policies or bots with their own generators.

Encoding, version 1 (games whose seats all have Discrete actions): ``b"MA"``, the version byte, the bits per action
(1, 2, 4, 8, 16 or 32: the fewest that hold the largest action), the number of seats (one byte) and of steps (four
bytes, little-endian), then the zlib-compressed actions in seat-major order (all of seat 0's steps, then seat 1's),
packed that many bits to a value, low bits first. Seat-major keeps a paddle's long runs of one action together for
zlib; packing Pong's three actions four to a byte makes the input a quarter the size, so compression is both smaller
and five times faster (about 1.4 kB and 0.1 ms for a game of 4,500 steps against a random player).

Version 2 (any seat with MultiDiscrete or Box actions): ``b"MA"``, version 2, the number of seats (one byte) and of
steps (four bytes), then per seat its kind (one byte: 0 Discrete, 1 MultiDiscrete, 2 Box), the number of dimensions
of one action (one byte) and each dimension (two bytes), then the bits per integer value (one byte, as in version
1). The zlib-compressed payload holds the integer columns (Discrete and MultiDiscrete values, seat by seat and
column by column, each column all its steps) packed as in version 1, then the Box columns as little-endian float32,
column by column: the exact values the game was given. Version 1 stays readable, and is still what a game of
Discrete actions writes (its bytes do not change).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import MarlError
from ..policies import Policy

if TYPE_CHECKING:
    from ..envs import EnvSpec

_MAGIC = b"MA"
_VERSION = 1
_VERSION_2 = 2
_HEADER = struct.Struct("<2sBBBI")  # magic, version, bits per action, seats, steps
_HEADER_2 = struct.Struct("<2sBBI")  # magic, version, seats, steps
_SEAT = struct.Struct("<BB")  # kind, dimensions of one action
_BITS = (1, 2, 4, 8, 16, 32)
_WIDE = {16: np.dtype("<u2"), 32: np.dtype("<u4")}
DISCRETE, MULTI_DISCRETE, BOX = 0, 1, 2
_KIND_NAMES = {DISCRETE: "Discrete", MULTI_DISCRETE: "MultiDiscrete", BOX: "Box"}


def action_dtype(n_actions: int | None) -> np.dtype:
    """The narrowest unsigned type that holds actions ``0 .. n_actions - 1`` (32 bits when unknown)."""
    if n_actions is not None and n_actions <= 256:
        return np.dtype(np.uint8)
    if n_actions is not None and n_actions <= 65536:
        return np.dtype("<u2")
    return np.dtype("<u4")


def _pack(values: np.ndarray, bits: int) -> bytes:
    if bits in _WIDE:
        return values.astype(_WIDE[bits]).tobytes()
    per = 8 // bits
    flat = np.zeros(-(-values.size // per) * per, dtype=np.uint8)
    flat[: values.size] = values
    shifts = (np.arange(per, dtype=np.uint8) * bits).astype(np.uint8)
    return np.bitwise_or.reduce(flat.reshape(-1, per) << shifts, axis=1).astype(np.uint8).tobytes()


def _packed_size(count: int, bits: int) -> int:
    return count * bits // 8 if bits in _WIDE else -(-count // (8 // bits))


def _unpack(data: bytes, bits: int, count: int) -> np.ndarray:
    if bits in _WIDE:
        return np.frombuffer(data, dtype=_WIDE[bits])[:count].astype(np.int64)
    per = 8 // bits
    shifts = (np.arange(per, dtype=np.uint8) * bits).astype(np.uint8)
    values = (np.frombuffer(data, dtype=np.uint8)[:, None] >> shifts) & np.uint8((1 << bits) - 1)
    return values.ravel()[:count].astype(np.int64)


def _bits_for(values: np.ndarray) -> int:
    if values.size and (values.min() < 0 or values.max() >= 2**32):
        raise ValueError("only integer actions in [0, 2**32) can be stored")
    top = int(values.max()) if values.size else 0
    return next(b for b in _BITS if top < 2**b)


def encode_actions(actions: np.ndarray | Sequence[np.ndarray]) -> bytes:
    """A game's actions -> bytes for ``games.actions``.

    ``actions`` is either a ``(steps, seats)`` array of non-negative integers (every seat Discrete: version 1) or one
    array per seat, ``(steps, *action_shape)``: integer 1-D (Discrete), integer of more dimensions (MultiDiscrete),
    float (Box, stored as float32) -- version 2, unless every seat is Discrete (then version 1)."""
    if not isinstance(actions, np.ndarray):
        seats = [np.asarray(a) for a in actions]
        if seats and all(a.ndim == 1 and a.dtype.kind in "iub" for a in seats):
            actions = np.stack(seats, axis=1) if len({len(a) for a in seats}) == 1 else None  # type: ignore[assignment]
            if actions is None:
                raise ValueError("every seat needs one action per step")
        else:
            return _encode_v2(seats)
    a = np.asarray(actions)
    if a.ndim != 2 or not 1 <= a.shape[1] <= 255:
        raise ValueError(f"actions must be (steps, seats) with 1 to 255 seats, got shape {a.shape}")
    bits = _bits_for(a)
    payload = zlib.compress(_pack(np.ascontiguousarray(a.T).ravel(), bits), 6)
    return _HEADER.pack(_MAGIC, _VERSION, bits, a.shape[1], a.shape[0]) + payload


def _encode_v2(seats: list[np.ndarray]) -> bytes:
    if not 1 <= len(seats) <= 255:
        raise ValueError(f"actions of 1 to 255 seats can be stored, not {len(seats)}")
    steps = {len(a) for a in seats}
    if len(steps) != 1:
        raise ValueError("every seat needs one action per step")
    n_steps = steps.pop()
    head = [_HEADER_2.pack(_MAGIC, _VERSION_2, len(seats), n_steps)]
    ints: list[np.ndarray] = []
    floats: list[np.ndarray] = []
    for a in seats:
        shape = a.shape[1:]
        if len(shape) > 255 or any(not 0 < d < 65536 for d in shape):
            raise ValueError(f"an action of shape {shape} cannot be stored")
        if a.dtype.kind == "f":
            kind = BOX
            floats.append(np.ascontiguousarray(a.reshape(n_steps, -1).T.astype("<f4")))
        elif a.dtype.kind in "iub":
            kind = DISCRETE if a.ndim == 1 else MULTI_DISCRETE
            ints.append(np.ascontiguousarray(a.reshape(n_steps, -1).T))
        else:
            raise ValueError(f"actions of dtype {a.dtype} cannot be stored")
        head.append(_SEAT.pack(kind, len(shape)) + struct.pack(f"<{len(shape)}H", *shape))
    int_values = np.concatenate([x.ravel() for x in ints]) if ints else np.zeros(0, dtype=np.int64)
    bits = _bits_for(int_values)
    head.append(struct.pack("<B", bits))
    body = _pack(int_values, bits) + b"".join(x.tobytes() for x in floats)
    return b"".join(head) + zlib.compress(body, 6)


def _unknown() -> MarlError:
    return MarlError("the stored actions are in an unknown format (written by a newer marl?)")


def decode_actions(blob: bytes, n_seats: int, length: int | None = None) -> np.ndarray | list[np.ndarray]:
    """Inverse of :func:`encode_actions`: a ``(steps, n_seats)`` int64 array (version 1), or one array per seat
    (version 2: ``(steps,)`` int64 Discrete, ``(steps, *shape)`` int64 MultiDiscrete, ``(steps, *shape)`` float32
    Box). ``length`` (steps) is checked if given. :func:`seat_actions` gives either as one array per seat."""
    if len(blob) < 4 or blob[:2] != _MAGIC:
        raise _unknown()
    if blob[2] == _VERSION_2:
        return _decode_v2(blob, n_seats, length)
    if len(blob) < _HEADER.size:
        raise _unknown()
    magic, version, bits, seats, steps = _HEADER.unpack_from(blob)
    if magic != _MAGIC or version != _VERSION or bits not in _BITS:
        raise _unknown()
    _check_size(seats, steps, n_seats, length)
    raw = _inflate(blob[_HEADER.size :])
    if len(raw) * 8 < seats * steps * bits:
        raise MarlError("the stored actions are cut short")
    return _unpack(raw, bits, seats * steps).reshape(seats, steps).T


def _check_size(seats: int, steps: int, n_seats: int, length: int | None) -> None:
    if seats != n_seats:
        raise MarlError(f"the stored actions are for {seats} seats, the game has {n_seats}")
    if length is not None and steps != length:
        raise MarlError(f"the stored actions cover {steps} steps, the game lasted {length}")


def _inflate(data: bytes) -> bytes:
    try:
        return zlib.decompress(data)
    except zlib.error as e:
        raise MarlError(f"the stored actions are corrupt ({e})") from None


def _decode_v2(blob: bytes, n_seats: int, length: int | None) -> list[np.ndarray]:
    if len(blob) < _HEADER_2.size:
        raise _unknown()
    _, _, seats, steps = _HEADER_2.unpack_from(blob)
    _check_size(seats, steps, n_seats, length)
    at = _HEADER_2.size
    layout: list[tuple[int, tuple[int, ...]]] = []
    try:
        for _ in range(seats):
            kind, ndim = _SEAT.unpack_from(blob, at)
            at += _SEAT.size
            shape = struct.unpack_from(f"<{ndim}H", blob, at)
            at += 2 * ndim
            if kind not in _KIND_NAMES or (kind == DISCRETE) != (ndim == 0):
                raise _unknown()
            layout.append((kind, tuple(shape)))
        (bits,) = struct.unpack_from("<B", blob, at)
        at += 1
    except struct.error:
        raise _unknown() from None
    if bits not in _BITS:
        raise _unknown()
    raw = _inflate(blob[at:])
    n_int = sum(int(np.prod(shape)) for kind, shape in layout if kind != BOX) * steps
    n_float = sum(int(np.prod(shape)) for kind, shape in layout if kind == BOX) * steps
    int_bytes = _packed_size(n_int, bits)
    if len(raw) < int_bytes + 4 * n_float:
        raise MarlError("the stored actions are cut short")
    ints = _unpack(raw[:int_bytes], bits, n_int)
    floats = np.frombuffer(raw, dtype="<f4", count=n_float, offset=int_bytes)
    out: list[np.ndarray] = []
    i = f = 0
    for kind, shape in layout:
        width = int(np.prod(shape))
        if kind == BOX:
            cols, f = floats[f : f + width * steps], f + width * steps
            out.append(cols.reshape(width, steps).T.reshape(steps, *shape).astype(np.float32))
        else:
            cols, i = ints[i : i + width * steps], i + width * steps
            out.append(cols.reshape(width, steps).T.reshape(steps, *shape))
    return out


def seat_actions(actions: np.ndarray | Sequence[np.ndarray]) -> list[np.ndarray]:
    """What :func:`decode_actions` returns, as one array per seat (a version-1 array's columns)."""
    if isinstance(actions, np.ndarray):
        if actions.ndim != 2:
            raise ValueError(f"actions must be (steps, seats), got shape {actions.shape}")
        return [actions[:, i] for i in range(actions.shape[1])]
    return list(actions)


# -------------------------------------------------------------------------------------------- the game loops' log


@dataclass(frozen=True)
class SeatActions:
    """What one seat's action is: ``kind`` (:data:`DISCRETE`, :data:`MULTI_DISCRETE`, :data:`BOX`), the ``shape``
    of one action (``()`` for Discrete), its dtype (int64 or float32) and, for integer actions, the largest value."""

    kind: int
    shape: tuple[int, ...]
    top: int | None = None

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.float32) if self.kind == BOX else np.dtype(np.int64)

    @property
    def width(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1

    @classmethod
    def of(cls, space: Any) -> SeatActions:
        """The action of a gymnasium ``Discrete``, ``MultiDiscrete`` or ``Box`` space."""
        from gymnasium import spaces

        if isinstance(space, spaces.Discrete):
            return cls(DISCRETE, (), int(space.start) + int(space.n) - 1)
        if isinstance(space, spaces.MultiDiscrete):
            return cls(MULTI_DISCRETE, tuple(space.nvec.shape), int(np.max(space.nvec)) - 1)
        if isinstance(space, spaces.Box):
            return cls(BOX, tuple(space.shape))
        raise ValueError(f"unsupported action space {space}: Discrete, MultiDiscrete or Box")


def action_layout(spec: EnvSpec, env_options: dict[str, Any] | None = None) -> list[SeatActions]:
    """Each seat's :class:`SeatActions`, from the game's declaration."""
    return [SeatActions.of(s.action) for s in spec.seat_spaces(spec.config(**(env_options or {})))]


class _Columns:
    """Every step's values of ``n_cols`` columns of every slot, kept from the first step of the oldest running game
    on (see :class:`ActionLog`)."""

    BLOCK = 256

    def __init__(self, n_cols: int, n_slots: int, dtype: np.dtype) -> None:
        self.block = np.zeros((self.BLOCK, n_cols, n_slots), dtype=dtype)  # the current block, step-major
        self.filled = 0
        self.blocks: list[tuple[int, np.ndarray]] = []  # (first step, (slots, cols, BLOCK) slot-major)
        self.now = 0

    def commit(self, start: np.ndarray, active: np.ndarray | None) -> None:
        """The current row is complete; ``start``: the first step of every slot's game, ``active``: the slots with
        a game running (None: all)."""
        self.filled += 1
        self.now += 1
        if self.filled == self.BLOCK:
            self.blocks.append((self.now - self.BLOCK, np.ascontiguousarray(self.block.transpose(2, 1, 0))))
            self.filled = 0
            running = start if active is None else start[active]
            oldest = int(running.min()) if running.size else self.now
            self.blocks = [(first, b) for first, b in self.blocks if first + self.BLOCK > oldest]

    def take(self, slot: int, begin: int) -> np.ndarray:
        """``(cols, steps)`` of the game in ``slot`` that began at step ``begin``."""
        parts = [b[slot, :, max(begin - first, 0):] for first, b in self.blocks if first + self.BLOCK > begin]
        tail = self.now - self.filled  # step number of the current block's first row
        parts.append(self.block[max(begin - tail, 0) : self.filled, :, slot].T)
        return np.concatenate(parts, axis=1)


class ActionLog:
    """Every step's actions of every slot, kept from the first step of the oldest running game on.

    Steps are appended to a step-major block (one contiguous row per step, a few kilobytes); every ``BLOCK`` steps
    the block is transposed once to slot-major, so a finished game's actions are a few contiguous pieces to join
    rather than a gather across the whole log (which cost a match a fifth of its speed). Blocks that no running
    game reaches back to are dropped, so the log's size follows the longest game, not the schedule.

    A game whose seats all have Discrete actions keeps one integer column per seat (the narrowest type that holds
    them) and takes ``(seats, slots)`` arrays; any other keeps integer and float32 columns (a MultiDiscrete seat one
    per dimension, a Box seat one per value) and takes one ``(slots, *shape)`` array per seat.
    """

    BLOCK = _Columns.BLOCK

    def __init__(self, layout: Sequence[SeatActions], n_slots: int) -> None:
        self.layout = list(layout)
        self.n_seats = len(self.layout)
        self.start = np.zeros(n_slots, dtype=np.int64)  # step number at which each slot's game began
        self.discrete = all(s.kind == DISCRETE for s in self.layout)
        tops = [s.top for s in self.layout if s.kind != BOX]
        int_dtype = action_dtype(max(t for t in tops if t is not None) + 1 if tops and None not in tops else None)
        if self.discrete:
            self.ints = _Columns(self.n_seats, n_slots, int_dtype)
            self.floats = None
            return
        self.columns: list[tuple[bool, int, int]] = []  # per seat: float?, first column, width
        n_int = n_float = 0
        for s in self.layout:
            if s.kind == BOX:
                self.columns.append((True, n_float, s.width))
                n_float += s.width
            else:
                self.columns.append((False, n_int, s.width))
                n_int += s.width
        self.ints = _Columns(n_int, n_slots, int_dtype)
        self.floats = _Columns(n_float, n_slots, np.dtype(np.float32)) if n_float else None

    @classmethod
    def for_env(cls, spec: EnvSpec, n_slots: int, env_options: dict[str, Any] | None = None) -> ActionLog:
        """A log for ``n_slots`` games of ``spec``."""
        return cls(action_layout(spec, env_options), n_slots)

    @property
    def now(self) -> int:
        return self.ints.now

    def begin(self, slots: np.ndarray) -> None:
        self.start[slots] = self.now

    def append(self, actions: np.ndarray | Sequence[np.ndarray], active: np.ndarray | None = None) -> None:
        """One step's actions: a ``(seats, slots)`` array (Discrete games) or one ``(slots, *shape)`` array per
        seat; ``active`` marks the slots with a game running (default: all)."""
        if self.discrete:
            self.ints.block[self.ints.filled] = actions
            self.ints.commit(self.start, active)
            return
        ints = self.ints.block[self.ints.filled]
        floats = self.floats.block[self.floats.filled] if self.floats is not None else None
        for (is_float, first, width), a in zip(self.columns, actions, strict=True):
            target = floats if is_float else ints
            target[first : first + width] = np.asarray(a).reshape(-1, width).T  # type: ignore[index]
        self.ints.commit(self.start, active)
        if self.floats is not None:
            self.floats.commit(self.start, active)

    def take(self, slot: int) -> np.ndarray | list[np.ndarray]:
        """The actions of the game that just ended in ``slot``: ``(steps, seats)`` (Discrete games) or one
        ``(steps, *shape)`` array per seat, as :func:`encode_actions` takes them."""
        begin = int(self.start[slot])
        ints = self.ints.take(slot, begin)
        if self.discrete:
            return ints.T
        floats = self.floats.take(slot, begin) if self.floats is not None else None
        out = []
        for (is_float, first, width), s in zip(self.columns, self.layout, strict=True):
            cols = (floats if is_float else ints)[first : first + width]  # type: ignore[index]
            out.append(cols.T.reshape(-1, *s.shape).astype(s.dtype))
        return out


# ------------------------------------------------------------------------------------------------ replays


class ReplayError(MarlError):
    """A replay left the recorded game: the actions ran out, or it ended with another score or length."""


class ReplayPolicy(Policy):
    """Plays one seat of one recorded game: at game step t it returns the action recorded at step t, whatever it
    observes (:func:`~.matches.play` tells it of every step through :meth:`after_step`, so a seat that acts only on
    some steps of a turn-based game still finds its own).

    It stands in for the original player under that player's id, so a replay goes through the same game loop (and
    shows the same names) as the game did.
    """

    kind = "replay"

    def __init__(self, id: str, env: str, actions: np.ndarray) -> None:
        super().__init__(id, env)
        self.actions = np.asarray(actions)
        if self.actions.dtype.kind != "f":
            self.actions = self.actions.astype(np.int64)
        self.t = 0

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        if len(obs) != 1:
            raise ValueError("a replay plays one game at a time")
        if self.t >= len(self.actions):
            raise ReplayError(f"the recorded actions of {self.id} ran out after {self.t} steps: the game no longer "
                              "plays as it was recorded")
        return self.actions[self.t : self.t + 1]

    def after_step(self) -> None:
        """One game step was played."""
        self.t += 1


def replay_policies(players: tuple[str, ...] | list[str], env: str,
                    actions: np.ndarray | Sequence[np.ndarray]) -> list[ReplayPolicy]:
    """One :class:`ReplayPolicy` per seat (seat i is policy i, so the game is ``Game(seed, (0, 1, ...))``), from
    :func:`decode_actions`' answer."""
    seats = seat_actions(actions)
    if len(seats) != len(players):
        raise ValueError(f"{len(seats)} seats of actions for {len(players)} players")
    return [ReplayPolicy(p, env, a) for p, a in zip(players, seats, strict=True)]


def check_replay(result: Any, length: int, scores: Sequence[float]) -> None:
    """Raise :class:`ReplayError` unless a replayed game ended after ``length`` steps with ``scores``, as the ledger
    says it did (scores to within float rounding of their storage)."""
    from ..results import format_score

    got = np.asarray(result.scores, dtype=np.float64)
    want = np.asarray(scores, dtype=np.float64)
    if result.length != length or got.shape != want.shape or not np.allclose(got, want, rtol=1e-9, atol=1e-9):
        raise ReplayError(f"the replay ended {'-'.join(map(format_score, got))} after {result.length} steps, the "
                          f"ledger says {'-'.join(map(format_score, want))} after {length}: the game no longer plays "
                          "as it was recorded (changed rules or game options?)")
