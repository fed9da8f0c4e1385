"""A team of distinct policies flown at another team size: which member each new seat takes (seed 001's rule).

A team of ``n_have`` members, one per seat (NoPS: one network per agent), flown, or trained on, with ``n_want``
seats:

* the first agents keep their places: seat ``i`` takes member ``i`` while both exist;
* more seats: each extra seat is a copy of a member chosen at random (with replacement) from the third on (members
  ``2 .. n_have - 1``); a team of 1 or 2 members has no third member, so its copies are drawn from all its members;
* fewer seats: randomly chosen members from the third on are dropped (without replacement); the members kept stay
  in their order. Where that is not enough (fewer than 2 seats wanted from a bigger team, or a team of 2 flown
  alone), the first ``n_want`` of the members left are kept: the first agents keep their places.

The draw is a fixed function of ``seed`` (numpy's ``default_rng(seed)``), so a run, a match or a video seats the
same members every time it is given the same seed.
"""

from __future__ import annotations

import numpy as np

KEPT = 2
"""The members that always keep their places (seed 001: the first two agents); copies and drops come from the
members after them."""


def resize_members(n_have: int, n_want: int, seed: int) -> list[int]:
    """The member index (of a team of ``n_have`` members, in seat order) that each of ``n_want`` seats takes, by
    seed 001's rule (see the module docstring); ``seed`` fixes the draw."""
    if n_have < 1 or n_want < 1:
        raise ValueError(f"a team and its seats need at least one member each, not {n_have} and {n_want}")
    if n_want == n_have:
        return list(range(n_have))
    rng = np.random.default_rng(seed)
    if n_want > n_have:
        low = KEPT if n_have > KEPT else 0  # the third on; a team of 1 or 2: all of it
        extra = rng.integers(low, n_have, size=n_want - n_have)
        return list(range(n_have)) + [int(i) for i in extra]
    droppable = np.arange(KEPT, n_have)
    k = min(n_have - n_want, droppable.size)
    dropped = {int(i) for i in rng.choice(droppable, size=k, replace=False)} if k else set()
    return [i for i in range(n_have) if i not in dropped][:n_want]


def describe_resize(n_have: int, n_want: int, drawn_from: str = "the run's seed") -> str:
    """The rule :func:`resize_members` applied to a team of ``n_have`` flown as ``n_want``, in words (the draw comes
    from ``drawn_from``)."""
    if n_want == n_have:
        return f"{n_have} members, {n_want} seats: each member keeps its place"
    if n_want > n_have:
        pool = "members from the third on" if n_have > KEPT else "all its members"
        extra = n_want - n_have
        seats = f"{extra} more seat{'s' * (extra > 1)}"
        return (f"{n_have} members, {n_want} seats: the {n_have} keep their places; {seats} copy {pool}, drawn at "
                f"random from {drawn_from}")
    if n_want >= KEPT:
        dropped = n_have - n_want
        return (f"{n_have} members, {n_want} seats: {dropped} member{'s' * (dropped > 1)} from the third on "
                f"dropped, drawn at random from {drawn_from}; the others keep their order")
    return f"{n_have} members, {n_want} seat{'s' * (n_want > 1)}: the first {n_want} keep their places"
