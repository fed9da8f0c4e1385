"""Elo arithmetic, head-to-head match statistics, GSPRT and Bradley-Terry rating fits.

Everything here uses numpy and the standard library only (no scipy, no torch).

Conventions
-----------
All ratings are on the classical logistic 400-point Elo scale: a rating difference ``d`` means an
expected score (points per game, a draw being half a point)

    E(d) = 1 / (1 + 10 ** (-d / 400)),      d(s) = 400 * log10(s / (1 - s)).

In natural-log units ``theta = d * ln(10) / 400`` this is the logistic function
``E = sigmoid(theta)``; the conversion factor ``400 / ln 10 ~= 173.72`` is :data:`NAT_TO_ELO`.

Infinite Elo never escapes this module: :func:`score_to_elo` clips to ``+-MAX_ELO`` (2400 Elo, the
difference at which the odds of scoring are 10^6 : 1) and every quantity that would otherwise be
infinite (perfect scores, disconnected players) is replaced by a finite, *flagged* value.

Contents
--------
* :func:`score_to_elo`, :func:`elo_to_score`, :func:`normal_quantile`, :func:`elo_update`.
* :class:`MatchStats` / :func:`match_stats`: score, Elo, confidence interval and LOS of one match-up,
  with the per-game (trinomial) or per-game-pair (pentanomial) variance as fastchess reports it.
* :func:`sprt_bounds`, :func:`sprt_llr`, :class:`SPRT`: the generalised sequential probability ratio
  test (GSPRT) of fishtest / fastchess, with the exact multinomial maximum-likelihood LLR
  (M. Van den Bergh, "Comments on normalized Elo" / "support_MLE_multinomial"), in logistic or
  normalized Elo.
* :func:`fit_bradley_terry`, :class:`BTFit`, :func:`bootstrap_ci`, :func:`rank_by_ci`: maximum-likelihood
  Bradley-Terry ratings for a whole population (Newton's method on the aggregated pair matrix),
  with Hunter's (2004) existence condition handled explicitly, bootstrap intervals and
  Chatbot-Arena style ranks.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

__all__ = [
    "BOUND_PRIOR_GAMES",
    "ELO_SCALE",
    "FLAG_DISCONNECTED",
    "FLAG_PERFECT",
    "FLAG_UNRATED",
    "FLAG_ZERO",
    "MAX_ELO",
    "NAT_TO_ELO",
    "SCORE_CLIP",
    "SPRT",
    "BTFit",
    "MatchStats",
    "bootstrap_ci",
    "elo_to_score",
    "elo_update",
    "fit_bradley_terry",
    "match_stats",
    "normal_quantile",
    "rank_by_ci",
    "score_to_elo",
    "sprt_bounds",
    "sprt_llr",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

ELO_SCALE: float = 400.0
"""Elo points per factor 10 in the odds of scoring."""

NAT_TO_ELO: float = ELO_SCALE / math.log(10.0)
"""Elo points per natural-log unit of the odds (400 / ln 10 ~= 173.7178)."""

MAX_ELO: float = 2400.0
"""Largest |Elo difference| ever returned by :func:`score_to_elo` (odds 10**6 : 1)."""

SCORE_CLIP: float = 1.0 / (1.0 + 10.0 ** (MAX_ELO / ELO_SCALE))
"""Scores are clipped to ``[SCORE_CLIP, 1 - SCORE_CLIP]`` (= E(-2400), E(+2400)) before taking logs."""

BOUND_PRIOR_GAMES: float = 1.0
"""Weight, in games, of the virtual draw that turns an infinite ML rating into a finite bound."""

FLAG_PERFECT = "perfect"
FLAG_ZERO = "zero"
FLAG_DISCONNECTED = "disconnected"
FLAG_UNRATED = "unrated"

# Elo-model names accepted by the SPRT functions.
EloModel = Literal["logistic", "normalized"]
CountModel = Literal["pentanomial", "trinomial"]

# Normalized Elo per unit of t-value: nElo = t * 800 / ln(10) (fishtest's ``nelo_divided_by_nt``).
_NELO_PER_T: float = 800.0 / math.log(10.0)
# fishtest / fastchess replace an empty outcome bin by this pseudo-count before any MLE.
_SPRT_EMPTY_BIN: float = 1e-3


# --------------------------------------------------------------------------------------------------
# Elo <-> score, normal quantile, online update
# --------------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------------
# Head-to-head statistics
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MatchStats:
    """Summary of a head-to-head between A and B, from A's point of view.

    Attributes:
        games: ``wins + draws + losses``.
        wins, draws, losses: A's results.
        score: A's mean points per game ``(W + D/2) / games`` (0.5 if there were no games).
        elo: estimated Elo difference A - B, ``score_to_elo(score)``; if ``bounded`` it is
            ``score_to_elo((W + D/2 + 1/2) / (games + 1))`` (one virtual draw added), see
            :func:`match_stats`.
        elo_low, elo_high: confidence interval of the Elo difference (always finite, within
            ``+-MAX_ELO``).
        los: likelihood of superiority ``P(A stronger than B)`` in [0, 1].
        bounded: True when the score is 0 or 1 (or there are no games), i.e. the maximum-likelihood
            Elo is infinite and ``elo`` / the interval are finite bounds, not an estimate.
        confidence: the two-sided confidence level of the interval.
        used_pentanomial: True when the interval used the game-pair (pentanomial) variance.
    """

    games: int
    wins: int
    draws: int
    losses: int
    score: float
    elo: float
    elo_low: float
    elo_high: float
    los: float
    bounded: bool
    confidence: float = 0.95
    used_pentanomial: bool = False


def _likelihood_of_superiority(wins: float, losses: float) -> float:
    """LOS = P(A stronger) ~= Phi((W - L) / sqrt(W + L)) = (1 + erf((W - L) / sqrt(2 (W + L)))) / 2.

    Normal approximation of the binomial test on the decisive games only (draws carry no information
    about who is stronger); 0.5 when there are no decisive games.
    """
    decisive = wins + losses
    if decisive <= 0:
        return 0.5
    return 0.5 * (1.0 + math.erf((wins - losses) / math.sqrt(2.0 * decisive)))


def match_stats(
    wins: int,
    draws: int,
    losses: int,
    pentanomial: tuple[int, int, int, int, int] | None = None,
    confidence: float = 0.95,
) -> MatchStats:
    """Score, Elo, confidence interval and LOS of one match-up (A vs B, A's point of view).

    Score: ``s = (W + D/2) / n`` with ``n = W + D + L``.

    Standard error of ``s``:

    * trinomial (no pentanomial given), games independent:
      ``var_g = [W (1-s)^2 + D (1/2-s)^2 + L s^2] / n`` per game, ``se = sqrt(var_g / n)``;
    * pentanomial, games played in colour-reversed pairs (as fastchess reports it): the counts
      ``(LL, LD, WL+DD, WD, WW)`` of the ``m`` pairs have pair-mean scores ``a = (0, 1/4, 1/2, 3/4, 1)``;
      ``mu = sum p_k a_k``, ``var_p = sum p_k (a_k - mu)^2`` with ``p_k = count_k / m`` and
      ``se = sqrt(var_p / m)``. This accounts for the correlation of the two games of a pair (the
      opening), which the trinomial variance ignores. The score itself still comes from W/D/L;
      the pentanomial only supplies the variance.

    Interval: the normal score interval ``s -+ z se`` with ``z = Phi^{-1}((1 + confidence) / 2)``
    (:func:`normal_quantile`), each endpoint clipped to ``[SCORE_CLIP, 1 - SCORE_CLIP]`` and mapped
    through :func:`score_to_elo` (endpoint transformation, not the delta method - this is what
    fastchess does, and it keeps the asymmetry of the logistic curve).

    0 % / 100 % scores (``bounded=True``): the ML Elo is infinite, so one virtual draw is added
    (``s' = (W + D/2 + 1/2) / (n + 1)``, trinomial variance of the record ``(W, D + 1, L)``); ``elo``
    and the interval are computed from ``s'`` and the interval endpoint on the open side is the
    clip, ``+-MAX_ELO``. With no games at all: ``score = 0.5``, ``elo = 0``, interval
    ``[-MAX_ELO, +MAX_ELO]``, ``bounded=True``.

    LOS: ``(1 + erf((W - L) / sqrt(2 (W + L)))) / 2`` (0.5 if ``W + L = 0``), always from W/L.

    Raises:
        ValueError: negative counts, a pentanomial that is not 5 non-negative counts, or
            ``confidence`` outside (0, 1).
    """
    w, d, lo = int(wins), int(draws), int(losses)
    if min(w, d, lo) < 0:
        raise ValueError("match_stats: counts must be non-negative")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"match_stats: confidence must be in (0, 1), got {confidence}")
    penta: tuple[int, ...] | None = None
    if pentanomial is not None:
        penta = tuple(int(c) for c in pentanomial)
        if len(penta) != 5 or min(penta) < 0:
            raise ValueError("match_stats: pentanomial must be 5 pair counts (LL, LD, WL+DD, WD, WW) >= 0")
    n = w + d + lo
    z = normal_quantile(0.5 + 0.5 * confidence)
    los = _likelihood_of_superiority(w, lo)
    if n == 0:
        return MatchStats(0, 0, 0, 0, 0.5, 0.0, -MAX_ELO, MAX_ELO, 0.5, True, confidence, False)

    score = (w + 0.5 * d) / n
    bounded = w + 0.5 * d <= 0.0 or lo + 0.5 * d <= 0.0  # score exactly 0 or 1
    use_penta = False
    if bounded:
        n_eff, w_eff, d_eff, l_eff = n + 1, w, d + 1, lo
        s_est = (w_eff + 0.5 * d_eff) / n_eff
        var_g = (w_eff * (1 - s_est) ** 2 + d_eff * (0.5 - s_est) ** 2 + l_eff * s_est**2) / n_eff
        se = math.sqrt(var_g / n_eff)
    else:
        s_est = score
        pairs = sum(penta) if penta is not None else 0
        if penta is not None and pairs > 0:
            a = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
            p = np.asarray(penta, dtype=float) / pairs
            mu = float(p @ a)
            var_p = float(p @ (a - mu) ** 2)
            se = math.sqrt(var_p / pairs)
            use_penta = True
        else:
            var_g = (w * (1 - score) ** 2 + d * (0.5 - score) ** 2 + lo * score**2) / n
            se = math.sqrt(var_g / n)
    lo_s = min(max(s_est - z * se, SCORE_CLIP), 1.0 - SCORE_CLIP)
    hi_s = min(max(s_est + z * se, SCORE_CLIP), 1.0 - SCORE_CLIP)
    elo = score_to_elo(s_est)
    elo_low, elo_high = score_to_elo(lo_s), score_to_elo(hi_s)
    if bounded:  # the open side of a 0 % / 100 % result is unbounded: report the clip.
        if score >= 1.0:
            elo_high = MAX_ELO
        else:
            elo_low = -MAX_ELO
    return MatchStats(
        games=n, wins=w, draws=d, losses=lo, score=score, elo=elo, elo_low=min(elo_low, elo),
        elo_high=max(elo_high, elo), los=los, bounded=bounded, confidence=confidence,
        used_pentanomial=use_penta,
    )


# --------------------------------------------------------------------------------------------------
# GSPRT (fishtest / fastchess)
# --------------------------------------------------------------------------------------------------


def sprt_bounds(alpha: float, beta: float) -> tuple[float, float]:
    """Wald's SPRT stopping bounds on the log-likelihood ratio.

    ``(log(beta / (1 - alpha)), log((1 - beta) / alpha))``: the test accepts H1 when the LLR reaches
    the upper bound and H0 when it falls to the lower one; ``alpha`` is the false-positive rate
    (accept H1 while H0 holds) and ``beta`` the false-negative rate. ``alpha = beta = 0.05`` gives
    ``(-2.944, +2.944)``.
    """
    if not (0.0 < alpha < 1.0 and 0.0 < beta < 1.0 and alpha + beta < 1.0):
        raise ValueError(f"sprt_bounds: need 0 < alpha, beta and alpha + beta < 1 (got {alpha}, {beta})")
    return math.log(beta / (1.0 - alpha)), math.log((1.0 - beta) / alpha)


def _brent_root(f: Callable[[float], float], lo: float, hi: float, f_lo: float, f_hi: float,
                xtol: float = 1e-15, max_iter: int = 300) -> float:
    """Root of ``f`` in ``[lo, hi]`` (``f_lo``, ``f_hi`` of opposite sign) by Brent's method.

    Inverse quadratic interpolation / secant steps, falling back to bisection whenever the
    interpolated point leaves the bracket or does not shrink it fast enough; the bracket always
    contains a sign change, so convergence is guaranteed.
    """
    a, b, fa, fb = lo, hi, f_lo, f_hi
    if fa == 0.0:
        return a
    if fb == 0.0:
        return b
    if (fa > 0) == (fb > 0):
        raise ValueError("_brent_root: the bracket does not contain a sign change")
    if abs(fa) < abs(fb):
        a, b, fa, fb = b, a, fb, fa
    c, fc = a, fa
    d = c
    bisected = True
    for _ in range(max_iter):
        if fb == 0.0 or abs(b - a) <= xtol * max(1.0, abs(b)):
            return b
        if fa != fc and fb != fc:  # inverse quadratic interpolation through (a, b, c)
            s = (a * fb * fc / ((fa - fb) * (fa - fc)) + b * fa * fc / ((fb - fa) * (fb - fc))
                 + c * fa * fb / ((fc - fa) * (fc - fb)))
        else:  # secant
            s = b - fb * (b - a) / (fb - fa)
        m = (3.0 * a + b) / 4.0
        outside = not (min(m, b) < s < max(m, b))
        prev_step = abs(b - c) if bisected else abs(c - d)
        slow = abs(s - b) >= prev_step / 2.0
        tiny = prev_step < xtol
        if outside or slow or tiny:
            s = 0.5 * (a + b)
            bisected = True
        else:
            bisected = False
        fs = f(s)
        d, c, fc = c, b, fb
        if (fa > 0) != (fs > 0):
            b, fb = s, fs
        else:
            a, fa = s, fs
        if abs(fa) < abs(fb):
            a, b, fa, fb = b, a, fb, fa
    return b


def _tilted_mle(phat: FloatArray, phi: FloatArray) -> FloatArray:
    """``p_i = phat_i / (1 + x phi_i)`` with ``x`` the root of ``sum phat_i phi_i / (1 + x phi_i) = 0``.

    This is the stationarity condition of ``max sum phat_i log p_i`` subject to ``sum p_i = 1`` and the
    linear constraint ``sum p_i phi_i = 0`` (Lagrange multiplier ``x``). The left side is strictly
    decreasing in ``x`` on the interval ``(-1/max phi, -1/min phi)`` where all ``1 + x phi_i > 0``, going
    from +inf to -inf, so there is exactly one root; it is found with :func:`_brent_root`. At the root
    ``sum p_i = 1 - x * 0 = 1`` automatically.
    """
    lo_phi, hi_phi = float(phi.min()), float(phi.max())
    if not lo_phi < 0.0 < hi_phi:
        raise ValueError("SPRT: the hypothesised score is not attainable for this outcome set")
    x_lo, x_hi = -1.0 / hi_phi, -1.0 / lo_phi

    def f(x: float) -> float:
        return float(np.sum(phat * phi / (1.0 + x * phi)))

    eps = 1e-12 * (x_hi - x_lo)
    a, b = x_lo + eps, x_hi - eps
    fa, fb = f(a), f(b)
    while fa <= 0.0 and eps > 1e-300:  # the pole is extremely sharp: move closer to it
        eps *= 1e-3
        a = x_lo + eps
        fa = f(a)
    while fb >= 0.0 and eps > 1e-300:
        eps *= 1e-3
        b = x_hi - eps
        fb = f(b)
    x = _brent_root(f, a, b, fa, fb)
    p = phat / (1.0 + x * phi)
    return p / p.sum()


def _mle_expected(phat: FloatArray, a: FloatArray, s: float) -> FloatArray:
    """ML distribution on the outcome values ``a`` with mean score ``s`` given empirical ``phat``.

    Constraint ``sum p_i (a_i - s) = 0``, i.e. :func:`_tilted_mle` with ``phi_i = a_i - s``
    (Van den Bergh, "support_MLE_multinomial", Proposition 1.1).
    """
    return _tilted_mle(phat, a - s)


def _mle_t_value(phat: FloatArray, a: FloatArray, ref: float, t: float, max_iter: int = 100) -> FloatArray:
    """ML distribution with t-value ``(mu - ref) / sigma = t`` given empirical ``phat``.

    Stationarity of ``sum phat_i log p_i`` under ``mu(p) - ref - t sigma(p) = 0`` gives
    ``p_i = phat_i / (1 + x phi_i)`` with the constraint gradient

        phi_i = a_i - ref - (t sigma / 2) (1 + ((a_i - mu) / sigma)^2)

    (``d mu / d p_i = a_i``, ``d sigma / d p_i = ((a_i - mu)^2 - sigma^2) / (2 sigma)`` up to the
    normalisation constraint; note ``sum p_i phi_i = mu - ref - t sigma``). Since ``phi`` depends on
    ``p`` through ``mu, sigma``, iterate: start from the uniform distribution, recompute
    ``phi`` and solve the secular equation until ``p`` changes by < 1e-13 (Van den Bergh,
    "Comments on normalized Elo", section 4.1).

    Raises:
        ValueError: if the iteration breaks down (no sign change of ``phi``, which happens for
            hypotheses far on the other side of the data) or does not converge.
    """
    p = np.full_like(phat, 1.0 / phat.size)
    for _ in range(max_iter):
        mu = float(p @ a)
        sigma = math.sqrt(float(p @ (a - mu) ** 2))
        phi = a - ref - 0.5 * t * sigma * (1.0 + ((a - mu) / sigma) ** 2)
        p_new = _tilted_mle(phat, phi)
        done = float(np.max(np.abs(p_new - p))) < 1e-13
        p = p_new
        if done:
            return p
    raise ValueError("SPRT: the normalized-Elo MLE iteration did not converge")


def _llr_normalized_approx(phat: FloatArray, a: FloatArray, total: float, pentanomial: bool,
                           nelo0: float, nelo1: float) -> float:
    """Approximate normalized-Elo LLR (Van den Bergh, "Comments on normalized Elo", section 4.2).

    ``LLR ~= (G / 2) ln[(1 + (nt - nt0)^2) / (1 + (nt - nt1)^2)]`` with ``G`` games, the observed
    per-game t-value ``nt = (mu - 1/2) / sigma_game`` and ``nt_h = nelo_h ln(10) / 800``; for pairs
    ``sigma_game = sqrt(2 var_pair)`` and ``G = 2 * pairs``. Used only as a fallback when the exact
    constrained MLE iteration breaks down.
    """
    mu = float(phat @ a)
    var = float(phat @ (a - mu) ** 2)
    sigma_game = math.sqrt(2.0 * var) if pentanomial else math.sqrt(var)
    games = 2.0 * total if pentanomial else total
    nt = (mu - 0.5) / sigma_game
    nt0, nt1 = nelo0 / _NELO_PER_T, nelo1 / _NELO_PER_T
    return 0.5 * games * math.log((1.0 + (nt - nt0) ** 2) / (1.0 + (nt - nt1) ** 2))


def sprt_llr(
    counts: Sequence[float],
    elo0: float,
    elo1: float,
    model: CountModel | None = None,
    elo_model: EloModel = "logistic",
) -> float:
    """Generalised log-likelihood ratio of H1: elo = elo1 against H0: elo = elo0 (fishtest's GSPRT).

    Args:
        counts: ``model="pentanomial"``: 5 game-pair counts ``(LL, LD+DL, WL+LW+DD, WD+DW, WW)``, i.e.
            pairs whose two-game score is 0, 1/2, 1, 3/2, 2 (pair-mean scores ``a = 0, 1/4, 1/2, 3/4, 1``);
            ``model="trinomial"``: ``(losses, draws, wins)`` with ``a = 0, 1/2, 1``.
        elo0, elo1: the hypotheses, in logistic Elo (``elo_model="logistic"``, the 400-scale Elo) or in
            normalized Elo (``elo_model="normalized"``, fishtest's / fastchess's "nElo").
        model: ``"pentanomial"`` or ``"trinomial"``; ``None`` infers it from ``len(counts)`` (5 or 3).
        elo_model: ``"logistic"`` or ``"normalized"``.

    Method (fishtest ``LLRcalc``): with ``N = sum n_i`` and ``phat_i = n_i / N``, for each hypothesis find
    the distribution ``p^(h)`` over the outcomes maximising the likelihood ``sum n_i log p_i`` subject to

    * logistic: the expected score ``sum p_i a_i = E(elo_h) = 1 / (1 + 10**(-elo_h/400))``;
    * normalized: the t-value ``(mu - 1/2) / sigma = t_h`` with ``t_h = nelo_h ln(10) / 800`` per game
      (trinomial) or ``sqrt(2) nelo_h ln(10) / 800`` for the pair-mean score (pentanomial, since a pair
      averages two games);

    the constrained MLE is found through its Lagrange multiplier by a 1-D root solve (see
    :func:`_tilted_mle`). Then ``LLR = sum_i n_i log(p^(1)_i / p^(0)_i)``.

    Empty bins: like fishtest and fastchess, every zero count is replaced by ``1e-3`` (a tiny prior,
    which also enters ``N``) so that all ``phat_i > 0`` and the MLE is well defined. Returns 0.0 when
    there are no games at all.

    The normalized-Elo MLE is a fixed-point iteration; if it breaks down (hypotheses far on the
    other side of the data) the closed-form approximation of Van den Bergh's section 4.2 is returned
    instead (:func:`_llr_normalized_approx`). The exact MLE is iterated to convergence, so in
    degenerate cases (e.g. only draws) it can differ from fastchess, which stops after 10 iterations.
    """
    vals = np.asarray(counts, dtype=float)
    if vals.ndim != 1:
        raise ValueError("sprt_llr: counts must be a flat sequence")
    if model is None:
        model = "pentanomial" if vals.size == 5 else "trinomial" if vals.size == 3 else None
        if model is None:
            raise ValueError(f"sprt_llr: cannot infer the model from {vals.size} counts (need 5 or 3)")
    expected = {"pentanomial": 5, "trinomial": 3}.get(model)
    if expected is None:
        raise ValueError(f"sprt_llr: model must be 'pentanomial' or 'trinomial', got {model!r}")
    if vals.size != expected:
        raise ValueError(f"sprt_llr: {model} model needs {expected} counts, got {vals.size}")
    if np.any(vals < 0) or not np.all(np.isfinite(vals)):
        raise ValueError("sprt_llr: counts must be finite and non-negative")
    if elo_model not in ("logistic", "normalized"):
        raise ValueError(f"sprt_llr: elo_model must be 'logistic' or 'normalized', got {elo_model!r}")
    if vals.sum() <= 0:
        return 0.0
    vals = np.where(vals == 0.0, _SPRT_EMPTY_BIN, vals)
    total = float(vals.sum())
    phat = vals / total
    a = np.linspace(0.0, 1.0, vals.size)
    if elo_model == "logistic":
        p0 = _mle_expected(phat, a, elo_to_score(elo0))
        p1 = _mle_expected(phat, a, elo_to_score(elo1))
    else:
        scale = math.sqrt(2.0) if model == "pentanomial" else 1.0
        try:
            p0 = _mle_t_value(phat, a, 0.5, scale * elo0 / _NELO_PER_T)
            p1 = _mle_t_value(phat, a, 0.5, scale * elo1 / _NELO_PER_T)
        except ValueError:
            return _llr_normalized_approx(phat, a, total, model == "pentanomial", elo0, elo1)
    return float(total * np.sum(phat * (np.log(p1) - np.log(p0))))


@dataclass(frozen=True)
class SPRT:
    """A configured GSPRT: H0: elo = elo0 against H1: elo = elo1 with error rates alpha / beta.

    ``lower, upper = sprt_bounds(alpha, beta)``; :meth:`decide` returns ``"H1"`` once the LLR is
    ``>= upper``, ``"H0"`` once it is ``<= lower`` and ``None`` while the test should continue.
    """

    elo0: float
    elo1: float
    alpha: float = 0.05
    beta: float = 0.05
    elo_model: EloModel = "logistic"

    def __post_init__(self) -> None:
        if not self.elo0 < self.elo1:
            raise ValueError(f"SPRT: need elo0 < elo1 (got {self.elo0}, {self.elo1})")
        if self.elo_model not in ("logistic", "normalized"):
            raise ValueError(f"SPRT: unknown elo_model {self.elo_model!r}")
        sprt_bounds(self.alpha, self.beta)  # validates alpha / beta

    @property
    def lower(self) -> float:
        """Lower (accept H0) LLR bound ``log(beta / (1 - alpha))``."""
        return sprt_bounds(self.alpha, self.beta)[0]

    @property
    def upper(self) -> float:
        """Upper (accept H1) LLR bound ``log((1 - beta) / alpha)``."""
        return sprt_bounds(self.alpha, self.beta)[1]

    def llr(self, counts: Sequence[float], model: CountModel | None = None) -> float:
        """:func:`sprt_llr` of ``counts`` for this test's hypotheses and Elo model."""
        return sprt_llr(counts, self.elo0, self.elo1, model=model, elo_model=self.elo_model)

    def decide(self, llr: float) -> Literal["H1", "H0"] | None:
        """``"H1"`` if ``llr >= upper``, ``"H0"`` if ``llr <= lower``, else ``None`` (keep playing)."""
        lower, upper = sprt_bounds(self.alpha, self.beta)
        if llr >= upper:
            return "H1"
        if llr <= lower:
            return "H0"
        return None


# --------------------------------------------------------------------------------------------------
# Bradley-Terry maximum likelihood
# --------------------------------------------------------------------------------------------------


@dataclass
class BTFit:
    """Result of :func:`fit_bradley_terry`.

    Attributes:
        ratings: (n_players,) Elo ratings, always finite; ``ratings[anchor] == anchor_rating`` if the
            anchor played.
        flags: per player ``None`` (a true ML estimate) or one of ``"perfect"``, ``"zero"``,
            ``"disconnected"``, ``"unrated"`` (see :func:`fit_bradley_terry`).
        games, wins, draws, losses: per-player (weighted) counts; int64 unless non-integer weights
            were given, then float64.
        score: per-player mean points per game (0.5 for players without games).
        iterations: total Newton iterations over all sub-problems.
        converged: True if every Newton solve reached the tolerance.
        anchor, anchor_rating: the gauge used.
    """

    ratings: FloatArray
    flags: list[str | None]
    games: npt.NDArray[np.int64] | FloatArray
    wins: npt.NDArray[np.int64] | FloatArray
    draws: npt.NDArray[np.int64] | FloatArray
    losses: npt.NDArray[np.int64] | FloatArray
    score: FloatArray
    iterations: int
    converged: bool
    anchor: int = 0
    anchor_rating: float = 1000.0


def _sigmoid(x: FloatArray) -> FloatArray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _loglik(w: FloatArray, theta: FloatArray) -> float:
    """``sum_ij W_ij log sigmoid(theta_i - theta_j)``: the Bradley-Terry log-likelihood (points as wins)."""
    d = theta[:, None] - theta[None, :]
    return -float(np.sum(w * np.logaddexp(0.0, -d)))


def _pcg(mat: FloatArray, rhs: FloatArray, rtol: float = 1e-12) -> FloatArray:
    """Solve ``mat x = rhs`` (symmetric positive (semi)definite) by Jacobi-preconditioned conjugate gradients.

    Used instead of a LAPACK factorisation because it needs only matrix-vector products: on small
    matrices a multi-threaded BLAS factorisation can be dominated by thread wake-up latency on a busy
    machine, while CG on a diagonally dominant graph Laplacian converges in a few dozen products.
    Stops when ``|r| <= rtol |rhs|`` or after ``4 * size + 50`` iterations.
    """
    diag = np.diag(mat).copy()
    inv_d = np.divide(1.0, diag, out=np.zeros_like(diag), where=diag > 0)
    x = np.zeros_like(rhs)
    r = rhs.copy()
    z = inv_d * r
    p = z.copy()
    rz = float(r @ z)
    stop = rtol * float(np.linalg.norm(rhs))
    for _ in range(4 * rhs.size + 50):
        if float(np.linalg.norm(r)) <= stop or rz <= 0.0:
            break
        q = mat @ p
        pq = float(p @ q)
        if pq <= 0.0:
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        z = inv_d * r
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x


def _newton(w: FloatArray, n: FloatArray, theta: FloatArray, free: npt.NDArray[np.bool_],
            tol_nat: float, max_iter: int) -> tuple[FloatArray, int, bool]:
    """Maximise the BT log-likelihood over ``theta[free]`` (the other entries stay fixed).

    ``w[i, j]``: points i scored against j, ``n[i, j] = n[j, i]``: games between them (both may include
    virtual games). Gradient ``g_i = sum_j (w_ij - n_ij p_ij)`` with ``p_ij = sigmoid(theta_i - theta_j)``;
    the negative Hessian is the weighted graph Laplacian ``L_ii = sum_j c_ij``, ``L_ij = -c_ij``,
    ``c_ij = n_ij p_ij (1 - p_ij)``, restricted to the free rows/columns (positive definite when every
    free player is linked to a fixed one). Newton step ``L delta = g``, capped at 5 nats
    (~870 Elo) per player and backtracked until the (concave) log-likelihood does not decrease.
    Stops when the largest accepted step is below ``tol_nat``.
    """
    theta = theta.copy()
    idx = np.flatnonzero(free)
    if idx.size == 0:
        return theta, 0, True
    sub = np.ix_(idx, idx)
    for it in range(1, max_iter + 1):
        d = theta[:, None] - theta[None, :]
        p = _sigmoid(d)
        grad = np.sum(w - n * p, axis=1)[idx]
        c = n * p * (1.0 - p)
        lap = -c[sub]
        lap[np.diag_indices_from(lap)] += c[idx].sum(axis=1)
        step = _pcg(lap, grad)
        big = float(np.max(np.abs(step)))
        if big > 5.0:
            step *= 5.0 / big
        ll0 = _loglik(w, theta)
        t = 1.0
        while True:
            trial = theta.copy()
            trial[idx] += t * step
            ll1 = _loglik(w, trial)
            if ll1 >= ll0 - 1e-12 * (1.0 + abs(ll0)) or t < 1e-6:
                break
            t *= 0.5
        theta = trial
        if t * float(np.max(np.abs(step))) < tol_nat:
            return theta, it, True
    return theta, max_iter, False


def reachable(adj: npt.NDArray[np.bool_], start: int) -> npt.NDArray[np.bool_]:
    """Players reachable from ``start`` along edges ``adj[i, j]`` (breadth-first, vectorised); with a symmetric
    ``adj`` this is ``start``'s connected component."""
    seen = np.zeros(adj.shape[0], dtype=bool)
    seen[start] = True
    frontier = seen.copy()
    while frontier.any():
        nxt = adj[frontier].any(axis=0) & ~seen
        seen |= nxt
        frontier = nxt
    return seen


def _fit_matrices(
    w: FloatArray, n: FloatArray, anchor: int, anchor_rating: float, prior_games: float,
    init: FloatArray | None, tol: float, max_iter: int,
) -> tuple[FloatArray, list[str | None], int, bool]:
    """Core of :func:`fit_bradley_terry` on the aggregated pair matrices (see its docstring)."""
    n_players = w.shape[0]
    games = n.sum(axis=1)
    has_games = games > 0
    played = n > 0
    scored = w > 0
    ratings = np.full(n_players, float(anchor_rating))
    flags: list[str | None] = [None if g else FLAG_UNRATED for g in has_games]
    tol_nat = tol / NAT_TO_ELO
    # Heuristic start: logit of each player's score with one virtual draw.
    points = w.sum(axis=1)
    heuristic = np.log((points + 0.5) / (games - points + 0.5))
    if init is None:
        start_theta = heuristic
    else:
        start_theta = np.where(np.isfinite(init), (init - anchor_rating) / NAT_TO_ELO, heuristic)
    iterations, converged = 0, True
    unassigned = has_games.copy()
    while unassigned.any():
        comp = reachable(played, int(np.flatnonzero(unassigned)[0]))
        unassigned &= ~comp
        members = np.flatnonzero(comp)
        with_anchor = bool(comp[anchor])
        root = anchor if with_anchor else int(members[np.argmax(games[members])])
        fwd = reachable(scored, root)  # players the root's group (transitively) scored against
        bwd = reachable(scored.T, root)  # players that (transitively) scored against the root
        main = fwd & bwd  # strongly connected component of the root: ML exists there (Hunter 2004)
        for i in members:
            if not with_anchor:
                flags[i] = FLAG_DISCONNECTED
            elif main[i]:
                continue
            elif bwd[i] and not fwd[i]:  # scored against the anchor's group, never conceded to it
                flags[i] = FLAG_PERFECT
            elif fwd[i] and not bwd[i]:
                flags[i] = FLAG_ZERO
            else:
                flags[i] = FLAG_DISCONNECTED
        r = int(np.searchsorted(members, root))
        wc, nc = w[np.ix_(members, members)], n[np.ix_(members, members)]
        main_c = main[members]
        theta = start_theta[members] - start_theta[root]
        theta[r] = 0.0
        # Virtual draws: prior_games for everybody, at least BOUND_PRIOR_GAMES for players outside
        # the root's strongly connected component; spread over each player's opponents pro rata.
        g = np.where(main_c, prior_games, max(prior_games, BOUND_PRIOR_GAMES))
        v = (g / games[members])[:, None] * nc
        v = v + v.T
        wv, nv = wc + 0.5 * v, nc + v
        if prior_games > 0.0:
            free = np.ones(members.size, dtype=bool)
            free[r] = False
            theta, its, ok = _newton(wv, nv, theta, free, tol_nat, max_iter)
            iterations, converged = iterations + its, converged and ok
        else:
            mi = np.flatnonzero(main_c)
            free_m = np.ones(mi.size, dtype=bool)
            free_m[int(np.flatnonzero(mi == r)[0])] = False
            sub = np.ix_(mi, mi)
            th_m, its, ok = _newton(wc[sub], nc[sub], theta[mi], free_m, tol_nat, max_iter)
            iterations, converged = iterations + its, converged and ok
            if not main_c.all():
                # Start the bounded players from their heuristic, shifted like the main group moved.
                theta[~main_c] += float(np.mean(th_m - theta[mi]))
                theta[mi] = th_m
                theta, its, ok = _newton(wv, nv, theta, ~main_c, tol_nat, max_iter)
                iterations, converged = iterations + its, converged and ok
            else:
                theta[mi] = th_m
        if with_anchor:
            ratings[members] = anchor_rating + (theta - theta[r]) * NAT_TO_ELO
        else:
            ratings[members] = anchor_rating + (theta - theta.mean()) * NAT_TO_ELO
    return ratings, flags, iterations, converged


def _validate_games(
    a: npt.ArrayLike, b: npt.ArrayLike, score_a: npt.ArrayLike, n_players: int, anchor: int,
    weights: npt.ArrayLike | None,
) -> tuple[IntArray, IntArray, FloatArray, FloatArray | None]:
    ai = np.asarray(a).astype(np.int64, copy=False).ravel()
    bi = np.asarray(b).astype(np.int64, copy=False).ravel()
    sc = np.asarray(score_a, dtype=np.float64).ravel()
    if not (ai.size == bi.size == sc.size):
        raise ValueError("a, b and score_a must have the same length")
    if n_players <= 0:
        raise ValueError("n_players must be positive")
    if not 0 <= anchor < n_players:
        raise ValueError(f"anchor {anchor} is not a player index in [0, {n_players})")
    if ai.size and (min(ai.min(), bi.min()) < 0 or max(ai.max(), bi.max()) >= n_players):
        raise ValueError("player indices must lie in [0, n_players)")
    if np.any(ai == bi):
        raise ValueError("a player cannot play against itself (a == b)")
    if not np.all((sc >= 0.0) & (sc <= 1.0)):
        raise ValueError("score_a must lie in [0, 1] (1 win, 0.5 draw, 0 loss)")
    wt = None
    if weights is not None:
        wt = np.asarray(weights, dtype=np.float64).ravel()
        if wt.size != ai.size or not np.all(np.isfinite(wt)) or np.any(wt < 0):
            raise ValueError("weights must be finite, non-negative and one per game")
    return ai, bi, sc, wt


def _pair_matrices(ai: IntArray, bi: IntArray, sc: FloatArray, wt: FloatArray | None,
                   n_players: int) -> tuple[FloatArray, FloatArray]:
    """Aggregate games: ``W[i, j]`` = points i scored against j, ``N[i, j] = N[j, i]`` = games i-j."""
    m = n_players * n_players
    code = ai * n_players + bi
    g = np.ones_like(sc) if wt is None else wt
    pts_a = np.bincount(code, weights=g * sc, minlength=m).reshape(n_players, n_players)
    pts_b = np.bincount(code, weights=g * (1.0 - sc), minlength=m).reshape(n_players, n_players)
    cnt = np.bincount(code, weights=g, minlength=m).reshape(n_players, n_players)
    return pts_a + pts_b.T, cnt + cnt.T


def fit_bradley_terry(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    score_a: npt.ArrayLike,
    n_players: int,
    anchor: int = 0,
    anchor_rating: float = 1000.0,
    weights: npt.ArrayLike | None = None,
    prior_games: float = 0.0,
    *,
    init: npt.ArrayLike | None = None,
    tol: float = 1e-6,
    max_iter: int = 100,
) -> BTFit:
    """Maximum-likelihood Bradley-Terry (Elo) ratings of a population from a list of games.

    Model: game ``k`` between ``a[k]`` and ``b[k]`` gives A ``score_a[k]`` points (1 win, 1/2 draw,
    0 loss) and B ``1 - score_a[k]``, with ``P(a beats b) = E(r_a - r_b) = 1 / (1 + 10**(-(r_a - r_b)/400))``.
    Draws count as half a win for each side (the usual Elo / Chatbot-Arena convention), so with
    ``W_ij`` = (weighted) points i scored against j and ``N_ij = N_ji`` the (weighted) games between
    them, the log-likelihood is ``sum_{i,j} W_ij log E(r_i - r_j)`` and the ML ratings solve the score
    equations

        sum_j N_ij (W_ij / N_ij - E(r_i - r_j)) = 0     for every player i except the anchor,

    with ``r_anchor = anchor_rating`` fixing the additive gauge. The games are first aggregated into
    the n x n matrices ``W, N`` (one ``bincount``), then solved by Newton's method with the n x n
    Hessian (the likelihood is concave, so Newton with backtracking converges; typically 5-8
    iterations) to ``tol`` Elo (largest update). ``weights`` multiplies each game (bootstrap counts);
    ``init`` (Elo, n_players) warm-starts the solver.

    Existence (Hunter 2004): the ML ratings are finite iff the directed graph "i scored something
    against j" is strongly connected. This function therefore

    1. fits the strongly connected component of the anchor ("main") exactly, using the games within
       it (these are the exact ML ratings of those players: in the full likelihood all other players
       drift to +-infinity and their games against main contribute nothing);
    2. gives every other player in the anchor's connected component a finite *bound*: the ML rating
       with main held fixed after adding, for each such player i, ``BOUND_PRIOR_GAMES`` (= 1) virtual
       draw spread over i's opponents in proportion to the games played against them. For a single
       player with ``P`` points in ``n`` games against fixed opponents this is the rating at which its
       expected score against its actual schedule equals ``(P + 1/2) / (n + 1)``, e.g. 2/2 wins against
       one opponent gives ``E(d) = 5/6``, ``d = 400 log10 5 = +279.6``. These players are flagged

       * ``"perfect"``: the ML rating is +infinity: the player belongs to a group that scored 100 %
         against every opponent outside the group (most often: the player won every game);
       * ``"zero"``: the mirror image, ML rating -infinity (most often: a 0 % score);
       * ``"disconnected"``: neither (its group both beat and lost to groups the anchor cannot be
         compared with), so its offset to the anchor is undetermined;

    3. connected components that do not contain the anchor are fitted the same way around their own
       most active player, then shifted so that the component's mean rating is ``anchor_rating``; all
       their players are flagged ``"disconnected"`` (their ratings are not comparable to the anchor's);
    4. players without any (non-zero-weight) game get ``anchor_rating`` and the flag ``"unrated"``.

    ``prior_games > 0`` turns this into a MAP fit: every player gets ``prior_games`` virtual draws (at
    least ``BOUND_PRIOR_GAMES`` for flagged players) spread over its opponents, and each connected
    component is fitted in one piece. Ratings are always finite, never NaN.

    Args:
        a, b: int arrays of player indices (``0 <= a, b < n_players``, ``a != b``).
        score_a: A's points per game in [0, 1] (W/D/L counts treat > 1/2 as a win, < 1/2 a loss).
        n_players: population size.
        anchor, anchor_rating: the player whose rating is fixed, and its value.
        weights: optional non-negative weight per game.
        prior_games: virtual draws per player (0 = pure maximum likelihood).
        init: optional warm start (Elo ratings, e.g. a previous fit's ``ratings``).
        tol: convergence tolerance on the ratings, in Elo.
        max_iter: Newton iteration cap per sub-problem.
    """
    ai, bi, sc, wt = _validate_games(a, b, score_a, n_players, anchor, weights)
    if prior_games < 0:
        raise ValueError("prior_games must be non-negative")
    w, nmat = _pair_matrices(ai, bi, sc, wt, n_players)
    init_arr = None if init is None else np.asarray(init, dtype=np.float64).ravel()
    if init_arr is not None and init_arr.size != n_players:
        raise ValueError("init must have one rating per player")
    ratings, flags, iterations, converged = _fit_matrices(
        w, nmat, anchor, float(anchor_rating), float(prior_games), init_arr, tol, max_iter
    )
    g = np.ones_like(sc) if wt is None else wt
    win, draw, loss = g * (sc > 0.5), g * (sc == 0.5), g * (sc < 0.5)

    def per_player(x_a: FloatArray, x_b: FloatArray) -> FloatArray:
        return np.bincount(ai, x_a, minlength=n_players) + np.bincount(bi, x_b, minlength=n_players)

    games = per_player(g, g)
    wins, draws, losses = per_player(win, loss), per_player(draw, draw), per_player(loss, win)
    points = per_player(g * sc, g * (1.0 - sc))
    score = np.divide(points, games, out=np.full(n_players, 0.5), where=games > 0)
    integral = wt is None or bool(np.all(wt == np.round(wt)))
    conv = (lambda x: np.rint(x).astype(np.int64)) if integral else (lambda x: x)
    return BTFit(
        ratings=ratings, flags=flags, games=conv(games), wins=conv(wins), draws=conv(draws),
        losses=conv(losses), score=score, iterations=iterations, converged=converged, anchor=int(anchor),
        anchor_rating=float(anchor_rating),
    )


def bootstrap_ci(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    score_a: npt.ArrayLike,
    n_players: int,
    anchor: int = 0,
    anchor_rating: float = 1000.0,
    n_boot: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    prior_games: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Percentile bootstrap confidence intervals of the :func:`fit_bradley_terry` ratings.

    Each replicate resamples the ``G`` games with replacement, i.e. draws multinomial counts
    ``Mult(G; 1/G, ..., 1/G)`` per game. Games with identical ``(a, b, score_a)`` are interchangeable,
    so the counts are drawn per distinct game type (``Mult(G; c_t / G)`` for a type seen ``c_t`` times,
    the same distribution, fewer categories) and the replicate is refitted from the re-weighted pair
    matrices, warm-started from the full-data fit. The interval is
    ``[q_{(1-c)/2}, q_{(1+c)/2}]`` of the replicate ratings, widened if necessary to contain the
    full-data rating.

    Flagged players get the quantiles of their (finite) bounded ratings; replicates in which a player
    drew no game are ignored for that player; a player with no game at all gets
    ``anchor_rating -+ MAX_ELO``. The anchor's interval is the single point ``anchor_rating``.

    Returns:
        ``(low, high)``, two float arrays of shape (n_players,), finite.
    """
    ai, bi, sc, _ = _validate_games(a, b, score_a, n_players, anchor, None)
    if n_boot < 1:
        raise ValueError("n_boot must be at least 1")
    if not 0.0 < confidence < 1.0:
        raise ValueError("confidence must be in (0, 1)")
    full = fit_bradley_terry(ai, bi, sc, n_players, anchor, anchor_rating, prior_games=prior_games)
    point = full.ratings
    low = point - MAX_ELO
    high = point + MAX_ELO
    n_games = ai.size
    if n_games == 0:
        return low, high
    # Distinct game types and their multiplicities.
    keys = np.stack([ai, bi, np.rint(sc * 1e9).astype(np.int64)], axis=1)
    uniq, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    first = np.zeros(uniq.shape[0], dtype=np.int64)
    first[inverse] = np.arange(n_games)
    t_a, t_b, t_s = ai[first], bi[first], sc[first]
    rng = np.random.default_rng(seed)
    probs = counts / n_games
    boot = np.empty((n_boot, n_players))
    for k in range(n_boot):
        wt = rng.multinomial(n_games, probs).astype(np.float64)
        w, nmat = _pair_matrices(t_a, t_b, t_s, wt, n_players)
        r, _, _, _ = _fit_matrices(w, nmat, anchor, float(anchor_rating), float(prior_games), point,
                                   1e-6, 100)
        r[nmat.sum(axis=1) == 0] = np.nan  # no game in this replicate: no information
        boot[k] = r
    seen = np.any(np.isfinite(boot), axis=0)
    if seen.any():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            q = np.nanquantile(boot[:, seen], [(1.0 - confidence) / 2.0, (1.0 + confidence) / 2.0], axis=0)
        low[seen], high[seen] = q[0], q[1]
    low = np.minimum(low, point)
    high = np.maximum(high, point)
    return low, high


def rank_by_ci(ratings: npt.ArrayLike, low: npt.ArrayLike, high: npt.ArrayLike) -> IntArray:
    """Chatbot-Arena rank: ``rank_i = 1 + #{j : low_j > high_i}``.

    A player is outranked only by players whose whole interval lies above its own, so players with
    overlapping intervals share ranks (ties are allowed and ranks need not be consecutive).
    ``ratings`` is only used to check the shapes (the rank depends on the intervals alone).
    """
    r = np.asarray(ratings, dtype=np.float64).ravel()
    lo = np.asarray(low, dtype=np.float64).ravel()
    hi = np.asarray(high, dtype=np.float64).ravel()
    if not (r.size == lo.size == hi.size):
        raise ValueError("rank_by_ci: ratings, low and high must have the same length")
    sorted_low = np.sort(lo)
    above = lo.size - np.searchsorted(sorted_low, hi, side="right")
    return (1 + above).astype(np.int64)
