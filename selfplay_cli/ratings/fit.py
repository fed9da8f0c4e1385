"""The generic Bradley-Terry fit of a table of games (:func:`fit_table`): ratings anchored at one player
(:func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`), MAP under BayesElo's prior of ``prior`` virtual draws
(default :data:`~selfplay_cli.stats.bradley_terry.DEFAULT_PRIOR` = 2, as BayesElo; ``prior=0`` is the plain
maximum-likelihood fit), a confidence interval per player, the rows' order, ranks, tiers and margins, and the
:class:`Fitted` population they are read from. It knows no league: the ladder of a league
(:mod:`selfplay_cli.ratings.ladder`) and of a results file (:mod:`selfplay_cli.ratings.results_csv`) are fitted here.

The prior
---------
See :mod:`selfplay_cli.stats.bradley_terry`: ``V_ij = (prior / 2) N_ij (1/N_i + 1/N_j)`` virtual draws are added
between every pair that played (BayesElo's ``AddPrior``), so a perfectly separated ledger (A always beats B, B
always beats C) still has finite MAP ratings, ordered as the results say. The flags ``perfect`` / ``zero`` mean
"the maximum-likelihood rating is infinite" and only appear with ``prior=0`` (where the rating shown is a
bound); ``disconnected`` (no chain of games to the anchor: the offset is unknown) and ``unrated`` (no games)
appear either way.

Confidence intervals
--------------------
``bootstrap > 0``: the percentile bootstrap of :func:`~selfplay_cli.stats.intervals.bootstrap_intervals`
(games resampled with replacement, ``bootstrap`` replicates, seeded, the prior's virtual draws added to every
replicate). ``bootstrap == 0``: the Laplace (normal) approximation
(:func:`~selfplay_cli.stats.intervals.laplace_intervals`): the negative Hessian of the log-posterior at the
fit (with ``prior=0``: the observed Fisher information) is the weighted graph Laplacian
``L_ii = sum_j c_ij, L_ij = -c_ij`` with ``c_ij = (N_ij + V_ij) p_ij (1 - p_ij)``; with the anchor's row and column
removed it is invertible on the anchor's connected component, and ``se_i = sqrt((L^-1)_ii) * 400 / ln 10`` Elo,
interval ``r_i -+ z se_i`` with ``z = Phi^-1((1 + confidence) / 2)``.

Under a prior a percentile bootstrap alone would be dishonest for separated data: a player that won all its
games wins all its games in every replicate, every replicate gives the same MAP and the interval would have
zero width, a precision nobody measured. So under a prior the bootstrap interval is widened to contain the
Laplace interval at the MAP: never narrower than the curvature of the log-posterior (the prior's virtual draws
included) allows. Either way the intervals are relative to the anchor (whose interval is the single point
``anchor_rating``). Without a prior, flagged players get an open side instead: a ``perfect`` player's upper end
and a ``zero`` player's lower end are ``rating +- MAX_ELO``; disconnected and unrated players get
``rating -+ MAX_ELO`` on both sides; standard errors are capped at ``MAX_ELO``. Every number in a
:class:`~selfplay_cli.ratings.ladder_rows.LadderRow` is finite.

Order, ranks and tiers
----------------------
Ranks and tiers are claims about pairs, and every claim about two players
comes from one model of the pair (:class:`~selfplay_cli.stats.predict.PairModel`): what the rest of the ledger says
of their difference (their ratings fitted without their own games, with that fit's uncertainty), widened by how far
the game's pairs scatter around their ratings (the spread, measured from the ledger), then updated by their own
games. Two ratings far apart through the scripted players, whose head-to-head games are even, are not claimed far
apart. One player is *above another beyond doubt* when the ``confidence`` interval of that pair's difference lies
wholly above 0.

A player's *rank* is one more than the number of players above it beyond doubt (as Chatbot Arena ranks): players
the games cannot order share a rank, and a rank never claims an order nobody measured. The rows go so that a
player another is above beyond doubt never stands over it, whatever the ratings say (self-play's rock-paper-scissors:
the ratings put a snapshot first through its games against the rest, while one below it beats it head to head), by
rank and Elo otherwise (:func:`~selfplay_cli.stats.ranks.claims_order`; players whose offset to the anchor is
unknown, ``disconnected``, and players without games, ``unrated``, last). Where the claims go round in a circle (A
above B above C above A, each beyond doubt), no order keeps them all: the players of the circle stand together, by
rank and Elo, and the verdicts under the table say the circle. Its *tier*: walking down the rows, a tier
boundary falls between two places only where every player above it (in the tier it closes) is above every player
below it beyond doubt, so a boundary reads "everyone above is stronger than everyone below".

Each row's ``margin`` is its difference over the next row, with its interval, from the same pair model. The summary of
``marl train``, ``marl league predict`` and ``marl match`` read the same model, so one claim has one figure wherever
it is printed.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.store import LeagueError
from selfplay_cli.ratings.ladder_rows import LadderRow, Margin
from selfplay_cli.stats.bradley_terry import (
    DEFAULT_PRIOR,
    FLAG_DISCONNECTED,
    FLAG_PERFECT,
    FLAG_UNRATED,
    FLAG_ZERO,
    fit_bradley_terry,
    pair_matrices,
)
from selfplay_cli.stats.elo import MAX_ELO
from selfplay_cli.stats.intervals import bootstrap_intervals, laplace_intervals
from selfplay_cli.stats.predict import PairModel, Spread
from selfplay_cli.stats.ranks import claims_order
from selfplay_cli.stats.ranks import tiers as claims_tiers

__all__ = ["Fitted", "check_prior", "fit_rows", "fit_table", "order_group"]


def _open_flagged_sides(ratings: np.ndarray, flags: list[str | None], low: np.ndarray, high: np.ndarray,
                        anchor: int) -> None:
    """Intervals of players without an estimate are open on the unknown side (whatever interval method was
    used): a perfect score has no upper limit under maximum likelihood, a zero score no lower one, and a player
    not connected to the anchor neither. The open side is drawn at +-MAX_ELO from the rating. The anchor's
    rating is fixed by definition, so its interval stays a point."""
    for i, flag in enumerate(flags):
        if i == anchor:
            continue
        if flag in (FLAG_PERFECT, FLAG_DISCONNECTED, FLAG_UNRATED):
            high[i] = max(high[i], ratings[i] + MAX_ELO)
        if flag in (FLAG_ZERO, FLAG_DISCONNECTED, FLAG_UNRATED):
            low[i] = min(low[i], ratings[i] - MAX_ELO)


@dataclass(frozen=True)
class Fitted:
    """A fitted population: its ratings, intervals and flags, by index into ``names``, and its pairs
    (:class:`~selfplay_cli.stats.predict.PairModel`: what the ladder says of any two players); what the rows are made
    of, and what margins, ranks and tiers are read from."""

    names: list[str]
    ratings: np.ndarray
    low: np.ndarray
    high: np.ndarray
    flags: list[str | None]
    confidence: float
    pairs: PairModel
    wdl: np.ndarray | None = None  # (3, n, n): i's wins, draws and losses against j in the fitted games

    def comparable(self, i: int) -> bool:
        """Whether player ``i`` has an estimate (not a flagged bound, not an unknown offset)."""
        return self.flags[i] is None

    def margin(self, i: int, j: int) -> Margin:
        """Player i's difference over player j, as the pair model says it (:meth:`PairModel.belief`: their ratings'
        difference with its uncertainty and the pairs' spread, their own games taken in) where both have an
        estimate; else from their whole intervals (the widest difference they allow)."""
        return self.margins([(i, j)])[0]

    def margins(self, pairs: list[tuple[int, int]]) -> list[Margin]:
        """:meth:`margin` of many pairs at once."""
        est = [k for k, (i, j) in enumerate(pairs) if self.comparable(i) and self.comparable(j)]
        beliefs = dict(zip(est, self.pairs.beliefs([pairs[k][0] for k in est], [pairs[k][1] for k in est]),
                           strict=True))
        out = []
        for k, (i, j) in enumerate(pairs):
            w, dr, lo = (0, 0, 0) if self.wdl is None else (int(x) for x in self.wdl[:, i, j])
            if k in beliefs:
                low, high = beliefs[k].interval(self.confidence)
                out.append(Margin(self.names[j], beliefs[k].mean, low, high, (w, dr, lo), beliefs[k]))
            else:
                out.append(Margin(self.names[j], float(self.ratings[i] - self.ratings[j]),
                                  float(self.low[i] - self.high[j]), float(self.high[i] - self.low[j]), (w, dr, lo)))
        return out

    def doubt(self, order: list[int]) -> np.ndarray:
        """``(m, m)`` over the players of ``order``: ``[a, b]`` the chance ``order[a]`` is not above ``order[b]``, as
        the pair model says it (:meth:`PairModel.below`); a flagged bound, which compares by its whole interval: 0
        where its interval lies wholly above the other's, else 1."""
        idx = np.asarray(order, dtype=np.int64)
        out = np.ones((idx.size, idx.size))
        est = np.array([self.comparable(int(i)) for i in idx], dtype=bool)
        if est.any():
            sub = np.flatnonzero(est)
            out[np.ix_(sub, sub)] = self.pairs.below(idx[sub])
        bound = ~est[:, None] | ~est[None, :]
        out = np.where(bound, np.where(self.low[idx][:, None] > self.high[idx][None, :], 0.0, 1.0), out)
        np.fill_diagonal(out, 1.0)
        return out

    def above(self, order: list[int]) -> np.ndarray:
        """``(m, m)`` bool over the players of ``order``: ``[a, b]`` when ``order[a]`` is above ``order[b]`` beyond
        doubt (the interval of their difference lies wholly above 0), as :meth:`margin` would say of each pair."""
        return self.doubt(order) < 0.5 * (1.0 - self.confidence)


