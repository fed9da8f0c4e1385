"""Counter-based randomness for the built-in games: SplitMix64 as a hash, so a draw is a function of the game's key and
a counter, never of a generator's history.

Each game has a 64-bit key (:func:`game_key`, from its seed) and its n-th draw is ``uniform(key, n)``: a game
therefore plays the same alone or inside a batch of thousands, and a seed reproduces it without any global random
state. The numpy functions work on uint64 arrays (whose arithmetic wraps silently, which is what the hash wants); the
``*_int`` functions are the same hash in Python integers masked to 64 bits, bit for bit, for one game played in plain
floats (pong's scalar game).
"""

from __future__ import annotations

from typing import Any

import numpy as np

GOLDEN = 0x9E3779B97F4A7C15  # SplitMix64's increment and multipliers
M1 = 0xBF58476D1CE4E5B9
M2 = 0x94D049BB133111EB
MASK = 0xFFFFFFFFFFFFFFFF
UNIT = 1.0 / 9007199254740992.0  # 2**-53: the top 53 bits of a hash as a float in [0, 1)

_GOLDEN, _M1, _M2 = np.uint64(GOLDEN), np.uint64(M1), np.uint64(M2)


def mix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser of uint64 values (in place on ``z``, which it returns)."""
    z ^= z >> np.uint64(30)
    z *= _M1
    z ^= z >> np.uint64(27)
    z *= _M2
    z ^= z >> np.uint64(31)
    return z


def splitmix64(x: Any) -> np.ndarray:
    """SplitMix64 of uint64 values: the finaliser of ``x + golden``."""
    return mix64(np.asarray(x, dtype=np.uint64) + _GOLDEN)


def to_unit(bits: np.ndarray) -> np.ndarray:
    """Hashes as uniform float64 numbers in [0, 1): their top 53 bits."""
    return (bits >> np.uint64(11)).astype(np.float64) * UNIT


def game_key(seed: Any) -> np.ndarray:
    """The 64-bit keys of games from their seeds (any integers; negative seeds wrap)."""
    return splitmix64(np.asarray(seed, dtype=np.int64).astype(np.uint64))


def uniform(keys: np.ndarray, counter: Any) -> np.ndarray:
    """The uniform [0, 1) draw number ``counter`` (integers, broadcast against ``keys``) of the games with ``keys``:
    ``hash(key ^ hash(counter))``."""
    return to_unit(splitmix64(keys ^ splitmix64(np.asarray(counter, dtype=np.int64).astype(np.uint64))))


def splitmix64_int(x: int) -> int:
    """:func:`splitmix64` of one non-negative Python integer below 2**64."""
    z = (x + GOLDEN) & MASK
    z ^= z >> 30
    z = (z * M1) & MASK
    z ^= z >> 27
    z = (z * M2) & MASK
    return z ^ (z >> 31)


def game_key_int(seed: int) -> int:
    """:func:`game_key` of one seed in 64 signed bits, as a Python integer."""
    return splitmix64_int(int(seed) & MASK)


def uniform_int(key: int, counter: int) -> float:
    """:func:`uniform` of one game's key and one counter, in Python numbers."""
    return (splitmix64_int(key ^ splitmix64_int(counter)) >> 11) * UNIT
