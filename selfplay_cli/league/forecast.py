"""What the ladder predicts of a match not yet played: A's score against B over ``n`` games, with the interval a
longer match checks (:mod:`selfplay_cli.stats.predict` for the model).

One :class:`Forecaster` fits the population once (Bradley-Terry under the ladder's prior, the Laplace covariance of
the differences: the same fit as ``marl league ladder --bootstrap 0``), measures how far the pairs that met scatter
around their ratings (``spread``), and keeps each pair's own record, so that any pair is predicted at once:
``marl league predict``, ``marl match`` (which checks the prediction against the games it plays) and
``benchmarks/ladder_truth.py`` (which checks many).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.stats.bradley_terry import DEFAULT_PRIOR, fit_bradley_terry, prior_draws
from selfplay_cli.stats.elo import NAT_TO_ELO
from selfplay_cli.stats.intervals import laplace_intervals
from selfplay_cli.stats.predict import ScorePrediction, pair_spread, predict_pair

__all__ = ["Forecaster"]


@dataclass(frozen=True)
class Forecaster:
    """A fitted population that predicts pairs (see the module docstring); players by name."""

    names: list[str]
    ratings: np.ndarray
    diff_sd: np.ndarray
    linked: np.ndarray  # (n,) bool: the player's rating is linked to the anchor by games
    points: np.ndarray  # (n, n): points i scored against j
    games: np.ndarray  # (n, n): results between i and j
    spread: float  # Elo: how far pairs scatter around their ratings' prediction
    aliases: dict[str, str] = field(default_factory=dict)  # another name of a player's weights -> its first name

    @classmethod
    def of_games(cls, names: list[str], a: npt.ArrayLike, b: npt.ArrayLike, score_a: npt.ArrayLike, anchor: str,
                 prior: float = DEFAULT_PRIOR) -> Forecaster:
        """Fit the population ``names`` from games given as index arrays (``a`` scored ``score_a`` against ``b``)."""
        n = len(names)
        ai, bi = np.asarray(a, dtype=np.int64).ravel(), np.asarray(b, dtype=np.int64).ravel()
        sc = np.asarray(score_a, dtype=np.float64).ravel()
        if anchor not in names:
            raise LeagueError(f"anchor '{anchor}' is not a rated player")
        k = names.index(anchor)
        fit = fit_bradley_terry(ai, bi, sc, n, anchor=k, prior_games=prior)
        _, _, diff_sd = laplace_intervals(ai, bi, n, fit.ratings, k, 0.95, prior)
        points, games = np.zeros((n, n)), np.zeros((n, n))
        np.add.at(points, (ai, bi), sc)
        np.add.at(points, (bi, ai), 1.0 - sc)
        np.add.at(games, (ai, bi), 1.0)
        np.add.at(games, (bi, ai), 1.0)
        linked = np.array([f is None for f in fit.flags])
        spread = _held_out_spread(np.asarray(fit.ratings), np.asarray(diff_sd), linked, points, games, prior)
        return cls(list(names), np.asarray(fit.ratings), np.asarray(diff_sd), linked, points, games, spread)

    @classmethod
    def of_league(cls, league: League, env: str, prior: float = DEFAULT_PRIOR, variant: str = "") -> Forecaster:
        """The forecaster of ``env``'s rated games in ``variant`` (the default unless given; players by full name),
        anchored at the game's anchor bot."""
        from selfplay_cli.league.ladder import declared_anchor, default_anchor

        table = league.games(env=env, variant=variant)
        if not len(table):
            raise LeagueError(f"{env} has no rated games yet: nothing to predict from")
        ids, a, b = table.indexed()
        known = {p.id: p for p in league.players(env=env, include_removed=True)}
        population = [known[int(i)] for i in ids.tolist()]
        counts = (np.bincount(a, minlength=ids.size) + np.bincount(b, minlength=ids.size)).tolist()
        anchor = default_anchor(population, dict(zip(ids.tolist(), counts, strict=True)), declared_anchor(env))
        fitted = cls.of_games([p.full_name for p in population], a, b, table.score_a, anchor.full_name, prior)
        lead = {p.id: p.full_name for p in population}
        aliases = {known[pid].full_name: lead[first] for pid, first in league.same_weights(env).items()
                   if first in lead}
        return replace(fitted, aliases=aliases)

    def predict(self, a: str, b: str, games: int, confidence: float = 0.95) -> ScorePrediction:
        """A's score over ``games`` games against B (players by name); LeagueError for a player without rated
        games or one whose rating is not linked to the anchor (nothing to predict from)."""
        a, b = self.aliases.get(a, a), self.aliases.get(b, b)  # one set of weights is one player
        for name in (a, b):
            if name not in self.names:
                raise LeagueError(f"{name} has no rated games: the ladder cannot predict its score")
        i, j = self.names.index(a), self.names.index(b)
        if i == j:
            raise LeagueError(f"{a} against itself (the same weights): nothing to predict")
        for k, name in ((i, a), (j, b)):
            if not self.linked[k]:
                raise LeagueError(f"{name}'s rating is not linked to the anchor by games: nothing to predict from")
        return predict_pair(float(self.ratings[i] - self.ratings[j]), float(self.diff_sd[i, j]), games,
                            spread=self.spread, met_points=float(self.points[i, j]),
                            met_games=float(self.games[i, j]), confidence=confidence)

    def met(self, a: str, b: str) -> tuple[float, int]:
        """A's points and the results between A and B in the fitted games."""
        i, j = self.names.index(self.aliases.get(a, a)), self.names.index(self.aliases.get(b, b))
        return float(self.points[i, j]), int(self.games[i, j])


