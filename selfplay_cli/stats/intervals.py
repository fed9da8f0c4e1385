"""Confidence intervals of Bradley-Terry ratings (Laplace approximation and percentile bootstrap, both under the
prior), and the standard deviations of every rating difference, from which a ladder reads who is separated
from whom.

:func:`laplace_ci`: the Laplace (normal) approximation of the log-posterior at the fit: its negative Hessian
is the weighted graph Laplacian of ``c_ij = (N_ij + V_ij) p_ij (1 - p_ij)`` (the virtual draws included),
with the anchor's row and column removed; ``se_i = sqrt((L^-1)_ii)`` nats. With ``prior_games=0`` it is the
usual Wald interval from the observed Fisher information.

:func:`bootstrap_ci`: the percentile bootstrap; every replicate resamples the real games and adds the prior's
virtual draws afresh (the prior is part of the model, not data). A percentile bootstrap alone is dishonest
under the prior when the data are separated: a player that won every game wins every game of every
replicate, all replicates give the same MAP and the percentile interval has zero width, a precision the
data never showed. So with a prior the reported interval is the union of the percentile interval and the
Laplace interval at the full-data MAP: never narrower than the curvature of the log-posterior says. (The
Laplace interval is symmetric while the posterior of a perfect score is skewed towards higher ratings; it
is a floor on the width, not an exact posterior interval.) Without a prior the bootstrap is reported as is
and the unbounded side of flagged players is opened by the caller.

numpy and the standard library only.
"""

from __future__ import annotations

import warnings

import numpy as np
import numpy.typing as npt

from .bradley_terry import (
    FloatArray,
    _fit_matrices,
    _pair_matrices,
    _sigmoid,
    _validate_games,
    fit_bradley_terry,
    prior_draws,
    reachable,
)
from .elo import MAX_ELO, NAT_TO_ELO, normal_quantile

__all__ = ["DEFAULT_BOOTSTRAP", "bootstrap_ci", "bootstrap_intervals", "laplace_ci", "laplace_intervals"]

DEFAULT_BOOTSTRAP = 200
"""Replicates of the percentile bootstrap behind a ladder's rating intervals unless told otherwise: ``marl league
ladder``, ``marl elo fit`` and the summary of ``marl train`` all use it, so a rating's interval reads the same in
each."""


def _difference_sd(cov: FloatArray) -> FloatArray:
    """``sd(r_i - r_j) = sqrt(cov_ii + cov_jj - 2 cov_ij)`` for every pair (clipped at 0 before the root)."""
    d = np.diag(cov)
    return np.sqrt(np.maximum(d[:, None] + d[None, :] - 2.0 * cov, 0.0))


