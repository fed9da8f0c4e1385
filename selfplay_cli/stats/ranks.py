"""Ranks, an order and tiers from claims about pairs: which player is above which beyond doubt.

A ladder's ratings order players by one number each, but what it may *claim* is about pairs (:mod:`.predict`): that
one player is above another beyond doubt, the pair's own games taken in. Self-play is full of rock-paper-scissors, so
those claims need not follow the ratings: a snapshot rated first through its games against the rest may lose to one
below it, head to head, beyond doubt. This module turns the claims into what a ladder shows:

* :func:`claims_order`: a player's *rank* is one more than the players above it beyond doubt (as Chatbot Arena ranks:
  players the games cannot order share one); the rows go so that nobody stands over a player that is above it beyond
  doubt (a topological order of the claims, the smallest rank then the highest rating first among those free to
  go), unless the claims themselves go round in a circle (A above B above C above A, each beyond doubt), where the
  circle is broken at its player of smallest rank and highest rating;
* :func:`tiers`: walking down that order, a tier boundary falls between two places only where every player of the
  tier it closes is above every player below it beyond doubt.

numpy only.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["claims_order", "tiers"]


def claims_order(above: npt.ArrayLike, ratings: npt.ArrayLike) -> tuple[list[int], list[int]]:
    """The rows' order (positions into ``above``) and each player's rank, from ``above[a, b]``: player ``a`` is above
    player ``b`` beyond doubt (see the module docstring); ``ratings`` break ties (higher first), then position."""
    sure = np.asarray(above, dtype=bool).copy()
    np.fill_diagonal(sure, False)
    r = np.asarray(ratings, dtype=np.float64)
    m = sure.shape[0]
    ranks = [1 + int(sure[:, b].sum()) for b in range(m)]
    key = sorted(range(m), key=lambda b: (ranks[b], -r[b], b))  # the preference among those free to go
    left = set(range(m))
    order: list[int] = []
    while left:
        free = [b for b in key if b in left and not any(sure[a, b] for a in left)]
        pick = free[0] if free else next(b for b in key if b in left)  # a circle of claims: broken at its first
        order.append(pick)
        left.remove(pick)
    return order, ranks


def tiers(above: npt.ArrayLike, order: list[int]) -> list[int]:
    """Each position's tier along ``order`` (positions into ``above``), in that order: a boundary falls between two
    places only where every player of the tier it closes is above every player below it beyond doubt."""
    sure = np.asarray(above, dtype=bool)[np.ix_(order, order)]
    out, start, tier = [], 0, 1
    for a in range(len(order)):
        out.append(tier)
        if a + 1 < len(order) and sure[start:a + 1, a + 1:].all():
            start, tier = a + 1, tier + 1
    return out
