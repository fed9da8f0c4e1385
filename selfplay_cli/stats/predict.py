"""What a ladder may claim of a pair of players: how far apart they are (a margin with its interval), whether one is
above the other beyond doubt, and what a match not yet played between them will show.

A ladder's ratings are a model, Bradley-Terry: ``P(A beats B) = E(r_A - r_B)``, one number per player. A claim about
two players is a claim about their *pair*: the difference ``T`` that sets A's expected score against B. Three things
stand between the fitted difference and ``T``, and a fourth between ``T`` and the score a real match will show:

1. the uncertainty of the fitted difference (from the covariance of the fit, so the uncertainty two players share
   through the anchor cancels);
2. what one number per player cannot say: self-play is full of rock-paper-scissors, a snapshot that beats the other
   learner's latest more than their ratings say and loses to an older one more; a tennis player rated far above
   another through their games against the serve bot while the two, head to head, are even. This is the *spread*
   ``tau`` of pairs around their ratings, measured from the ledger itself (:func:`measure_spread`): how far the pairs
   that met stand from what the rest of the ledger predicts of them, beyond what (1) and their luck explain. Where
   few pairs met, ``tau`` is little known: its posterior (a half-normal prior of scale :data:`SPREAD_PRIOR` Elo,
   then the pairs' marginal likelihood) is kept whole, not replaced by its most likely value, so a ladder with
   little evidence of its model claims little;
3. the pair's own games: where the two met, ``T`` is what the rest of the ledger says of it (ratings fitted without
   those games, :class:`PairModel`) updated by their own record, so a pair that met often is judged by its games and
   a pair that never met by the ratings and the spread alone;
4. the luck of the match itself: ``n`` games give a score that is binomial around ``E(T)``.

:func:`belief` gives the distribution of ``T`` on a grid (:class:`~.belief.Belief`, :mod:`.belief`): its mean and
central interval are a margin ("A over B by +M [lo, hi]"), its lower tail says whether A is above B beyond doubt, and
:meth:`~.belief.Belief.predict` adds (4) for a match of ``n`` games (exact binomials, mixed over ``T``). Draws count as
half a point and are modelled as a coin of the same mean, which overstates the spread of a score with draws: the
intervals err wide, never narrow. Games played in rounds on one seed (a seat-swapped pair) may be correlated: where a
policy that wins one game of a seed tends to win the other, 200 games say what fewer independent ones would. The caller
measures that from the ledger (:func:`~selfplay_cli.ratings.pairs.design_effect`) and :class:`PairModel` tempers every
record by it, widens the fit's uncertainty and predicts a match from the independent results it is worth (where the
games of a round are anti-correlated, a serve that wins either way, the binomial errs wide: left so).

numpy and scipy only.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .belief import NODES, Belief, cdf_at
from .bradley_terry import _fit_matrices, prior_draws, reachable
from .elo import MAX_ELO, NAT_TO_ELO

__all__ = ["FREE_SD", "SPREAD_PRIOR", "PairModel", "Spread", "belief", "measure_spread"]

SPREAD_PRIOR: float = 200.0
"""Scale (Elo) of the half-normal prior on the pairs' spread ``tau``: before any pair has met, a pair is believed to
stand within a few hundred Elo of what its ratings say (the default pong runs measure 120 to 214)."""

FREE_SD: float = 1000.0
"""Standard deviation (Elo) of the prior of a pair's difference where the rest of the ledger says nothing of it (the
pair's own games are all that link the two)."""

_TAUS = np.concatenate([np.arange(0.0, 200.0, 10.0), np.arange(200.0, 500.0, 25.0), np.arange(500.0, 1001.0, 50.0)])
"""The spread's grid (Elo)."""
_MIXTURE = 8  # components the spread's posterior is gathered into where it enters a pair's belief
_HERMITE = np.polynomial.hermite_e.hermegauss(12)  # nodes and weights of E[f(x)], x ~ N(0, 1), up to sqrt(2 pi)
_LEVERAGE = 0.3  # a pair carrying more of its two players' link than this is left out by a refit, not one step
_REFITS = 64  # refits at most in one population (the most leveraged pairs; the others say nothing)
_DRAW_PRIOR = 8.0  # results of the population's draw rate a pair's own draws are mixed with