def order_group(flag: str | None) -> int:
    """Rows' order: players comparable with the anchor (estimates and flagged bounds) first, then those whose offset
    is unknown, then those without games."""
    return {FLAG_DISCONNECTED: 1, FLAG_UNRATED: 2}.get(flag or "", 0)


def _order(fitted: Fitted, shown: list[int]) -> list[int]:
    return sorted(shown, key=lambda i: (order_group(fitted.flags[i]), -fitted.ratings[i], fitted.names[i]))


def _ranks_and_tiers(fitted: Fitted, order: list[int]
                     ) -> tuple[list[int], dict[int, int], dict[int, int | None], dict[int, tuple[int, ...]]]:
    """The rows' order, and each player's rank, tier and circle, from the pairs' claims
    (:func:`~selfplay_cli.stats.ranks.claims_order`, :func:`~selfplay_cli.stats.ranks.tiers`): rank, one more than
    the players above it beyond doubt; rows in which nobody stands over a player above it beyond doubt, by rank
    and Elo otherwise (``order``: the players by Elo), save within a circle of claims; tiers, boundaries where
    everyone above is above everyone below; a player's circle, a shortest circle of claims through it (itself first,
    each above the next, the last above it). Players whose offset to the anchor is unknown keep their
    place (last) as rank and have no tier."""
    placed = [i for i in order if not order_group(fitted.flags[i])]
    above = fitted.above(placed)
    rows, ranks, circles = claims_order(above, fitted.ratings[placed])
    tier_of = claims_tiers(above, rows)
    rank = {placed[a]: ranks[a] for a in range(len(placed))}
    tier: dict[int, int | None] = {placed[a]: t for a, t in zip(rows, tier_of, strict=True)}
    circle = {placed[a]: tuple(placed[x] for x in c) for a, c in circles.items()}
    rest = [i for i in order if order_group(fitted.flags[i])]
    for place, i in enumerate(rest, start=len(placed)):
        rank[i], tier[i] = place + 1, None
    return [placed[a] for a in rows] + rest, rank, tier, circle


