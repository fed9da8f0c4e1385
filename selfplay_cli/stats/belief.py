"""What is believed of one pair's difference ``T`` (Elo, A's over B's), and what a match of ``n`` games between the two
will show: :class:`Belief`, a distribution of ``T`` on a grid (its mean and central interval a margin, its lower tail
whether A is above B beyond doubt), and :meth:`Belief.predict`, the score a match will show (:class:`ScorePrediction`:
exact binomials, or trinomials with draws, mixed over ``T``); :func:`record_prediction` is what a pair's own record
alone predicts.

Where a belief comes from (a ladder's ratings, the spread of pairs around them, the pair's own games) is
:mod:`.predict`'s. numpy and scipy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .elo import NAT_TO_ELO

__all__ = ["NODES", "Belief", "ScorePrediction", "cdf_at", "record_prediction"]

NODES = 121  # grid points of a pair's difference, in each of two passes (the whole range, then the posterior's bulk)


@dataclass(frozen=True)
class ScorePrediction:
    """A's predicted score against B over ``games`` games: its expectation and the central interval the measured
    score falls in with probability ``confidence``; ``diff`` / ``sd`` the mean and standard deviation (Elo) of the
    pair's difference the prediction rests on."""

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

    @property
    def width(self) -> float:
        return self.high - self.low

    def to_json(self) -> dict[str, float | int]:
        return {"score": round(self.score, 4), "low": round(self.low, 4), "high": round(self.high, 4),
                "games": self.games, "confidence": self.confidence, "elo_diff": round(self.diff, 1),
                "elo_sd": round(self.sd, 1)}


@dataclass(frozen=True)
class Belief:
    """What is known of one pair's difference ``T`` (Elo, A's over B's): a distribution on the grid ``nodes``
    (increasing) with ``weights`` summing to 1. ``met`` / ``met_points``: the results between the two it
    includes."""

    nodes: np.ndarray
    weights: np.ndarray
    met: float = 0.0
    met_points: float = 0.0
    deff: float = 1.0  # the design effect of the game's rounds: one result is worth 1 / deff independent ones
    draw: float = 0.0  # the share of the pair's results that are draws, as a match of the two is predicted to have

    @property
    def mean(self) -> float:
        return float(self.nodes @ self.weights)

    @property
    def sd(self) -> float:
        return math.sqrt(max(float(((self.nodes - self.mean) ** 2) @ self.weights), 0.0))

    def quantile(self, q: float) -> float:
        """The ``q`` quantile of ``T`` (linear between the grid's points)."""
        cdf = np.cumsum(self.weights) - 0.5 * self.weights  # each node's mass centred on it
        return float(np.interp(q, cdf, self.nodes))

    def interval(self, confidence: float = 0.95) -> tuple[float, float]:
        """The central ``confidence`` interval of ``T`` (Elo)."""
        tail = 0.5 * (1.0 - confidence)
        return self.quantile(tail), self.quantile(1.0 - tail)

    def below(self, x: float = 0.0) -> float:
        """``P(T <= x)``."""
        return float(cdf_at(self.nodes[None, :], self.weights[None, :], x)[0])

    def flipped(self) -> Belief:
        """B's difference over A's."""
        return Belief(-self.nodes[::-1], self.weights[::-1], self.met, self.met - self.met_points, self.deff,
                      self.draw)

    def predict(self, games: int, confidence: float = 0.95) -> ScorePrediction:
        """A's score over ``games`` games, mixed over ``T``: the ``n = games / deff`` independent results those
        games are worth (all of them unless rounds correlate), each a win, a draw (at the pair's :attr:`draw` rate)
        or a loss of mean ``E(T)``; the smallest and largest scores that leave at most ``(1 - confidence) / 2``
        outside on either side. Without draws the count of wins is binomial; with them, the half-points of the
        ``n`` results are the trinomial's, whose spread is the smaller a coin's of the same mean would overstate."""
        if games < 1:
            raise ValueError(f"games must be at least 1, not {games}")
        if not 0.0 < confidence < 1.0:
            raise ValueError("confidence must be in (0, 1)")
        keep = self.weights > 1e-12 * self.weights.max()
        p = 1.0 / (1.0 + np.exp(-self.nodes[keep] / NAT_TO_ELO))
        post = self.weights[keep] / self.weights[keep].sum()
        expected = float(post @ p)
        if p.size > 256:  # the mixture at 256 levels of p, each weighted by the nodes it gathers
            edges = np.linspace(p.min(), p.max(), 257)
            where = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, 255)
            mass = np.bincount(where, weights=post, minlength=256)
            level = np.bincount(where, weights=post * p, minlength=256) / np.maximum(mass, 1e-300)
            p, post = level[mass > 0], mass[mass > 0]
        n = max(1, int(round(games / self.deff)))
        if self.draw > 0.0:
            pmf, halves = post @ _trinomial(n, p, self.draw), 2 * n  # over half-points 0 .. 2n
        else:
            pmf, halves = post @ _binomial(n, p), n
        tail = 0.5 * (1.0 - confidence)
        lo_k = int(np.searchsorted(np.cumsum(pmf), tail - 1e-12))  # the smallest k with P(K <= k) >= tail
        upper = np.cumsum(pmf[::-1])[::-1]  # P(K >= k)
        hi_k = int(np.flatnonzero(upper >= tail - 1e-12)[-1])  # the largest k with P(K >= k) >= tail
        return ScorePrediction(expected, lo_k / halves, hi_k / halves, games, confidence, self.mean, self.sd)


