"""Ranks, an order and tiers from claims about pairs: which player is above which beyond doubt.

A ladder's ratings order players by one number each, but what it may *claim* is about pairs (:mod:`.predict`): that
one player is above another beyond doubt, the pair's own games taken in. Self-play is full of rock-paper-scissors, so
those claims need not follow the ratings: a snapshot rated first through its games against the rest may lose to one
below it, head to head, beyond doubt. This module turns the claims into what a ladder shows:

* :func:`claims_order`: a player's *rank* is one more than the players above it beyond doubt (as Chatbot Arena ranks:
  players the games cannot order share one); the rows go so that nobody stands over a player that is above it beyond
  doubt (a topological order of the claims, the smallest rank then the highest rating first among those free to
  go), unless the claims themselves go round in a circle (A above B above C above A, each beyond doubt: self-play's
  rock-paper-scissors, measured): players tied up in circles stand together, by rank and rating, and the circles
  are said;
* :func:`tiers`: walking down that order, a tier boundary falls between two places only where every player of the
  tier it closes is above every player below it beyond doubt.

numpy only.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["claims_order", "tiers"]


def claims_order(above: npt.ArrayLike, ratings: npt.ArrayLike
                 ) -> tuple[list[int], list[int], dict[int, tuple[int, ...]]]:
    """The rows' order (positions into ``above``), each player's rank, and the circles of claims, from ``above[a,
    b]``: player ``a`` is above player ``b`` beyond doubt (see the module docstring); ``ratings`` break ties (higher
    first), then position.

    The players whose claims go round in a circle (a strongly connected group of the claims) stand together, by rank
    and rating among themselves: no order of them keeps every claim. Between groups every claim is kept (the groups
    go in a topological order, the one whose first player has the smallest rank and highest rating first among those
    free to go). ``circles``: for each player of such a group, a shortest circle through it, ``(a, b, ..., z)``: a
    above b above ... above z above a."""
    sure = np.asarray(above, dtype=bool).copy()
    np.fill_diagonal(sure, False)
    r = np.asarray(ratings, dtype=np.float64)
    m = sure.shape[0]
    ranks = [1 + int(sure[:, b].sum()) for b in range(m)]

    def key(b: int) -> tuple[int, float, int]:
        return ranks[b], -r[b], b

    groups = _strong_groups(sure)
    group_of = {b: g for g, members in enumerate(groups) for b in members}
    members = [sorted(g, key=key) for g in groups]
    above_group = {(group_of[a], group_of[b]) for a, b in zip(*np.nonzero(sure), strict=True)
                   if group_of[a] != group_of[b]}
    left = set(range(len(groups)))
    order: list[int] = []
    while left:
        free = [g for g in left if not any((h, g) in above_group for h in left)]
        g = min(free, key=lambda g: key(members[g][0]))
        order += members[g]
        left.remove(g)
    circles = {b: _circle(sure, set(g), b) for g in groups if len(g) > 1 for b in g}
    return order, ranks, circles


def _strong_groups(sure: np.ndarray) -> list[list[int]]:
    """The strongly connected groups of the claims (Kosaraju, iteratively): players each of whom leads to every
    other by claims."""
    m = sure.shape[0]
    succ = [np.flatnonzero(sure[a]).tolist() for a in range(m)]
    pred = [np.flatnonzero(sure[:, b]).tolist() for b in range(m)]
    seen, finish = [False] * m, []
    for start in range(m):
        if seen[start]:
            continue
        seen[start] = True
        stack = [(start, iter(succ[start]))]
        while stack:
            node, it = stack[-1]
            nxt = next((y for y in it if not seen[y]), None)
            if nxt is None:
                finish.append(node)
                stack.pop()
            else:
                seen[nxt] = True
                stack.append((nxt, iter(succ[nxt])))
    group = [-1] * m
    out: list[list[int]] = []
    for start in reversed(finish):
        if group[start] >= 0:
            continue
        group[start] = len(out)
        members, todo = [start], [start]
        while todo:
            x = todo.pop()
            for y in pred[x]:
                if group[y] < 0:
                    group[y] = len(out)
                    members.append(y)
                    todo.append(y)
        out.append(sorted(members))
    return out


def _circle(sure: np.ndarray, group: set[int], a: int) -> tuple[int, ...]:
    """A shortest circle of claims through ``a`` within its strongly connected ``group``: ``(a, ..., z)``, a above
    the next ... and z above a (breadth first from a back to it)."""
    back: dict[int, int] = {}
    frontier, seen = [a], {a}
    while frontier:
        nxt = []
        for x in frontier:
            for y in sorted(group):
                if not sure[x, y]:
                    continue
                if y == a:  # back at a: the circle a -> ... -> x -> a
                    chain = [x]
                    while chain[-1] != a:
                        chain.append(back[chain[-1]])
                    return tuple(reversed(chain))
                if y not in seen:
                    seen.add(y)
                    back[y] = x
                    nxt.append(y)
        frontier = nxt
    return (a,)  # pragma: no cover - every member of a group of two or more lies on a circle


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