def check_prior(prior: float) -> float:
    """``prior`` as a float; LeagueError unless it is a finite number >= 0."""
    try:
        value = float(prior)
    except (TypeError, ValueError):
        raise LeagueError(f"the prior must be a number of virtual draws >= 0, not {prior!r}") from None
    if not math.isfinite(value) or value < 0:
        raise LeagueError(f"the prior must be a number of virtual draws >= 0, not {prior}")
    return value


def fit_table(
    names: list[str],
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    score_a: npt.ArrayLike,
    anchor: str,
    anchor_rating: float = 1000.0,
    bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    kinds: dict[str, str] | None = None,
    steps: dict[str, int] | None = None,
    player_ids: dict[str, int] | None = None,
    *,
    prior: float = DEFAULT_PRIOR,
    hidden: Collection[str] = (),
    spread: Spread | None = None,
) -> list[LadderRow]:
    """Fit a ladder from games given as index arrays into ``names``.

    Bradley-Terry MAP ratings under BayesElo's prior of ``prior`` virtual draws (``prior=0``: maximum
    likelihood) anchored at ``anchor`` (its rating is ``anchor_rating``), intervals by a ``bootstrap``-replicate
    percentile bootstrap (``bootstrap=0``: Laplace / normal approximation), order, ranks, tiers and margins as the
    module docstring says. One row per name (players without games are flagged ``unrated``), in the ladder's
    order. ``kinds`` / ``steps`` / ``player_ids`` (keyed by name) fill the corresponding columns (default kind
    ``"player"``). Players in ``hidden`` are fitted (their games count) but get no row and take no part in the
    order.

    Raises:
        LeagueError: anchor not among the names (or hidden), no games, bad indices or options.
    """
    rows, _ = fit_rows(names, a, b, score_a, anchor, anchor_rating, bootstrap, confidence, seed, kinds, steps,
                       player_ids, prior=prior, hidden=hidden, spread=spread)
    return rows