def laplace_intervals(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    n_players: int,
    ratings: npt.ArrayLike,
    anchor: int = 0,
    confidence: float = 0.95,
    prior_games: float = 0.0,
    weights: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`laplace_ci` and, third, the ``(n, n)`` standard deviations of the rating differences ``r_i - r_j``
    (Elo) from the same covariance ``L^-1`` (so the uncertainty two players share through the anchor cancels).
    Players outside the anchor's component have ``MAX_ELO`` there."""
    ai, bi, _, wt = _validate_games(a, b, np.zeros(np.asarray(a).size), n_players, anchor, weights)
    if not 0.0 < confidence < 1.0:
        raise ValueError("confidence must be in (0, 1)")
    r = np.asarray(ratings, dtype=np.float64).ravel()
    if r.size != n_players or not np.all(np.isfinite(r)):
        raise ValueError("ratings must be finite, one per player")
    _, n = _pair_matrices(ai, bi, np.zeros(ai.size), wt, n_players)
    nn = n + prior_draws(n, float(prior_games))
    cov = np.diag(np.full(n_players, MAX_ELO**2))
    cov[anchor, anchor] = 0.0
    idx = np.flatnonzero(reachable(nn > 0, anchor) & (np.arange(n_players) != anchor))
    if idx.size:
        theta = (r - r[anchor]) / NAT_TO_ELO
        p = _sigmoid(theta[:, None] - theta[None, :])
        c = nn * p * (1.0 - p)
        lap = -c[np.ix_(idx, idx)]
        lap[np.diag_indices_from(lap)] += c[idx].sum(axis=1)
        try:
            sub = np.linalg.inv(lap)
        except np.linalg.LinAlgError:
            sub = np.linalg.pinv(lap)
        sub = sub * NAT_TO_ELO**2
        if not np.all(np.isfinite(sub)):  # pragma: no cover - L is positive definite on the component
            sub = np.diag(np.full(idx.size, MAX_ELO**2))
        cov[np.ix_(idx, idx)] = sub
    var = np.diag(cov)
    se = np.minimum(np.sqrt(np.where(var > 0.0, var, 0.0)), MAX_ELO)
    diff = np.minimum(_difference_sd(cov), MAX_ELO)
    outside = np.ones(n_players, dtype=bool)
    outside[idx] = False
    outside[anchor] = False
    diff[outside, :] = MAX_ELO
    diff[:, outside] = MAX_ELO
    np.fill_diagonal(diff, 0.0)
    z = normal_quantile(0.5 + 0.5 * confidence)
    return r - z * se, r + z * se, diff


def laplace_ci(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    n_players: int,
    ratings: npt.ArrayLike,
    anchor: int = 0,
    confidence: float = 0.95,
    prior_games: float = 0.0,
    weights: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Laplace (normal) intervals ``ratings -+ z se`` from the curvature of the log-posterior at ``ratings``.

    The negative Hessian of the Bradley-Terry log-likelihood plus BayesElo's virtual draws, in nats, is the
    weighted graph Laplacian ``L_ii = sum_j c_ij``, ``L_ij = -c_ij`` with ``c_ij = (N_ij + V_ij) p_ij (1 - p_ij)``,
    ``V = prior_draws(N, prior_games)``, ``p_ij = E(r_i - r_j)``; it does not depend on the results, only on
    who played whom and on the ratings. With the anchor's row and column removed (the anchor is fixed) it is
    invertible on the anchor's connected component, and ``se_i = sqrt((L^-1)_ii) * 400 / ln 10`` Elo, capped
    at ``MAX_ELO``; ``z = Phi^-1((1 + confidence) / 2)``. Players outside the anchor's component (or without
    games) get ``se = MAX_ELO``; the anchor's interval is the point ``ratings[anchor]``. With
    ``prior_games=0`` this is the Wald interval from the observed Fisher information.

    Returns:
        ``(low, high)``, two finite float arrays of shape (n_players,).
    """
    low, high, _ = laplace_intervals(a, b, n_players, ratings, anchor, confidence, prior_games, weights)
    return low, high


def bootstrap_intervals(
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
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`bootstrap_ci` and, third, the ``(n, n)`` standard deviations of the rating differences
    ``r_i - r_j`` (Elo) over the replicates (pairwise-complete covariance of the replicate ratings); with a
    prior, never below the :func:`laplace_intervals` ones at the full-data MAP. Players without games:
    ``MAX_ELO``."""
    ai, bi, sc, _ = _validate_games(a, b, score_a, n_players, anchor, None)
    if n_boot < 1:
        raise ValueError("n_boot must be at least 1")
    if not 0.0 < confidence < 1.0:
        raise ValueError("confidence must be in (0, 1)")
    full = fit_bradley_terry(ai, bi, sc, n_players, anchor, anchor_rating, prior_games=prior_games)
    point = full.ratings
    low = point - MAX_ELO
    high = point + MAX_ELO
    diff = np.full((n_players, n_players), MAX_ELO)
    np.fill_diagonal(diff, 0.0)
    n_games = ai.size
    if n_games == 0:
        return low, high, diff
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
        # Pairwise-complete covariance of the replicates (a player absent from a replicate is left out of it).
        present = np.isfinite(boot)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            centred = np.where(present, boot - np.nanmean(np.where(present, boot, np.nan), axis=0), 0.0)
        pairs = present.T.astype(np.float64) @ present.astype(np.float64)
        cov = np.divide(centred.T @ centred, pairs - 1.0, out=np.zeros((n_players, n_players)), where=pairs > 1.0)
        sd = _difference_sd(cov)
        both = pairs > 1.0
        diff = np.where(both, np.minimum(sd, MAX_ELO), MAX_ELO)
        np.fill_diagonal(diff, 0.0)
    low = np.minimum(low, point)
    high = np.maximum(high, point)
    if prior_games > 0.0:
        lap_low, lap_high, lap_diff = laplace_intervals(ai, bi, n_players, point, anchor, confidence, prior_games)
        low, high = np.minimum(low, lap_low), np.maximum(high, lap_high)
        diff = np.maximum(diff, lap_diff)
    return low, high, diff


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
    matrices, warm-started from the full-data fit; under a prior the replicate gets its own virtual draws
    (:func:`prior_draws` of its re-weighted games). The interval is ``[q_{(1-c)/2}, q_{(1+c)/2}]`` of the
    replicate ratings, widened if necessary to contain the full-data rating.

    With ``prior_games > 0`` the interval is also widened to contain the :func:`laplace_ci` interval at the
    full-data MAP, so that separated data (every replicate of a perfect score is the same perfect score, and
    the percentile interval collapses to a point) never give an interval narrower than the posterior's
    curvature. Without a prior, flagged players get the quantiles of their (finite) bounded ratings (callers
    open the unbounded side).

    Replicates in which a player drew no game are ignored for that player; a player with no game at all gets
    ``anchor_rating -+ MAX_ELO``. The anchor's interval is the single point ``anchor_rating``.

    Returns:
        ``(low, high)``, two float arrays of shape (n_players,), finite.
    """
    low, high, _ = bootstrap_intervals(a, b, score_a, n_players, anchor, anchor_rating, n_boot, confidence, seed,
                                       prior_games)
    return low, high
