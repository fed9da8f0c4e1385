"""Nash equilibria of zero-sum meta-games (players as pure strategies), numpy and scipy only.

The meta-game of a population: each of two sides picks a player, and the row side gets the payoff
``A[i, j]``, e.g. ``score(i vs j) - 0.5`` from the ledger. With ``A = -A^T`` (a symmetric zero-sum game, as any
matrix of head-to-head scores minus one half is), the game's value is 0 and an equilibrium mixture ``x`` is a
population mix that no single player beats on average: ``sum_i x_i A[i, j] >= 0`` for every ``j``.

Linear program (von Neumann's maximin, solved by :func:`scipy.optimize.linprog` with HiGHS)::

    maximise v   over x in R^n, v in R
    subject to   sum_i x_i A[i, j] >= v   for every column j
                 sum_i x_i = 1,  x >= 0

i.e. ``minimise -v`` with the inequality rows ``-A^T x + v <= 0``. The optimum ``v*`` is the value of the game
(0 for a symmetric game up to rounding). An equilibrium is unique in many games (rock-paper-scissors: 1/3 each)
but not in all of them (two identical players can share any split of their weight); HiGHS then returns one
vertex of the set of equilibria. Weights below :data:`WEIGHT_EPS` are set to 0 and the rest renormalised.

:func:`measured_subgame` picks the players over which the mixture is solved when some pairs have not been
measured (see its docstring).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["WEIGHT_EPS", "NashResult", "measured_subgame", "solve_zero_sum", "symmetric_nash"]

WEIGHT_EPS = 1e-9
"""Equilibrium weights below this are reported as exactly 0."""


@dataclass(frozen=True)
class NashResult:
    """An equilibrium of a zero-sum matrix game, from the row player's side.

    Attributes:
        mixture: the row player's equilibrium weights (non-negative, sum 1), one per row.
        value: the value of the game for the row player (``min_j sum_i x_i A[i, j]`` at the optimum).
        support: indices with a positive weight, heaviest first.
    """

    mixture: npt.NDArray[np.float64]
    value: float
    support: tuple[int, ...]


def solve_zero_sum(payoff: npt.ArrayLike) -> NashResult:
    """The row player's maximin mixture of the zero-sum game ``payoff`` (rows: row player's strategies, entries:
    the row player's gain), by the linear program of the module docstring.

    Raises:
        ValueError: an empty, non-2-D or non-finite matrix, or a solver failure.
    """
    from scipy.optimize import linprog

    a = np.asarray(payoff, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"payoff must be a non-empty 2-D matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("payoff has a non-finite entry")
    n, m = a.shape
    # Variables z = (x_1..x_n, v); minimise -v.
    c = np.zeros(n + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-a.T, np.ones((m, 1))])  # v - sum_i x_i A[i, j] <= 0
    b_ub = np.zeros(m)
    a_eq = np.zeros((1, n + 1))
    a_eq[0, :n] = 1.0
    bounds = [(0.0, None)] * n + [(None, None)]
    res = linprog(c, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=[1.0], bounds=bounds, method="highs")
    if res.status != 0 or res.x is None:
        raise ValueError(f"the Nash linear program failed: {res.message}")
    x = np.clip(np.asarray(res.x[:n], dtype=np.float64), 0.0, None)
    x[x < WEIGHT_EPS] = 0.0
    total = x.sum()
    if total <= 0.0:  # cannot happen for a feasible optimum; guard the division anyway
        raise ValueError("the Nash linear program returned no weight")
    x /= total
    value = float(np.min(x @ a))
    support = tuple(int(i) for i in sorted(np.flatnonzero(x > 0.0), key=lambda i: (-x[i], i)))
    return NashResult(mixture=x, value=value, support=support)


def symmetric_nash(payoff: npt.ArrayLike, atol: float = 1e-9) -> NashResult:
    """An equilibrium mixture of the symmetric zero-sum game ``payoff`` (``A = -A^T``; e.g. score minus 0.5).

    Its value is 0 up to rounding; the mixture is what :func:`solve_zero_sum` finds.

    Raises:
        ValueError: a matrix that is not square, not finite, or not antisymmetric within ``atol``.
    """
    a = np.asarray(payoff, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0:
        raise ValueError(f"payoff must be a non-empty square matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("payoff has a non-finite entry")
    if not np.allclose(a, -a.T, atol=atol, rtol=0.0):
        raise ValueError("payoff is not antisymmetric: not a symmetric zero-sum game")
    return solve_zero_sum(0.5 * (a - a.T))


def measured_subgame(measured: npt.ArrayLike, max_steps: int = 200_000) -> list[int]:
    """The players the meta-game is solved over when some pairs are not measured.

    ``measured[i, j]`` says whether pair ``(i, j)`` has enough games (only pairs measured both ways count; the
    diagonal is ignored). The result is the largest set of players whose pairs are all measured (a maximum clique
    of the measured graph); among sets of that size, the one whose sorted indices come first lexicographically,
    i.e. with the better players when callers pass them best-rated first. So the Nash mixture over it uses
    measured scores only and never guesses a missing one. Sorted indices; ``[0]`` when no pair is measured.

    Cliques are enumerated by Bron-Kerbosch with pivoting; past ``max_steps`` recursive calls (only for large,
    adversarial graphs) the best set found so far is returned.
    """
    m = np.asarray(measured, dtype=bool)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ValueError(f"measured must be a square matrix, got shape {m.shape}")
    n = m.shape[0]
    if n == 0:
        return []
    m = m & m.T & ~np.eye(n, dtype=bool)
    nbrs = [frozenset(np.flatnonzero(m[i]).tolist()) for i in range(n)]
    best: list[int] = [0]
    steps = 0

    def better(clique: list[int]) -> bool:
        return len(clique) > len(best) or (len(clique) == len(best) and clique < best)

    def expand(r: list[int], p: set[int], x: set[int]) -> None:
        nonlocal best, steps
        steps += 1
        if not p and not x:
            clique = sorted(r)
            if better(clique):
                best = clique
            return
        if steps > max_steps or len(r) + len(p) < len(best):
            return
        pivot = max(p | x, key=lambda u: len(nbrs[u] & p))
        for v in sorted(p - nbrs[pivot]):
            expand(r + [v], p & nbrs[v], x & nbrs[v])
            p = p - {v}
            x = x | {v}

    expand([], set(range(n)), set())
    return best