def record_prediction(wins: int, draws: int, losses: int, games: int = 200,
                      confidence: float = 0.95) -> ScorePrediction:
    """What a pair's own record alone says of a ``games``-game match between the two: the pair's expected score
    ``p`` has the posterior of a uniform prior (one virtual win and one virtual loss) updated by the record, and
    the match is ``games`` results of mean ``p`` drawn at the record's draw rate (``D / (n + 1)``), mixed over ``p``
    (:meth:`Belief.predict`). Exact where a normal approximation is worst, at one-sided records: 8-0 leaves ``p``
    anywhere above 0.66 (``Beta(9, 1)``'s 2.5% quantile, ``0.025 ** (1 / 9)``), so a 200-game match is predicted no
    better than [66%, 100%].

    Without draws the posterior is ``Beta(1 + W, 1 + L)`` and the prediction the beta-binomial's. A draw, half a
    point, tells more of ``p`` than a coin's toss of the same mean (the points of a record with draws spread less):
    the posterior is the beta of the same mean ``m = (1 + W + D/2) / (n + 2)`` whose variance is the record's
    points' variance ``v`` (virtual results included) over ``n + 2`` results, i.e. of concentration
    ``(n + 2) m (1 - m) / v`` (``n + 2`` without draws)."""
    from scipy.stats import beta as beta_dist

    if min(wins, draws, losses) < 0:
        raise ValueError(f"a record counts no negative results, not {wins}-{draws}-{losses}")
    n = wins + draws + losses
    m = (1.0 + wins + 0.5 * draws) / (n + 2.0)
    v = (1.0 + wins + 0.25 * draws) / (n + 2.0) - m * m  # > 0: the virtual loss and win are always there
    concentration = (n + 2.0) * m * (1.0 - m) / v
    q = (np.arange(NODES) + 0.5) / NODES  # the posterior's quantiles, each with an equal share of its mass
    p = np.clip(beta_dist.ppf(q, m * concentration, (1.0 - m) * concentration), 1e-12, 1.0 - 1e-12)
    nodes = NAT_TO_ELO * np.log(p / (1.0 - p))
    return Belief(nodes, np.full(NODES, 1.0 / NODES), float(n), wins + 0.5 * draws,
                  draw=draws / (n + 1.0)).predict(games, confidence)


def _binomial(n: int, p: np.ndarray) -> np.ndarray:
    """``(levels, n + 1)``: the binomial pmf of ``n`` trials at each success rate of ``p`` (one row per level), from
    log-gamma in closed form (scipy's ``binom.pmf`` evaluates each cell apart: 2.4 ms for 121 x 201 against 0.3);
    a rate of 0 or 1 gives its certain count exactly."""
    from scipy.special import gammaln, xlog1py, xlogy  # (here: a command that only names players needs no scipy)

    k = np.arange(n + 1, dtype=np.float64)
    log_choose = gammaln(n + 1.0) - gammaln(k + 1.0) - gammaln(n - k + 1.0)
    q = p[:, None]
    return np.exp(log_choose[None, :] + xlogy(k[None, :], q) + xlog1py(n - k[None, :], -q))


def _trinomial(n: int, p: np.ndarray, draw: float) -> np.ndarray:
    """``(levels, 2n + 1)``: the chance of each count of half-points in ``n`` results, each a loss, a draw or a win
    with mean points ``p`` (one row per level) and draws at ``draw`` where the mean allows (a mean of 0.9 leaves
    room for 20% of draws at most): the coefficients of ``(l + d x + w x^2)^n``, by FFT."""
    d = np.minimum(draw, 2.0 * np.minimum(p, 1.0 - p))
    size = 1 << int(np.ceil(np.log2(2 * n + 1)))
    poly = np.zeros((p.size, size))
    poly[:, 0], poly[:, 1], poly[:, 2] = 1.0 - p - 0.5 * d, d, p - 0.5 * d
    out = np.fft.irfft(np.fft.rfft(poly, axis=1) ** n, size, axis=1)[:, : 2 * n + 1]
    out = np.maximum(out, 0.0)
    return out / out.sum(axis=1, keepdims=True)


def cdf_at(nodes: np.ndarray, w: np.ndarray, x: float) -> np.ndarray:
    """``P(T <= x)`` of beliefs on grids (pairs, nodes), each node's mass centred on it, linear between nodes."""
    cdf = np.cumsum(w, axis=1) - 0.5 * w
    k = np.clip((nodes <= x).sum(axis=1), 1, nodes.shape[1] - 1)  # x lies between nodes k-1 and k
    rows = np.arange(nodes.shape[0])
    x0, x1, c0, c1 = nodes[rows, k - 1], nodes[rows, k], cdf[rows, k - 1], cdf[rows, k]
    t = np.clip((x - x0) / np.where(x1 > x0, x1 - x0, 1.0), 0.0, 1.0)
    return np.where(x < nodes[:, 0], 0.0, np.where(x >= nodes[:, -1], 1.0, c0 + t * (c1 - c0)))
