"""Elo arithmetic on the classical logistic 400-point scale, the normal quantile, and the online Elo update.

A rating difference ``d`` means an expected score (points per game, a draw being half a point)

    E(d) = 1 / (1 + 10 ** (-d / 400)),      d(s) = 400 * log10(s / (1 - s)).

In natural-log units ``theta = d * ln(10) / 400`` this is the logistic function ``E = sigmoid(theta)``; the
conversion factor ``400 / ln 10 ~= 173.72`` is :data:`NAT_TO_ELO`. Infinite Elo never escapes: :func:`score_to_elo`
clips to ``+-MAX_ELO`` (2400 Elo, odds of 10^6 : 1).

numpy and the standard library only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["ELO_SCALE", "MAX_ELO", "NAT_TO_ELO", "SCORE_CLIP", "elo_to_score", "elo_update", "normal_quantile",
           "score_to_elo"]

ELO_SCALE: float = 400.0
"""Elo points per factor 10 in the odds of scoring."""

NAT_TO_ELO: float = ELO_SCALE / math.log(10.0)
"""Elo points per natural-log unit of the odds (400 / ln 10 ~= 173.7178)."""

MAX_ELO: float = 2400.0
"""Largest |Elo difference| ever returned by :func:`score_to_elo` (odds 10**6 : 1)."""

SCORE_CLIP: float = 1.0 / (1.0 + 10.0 ** (MAX_ELO / ELO_SCALE))
"""Scores are clipped to ``[SCORE_CLIP, 1 - SCORE_CLIP]`` (= E(-2400), E(+2400)) before taking logs."""




def elo_to_score(diff: float) -> float:
    """Expected score ``E(d) = 1 / (1 + 10**(-d/400))`` of a player ``d`` Elo stronger than its opponent.

    Evaluated as the logistic function of ``theta = d ln(10) / 400`` in an overflow-free form, so any
    finite ``d`` is accepted (e.g. ``elo_to_score(100) = 0.6401``).
    """
    x = float(diff) / NAT_TO_ELO
    if x >= 0.0:
        return 1.0 / (1.0 + math.exp(-x))
    ex = math.exp(x)
    return ex / (1.0 + ex)


def score_to_elo(score: float) -> float:
    """Elo difference ``d(s) = 400 log10(s / (1 - s))`` whose expected score is ``s``.

    The score is clipped to ``[SCORE_CLIP, 1 - SCORE_CLIP]`` first, so ``s = 1`` gives ``+MAX_ELO``
    (+2400 Elo, odds of 10**6 : 1) and ``s = 0`` gives ``-MAX_ELO`` instead of infinities.
    Example: ``score_to_elo(0.75) = 400 log10(3) = 190.85``.

    Raises:
        ValueError: if ``score`` is NaN.
    """
    s = float(score)
    if math.isnan(s):
        raise ValueError("score_to_elo: score is NaN")
    s = min(max(s, SCORE_CLIP), 1.0 - SCORE_CLIP)
    elo = ELO_SCALE * math.log10(s / (1.0 - s))
    return min(max(elo, -MAX_ELO), MAX_ELO)


# Acklam's rational approximation of the inverse normal CDF (relative error < 1.15e-9 before the
# refinement step); the coefficients are the published constants of the algorithm.
_ACKLAM_A = (-39.69683028665376, 220.9460984245205, -275.9285104469687, 138.3577518672690,
             -30.66479806614716, 2.506628277459239)
_ACKLAM_B = (-54.47609879822406, 161.5858368580409, -155.6989798598866, 66.80131188771972,
             -13.28068155288572)
_ACKLAM_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838, -2.549732539343734,
             4.374664141464968, 2.938163982698783)
_ACKLAM_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996, 3.754408661907416)
_ACKLAM_P_LOW = 0.02425


def _horner(coeffs: Sequence[float], x: float) -> float:
    acc = 0.0
    for c in coeffs:
        acc = acc * x + c
    return acc


def normal_quantile(p: float) -> float:
    """Inverse of the standard normal CDF, ``Phi^{-1}(p)`` for ``0 < p < 1``.

    Acklam's piecewise rational approximation (central region ``|p - 1/2| <= 0.47575`` in
    ``q = p - 1/2``, tails in ``q = sqrt(-2 ln p)``) followed by one Halley step on
    ``f(x) = Phi(x) - p`` with ``Phi(x) = erfc(-x / sqrt 2) / 2``:

        u = f(x) * sqrt(2 pi) * exp(x^2 / 2),     x <- x - u / (1 + x u / 2),

    which brings the error to ~1e-15 (well inside the required 1e-9).

    Raises:
        ValueError: unless ``0 < p < 1``.
    """
    p = float(p)
    if not 0.0 < p < 1.0:
        raise ValueError(f"normal_quantile: p must lie in (0, 1), got {p}")
    if p < _ACKLAM_P_LOW:
        q = math.sqrt(-2.0 * math.log(p))
        x = _horner(_ACKLAM_C, q) / (_horner(_ACKLAM_D, q) * q + 1.0)
    elif p <= 1.0 - _ACKLAM_P_LOW:
        q = p - 0.5
        r = q * q
        x = _horner(_ACKLAM_A, r) * q / (_horner(_ACKLAM_B, r) * r + 1.0)
    else:
        q = math.sqrt(-2.0 * math.log1p(-p))
        x = -_horner(_ACKLAM_C, q) / (_horner(_ACKLAM_D, q) * q + 1.0)
    if abs(x) < 38.0:  # beyond this erfc underflows (p < 1e-310) and the tail formula is kept as is.
        # e = Phi(x) - p; for p > 1/2 use Phi(x) - p = (1 - p) - Phi(-x) to avoid cancellation.
        if p <= 0.5:
            e = 0.5 * math.erfc(-x / math.sqrt(2.0)) - p
        else:
            e = (1.0 - p) - 0.5 * math.erfc(x / math.sqrt(2.0))
        half = math.exp(0.25 * x * x)  # exp(x^2/2) = half^2, split so it cannot overflow
        u = e * math.sqrt(2.0 * math.pi) * half * half
        x = x - u / (1.0 + 0.5 * x * u)
    return x


def elo_update(r_a: float, r_b: float, score_a: float, k: float = 16.0) -> tuple[float, float]:
    """One online (incremental) Elo update after a game between A and B.

    ``delta = K (S_A - E(r_A - r_B))``; returns ``(r_A + delta, r_B - delta)``, so the update is
    zero-sum. ``K`` is the largest possible rating change per game (reached by a win against an
    infinitely stronger opponent); K = 16 is the classical value for established players, larger K
    (32, 40) reacts faster but is noisier. Equal players, A wins, K = 16: ``(+8, -8)``.
    """
    if not 0.0 <= score_a <= 1.0:
        raise ValueError(f"elo_update: score_a must be in [0, 1], got {score_a}")
    delta = float(k) * (float(score_a) - elo_to_score(float(r_a) - float(r_b)))
    return float(r_a) + delta, float(r_b) - delta

