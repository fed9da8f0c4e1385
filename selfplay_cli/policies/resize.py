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


_ORDINALS = ("first", "second", "third", "fourth", "fifth", "sixth", "seventh", "eighth", "ninth", "tenth")


def _ordinal(i: int) -> str:
    """``0`` -> ``first``, ``10`` -> ``11th``: member ``i`` (from 0) in words."""
    n = i + 1
    if n <= len(_ORDINALS):
        return _ORDINALS[i]
    return f"{n}{'th' if 10 <= n % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')}"


def _some_of(low: int, high: int) -> str:
    """One of the members ``low .. high - 1``, in words: ``the third member``, ``the third or the fourth member``,
    ``members from the third to the sixth``."""
    if high - low == 1:
        return f"the {_ordinal(low)} member"
    if high - low == 2:
        return f"the {_ordinal(low)} or the {_ordinal(low + 1)} member"
    return f"members from the {_ordinal(low)} to the {_ordinal(high - 1)}"


def _all_of(low: int, high: int) -> str:
    """All the members ``low .. high - 1``, in words."""
    if high - low == 1:
        return f"the {_ordinal(low)} member"
    if high - low == 2:
        return f"the {_ordinal(low)} and the {_ordinal(low + 1)} members"
    return f"the members from the {_ordinal(low)} to the {_ordinal(high - 1)}"


def describe_resize(n_have: int, n_want: int, drawn_from: str = "the run's seed") -> str:
    """The rule :func:`resize_members` applied to a team of ``n_have`` flown as ``n_want``, in words that name the
    members the draw takes from for this team (a team of 2 has no third member); the draw comes from
    ``drawn_from``."""
    head = f"{n_have} member{'s' * (n_have > 1)}, {n_want} seat{'s' * (n_want > 1)}: "
    if n_want == n_have:
        return head + ("each member keeps its place" if n_have > 1 else "the member keeps its place")
    if n_want > n_have:
        extra = n_want - n_have
        seats = f"{extra} more seat{'s' * (extra > 1)} " + ("flies a copy of " if extra == 1 else "fly copies of ")
        if n_have == 1:
            return head + f"it keeps its place; {seats}it"
        low = KEPT if n_have > KEPT else 0  # as resize_members draws
        kept = "both keep their places" if n_have == 2 else f"the {n_have} keep their places"
        draw = "" if n_have - low == 1 else f", {'drawn' if extra == 1 else 'each drawn'} at random from {drawn_from}"
        return head + f"{kept}; {seats}{_some_of(low, n_have)}{draw}"
    if n_want < KEPT:  # the first n_want keep their places, whatever the draw dropped
        others = n_have - n_want
        gone = f"the {_ordinal(1)} is dropped" if n_have == 2 else f"the other {others} are dropped"
        return head + f"the first member flies alone; {gone}"
    dropped, droppable = n_have - n_want, n_have - KEPT
    if dropped == droppable:  # all of them: nothing to draw
        return head + (f"the first {KEPT} keep their places; {_all_of(KEPT, n_have)} "
                       f"{'is' if dropped == 1 else 'are'} dropped")
    return head + (f"the first {KEPT} keep their places; {dropped} of {_all_of(KEPT, n_have)} "
                   f"{'is' if dropped == 1 else 'are'} dropped, drawn at random from {drawn_from}; the others keep "
                   "their order")
