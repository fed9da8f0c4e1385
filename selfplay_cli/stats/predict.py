"""What a ladder predicts of a match not yet played: the score of A against B over ``n`` games, with an interval
that a longer match can check.

A ladder's ratings are a model, Bradley-Terry: ``P(A beats B) = E(r_A - r_B)``, one number per player. Three things
stand between a fitted difference and the score a real match will show:

1. the uncertainty of the fitted difference (its standard deviation ``sd``, from the same covariance as the ladder's
   intervals, so the uncertainty two players share through the anchor cancels);
2. the luck of the match itself: ``n`` games give a score that is binomial around the true expectation;
3. what one number per player cannot say: self-play is full of rock-paper-scissors, a snapshot that beats the
   other paddle's latest more than their ratings say and loses to an older one more. :func:`pair_spread` measures
   this spread ``tau`` (Elo) from the ledger itself: the excess of the pairs' observed scores over what (1) and (2)
   explain, a random-effects (DerSimonian-Laird) estimate on the logit scale. A pair's own games then say where
   this pair stands within that spread (:func:`pair_effect`): the prediction leans on them as far as their number
   allows, and on the ratings for the rest.

:func:`predict_score` integrates all three: the difference ``d ~ N(diff, sd^2 + spread^2)``, the score ``K / n``
with ``K ~ Binomial(n, E(d))``; its interval is the central ``confidence`` interval of that mixture (Gauss-Hermite
quadrature over ``d``, exact binomial over ``K``). Draws are counted as half a point and modelled as a coin of the
same mean, which overstates the spread of a score with draws: the interval errs wide, never narrow.

numpy and scipy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.stats import binom

from .elo import NAT_TO_ELO, normal_quantile

__all__ = ["ScorePrediction", "pair_effect", "pair_spread", "predict_score"]

_NODES, _WEIGHTS = np.polynomial.hermite_e.hermegauss(48)  # probabilists' Hermite: weight exp(-x^2 / 2)
_WEIGHTS = _WEIGHTS / _WEIGHTS.sum()


def _expected(d_elo: npt.ArrayLike) -> np.ndarray:
    return 1.0 / (1.0 + np.power(10.0, -np.asarray(d_elo, dtype=np.float64) / 400.0))


@dataclass(frozen=True)
class ScorePrediction:
    """A's predicted score against B over ``games`` games: its expectation and the central interval the measured
    score falls in with probability ``confidence``; ``diff`` / ``sd`` the Elo difference the prediction rests on
    (after the pair's own games) and its standard deviation (model spread included)."""

    score: float
    low: float
    high: float
    games: int
    confidence: float
    diff: float
    sd: float

    def holds(self, measured: float) -> bool:
        """Whether a measured score lies in the predicted interval."""
        return self.low - 1e-12 <= measured <= self.high + 1e-12

    def to_json(self) -> dict[str, float | int]:
        return {"score": round(self.score, 4), "low": round(self.low, 4), "high": round(self.high, 4),
                "games": self.games, "confidence": self.confidence, "elo_diff": round(self.diff, 1),
                "elo_sd": round(self.sd, 1)}


def predict_score(diff: float, sd: float, games: int, confidence: float = 0.95) -> ScorePrediction:
    """The score of A over ``games`` games when ``r_A - r_B ~ N(diff, sd^2)`` (Elo; see the module docstring).
    ``games = 0`` predicts the expectation alone: the interval is that of ``E(d)``."""
    if not (math.isfinite(diff) and math.isfinite(sd) and sd >= 0):
        raise ValueError(f"the difference and its sd must be finite (sd >= 0), not {diff} / {sd}")
    if games < 0:
        raise ValueError(f"games must be >= 0, not {games}")
    if not 0.0 < confidence < 1.0:
        raise ValueError("confidence must be in (0, 1)")
    p = _expected(diff + sd * _NODES)
    expected = float(np.dot(_WEIGHTS, p))
    tail = 0.5 * (1.0 - confidence)
    if games == 0:
        z = normal_quantile(1.0 - tail)
        low, high = _expected([diff - z * sd, diff + z * sd]).tolist()
        return ScorePrediction(expected, low, high, 0, confidence, diff, sd)
    k = np.arange(games + 1)
    pmf = _WEIGHTS @ binom.pmf(k[None, :], games, p[:, None])
    cdf = np.cumsum(pmf)
    lo_k = int(np.searchsorted(cdf, tail - 1e-12))  # the smallest k with P(K <= k) >= tail
    upper = np.cumsum(pmf[::-1])[::-1]  # P(K >= k)
    hi_k = int(np.flatnonzero(upper >= tail - 1e-12)[-1])  # the largest k with P(K >= k) >= tail
    return ScorePrediction(expected, lo_k / games, hi_k / games, games, confidence, diff, sd)


def _logit_residuals(points: np.ndarray, games: np.ndarray, diff_elo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pair: the observed score's logit less the fitted one (nats), and its sampling variance, with half a point
    of continuity correction (a perfect score keeps a finite logit)."""
    s = (points + 0.5) / (games + 1.0)
    p = _expected(diff_elo)
    y = np.log(s / (1.0 - s)) - np.log(p / (1.0 - p))
    v = 1.0 / ((games + 1.0) * s * (1.0 - s))
    return y, v


def pair_spread(points: npt.ArrayLike, games: npt.ArrayLike, diff_elo: npt.ArrayLike, n_players: int) -> float:
    """The spread ``tau`` (Elo) of pairs around what their ratings predict, from the pairs that met.

    ``points[k]`` / ``games[k]``: the first player's points and the games of pair ``k``; ``diff_elo[k]`` its fitted
    rating difference. DerSimonian-Laird on the logit scale: ``Q = sum w y^2`` with ``y`` the residual logit and
    ``w = 1 / v`` its inverse sampling variance, ``tau^2 = max(0, (Q - df) / (sum w - sum w^2 / sum w))`` where
    ``df = pairs - (n_players - 1)`` (the ratings were fitted to the same games). 0 when the pairs are too few to
    tell (df < 1)."""
    pts = np.asarray(points, dtype=np.float64)
    n = np.asarray(games, dtype=np.float64)
    d = np.asarray(diff_elo, dtype=np.float64)
    keep = n > 0
    pts, n, d = pts[keep], n[keep], d[keep]
    df = pts.size - (n_players - 1)
    if df < 1:
        return 0.0
    y, v = _logit_residuals(pts, n, d)
    w = 1.0 / v
    q = float(np.sum(w * y * y))
    denom = float(w.sum() - np.sum(w * w) / w.sum())
    if denom <= 0:
        return 0.0
    tau2 = max(0.0, (q - df) / denom)
    return math.sqrt(tau2) * NAT_TO_ELO


def pair_effect(points: float, games: float, diff_elo: float, spread_elo: float) -> tuple[float, float]:
    """How far this pair stands from its ratings' prediction, from its own games: the posterior mean and standard
    deviation (Elo) of its deviation, a normal prior of sd ``spread_elo`` updated with the pair's residual logit.
    Without games, or without spread, the ratings alone: ``(0, spread)``."""
    if games <= 0 or spread_elo <= 0:
        return 0.0, float(spread_elo)
    y, v = _logit_residuals(np.array([points], dtype=np.float64), np.array([games], dtype=np.float64),
                            np.array([diff_elo], dtype=np.float64))
    t2 = (spread_elo / NAT_TO_ELO) ** 2
    shrink = t2 / (t2 + float(v[0]))
    mean = shrink * float(y[0]) * NAT_TO_ELO
    sd = math.sqrt(t2 * float(v[0]) / (t2 + float(v[0]))) * NAT_TO_ELO
    return mean, sd
