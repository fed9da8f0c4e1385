"""What a ladder predicts of a match not yet played: the score of A against B over ``n`` games, with an interval
that a longer match can check.

A ladder's ratings are a model, Bradley-Terry: ``P(A beats B) = E(r_A - r_B)``, one number per player. Three things
stand between a fitted difference and the score a real match will show:

1. the uncertainty of the fitted difference (its standard deviation ``sd``, from the same covariance as the ladder's
   intervals, so the uncertainty two players share through the anchor cancels);
2. the luck of the match itself: ``n`` games give a score that is binomial around the true expectation;
3. what one number per player cannot say: self-play is full of rock-paper-scissors, a snapshot that beats the
   other learner's latest more than their ratings say and loses to an older one more. :func:`pair_spread` measures
   this spread ``tau`` (Elo) from the ledger itself: how far the pairs that met stand from what the rest of the
   ledger predicts of them, beyond what (1) and (2) explain (a random effect per pair, fitted by marginal
   likelihood). A pair's own games then say where this pair stands within that spread: the prediction leans on
   them as far as their number allows, and on the ratings for the rest.

:func:`predict_pair` integrates all three: the difference ``diff + e + delta`` with the pair's deviation ``e ~
N(0, spread^2)`` updated by its own games and the fit's uncertainty ``delta ~ N(0, sd^2)``, the score ``K / n`` with
``K ~ Binomial(n, E(d))``; its interval is the central ``confidence`` interval of that mixture (quadrature on a grid
over ``e`` and ``delta``, gathered into 256 levels of ``E(d)``, exact binomials over ``K``). Draws are counted as
half a point and modelled as a coin of the same mean, which overstates the spread of a score with draws: the
interval errs wide, never narrow.

numpy and scipy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar
from scipy.stats import binom

from .elo import NAT_TO_ELO

__all__ = ["ScorePrediction", "pair_spread", "predict_pair"]


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


def _grid(scale: float, size: int = 241) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (nats) and weights of ``N(0, scale^2)`` on an even grid over +-6 standard deviations."""
    if scale <= 0:
        return np.zeros(1), np.ones(1)
    x = np.linspace(-6.0, 6.0, size)
    w = np.exp(-0.5 * x * x)
    return scale * x, w / w.sum()