def fit_rows(
    names: list[str], a: npt.ArrayLike, b: npt.ArrayLike, score_a: npt.ArrayLike, anchor: str,
    anchor_rating: float, bootstrap: int, confidence: float, seed: int, kinds: dict[str, str] | None,
    steps: dict[str, int] | None, player_ids: dict[str, int] | None, *, prior: float, hidden: Collection[str],
    spread: Spread | None = None, deff: float = 1.0,
) -> tuple[list[LadderRow], Fitted]:
    """:func:`fit_table`'s rows and the :class:`Fitted` population they come from."""
    names = [str(n) for n in names]
    if len(set(names)) != len(names):
        raise LeagueError("duplicate player names in the rating table")
    if anchor not in names:
        shown_names = ", ".join(names[:20]) + (", ..." if len(names) > 20 else "")
        raise LeagueError(f"anchor '{anchor}' is not a rated player; players: {shown_names or '(none)'}")
    if bootstrap < 0:
        raise LeagueError(f"bootstrap must be >= 0, got {bootstrap}")
    if not 0.0 < confidence < 1.0:
        raise LeagueError(f"confidence must be between 0 and 1, got {confidence}")
    prior = check_prior(prior)
    ai = np.asarray(a, dtype=np.int64).ravel()
    bi = np.asarray(b, dtype=np.int64).ravel()
    sc = np.asarray(score_a, dtype=np.float64).ravel()
    if ai.size == 0:
        raise LeagueError("no games to rate")
    n = len(names)
    k = names.index(anchor)
    try:
        fit = fit_bradley_terry(ai, bi, sc, n, anchor=k, anchor_rating=anchor_rating, prior_games=prior)
        low, high, diff_sd = laplace_intervals(ai, bi, n, fit.ratings, k, confidence, prior)
        if bootstrap > 0:
            low, high, _ = bootstrap_intervals(ai, bi, sc, n, anchor=k, anchor_rating=anchor_rating,
                                               n_boot=bootstrap, confidence=confidence, seed=seed, prior_games=prior)
    except ValueError as exc:
        raise LeagueError(f"cannot fit ratings: {exc}") from exc
    ratings = np.asarray(fit.ratings, dtype=np.float64)
    widen = math.sqrt(deff)  # results of one round that go together are worth fewer independent ones
    low = ratings - widen * np.maximum(ratings - np.asarray(low, dtype=np.float64), 0.0)
    high = ratings + widen * np.maximum(np.asarray(high, dtype=np.float64) - ratings, 0.0)
    _open_flagged_sides(ratings, list(fit.flags), low, high, k)
    if not (np.all(np.isfinite(ratings)) and np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise AssertionError("rating fit produced a non-finite value")  # pragma: no cover
    wdl = np.zeros((3, n, n), dtype=np.int64)
    for result, (x, y) in enumerate(((sc > 0.5, sc < 0.5), (sc == 0.5, sc == 0.5), (sc < 0.5, sc > 0.5))):
        np.add.at(wdl[result], (ai[x], bi[x]), 1)  # a's win, draw or loss against b, and b's against a
        np.add.at(wdl[result], (bi[y], ai[y]), 1)
    points, games = pair_matrices(ai, bi, sc, n)
    whole = bool(np.all(np.isin(sc, (0.0, 0.5, 1.0))))  # wins, draws and losses (not a game played for stakes)
    pairs = PairModel(ratings, diff_sd, [f is None for f in fit.flags], points, games, prior, spread, anchor=k,
                      deff=deff, draws=wdl[1] if whole else None)
    fitted = Fitted(names, ratings, low, high, list(fit.flags), confidence, pairs, wdl)
    order, ranks, tiers, circles = _ranks_and_tiers(fitted, _order(fitted, [i for i, name in enumerate(names)
                                                                             if name not in hidden]))
    kinds, steps, player_ids = kinds or {}, steps or {}, player_ids or {}
    adjacent = [(i, j) for i, j in zip(order, order[1:], strict=False) if not order_group(fit.flags[i])
                and not order_group(fit.flags[j])]
    margins = dict(zip((i for i, _ in adjacent), fitted.margins(adjacent), strict=True))
    rows = []
    for i in order:
        name = names[i]
        rows.append(LadderRow(
            policy=name, player_id=player_ids.get(name), kind=kinds.get(name, "player"), step=steps.get(name),
            elo=float(ratings[i]), ci_low=float(low[i]), ci_high=float(high[i]), games=int(fit.games[i]),
            wins=int(fit.wins[i]), draws=int(fit.draws[i]), losses=int(fit.losses[i]), score=float(fit.score[i]),
            rank=ranks[i], flag=fit.flags[i], anchor=i == k, tier=tiers[i], margin=margins.get(i),
            circle=tuple(names[x] for x in circles.get(i, ())),
        ))
    return rows, fitted

