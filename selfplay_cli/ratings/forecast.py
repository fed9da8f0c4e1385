"""What the ladder says of a pair of players, by name: the margin of one over the other and what a match not yet
played between them will show (:mod:`selfplay_cli.stats.predict` for the model).

One :class:`Forecaster` fits the population once (Bradley-Terry under the ladder's prior, the Laplace covariance of
the differences: the fit of ``marl league ladder``), measures how far the pairs that met scatter around their
ratings (the spread) and keeps each pair's own record (:class:`~selfplay_cli.stats.predict.PairModel`), so that any
pair is judged at once: ``marl league predict``, ``marl match`` (which checks the prediction against the games it
plays) and ``benchmarks/ladder_truth.py`` (which checks many). The ladder's margins, ranks and tiers come from the same
model (:func:`selfplay_cli.ratings.fit.fit_table`), so a claim about two players reads the same wherever it is
printed.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.stats.belief import Belief, ScorePrediction
from selfplay_cli.stats.bradley_terry import DEFAULT_PRIOR, fit_bradley_terry, pair_matrices
from selfplay_cli.stats.intervals import laplace_intervals
from selfplay_cli.stats.predict import PairModel, Spread

__all__ = ["Forecaster"]


@dataclass(frozen=True)
class Forecaster:
    """A fitted population that judges pairs (see the module docstring); players by name."""

    names: list[str]
    model: PairModel
    aliases: dict[str, str] = field(default_factory=dict)  # another name of a player's weights -> its first name

    @property
    def spread(self) -> float:
        """The pairs' spread around their ratings (Elo, its posterior mean)."""
        return self.model.spread.mean

    @classmethod
    def of_games(cls, names: list[str], a: npt.ArrayLike, b: npt.ArrayLike, score_a: npt.ArrayLike, anchor: str,
                 prior: float = DEFAULT_PRIOR, spread: Spread | None = None, deff: float = 1.0) -> Forecaster:
        """Fit the population ``names`` from games given as index arrays (``a`` scored ``score_a`` against ``b``);
        ``spread`` taken as given instead of measured (a simulation's truth); ``deff``: the games' design effect
        (:func:`~selfplay_cli.ratings.pairs.design_effect`)."""
        n = len(names)
        ai, bi = np.asarray(a, dtype=np.int64).ravel(), np.asarray(b, dtype=np.int64).ravel()
        sc = np.asarray(score_a, dtype=np.float64).ravel()
        if anchor not in names:
            raise LeagueError(f"anchor '{anchor}' is not a rated player")
        k = names.index(anchor)
        fit = fit_bradley_terry(ai, bi, sc, n, anchor=k, prior_games=prior)
        _, _, diff_sd = laplace_intervals(ai, bi, n, fit.ratings, k, 0.95, prior)
        points, games = pair_matrices(ai, bi, sc, n)
        linked = np.array([f is None for f in fit.flags])
        draws = None
        if np.all(np.isin(sc, (0.0, 0.5, 1.0))):  # wins, draws and losses (not a game played for stakes)
            draws = np.zeros((n, n))
            level = sc == 0.5
            np.add.at(draws, (ai[level], bi[level]), 1.0)
            np.add.at(draws, (bi[level], ai[level]), 1.0)
        return cls(list(names), PairModel(fit.ratings, diff_sd, linked, points, games, prior, spread, anchor=k,
                                          deff=deff, draws=draws))

    @classmethod
    def of_league(cls, league: League, env: str, prior: float = DEFAULT_PRIOR, variant: str = "") -> Forecaster:
        """The forecaster of ``env``'s rated games in ``variant`` (the default unless given; players by full name),
        anchored at the game's anchor bot."""
        from selfplay_cli.ratings.ladder import declared_anchor, default_anchor
        from selfplay_cli.ratings.pairs import design_effect

        table = league.ledger.games(env=env, variant=variant)
        if not len(table):
            raise LeagueError(f"{env} has no rated games yet: nothing to predict from")
        ids, a, b = table.indexed()
        known = {p.id: p for p in league.roster.players(env=env, include_removed=True)}
        population = [known[int(i)] for i in ids.tolist()]
        counts = (np.bincount(a, minlength=ids.size) + np.bincount(b, minlength=ids.size)).tolist()
        anchor = default_anchor(population, dict(zip(ids.tolist(), counts, strict=True)), declared_anchor(env))
        fitted = cls.of_games([p.full_name for p in population], a, b, table.score_a, anchor.full_name, prior,
                              deff=design_effect(table))
        lead = {p.id: p.full_name for p in population}
        aliases = {known[pid].full_name: lead[first] for pid, first in league.ledger.same_weights(env).items()
                   if first in lead}
        return replace(fitted, aliases=aliases)

    def _pair(self, a: str, b: str) -> tuple[int, int]:
        a, b = self.aliases.get(a, a), self.aliases.get(b, b)  # one set of weights is one player
        for name in (a, b):
            if name not in self.names:
                raise LeagueError(f"{name} has no rated games: the ladder cannot predict its score")
        i, j = self.names.index(a), self.names.index(b)
        if i == j:
            raise LeagueError(f"{a} against itself (the same weights): nothing to predict")
        for k, name in ((i, a), (j, b)):
            if not self.model.linked[k]:
                raise LeagueError(f"{name}'s rating is not linked to the anchor by games: nothing to predict from")
        return i, j

    def belief(self, a: str, b: str) -> Belief:
        """A's difference over B (Elo, a distribution: the margin the ladder prints is its mean and interval);
        LeagueError for a player without rated games or one whose rating is not linked to the anchor."""
        return self.model.belief(*self._pair(a, b))

    def predict(self, a: str, b: str, games: int, confidence: float = 0.95) -> ScorePrediction:
        """A's score over ``games`` games against B (players by name); LeagueError as :meth:`belief`."""
        return self.belief(a, b).predict(games, confidence)

    def met(self, a: str, b: str) -> tuple[float, int]:
        """A's points and the results between A and B in the fitted games."""
        i, j = self.names.index(self.aliases.get(a, a)), self.names.index(self.aliases.get(b, b))
        return float(self.model.met_points[i, j]), int(self.model.met_games[i, j])