@dataclass(frozen=True)
class Spread:
    """The posterior of the pairs' spread ``tau`` (Elo) on a grid: ``taus`` with their ``weights`` (summing to 1),
    measured from ``pairs`` pairs."""

    taus: np.ndarray
    weights: np.ndarray
    pairs: int = 0

    @property
    def mean(self) -> float:
        return float(self.taus @ self.weights)

    def __post_init__(self) -> None:
        keep = self.weights > 1e-9 * self.weights.max()  # nodes that weigh nothing cost a mixture term each
        w = self.weights[keep]
        object.__setattr__(self, "taus", np.asarray(self.taus[keep], dtype=np.float64))
        object.__setattr__(self, "weights", w / w.sum())

    @functools.cached_property
    def mixture(self) -> tuple[np.ndarray, np.ndarray]:
        """The posterior gathered into at most :data:`_MIXTURE` components of equal mass (each the root mean square
        of the spreads it gathers, which keeps ``E[tau^2]``): ``(taus, weights)``, what a pair's belief mixes over."""
        if self.taus.size <= _MIXTURE:
            return self.taus, self.weights
        edges = np.linspace(0.0, 1.0, _MIXTURE + 1)[1:-1]
        group = np.searchsorted(edges, np.cumsum(self.weights) - 0.5 * self.weights)
        mass = np.bincount(group, weights=self.weights, minlength=_MIXTURE)
        power = np.bincount(group, weights=self.weights * self.taus**2, minlength=_MIXTURE)
        keep = mass > 0
        return np.sqrt(power[keep] / mass[keep]), mass[keep] / mass[keep].sum()

    @classmethod
    def known(cls, tau: float) -> Spread:
        """A spread taken as exactly ``tau`` (a simulation's truth, a test's)."""
        return cls(np.array([float(tau)]), np.ones(1))


def _log_likelihood(points: np.ndarray, games: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``W log p + (n - W) log(1 - p)`` with ``p = sigmoid(theta)`` (nats), broadcast; a draw is half a point."""
    return points * theta - games * np.logaddexp(0.0, theta)


def measure_spread(points: npt.ArrayLike, games: npt.ArrayLike, diff_elo: npt.ArrayLike,
                   sd_elo: npt.ArrayLike | float = 0.0, prior_scale: float = SPREAD_PRIOR) -> Spread:
    """The posterior of the spread ``tau`` (Elo) of pairs around what their ratings predict, from the pairs that met.

    ``points[k]`` / ``games[k]``: the first player's points and the games of pair ``k``; ``diff_elo[k]`` the
    difference its ratings predict and ``sd_elo[k]`` that prediction's own uncertainty, best read from ratings fitted
    without the pair's games (:class:`PairModel` leaves each pair out in turn: a fit that includes them has already
    moved toward them, and the spread it shows is too small). Each pair's true difference is its predicted one plus
    ``N(0, sd^2 + tau^2)``; the likelihood of ``tau`` is ``prod_k E[Binomial(W_k; n_k, E(d))]`` (quadrature), its
    prior half-normal of scale ``prior_scale``. A 0-8 between players 1,500 Elo apart says nothing against the
    ratings, an upset there says much: the likelihood weighs each as it should. Without pairs, the prior."""
    pts = np.asarray(points, dtype=np.float64).ravel()
    n = np.asarray(games, dtype=np.float64).ravel()
    d = np.asarray(diff_elo, dtype=np.float64).ravel() / NAT_TO_ELO
    sd = np.broadcast_to(np.asarray(sd_elo, dtype=np.float64) / NAT_TO_ELO, d.shape)
    keep = n > 0
    pts, n, d, sd = pts[keep], n[keep], d[keep], sd[keep]
    mids = 0.5 * (_TAUS[1:] + _TAUS[:-1])
    cell = np.diff(np.concatenate([_TAUS[:1], mids, _TAUS[-1:]]))  # the grid is finer near 0: each node weighs its cell
    log_w = -0.5 * (_TAUS / prior_scale) ** 2 + np.log(cell)
    if pts.size:
        x, wx = _HERMITE
        lx = np.log(wx / wx.sum())
        tau = _TAUS / NAT_TO_ELO
        scale = np.sqrt(sd[:, None] ** 2 + tau[None, :] ** 2)  # (pairs, taus)
        theta = d[:, None, None] + scale[:, :, None] * x[None, None, :]
        ll = _log_likelihood(pts[:, None, None], n[:, None, None], theta) + lx
        log_w = log_w + _logsumexp(ll, axis=2).sum(axis=0)
    w = np.exp(log_w - log_w.max())
    return Spread(_TAUS.copy(), w / w.sum(), int(pts.size))


def _logsumexp(x: np.ndarray, axis: int) -> np.ndarray:
    top = x.max(axis=axis, keepdims=True)
    return np.log(np.exp(x - top).sum(axis=axis)) + np.squeeze(top, axis=axis)


def _posterior(nodes: np.ndarray, diff: np.ndarray, sd: np.ndarray, spread: Spread, met_points: np.ndarray,
               met_games: np.ndarray) -> np.ndarray:
    """Weights (pairs, nodes) of the pairs' beliefs on the grids ``nodes``: the prior mixture times the games."""
    taus, tw = spread.mixture
    s_mix = np.sqrt(sd[:, None] ** 2 + taus[None, :] ** 2)  # (pairs, components)
    z = (nodes[:, :, None] - diff[:, None, None]) / s_mix[:, None, :]
    log_prior = _logsumexp(np.log(tw)[None, None, :] - np.log(s_mix)[:, None, :] - 0.5 * z * z, axis=2)
    log_post = log_prior + _log_likelihood(met_points[:, None], met_games[:, None], nodes / NAT_TO_ELO)
    w = np.exp(log_post - log_post.max(axis=1, keepdims=True))
    return w / w.sum(axis=1, keepdims=True)