def _held_out_spread(ratings: np.ndarray, diff_sd: np.ndarray, linked: np.ndarray, points: np.ndarray,
                     games: np.ndarray, prior: float) -> float:
    """How far pairs scatter around their ratings (:func:`~selfplay_cli.stats.predict.pair_spread`), measured pair by
    pair against ratings fitted without that pair's games: exactly the question a prediction of two players answers
    (what the rest of the ledger says of them), and free of the bias of a fit that has already moved toward each
    pair.

    Each held-out fit is one Newton step from the full one, in closed form: without pair (i, j) the log-posterior's
    Hessian loses ``c (e_i - e_j)(e_i - e_j)^T`` with ``c = (N_ij + V_ij) p q`` (its games and its virtual draws), so
    the variance of the difference ``v = sd_ij^2`` becomes ``v' = v / (1 - c v)`` (Sherman-Morrison), and its gradient
    loses the pair's residual ``r = W_ij + V_ij / 2 - (N_ij + V_ij) p``, so the difference moves to ``d - r v'``. No
    refit: a league of 500 players is measured in a fraction of a second. A pair whose games alone link the two
    (``c v >= 1``) says nothing of the rest and is left out."""
    n = ratings.size
    iu = np.triu_indices(n, 1)
    met = (games[iu] > 0) & linked[iu[0]] & linked[iu[1]]
    i, j = iu[0][met], iu[1][met]
    if not i.size:
        return 0.0
    theta = ratings / NAT_TO_ELO
    virtual = prior_draws(games, prior)[i, j]
    n_ij, w_ij = games[i, j] + virtual, points[i, j] + 0.5 * virtual
    p = 1.0 / (1.0 + np.exp(-(theta[i] - theta[j])))
    c = n_ij * p * (1.0 - p)
    v = (diff_sd[i, j] / NAT_TO_ELO) ** 2
    keep = c * v < 1.0 - 1e-9
    v_out = v[keep] / (1.0 - c[keep] * v[keep])
    d_out = (theta[i] - theta[j])[keep] - (w_ij - n_ij * p)[keep] * v_out
    return pair_spread(points[i, j][keep], games[i, j][keep], d_out * NAT_TO_ELO, np.sqrt(v_out) * NAT_TO_ELO)
