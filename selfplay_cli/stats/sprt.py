"""The generalised sequential probability ratio test (GSPRT) of fishtest / fastchess, with the exact multinomial
maximum-likelihood LLR (M. Van den Bergh, "Comments on normalized Elo" / "support_MLE_multinomial"), in logistic
or normalized Elo, on game-pair (pentanomial) or per-game (trinomial) counts.

numpy and the standard library only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from .elo import elo_to_score

__all__ = ["SPRT", "sprt_bounds", "sprt_llr"]

FloatArray = npt.NDArray[np.float64]

# Elo-model names accepted by the SPRT functions.
EloModel = Literal["logistic", "normalized"]
CountModel = Literal["pentanomial", "trinomial", "categorical"]
LEVELS = 17  # a categorical count's levels of a round's mean points: 0, 1/16, ..., 1

# Normalized Elo per unit of t-value: nElo = t * 800 / ln(10) (fishtest's ``nelo_divided_by_nt``).
_NELO_PER_T: float = 800.0 / math.log(10.0)
# fishtest / fastchess replace an empty outcome bin by this pseudo-count before any MLE.
_SPRT_EMPTY_BIN: float = 1e-3




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
            ``model="trinomial"``: ``(losses, draws, wins)`` with ``a = 0, 1/2, 1``; ``model="categorical"``
            (results worth any points, a game played for stakes: :func:`round_counts`): counts of rounds by their
            mean points at ``a = 0, 1/(k-1), ..., 1``, logistic Elo only.
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
    if model == "categorical":
        if vals.size < 2 or np.any(vals < 0) or not np.all(np.isfinite(vals)) or elo_model != "logistic":
            raise ValueError("sprt_llr: categorical counts are 2 or more finite counts >= 0, in logistic Elo")
        if vals.sum() <= 0:
            return 0.0
        vals = np.where(vals == 0.0, _SPRT_EMPTY_BIN, vals)
        total = float(vals.sum())
        phat, a = vals / total, np.linspace(0.0, 1.0, vals.size)
        p0, p1 = _mle_expected(phat, a, elo_to_score(elo0)), _mle_expected(phat, a, elo_to_score(elo1))
        return float(total * np.sum(phat * (np.log(p1) - np.log(p0))))
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


def round_counts(round_points: Sequence[Sequence[float]], paired: bool) -> tuple[list[int], CountModel]:
    """What a GSPRT counts of a match's rounds (A's points in each result of each round): game pairs by A's points
    in them, ``(LL, LD, WL+DD, WD, WW)``, where the rounds are seat-swapped pairs of wins, draws and losses; A's
    results ``(losses, draws, wins)`` where they are not paired; where results are worth any points (a game played
    for stakes), the rounds by their mean points at :data:`LEVELS` levels (``categorical``)."""
    model = count_model(round_points, paired)
    counts = [0] * {"categorical": LEVELS, "pentanomial": 5, "trinomial": 3}[model]
    for r in round_points:
        for k in categories(r, model):
            counts[k] += 1
    return counts, model


def count_model(round_points: Sequence[Sequence[float]], paired: bool) -> CountModel:
    """The :func:`round_counts` model of these rounds."""
    if any(float(x) not in (0.0, 0.5, 1.0) for r in round_points for x in r):
        return "categorical"
    return "pentanomial" if paired else "trinomial"


def categories(points: Sequence[float], model: CountModel) -> list[int]:
    """The count(s) one round adds to, under ``model`` (a trinomial round: one per result)."""
    if model == "categorical":
        return [int(round((LEVELS - 1) * sum(points) / len(points)))] if len(points) else []
    if model == "pentanomial":
        return [min(max(int(round(2 * sum(points))), 0), 4)]
    return [0 if x < 0.5 else 1 if x == 0.5 else 2 for x in points]


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