def _log_likelihood(points: np.ndarray, games: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``W log p + (n - W) log(1 - p)`` with ``p = sigmoid(theta)`` (nats), broadcast; a draw is half a point."""
    return -points * np.logaddexp(0.0, -theta) - (games - points) * np.logaddexp(0.0, theta)


def pair_spread(points: npt.ArrayLike, games: npt.ArrayLike, diff_elo: npt.ArrayLike,
                sd_elo: npt.ArrayLike | float = 0.0) -> float:
    """The spread ``tau`` (Elo) of pairs around what their ratings predict, from the pairs that met.

    ``points[k]`` / ``games[k]``: the first player's points and the games of pair ``k``; ``diff_elo[k]`` the
    difference its ratings predict and ``sd_elo[k]`` that prediction's own uncertainty. Best read from ratings fitted
    without the pair's games (:meth:`~selfplay_cli.league.forecast.Forecaster.of_games` leaves each pair out in
    turn): a fit that includes them has already moved toward them, and the spread it shows is too small. Each pair's
    true difference is its predicted one plus ``N(0, sd^2 + tau^2)``; ``tau`` maximises the marginal likelihood
    ``prod_k E[Binomial(W_k; n_k, E(d))]`` (quadrature). A 0-8 between players 1,500 Elo apart says nothing against
    the ratings, an upset there says much: the likelihood weighs each as it should, where moment estimates on logits
    blow up at perfect scores. 0 without pairs, or when no spread fits better than none."""
    pts = np.asarray(points, dtype=np.float64)
    n = np.asarray(games, dtype=np.float64)
    d = np.asarray(diff_elo, dtype=np.float64) / NAT_TO_ELO
    sd = np.broadcast_to(np.asarray(sd_elo, dtype=np.float64) / NAT_TO_ELO, d.shape)
    keep = n > 0
    pts, n, d, sd = pts[keep], n[keep], d[keep], sd[keep]
    if not pts.size:
        return 0.0
    x, w = _grid(1.0, 61)

    def neg(tau: float) -> float:
        scale = np.sqrt(sd * sd + tau * tau)
        ll = _log_likelihood(pts[:, None], n[:, None], d[:, None] + scale[:, None] * x[None, :]) + np.log(w)[None, :]
        return -float(np.sum(np.logaddexp.reduce(ll, axis=1)))

    best = minimize_scalar(neg, bounds=(0.0, 1500.0 / NAT_TO_ELO), method="bounded", options={"xatol": 1e-3})
    return 0.0 if neg(0.0) <= best.fun + 1e-9 else float(best.x) * NAT_TO_ELO


def predict_pair(diff: float, sd: float, games: int, *, spread: float = 0.0, met_points: float = 0.0,
                 met_games: float = 0.0, confidence: float = 0.95) -> ScorePrediction:
    """A's score over ``games`` games against B as a ladder predicts it: the fitted difference ``diff`` with its
    ``sd`` (Elo), widened by the pairs' ``spread`` (:func:`pair_spread`), then updated with the pair's own record
    (``met_points`` of ``met_games``): where the two met often, the prediction leans on their games; where they
    never met, on the ratings and the spread alone."""
    if not (math.isfinite(diff) and math.isfinite(sd) and sd >= 0 and math.isfinite(spread) and spread >= 0):
        raise ValueError(f"the difference, its sd and the spread must be finite (sd, spread >= 0), not "
                         f"{diff} / {sd} / {spread}")
    if games < 1:
        raise ValueError(f"games must be at least 1, not {games}")
    if not 0.0 < confidence < 1.0:
        raise ValueError("confidence must be in (0, 1)")
    # The pair's deviation e from its ratings ~ N(0, spread^2), updated with the pair's own games (read at the fitted
    # difference: the fit's own uncertainty delta already holds what those games say of the ratings, so they update
    # e alone), then the fit's uncertainty delta ~ N(0, sd^2) on top: theta = diff + e + delta.
    e, we = _grid(spread / NAT_TO_ELO, 121)
    loge = np.log(we) + _log_likelihood(float(met_points), float(met_games), diff / NAT_TO_ELO + e)
    we = np.exp(loge - loge.max())
    we /= we.sum()
    delta, wd = _grid(sd / NAT_TO_ELO, 41)
    x = (e[:, None] + delta[None, :]).ravel()
    post = (we[:, None] * wd[None, :]).ravel()
    keep = post > 1e-12 * post.max()  # nodes that weigh nothing cost a binomial each
    x, post = x[keep], post[keep] / post[keep].sum()
    theta = diff / NAT_TO_ELO + x
    p = 1.0 / (1.0 + np.exp(-theta))
    mean_u = float(np.dot(post, x))
    sd_u = math.sqrt(max(float(np.dot(post, (x - mean_u) ** 2)), 0.0))
    expected = float(np.dot(post, p))
    tail = 0.5 * (1.0 - confidence)
    shift, spread_sd = diff + mean_u * NAT_TO_ELO, sd_u * NAT_TO_ELO
    if p.size > 256:  # the mixture's binomials at 256 levels of p, each weighted by the nodes it gathers
        edges = np.linspace(p.min(), p.max(), 257)
        where = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, 255)
        mass = np.bincount(where, weights=post, minlength=256)
        level = np.bincount(where, weights=post * p, minlength=256) / np.maximum(mass, 1e-300)
        p, post = level[mass > 0], mass[mass > 0]
    k = np.arange(games + 1)
    pmf = post @ binom.pmf(k[None, :], games, p[:, None])
    cdf = np.cumsum(pmf)
    lo_k = int(np.searchsorted(cdf, tail - 1e-12))  # the smallest k with P(K <= k) >= tail
    upper = np.cumsum(pmf[::-1])[::-1]  # P(K >= k)
    hi_k = int(np.flatnonzero(upper >= tail - 1e-12)[-1])  # the largest k with P(K >= k) >= tail
    return ScorePrediction(expected, lo_k / games, hi_k / games, games, confidence, shift, spread_sd)