def _beliefs(diff: np.ndarray, sd: np.ndarray, spread: Spread, met_points: np.ndarray,
             met_games: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grids (pairs, nodes) and weights of many pairs' beliefs at once (see :func:`belief`): a first grid over
    everything the prior and the games allow, then a second over the bulk of the posterior the first found."""
    s_max = np.sqrt(sd**2 + float(spread.taus.max()) ** 2)
    lo, hi = diff - 6.0 * s_max, diff + 6.0 * s_max
    met = met_games > 0
    if met.any():  # the games' own likelihood, wherever it lies
        s = (met_points + 0.5) / (met_games + 1.0)
        mode = NAT_TO_ELO * np.log(s / (1.0 - s))
        se = NAT_TO_ELO / np.sqrt((met_games + 1.0) * s * (1.0 - s))
        lo = np.where(met, np.minimum(lo, mode - 6.0 * se), lo)
        hi = np.where(met, np.maximum(hi, mode + 6.0 * se), hi)
    lo, hi = np.maximum(lo, diff - 3 * MAX_ELO), np.minimum(hi, diff + 3 * MAX_ELO)
    u = np.linspace(0.0, 1.0, NODES)
    nodes = lo[:, None] + (hi - lo)[:, None] * u[None, :]  # (pairs, nodes)
    w = _posterior(nodes, diff, sd, spread, met_points, met_games)
    mean = (nodes * w).sum(axis=1)
    width = np.sqrt(np.maximum((((nodes - mean[:, None]) ** 2) * w).sum(axis=1), 0.0))
    step = (hi - lo) / (NODES - 1)
    half = 8.0 * np.maximum(width, step)
    lo2, hi2 = np.maximum(mean - half, lo), np.minimum(mean + half, hi)
    nodes = lo2[:, None] + (hi2 - lo2)[:, None] * u[None, :]
    return nodes, _posterior(nodes, diff, sd, spread, met_points, met_games)


def belief(diff: float, sd: float, spread: Spread | float = 0.0, met_points: float = 0.0,
           met_games: float = 0.0) -> Belief:
    """One pair's difference ``T`` (Elo): before its own games, ``N(diff, sd^2 + tau^2)`` mixed over the spread's
    posterior (``diff`` / ``sd`` what the rest of the ledger says of the two: their ratings fitted without the
    pair's games and that fit's uncertainty), then updated by its own record, ``met_points`` of ``met_games``."""
    if not (math.isfinite(diff) and math.isfinite(sd) and sd >= 0):
        raise ValueError(f"the difference and its sd must be finite (sd >= 0), not {diff} / {sd}")
    if met_games < 0 or not 0 <= met_points <= met_games:
        raise ValueError(f"a pair's record must have 0 <= points <= games, not {met_points} / {met_games}")
    spread = spread if isinstance(spread, Spread) else Spread.known(float(spread))
    if sd == 0.0 and float(spread.taus.max()) == 0.0:  # nothing uncertain: one point
        return Belief(np.array([float(diff)]), np.ones(1), float(met_games), float(met_points))
    nodes, w = _beliefs(np.array([float(diff)]), np.array([max(float(sd), 1e-6)]), spread,
                        np.array([float(met_points)]), np.array([float(met_games)]))
    return Belief(nodes[0], w[0], float(met_games), float(met_points))


class PairModel:
    """A fitted population's pairs (:func:`belief` for any two, by index), from the fit itself: the ratings (Elo)
    and the standard deviations of their differences (the Laplace covariance of the fit under BayesElo's prior of
    ``prior`` virtual draws, anchored at ``anchor``), which players' ratings are linked to the anchor, and every
    pair's points and games.

    For a pair that met, "what the rest of the ledger says" is the fit without its games. Mostly one Newton step from
    the full one, in closed form: without pair (i, j) the log-posterior's Hessian loses ``c (e_i - e_j)(e_i - e_j)^T``
    with ``c = (N_ij + V_ij) p q`` (its games and its virtual draws), so the variance of the difference ``v =
    sd_ij^2`` becomes ``v' = v / (1 - c v)`` (Sherman-Morrison), and its gradient loses the pair's residual ``r = W_ij
    + V_ij / 2 - (N_ij + V_ij) p``, so the difference moves to ``d - r v'``. No refit: a league of 500 players is
    measured in a fraction of a second. Where the pair carries much of what links the two (``c v`` above
    :data:`_LEVERAGE`: one step from the full fit would be a long, unreliable extrapolation, thousands of Elo where
    every game was won), the fit without the pair is refitted outright (at most :data:`_REFITS` of them, the most
    leveraged first); a pair whose games alone link the two has no such fit: the rest says nothing of it (a prior of
    sd :data:`FREE_SD` around its rated difference), and it is left out of the spread's measure, as are pairs left
    unrefitted."""

    def __init__(self, ratings: npt.ArrayLike, diff_sd: npt.ArrayLike, linked: npt.ArrayLike, points: npt.ArrayLike,
                 games: npt.ArrayLike, prior: float, spread: Spread | None = None, anchor: int | None = None,
                 deff: float = 1.0, draws: npt.ArrayLike | None = None) -> None:
        if not (math.isfinite(deff) and deff >= 1.0):
            raise ValueError(f"the design effect must be a finite number >= 1, not {deff}")
        self.deff = float(deff)  # one result is worth 1 / deff independent ones: every record and the fit tempered
        self.ratings = np.asarray(ratings, dtype=np.float64)
        self.diff_sd = np.asarray(diff_sd, dtype=np.float64) * math.sqrt(self.deff)
        self.linked = np.asarray(linked, dtype=bool)
        self.met_points = np.asarray(points, dtype=np.float64)
        self.met_games = np.asarray(games, dtype=np.float64)
        self.points, self.games = self.met_points / self.deff, self.met_games / self.deff
        # each pair's draw rate for its predictions: its own draws, shrunk toward the population's by _DRAW_PRIOR
        # results (none where results are worth any points: a game played for stakes)
        if draws is None:
            self.draw = np.zeros_like(self.met_games)
        else:
            d = np.asarray(draws, dtype=np.float64)
            base = float(d.sum() / self.met_games.sum()) if self.met_games.sum() > 0 else 0.0
            self.draw = (d + _DRAW_PRIOR * base) / (self.met_games + _DRAW_PRIOR)
        self.prior = float(prior)
        n = self.ratings.size
        # the gauge of a refit (differences do not depend on it): the fit's anchor, or any linked player
        self.anchor = int(anchor) if anchor is not None else int(np.argmax(self.linked)) if n else 0
        self.out_diff = np.subtract.outer(self.ratings, self.ratings)  # what the rest says of each pair (Elo)
        self.out_sd = self.diff_sd.copy()
        iu = np.triu_indices(n, 1)
        met = (self.games[iu] > 0) & self.linked[iu[0]] & self.linked[iu[1]]
        i, j = iu[0][met], iu[1][met]
        keep = np.zeros(i.size, dtype=bool)
        if i.size:
            theta = self.ratings / NAT_TO_ELO
            virtual = prior_draws(self.games, prior)[i, j]
            n_ij, w_ij = self.games[i, j] + virtual, self.points[i, j] + 0.5 * virtual
            p = 1.0 / (1.0 + np.exp(-(theta[i] - theta[j])))
            c = n_ij * p * (1.0 - p)
            v = (self.diff_sd[i, j] / NAT_TO_ELO) ** 2
            leverage = c * v
            keep = leverage <= _LEVERAGE
            v_out = v / (1.0 - np.minimum(leverage, _LEVERAGE))
            d_out = ((theta[i] - theta[j]) - (w_ij - n_ij * p) * v_out) * NAT_TO_ELO
            sd_out = np.sqrt(v_out) * NAT_TO_ELO
            for k in np.argsort(-leverage)[: _REFITS]:
                if keep[k]:
                    break
                refit = self._refit_without(int(i[k]), int(j[k]))
                if refit is not None:
                    (d_out[k], sd_out[k]), keep[k] = refit, True
            d_out = np.where(keep, d_out, (theta[i] - theta[j]) * NAT_TO_ELO)
            sd_out = np.where(keep, sd_out, FREE_SD)
            self.out_diff[i, j], self.out_diff[j, i] = d_out, -d_out
            self.out_sd[i, j] = self.out_sd[j, i] = sd_out
        self._held_out = (i[keep], j[keep])  # the pairs the spread is measured from
        if spread is not None:
            self.spread = spread

    def _refit_without(self, i: int, j: int) -> tuple[float, float] | None:
        """The difference of i over j and its sd (Elo) in the population fitted without their games; None when
        nothing else links the two."""
        w, n = self.points.copy(), self.games.copy()
        w[i, j] = w[j, i] = n[i, j] = n[j, i] = 0.0
        ratings, flags, _, _ = _fit_matrices(w, n, self.anchor, 0.0, self.prior, self.ratings, 1e-3, 100)
        if flags[i] is not None or flags[j] is not None or not reachable(n > 0, i)[j]:
            return None
        theta = ratings / NAT_TO_ELO
        nn = n + prior_draws(n, self.prior)
        p = 1.0 / (1.0 + np.exp(-(theta[:, None] - theta[None, :])))
        c = nn * p * (1.0 - p)
        idx = np.flatnonzero(reachable(nn > 0, self.anchor) & (np.arange(n.shape[0]) != self.anchor))
        lap = -c[np.ix_(idx, idx)]
        lap[np.diag_indices_from(lap)] += c[idx].sum(axis=1)
        e = np.zeros(idx.size)
        for player, sign in ((i, 1.0), (j, -1.0)):
            if player != self.anchor:
                e[int(np.searchsorted(idx, player))] = sign
        try:
            var = float(e @ np.linalg.solve(lap, e))
        except np.linalg.LinAlgError:
            return None
        return float(theta[i] - theta[j]) * NAT_TO_ELO, math.sqrt(max(var, 0.0)) * NAT_TO_ELO

    @functools.cached_property
    def spread(self) -> Spread:
        """The pairs' spread around their ratings (:func:`measure_spread` of the pairs that met, each against the
        fit without its games); measured when first asked for."""
        i, j = self._held_out
        return measure_spread(self.points[i, j], self.games[i, j], self.out_diff[i, j], self.out_sd[i, j])

    def belief(self, i: int, j: int) -> Belief:
        """Player i's difference over player j (both linked to the anchor)."""
        return self.beliefs([i], [j])[0]

    def beliefs(self, i: npt.ArrayLike, j: npt.ArrayLike) -> list[Belief]:
        """:meth:`belief` of many pairs ``(i[k], j[k])`` at once."""
        i, j = np.asarray(i, dtype=np.int64).ravel(), np.asarray(j, dtype=np.int64).ravel()
        if not i.size:
            return []
        met_points, met_games = self.points[i, j], self.games[i, j]
        nodes, w = _beliefs(self.out_diff[i, j], np.maximum(self.out_sd[i, j], 1e-6), self.spread, met_points,
                            met_games)
        raw_points, raw_games, draw = self.met_points[i, j], self.met_games[i, j], self.draw[i, j]
        return [Belief(nodes[k], w[k], float(raw_games[k]), float(raw_points[k]), self.deff, float(draw[k]))
                for k in range(i.size)]

    def below(self, order: npt.ArrayLike) -> np.ndarray:
        """``P(T_ab <= 0)`` for every two players of ``order`` (indices; linked players), as an ``(m, m)`` matrix:
        the chance that ``order[a]`` is not above ``order[b]``. Pairs that never met in closed form (a mixture of
        normals), pairs that met on their grids."""
        idx = np.asarray(order, dtype=np.int64)
        m = idx.size
        if not m:
            return np.zeros((0, 0))
        d = self.out_diff[np.ix_(idx, idx)]
        s = self.out_sd[np.ix_(idx, idx)]
        taus, tw = self.spread.mixture
        scale = np.sqrt(s[:, :, None] ** 2 + taus[None, None, :] ** 2)
        from scipy.special import ndtr  # (here: a command that only names players needs no scipy)

        with np.errstate(divide="ignore", invalid="ignore"):
            p = ndtr(np.where(scale > 0, -d[:, :, None] / np.where(scale > 0, scale, 1.0),
                              np.where(d[:, :, None] > 0, -np.inf, np.inf))) @ tw
        g = self.games[np.ix_(idx, idx)]
        a, b = np.nonzero(np.triu(g > 0, 1))
        if a.size:
            pts = self.points[idx[a], idx[b]]
            clear, rough = _clear_cut(d[a, b], s[a, b], self.spread, pts, g[a, b])
            p[a[clear], b[clear]] = rough[clear]
            p[b[clear], a[clear]] = 1.0 - rough[clear]
            a, b, pts = a[~clear], b[~clear], pts[~clear]
            for start in range(0, a.size, 512):  # a few hundred pairs' grids at a time
                sa, sb = a[start:start + 512], b[start:start + 512]
                nodes, w = _beliefs(d[sa, sb], np.maximum(s[sa, sb], 1e-6), self.spread, pts[start:start + 512],
                                    g[sa, sb])
                p[sa, sb] = cdf_at(nodes, w, 0.0)
                p[sb, sa] = 1.0 - p[sa, sb]
        np.fill_diagonal(p, 1.0)
        return p


def _clear_cut(diff: np.ndarray, sd: np.ndarray, spread: Spread, met_points: np.ndarray,
               met_games: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which pairs' ``P(T <= 0)`` is far from any threshold a ladder uses (below 1e-4 or above 0.3 under every
    component of the spread's mixture, each a normal prior times the normal approximation of the games), and that
    rough figure: the pairs a grid need not settle."""
    taus, tw = spread.mixture
    s = (met_points + 0.5) / (met_games + 1.0)
    mode = NAT_TO_ELO * np.log(s / (1.0 - s))
    lik_var = NAT_TO_ELO**2 / ((met_games + 1.0) * s * (1.0 - s))
    prior_var = sd[:, None] ** 2 + taus[None, :] ** 2
    var = 1.0 / (1.0 / prior_var + 1.0 / lik_var[:, None])
    mean = var * (diff[:, None] / prior_var + mode[:, None] / lik_var[:, None])
    from scipy.special import ndtr

    p = ndtr(-mean / np.sqrt(var))
    clear = (p.max(axis=1) < 1e-4) | (p.min(axis=1) > 0.3)
    return clear, p @ tw
