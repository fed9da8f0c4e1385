"""Non-transitive 3-cycles (A beats B, B beats C, C beats A) in which every edge is statistically significant.

numpy and scipy only.

The test of one edge "i beats j"
--------------------------------
An exact one-sided sign test. The evidence of a pair comes in independent *units*: a pair of games played on
the same seed with the seats swapped (a game pair, as :func:`~selfplay_cli.stats.sprt.sprt_llr` counts them)
is one unit, won by whoever scored more than half of its two games; a game without a partner is a unit of its
own. Level units (draws, a win each) are dropped. Under the null hypothesis "a unit is as likely to be won by
either player" the number ``w`` of units ``i`` won out of the ``n = w + l`` decisive ones is Binomial(n, 1/2),
so ``p = P(Bin(n, 1/2) >= w)``. Counting game pairs as one unit keeps the test valid however the two games of a
pair are correlated (the seed decides much of a game); it needs no normal approximation, so it holds for few
games too.

The correction
--------------
Every measured pair is tested in both directions, ``2 m`` one-sided tests for ``m`` measured pairs, and Holm's
step-down procedure keeps the family-wise error rate at ``alpha`` (default 0.05): sort the p-values, reject the
k-th smallest (0-based) while ``p_(k) <= alpha / (2 m - k)``. So with probability at least ``1 - alpha`` not one
of the edges claimed is in the wrong direction (or between players of equal strength), and a reported cycle is
real with at least that probability. Holm is uniformly more powerful than Bonferroni under the same guarantee.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["Cycle", "EdgeTests", "holm_reject", "sign_test_pvalue", "significant_three_cycles", "edge_tests",
           "three_cycles"]

DEFAULT_ALPHA = 0.05


@dataclass(frozen=True)
class EdgeTests:
    """The one-sided test of every directed edge.

    Attributes:
        p_value: ``p_value[i, j]`` of "i beats j" (1.0 for pairs not tested and on the diagonal).
        beats: ``beats[i, j]`` True when "i beats j" is significant after the correction.
        tests: the number of one-sided tests in the family (two per measured pair).
        alpha: the family-wise error rate.
    """

    p_value: npt.NDArray[np.float64]
    beats: npt.NDArray[np.bool_]
    tests: int
    alpha: float


@dataclass(frozen=True)
class Cycle:
    """A 3-cycle ``players[0]`` beats ``players[1]`` beats ``players[2]`` beats ``players[0]``; ``p_values`` of the
    three edges in that order. The smallest index comes first."""

    players: tuple[int, int, int]
    p_values: tuple[float, float, float]


def sign_test_pvalue(wins: int, losses: int) -> float:
    """One-sided exact sign test: ``P(Bin(wins + losses, 1/2) >= wins)`` (1.0 without decisive units)."""
    from scipy.stats import binom

    w, lo = int(wins), int(losses)
    if w < 0 or lo < 0:
        raise ValueError("sign test: counts must be non-negative")
    n = w + lo
    if n == 0:
        return 1.0
    return float(min(max(binom.sf(w - 1, n, 0.5), 0.0), 1.0))


def holm_reject(p_values: npt.ArrayLike, alpha: float = DEFAULT_ALPHA) -> npt.NDArray[np.bool_]:
    """Holm's step-down procedure: which of the hypotheses are rejected at family-wise error rate ``alpha``."""
    p = np.asarray(p_values, dtype=np.float64).ravel()
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    reject = np.zeros(p.size, dtype=bool)
    order = np.argsort(p, kind="stable")
    m = p.size
    for k, idx in enumerate(order):
        if p[idx] <= alpha / (m - k):
            reject[idx] = True
        else:
            break
    return reject


def edge_tests(unit_wins: npt.ArrayLike, measured: npt.ArrayLike, alpha: float = DEFAULT_ALPHA) -> EdgeTests:
    """Test every directed edge of the measured pairs (see the module docstring).

    Args:
        unit_wins: ``unit_wins[i, j]``: units (game pairs, or unpaired games) ``i`` won against ``j``.
        measured: ``measured[i, j]``: the pair has enough games to be tested (symmetric; diagonal ignored).
        alpha: family-wise error rate over all ``2 m`` tests.
    """
    u = np.asarray(unit_wins, dtype=np.int64)
    meas = np.asarray(measured, dtype=bool)
    if u.ndim != 2 or u.shape[0] != u.shape[1] or meas.shape != u.shape:
        raise ValueError("unit_wins and measured must be square matrices of the same shape")
    if np.any(u < 0):
        raise ValueError("unit_wins must be non-negative")
    n = u.shape[0]
    meas = meas & meas.T & ~np.eye(n, dtype=bool)
    p = np.ones((n, n))
    ii, jj = np.nonzero(meas)
    for i, j in zip(ii.tolist(), jj.tolist(), strict=True):
        p[i, j] = sign_test_pvalue(u[i, j], u[j, i])
    beats = np.zeros((n, n), dtype=bool)
    if ii.size:
        beats[ii, jj] = holm_reject(p[ii, jj], alpha)
    return EdgeTests(p_value=p, beats=beats, tests=int(ii.size), alpha=float(alpha))


def three_cycles(beats: npt.ArrayLike) -> list[tuple[int, int, int]]:
    """Every directed 3-cycle ``(a, b, c)`` of the relation ``beats`` (a beats b, b beats c, c beats a), each once,
    its smallest index first, in lexicographic order."""
    g = np.asarray(beats, dtype=bool)
    if g.ndim != 2 or g.shape[0] != g.shape[1]:
        raise ValueError("beats must be a square matrix")
    n = g.shape[0]
    idx = np.arange(n)
    out: list[tuple[int, int, int]] = []
    for a in range(n):
        for b in np.flatnonzero(g[a] & (idx > a)).tolist():
            for c in np.flatnonzero(g[b] & g[:, a] & (idx > a)).tolist():
                out.append((a, b, c))
    return out


def significant_three_cycles(
    unit_wins: npt.ArrayLike, measured: npt.ArrayLike, alpha: float = DEFAULT_ALPHA
) -> tuple[EdgeTests, list[Cycle]]:
    """The edge tests and the 3-cycles all of whose edges are significant (:func:`edge_tests`)."""
    tests = edge_tests(unit_wins, measured, alpha)
    cycles = [
        Cycle(players=(a, b, c), p_values=(float(tests.p_value[a, b]), float(tests.p_value[b, c]),
                                           float(tests.p_value[c, a])))
        for a, b, c in three_cycles(tests.beats)
    ]
    return tests, cycles
