"""Ladders: Bradley-Terry ratings of a whole population, derived from the game ledger (or, through
:mod:`selfplay_cli.ratings.results_csv`, from a results file).

Nothing here is stored: every ladder is refitted from the games, so it always agrees with the ledger.

* :func:`fit_table` is the generic core: Bradley-Terry ratings anchored at one player
  (:func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`), MAP under BayesElo's prior of
  ``prior`` virtual draws (default :data:`~selfplay_cli.stats.bradley_terry.DEFAULT_PRIOR` = 2, as BayesElo;
  ``prior=0`` is the plain maximum-likelihood fit), a confidence interval per player and ranks.
* :func:`ladder` fits the pairwise results of one env of the league (:meth:`~selfplay_cli.league.store.League.games`:
  a two-sides game, a cooperative comparison of two episodes on one seed, each two players of a free-for-all game),
  and adds what the league knows: each snapshot's run, the best snapshot of each run, every player's record against
  the env's scripted players, and in cooperative games its mean team return.
* :func:`select_rows` keeps one run's snapshots (plus the scripted players) and / or the first rows,
  without changing any rank.

Two players' record and the games a tournament still needs are in :mod:`selfplay_cli.ratings.pairs`.

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
:class:`LadderRow` is finite.

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

Each row's ``margin`` is its difference over the next row, with its interval, from the same pair model; the best
snapshot of each run carries its margin over the run's next best (another name of its own weights, or a teammate of
a cooperative game's team, is not its rival) and the run's snapshots it is not separated from (``tied``): the ladder
says who is best, by how much, and when it cannot tell. The summary of ``marl train``, ``marl league predict`` and
``marl match`` read the same model, so one claim has one figure wherever it is printed.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Collection
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.games import declaration
from selfplay_cli.league.ledger import GameTable, rules_for_env
from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.league.variants import variant_options
from selfplay_cli.ratings.pairs import design_effect
from selfplay_cli.results import COOPERATIVE
from selfplay_cli.stats.belief import Belief
from selfplay_cli.stats.bradley_terry import (
    DEFAULT_PRIOR,
    FLAG_DISCONNECTED,
    FLAG_PERFECT,
    FLAG_UNRATED,
    FLAG_ZERO,
    fit_bradley_terry,
    pair_matrices,
)
from selfplay_cli.stats.elo import MAX_ELO, score_to_elo
from selfplay_cli.stats.intervals import DEFAULT_BOOTSTRAP, bootstrap_intervals, laplace_intervals
from selfplay_cli.stats.predict import PairModel, Spread
from selfplay_cli.stats.ranks import claims_order
from selfplay_cli.stats.ranks import tiers as claims_tiers

__all__ = [
    "DEFAULT_BOOTSTRAP",
    "DEFAULT_PRIOR",
    "BotRecord",
    "Fitted",
    "MATCH_GAMES",
    "LadderRow",
    "Margin",
    "fit_table",
    "ladder",
    "pick_env",
    "select_rows",
    "shown_exploitability",
    "verdict_lines",
]

_JSON_KEYS = ("policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses", "rank",
              "tier", "score", "step", "flag", "anchor", "run", "best", "margin", "best_margin", "tied", "copy_of",
              "copies", "vs", "league_role", "exploitability", "circle")

MATCH_GAMES = 200  # a margin says what a match of this many games between the two would measure


# --------------------------------------------------------------------------------------------------
# Rows
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BotRecord:
    """A player's record against one scripted player: ``games`` played and ``points`` scored (draw = 1/2)."""

    bot: str
    games: int
    points: float

    @property
    def score(self) -> float | None:
        """Mean points per game, None without games."""
        return self.points / self.games if self.games else None


@dataclass(frozen=True)
class Margin:
    """How far a player stands above another (``over``): the rating difference ``elo`` with its confidence interval
    ``low .. high`` (from the same covariance as the ladder's intervals, so what the two share through the anchor
    cancels). ``separated``: the whole interval lies above 0.

    That interval is about the pair's expected difference; a match of the two measures it with its own luck. So a
    margin also says what a match of :data:`MATCH_GAMES` games would measure (:attr:`match`, from the pair's belief:
    :meth:`~selfplay_cli.stats.belief.Belief.predict`), the figure a user checks the claim with."""

    over: str
    elo: float
    low: float
    high: float
    record: tuple[int, int, int] = (0, 0, 0)  # the two's own results: wins, draws, losses of the first
    belief: Belief | None = field(default=None, repr=False, compare=False)  # None: a flagged bound's margin

    @property
    def separated(self) -> bool:
        return self.low > 0.0

    @cached_property
    def match(self) -> tuple[float | None, float | None] | None:
        """The central 95% range of the Elo difference a :data:`MATCH_GAMES`-game match of the two measures (the
        range of its score, turned into Elo); an end is None where the score's range reaches 0% or 100% (no finite
        Elo). None for a flagged bound's margin (no pair belief)."""
        if self.belief is None:
            return None
        pred = self.belief.predict(MATCH_GAMES)
        return (None if pred.low <= 0.0 else score_to_elo(pred.low),
                None if pred.high >= 1.0 else score_to_elo(pred.high))

    def to_json(self) -> dict[str, Any]:
        m = self.match
        return {"over": self.over, "elo": round(float(self.elo), 1), "low": round(float(self.low), 1),
                "high": round(float(self.high), 1), "separated": self.separated, "head_to_head": list(self.record),
                "match": None if m is None else {"games": MATCH_GAMES,
                                                 "low": None if m[0] is None else round(m[0], 1),
                                                 "high": None if m[1] is None else round(m[1], 1)}}

    def text(self) -> str:
        """``+97 [+12, +182] Elo over NAME (head to head 40-3-17; 200 games would measure +40 to +160)``: the
        two's own record where they met, and the range a 200-game match of the two lands in 95% of the time."""
        w, d, lo = self.record
        met = f"head to head {w}-{d}-{lo}" if w + d + lo else "they never met"
        m = self.match
        if m is not None:
            low, high = m
            span = (f"{low:+.0f} to {high:+.0f}" if low is not None and high is not None else
                    f"{low:+.0f} or more" if low is not None else f"{high:+.0f} or less" if high is not None else
                    "anything")
            met += f"; {MATCH_GAMES} games would measure {span}"
        return f"{self.elo:+.0f} [{self.low:+.0f}, {self.high:+.0f}] Elo over {self.over} ({met})"


@dataclass(frozen=True)
class LadderRow:
    """One player of a ladder.

    Attributes:
        policy: display name (bot name, ``run/name`` of a snapshot, or the CSV name).
        player_id: league player id (None for CSV players).
        kind: ``"bot"``, ``"snapshot"`` or ``"player"`` (CSV).
        step: training step of a snapshot (None for bots / CSV players).
        elo: fitted Bradley-Terry rating (finite; MAP under a prior, a bound for ML-flagged players).
        ci_low, ci_high: confidence interval of the rating, relative to the anchor.
        games, wins, draws, losses: the player's record in the fitted games.
        score: mean points per game.
        rank: the place in the ladder's order (1, 2, 3, ...: see the module docstring).
        tier: the group of players that cannot be told apart (1: the top's); None for players whose offset to the
            anchor is unknown.
        flag: None, or the fit's flag: ``perfect``, ``zero`` (prior 0 only), ``disconnected``, ``unrated``.
        anchor: True for the anchor player.
        run: the snapshot's run (None for bots, run-less snapshots and CSV players).
        best: True for the best snapshot of its run (highest rating among the run's live snapshots that are
            comparable with the anchor).
        margin: the difference over the next row of the ladder, with its interval (None for the last row and for
            players without a comparable rating).
        best_margin: for a run's best snapshot, its difference over the run's next best (None alone in its run).
        tied: for a run's best snapshot, the run's snapshots it is not separated from, neither above it nor below it
            beyond doubt (empty: the best beyond doubt, save the snapshots a circle of claims puts above it).
        copy_of / copies: one set of weights is one player: its other names (a run repeated with its seed) get a
            row each, with its rating, right under it (``copy_of`` it), and it lists them (``copies``).
        vs: the record against each scripted player of the env, in the league's bot order (empty for CSV
            ladders); a bot's own entry has no games.
        mean_return: the player's mean team return over its cooperative episodes (None in other games).
        side: in a two-sides game whose sides differ (rated per side: see :func:`ladder`), the side's role(s)
            this row is rated on (``adversary``); None in every other game.
        league_role: the snapshot's role in its league (``meta["league_role"]``: ``main``, ``main_exploiter``,
            ``league_exploiter``, ``exploiter``); None for ordinary snapshots, bots and CSV players.
        exploitability: the exploitability filed for the player (:func:`shown_exploitability`): its exact figure
            where there is one, else its lower bound, as filed (``kind``, ``value``, ``low``, ``high``, ...); None
            where none was measured.
    """

    policy: str
    player_id: int | None
    kind: str
    step: int | None
    elo: float
    ci_low: float
    ci_high: float
    games: int
    wins: int
    draws: int
    losses: int
    score: float
    rank: int
    flag: str | None
    anchor: bool
    run: str | None = None
    best: bool = False
    vs: tuple[BotRecord, ...] = ()
    mean_return: float | None = None
    tier: int | None = None
    margin: Margin | None = None
    best_margin: Margin | None = None
    tied: tuple[str, ...] = ()
    copy_of: str | None = None  # another name of the weights of this player (its row just above): one player
    copies: tuple[str, ...] = ()  # the player's other names (the same weights under another run or name)
    side: str | None = None
    league_role: str | None = None
    exploitability: dict[str, Any] | None = None
    circle: tuple[str, ...] = ()  # a circle of claims beyond doubt it is in: itself, above the next, ..., the last
    # above it (self-play's rock-paper-scissors, measured); empty where there is none

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict: ``policy, kind, elo, ci_low, ci_high, games, wins, draws, losses, rank`` then
        ``score, step, flag, anchor, run, best, vs, league_role, exploitability`` (Elo values rounded to 0.1,
        scores to 1e-4; never NaN / inf; ``league_role`` and ``exploitability`` null where the player has none),
        and ``mean_return`` last for a player of a cooperative game, ``side`` for a row of a game rated per side.
        ``vs`` maps each scripted player to ``{"score": s, "games": n}`` (``score`` null without games)."""
        for value in (self.elo, self.ci_low, self.ci_high, self.score):
            assert math.isfinite(value), f"non-finite value in ladder row {self.policy}: {value}"
        out: dict[str, Any] = {
            "policy": self.policy,
            "kind": self.kind,
            "elo": round(float(self.elo), 1),
            "ci_low": round(float(self.ci_low), 1),
            "ci_high": round(float(self.ci_high), 1),
            "games": int(self.games),
            "wins": int(self.wins),
            "draws": int(self.draws),
            "losses": int(self.losses),
            "rank": int(self.rank),
            "tier": self.tier,
            "score": round(float(self.score), 4),
            "step": None if self.step is None else int(self.step),
            "flag": self.flag,
            "anchor": bool(self.anchor),
            "run": self.run,
            "best": bool(self.best),
            "margin": None if self.margin is None else self.margin.to_json(),
            "best_margin": None if self.best_margin is None else self.best_margin.to_json(),
            "tied": list(self.tied),
            "copy_of": self.copy_of,
            "copies": list(self.copies),
            "vs": {v.bot: {"score": None if v.score is None else round(float(v.score), 4), "games": int(v.games)}
                   for v in self.vs},
            "league_role": self.league_role,
            "exploitability": None if self.exploitability is None else dict(self.exploitability),
            "circle": list(self.circle),
        }
        assert tuple(out) == _JSON_KEYS
        if self.mean_return is not None:
            assert math.isfinite(self.mean_return), f"non-finite mean return in ladder row {self.policy}"
            out["mean_return"] = round(float(self.mean_return), 4)
        if self.side is not None:
            out["side"] = self.side
        return out


# --------------------------------------------------------------------------------------------------
# Generic fit
# --------------------------------------------------------------------------------------------------


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


def _group(flag: str | None) -> int:
    """Rows' order: players comparable with the anchor (estimates and flagged bounds) first, then those whose offset
    is unknown, then those without games."""
    return {FLAG_DISCONNECTED: 1, FLAG_UNRATED: 2}.get(flag or "", 0)


def _order(fitted: Fitted, shown: list[int]) -> list[int]:
    return sorted(shown, key=lambda i: (_group(fitted.flags[i]), -fitted.ratings[i], fitted.names[i]))


def _ranks_and_tiers(fitted: Fitted, order: list[int]
                     ) -> tuple[list[int], dict[int, int], dict[int, int | None], dict[int, tuple[int, ...]]]:
    """The rows' order, and each player's rank, tier and circle, from the pairs' claims
    (:func:`~selfplay_cli.stats.ranks.claims_order`, :func:`~selfplay_cli.stats.ranks.tiers`): rank, one more than
    the players above it beyond doubt; rows in which nobody stands over a player above it beyond doubt, by rank
    and Elo otherwise (``order``: the players by Elo), save within a circle of claims; tiers, boundaries where
    everyone above is above everyone below; a player's circle, a shortest circle of claims through it (itself first,
    each above the next, the last above it). Players whose offset to the anchor is unknown keep their
    place (last) as rank and have no tier."""
    placed = [i for i in order if not _group(fitted.flags[i])]
    above = fitted.above(placed)
    rows, ranks, circles = claims_order(above, fitted.ratings[placed])
    tier_of = claims_tiers(above, rows)
    rank = {placed[a]: ranks[a] for a in range(len(placed))}
    tier: dict[int, int | None] = {placed[a]: t for a, t in zip(rows, tier_of, strict=True)}
    circle = {placed[a]: tuple(placed[x] for x in c) for a, c in circles.items()}
    rest = [i for i in order if _group(fitted.flags[i])]
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
    rows, _ = _fit_rows(names, a, b, score_a, anchor, anchor_rating, bootstrap, confidence, seed, kinds, steps,
                        player_ids, prior=prior, hidden=hidden, spread=spread)
    return rows


def _fit_rows(
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
    adjacent = [(i, j) for i, j in zip(order, order[1:], strict=False) if not _group(fit.flags[i])
                and not _group(fit.flags[j])]
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


# --------------------------------------------------------------------------------------------------
# Ladder of the league
# --------------------------------------------------------------------------------------------------


def _envs_in_order(league: League) -> list[str]:
    """Envs that have rated results in the ledger (in any variant), in order of their first one."""
    table = league.ledger.games(variant=None)
    if len(table) == 0:
        return []
    env_of = {p.id: p.env for p in league.roster.players(include_removed=True)}
    envs: dict[str, None] = {}
    for pid in table.player_a.tolist():
        e = env_of.get(int(pid))
        if e is not None:
            envs.setdefault(e, None)
    return list(envs)


def pick_env(league: League, env: str | None) -> str:
    """``env``, or the ledger's only env when None (LeagueError when it has none or several)."""
    if env is not None:
        return env
    envs = _envs_in_order(league)
    if not envs:
        raise LeagueError("the league has no rated games yet: train a run (marl train GAME) or play some (marl match "
                          "A B --env GAME, marl league tournament)")
    if len(envs) > 1:
        raise LeagueError(f"several envs in the league ({', '.join(envs)}): pass --env")
    return envs[0]


def declared_anchor(env: str) -> str:
    """The scripted player a game anchors its ratings at (its declaration's ``anchor``: the lander's heuristic),
    ``random`` for a game this process does not know."""
    spec = declaration(env)
    return "random" if spec is None else spec.anchor


def default_anchor(population: list[PlayerRow], games: dict[int, int], preferred: str = "random") -> PlayerRow:
    """The game's anchor bot (``preferred``) if it played, else ``random``, else the first bot (by id) that played,
    else the most active player."""
    bots = [p for p in population if p.is_bot]
    for name in dict.fromkeys((preferred, "random")):
        for p in bots:
            if p.name == name:
                return p
    if bots:
        return bots[0]
    live = [p for p in population if not p.removed] or population
    return max(live, key=lambda p: (games[p.id], -p.id))


def _find_anchor(population: list[PlayerRow], anchor: PlayerRow | int | str, env: str) -> PlayerRow:
    """The anchor among the players with games: a player row, an id (``17``, ``"#17"``) or a full name."""
    if isinstance(anchor, PlayerRow):
        pid: int | None = anchor.id
        label = anchor.full_name
    elif isinstance(anchor, int | np.integer):
        pid, label = int(anchor), f"#{int(anchor)}"
    else:
        label = str(anchor).strip()
        digits = label[1:] if label.startswith("#") else label
        pid = int(digits) if digits.isdigit() else None
        if pid is None:
            named = [p for p in population if p.full_name == label]
            if named:
                return named[0]
    for p in population:
        if p.id == pid:
            return p
    shown = ", ".join(p.full_name for p in population[:12]) + (", ..." if len(population) > 12 else "")
    raise LeagueError(f"anchor '{label}' has no games in {env}; players with games: {shown}")


def _bot_records(ids: npt.NDArray[np.int64], a: npt.NDArray[np.int64], b: npt.NDArray[np.int64],
                 score_a: npt.NDArray[np.float64], bots: list[PlayerRow]) -> dict[int, tuple[BotRecord, ...]]:
    """Every player's games and points against each bot (draw = 1/2), keyed by player id."""
    n = ids.size
    games = np.zeros((n, n))
    points = np.zeros((n, n))
    np.add.at(games, (a, b), 1.0)
    np.add.at(games, (b, a), 1.0)
    np.add.at(points, (a, b), score_a)
    np.add.at(points, (b, a), 1.0 - score_a)
    index = {int(pid): i for i, pid in enumerate(ids.tolist())}
    out = {}
    for pid, i in index.items():
        recs = []
        for bot in bots:
            j = index.get(bot.id)
            g = 0 if j is None else int(round(games[i, j]))
            recs.append(BotRecord(bot=bot.name, games=g, points=0.0 if j is None else float(points[i, j])))
        out[pid] = tuple(recs)
    return out


def _mark_best(rows: list[LadderRow], removed: set[int], fitted: Fitted, teams: bool = False) -> list[LadderRow]:
    """``best=True`` on each run's highest-rated live snapshot; players comparable with the anchor first (a
    ``disconnected`` or ``unrated`` rating only counts when no snapshot of the run has a comparable one). The best
    carries its margin over the run's next best and the run's snapshots it is not separated from. Neither counts
    another name of the best's own weights, nor, where ``teams`` (a cooperative game, whose per-seat snapshots of
    one moment fly as one team), the best's teammates: the best is not compared with itself."""
    by_run: dict[str, list[LadderRow]] = defaultdict(list)
    for r in rows:  # in the ladder's order: the first comparable one of a run is its best
        if r.kind == "snapshot" and r.run is not None and r.player_id not in removed:
            by_run[r.run].append(r)
    index = {name: i for i, name in enumerate(fitted.names)}
    marked: dict[str, LadderRow] = {}
    for members in by_run.values():
        comparable = [r for r in members if not _group(r.flag)] or members
        best = comparable[0]
        i = index[best.copy_of or best.policy]
        rest = [r for r in comparable[1:] if index[r.copy_of or r.policy] != i
                and not (teams and r.step == best.step)]
        margin = replace(fitted.margin(i, index[rest[0].copy_of or rest[0].policy]), over=rest[0].policy) \
            if rest else None
        sure = fitted.above([i] + [index[r.copy_of or r.policy] for r in rest]) if rest else np.zeros((1, 1), bool)
        tied = tuple(r.policy for k, r in enumerate(rest, start=1) if not sure[0, k] and not sure[k, 0])
        marked[best.policy] = replace(best, best=True, best_margin=margin, tied=tied)
    return [marked.get(r.policy, r) for r in rows]


def ladder(
    league: League,
    env: str | None = None,
    anchor: PlayerRow | int | str | None = None,
    anchor_rating: float = 1000.0,
    bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    include_removed: bool = False,
    *,
    prior: float = DEFAULT_PRIOR,
    variant: str = "",
) -> list[LadderRow]:
    """The ladder of ``env``: a :func:`fit_table` over all pairwise results of that env in the ledger, in one
    ``variant`` (its key, :func:`~selfplay_cli.league.variants.variant_key`; the default variant unless given).

    ``env=None`` uses the ledger's only env (LeagueError if it has several, or no games at all); an env
    without games gives an empty list. Only players with games appear. ``prior``: BayesElo's prior in virtual
    draws (default :data:`DEFAULT_PRIOR` = 2, BayesElo's default; 0 = maximum likelihood).

    The default anchor is the env's ``random`` bot if it played, else the first bot (lowest id) that played,
    else the (non-removed) player with the most games. ``anchor`` may be a player row (e.g. from
    :func:`selfplay_cli.ratings.names.resolve`, which understands every name a user types), a player id
    (``17`` or ``"#17"``) or a full name as shown in the ladder (``"r1/ep90"``, ``"cpu"``); the anchor must
    have games in the env. Removed snapshots are fitted (their games count) but left out of the rows and the
    ranks unless ``include_removed``.

    Each row also carries its ``run``, ``best`` (the best snapshot of its run) and ``vs`` (its record
    against each scripted player of the env: ``league.roster.players(env=env, kind="bot")``) and, in a cooperative game,
    ``mean_return`` (its mean team return over its episodes).
    """
    env = pick_env(league, env)
    table = league.ledger.games(env=env, variant=variant)
    if len(table) == 0:
        return []
    rules = rules_for_env(env, variant_options(variant))
    if rules.sides_differ:
        return _ladder_by_side(league, env, table, rules.side_roles(), anchor, anchor_rating, bootstrap, confidence,
                               seed, include_removed, prior, variant)
    ids, a, b = table.indexed()
    known = {p.id: p for p in league.roster.players(env=env, include_removed=True)}
    population = [known[int(i)] if int(i) in known else league.roster.get_player(int(i)) for i in ids.tolist()]
    games = dict(zip(ids.tolist(), (np.bincount(a, minlength=ids.size) + np.bincount(b, minlength=ids.size))
                     .tolist(), strict=True))
    anchor_player = (default_anchor(population, games, declared_anchor(env)) if anchor is None
                     else _find_anchor(population, anchor, env))
    removed = {p.id for p in population if p.removed}
    hidden = set() if include_removed else {p.full_name for p in population if p.removed}
    if anchor_player.full_name in hidden:
        hidden.discard(anchor_player.full_name)  # an explicitly chosen removed anchor stays visible
    names = [p.full_name for p in population]
    rows, fitted = _fit_rows(
        names, a, b, table.score_a, anchor_player.full_name, anchor_rating, bootstrap, confidence, seed,
        {p.full_name: p.kind for p in population}, {p.full_name: p.step for p in population if not p.is_bot},
        {p.full_name: p.id for p in population}, prior=prior, hidden=hidden, deff=design_effect(table),
    )
    bots = league.roster.players(env=env, kind="bot", include_removed=True)
    records = _bot_records(ids, a, b, table.score_a, bots)
    run_of = {p.id: p.run for p in population if not p.is_bot}
    returns = league.ledger.mean_returns(env, variant=variant)
    rows = [replace(r, run=run_of.get(int(r.player_id)), vs=records.get(int(r.player_id), ()),
                    mean_return=returns[int(r.player_id)][1] if int(r.player_id) in returns else None)
            if r.player_id is not None else r for r in rows]
    rows = _with_copies(league, env, rows, include_removed)
    teams = rules.kind == COOPERATIVE
    return _with_league_marks(_mark_best(rows, removed, fitted, teams), known | {p.id: p for p in population})


def shown_exploitability(meta: dict[str, Any]) -> dict[str, Any] | None:
    """The exploitability a player's row shows, from its ``meta["exploitability"]`` (filed by
    :meth:`~selfplay_cli.league.store.League.set_exploitability`): the exact figure where there is one (it says how
    beatable the player is), else the lower bound (a trained best response's return: the player is at least that
    beatable), as filed with its ``kind``; None where nothing was measured."""
    book = meta.get("exploitability") or {}
    for kind in ("exact", "lower_bound"):
        record = book.get(kind)
        if isinstance(record, dict):
            return {**record, "kind": kind}
    return None


def _with_league_marks(rows: list[LadderRow], players: dict[int, PlayerRow]) -> list[LadderRow]:
    """Each row's league role and filed exploitability, read from its player's meta (a copy's from its own row)."""
    out = []
    for r in rows:
        p = players.get(r.player_id) if r.player_id is not None else None
        meta = p.meta if p is not None else {}
        role = meta.get("league_role")
        out.append(replace(r, league_role=str(role) if role else None, exploitability=shown_exploitability(meta)))
    return out


def _with_copies(league: League, env: str, rows: list[LadderRow], include_removed: bool) -> list[LadderRow]:
    """Every other name of a rated player's weights (a run repeated with its seed, in the same league), as a row of
    its own right under the player's: the same rating, rank and tier, ``copy_of`` the player; the player's row
    lists them in ``copies``."""
    same = league.ledger.same_weights(env)
    if not same:
        return rows
    by_lead: dict[int, list[PlayerRow]] = defaultdict(list)
    known = {p.id: p for p in league.roster.players(env=env, kind="snapshot", include_removed=True)}
    for pid, lead in same.items():
        p = known[pid]
        if include_removed or not p.removed:
            by_lead[lead].append(p)
    out = []
    for r in rows:
        copies = by_lead.get(r.player_id, []) if r.player_id is not None else []
        out.append(replace(r, copies=tuple(p.full_name for p in copies)) if copies else r)
        out += [replace(r, policy=p.full_name, player_id=p.id, run=p.run, step=p.step, anchor=False,
                        copy_of=r.policy, copies=()) for p in copies]
    return out


def _ladder_by_side(league: League, env: str, table: GameTable, labels: tuple[str, ...],
                    anchor: PlayerRow | int | str | None, anchor_rating: float, bootstrap: int, confidence: float,
                    seed: int, include_removed: bool, prior: float, variant: str = "") -> list[LadderRow]:
    """The ladder of a two-sides game whose sides differ (``labels``: each side's role): one table per side.

    A player of one side meets only the other side's players, so its rating compares only with its own side's:
    each player is fitted as the side it played (:meth:`GameTable.by_side`; a scripted player, which plays either
    side, is one player a side), and each side's table is anchored at its own anchor (the anchor bot playing that
    side, at ``anchor_rating``), its rows carrying ``side``. Everything else reads as in :func:`ladder`, per side:
    ranks, tiers, margins, each run's best and the records against the scripted players (on the other side)."""
    sided, sides = table.by_side()
    keys, a, b = sided.indexed()
    known = {p.id: p for p in league.roster.players(env=env, include_removed=True)}
    row_of = {int(k): known.get(sides[int(k)][0]) or league.roster.get_player(sides[int(k)][0]) for k in keys.tolist()}
    side_of = {int(k): sides[int(k)][1] for k in keys.tolist()}
    counts = np.bincount(a, minlength=keys.size) + np.bincount(b, minlength=keys.size)
    bots = league.roster.players(env=env, kind="bot", include_removed=True)
    returns = league.ledger.mean_returns(env, variant=variant)
    chosen = None if anchor is None else _find_anchor(list({p.id: p for p in row_of.values()}.values()), anchor, env)
    out: list[LadderRow] = []
    for side, label in enumerate(labels):
        mine = [k for k in row_of if side_of[k] == side]
        if not mine:
            continue
        names = [row_of[k].full_name if side_of[k] == side else f"{row_of[k].full_name} ({labels[side_of[k]]})"
                 for k in keys.tolist()]
        population = [row_of[k] for k in mine]
        games = {row_of[k].id: int(counts[i]) for i, k in enumerate(keys.tolist()) if side_of[k] == side}
        lead = (chosen if chosen is not None and chosen.id in games
                else default_anchor(population, games, declared_anchor(env)))
        removed = {p.id for p in population if p.removed}
        hidden = {n for n, k in zip(names, keys.tolist(), strict=True) if side_of[k] != side}
        if not include_removed:
            hidden |= {p.full_name for p in population if p.removed and p.id != lead.id}
        rows, fitted = _fit_rows(
            names, a, b, sided.score_a, lead.full_name, anchor_rating, bootstrap, confidence, seed,
            {p.full_name: p.kind for p in population}, {p.full_name: p.step for p in population if not p.is_bot},
            {p.full_name: p.id for p in population}, prior=prior, hidden=hidden, deff=design_effect(table),
        )
        key_of = {row_of[k].id: k for k in mine}
        # each row's record against the scripted players, as they played the other side
        other = {row_of[k].id: k for k in row_of if side_of[k] != side}
        theirs = [replace(bot, id=other.get(bot.id, -(2 * bot.id + 1 - side) - 1)) for bot in bots]  # (or no games)
        records = _bot_records(keys, a, b, sided.score_a, theirs)
        rows = [replace(r, run=row_of[key_of[int(r.player_id)]].run, side=label,
                        vs=records.get(key_of[int(r.player_id)], ()),
                        mean_return=returns[int(r.player_id)][1] if int(r.player_id) in returns else None)
                for r in rows]
        out += _mark_best(rows, removed, fitted)
    return _with_league_marks(out, known | {p.id: p for p in row_of.values()})


def verdict_lines(rows: list[LadderRow]) -> list[str]:
    """Who is best, and by how much, in plain lines: the ladder's top over the next player, then each run's best
    over the run's next best (or the snapshots it cannot be told apart from); in a game rated per side, for each
    side (its lines led by ``<side> side:``), since ratings compare only within a side."""
    by_side: dict[str | None, list[LadderRow]] = {}
    for r in rows:
        by_side.setdefault(r.side, []).append(r)
    if list(by_side) != [None] and by_side:
        return [f"{side} side: {line}" for side, group in by_side.items() for line in _verdicts(group)]
    return _verdicts(rows)


def _verdicts(rows: list[LadderRow]) -> list[str]:
    """:func:`verdict_lines` of one table."""
    lines = []
    ranked = [r for r in rows if r.tier is not None and r.copy_of is None]
    if len(ranked) >= 2 and ranked[0].margin is not None:
        top, m = ranked[0], ranked[0].margin
        shared = sum(1 for r in ranked if r.tier == top.tier) - 1
        though = f", though {m.over} is above it beyond doubt" if m.high < 0.0 else ""  # (a circle of claims)
        lines.append(f"top: {top.policy}{though}, {m.text()}" + (
            "" if m.separated and not shared else
            f"; {shared} more player{'s' if shared != 1 else ''} in its tier") + _circle_text(top))
    for r in rows:
        if not r.best:
            continue
        m = r.best_margin
        if m is None:
            lines.append(f"best of {r.run}: {r.policy} (the run's only rated snapshot)")
        elif m.high < 0.0:  # the next is above it beyond doubt: only where the claims go round in a circle
            lines.append(f"best of {r.run}: {r.policy} by Elo, though {m.over} is above it beyond doubt: {m.text()}"
                         + _circle_text(r))
        elif not r.tied:
            lines.append(f"best of {r.run}: {r.policy}, {m.text()}" + _circle_text(r))
        else:
            names = ", ".join(r.tied[:3]) + (f" and {len(r.tied) - 3} more" if len(r.tied) > 3 else "")
            lines.append(f"best of {r.run}: {r.policy} by Elo, not separated from {names}: {m.text()}"
                         + _circle_text(r))
    said = {frozenset(r.circle) for r in ranked[:1] if r.circle} | {frozenset(r.circle) for r in rows if r.best}
    circles = {frozenset(r.circle): r.circle for r in ranked if r.circle and frozenset(r.circle) not in said}
    for c in list(circles.values())[:3]:
        lines.append("a circle beyond doubt: " + " above ".join((*c, c[0])))
    if len(circles) > 3:
        more = len(circles) - 3
        lines.append(f"and {more} more circle{'s' * (more > 1)} (each row's own in --json)")
    return lines


def _circle_text(row: LadderRow) -> str:
    """``; in a circle beyond doubt: A above B above C above A`` where the row is in one, else ''."""
    if not row.circle:
        return ""
    return "; in a circle beyond doubt: " + " above ".join((*row.circle, row.circle[0]))


def select_rows(rows: list[LadderRow], run: str | None = None, top: int | None = None) -> list[LadderRow]:
    """The rows to show: with ``run``, that run's snapshots plus the scripted players (for reference); with
    ``top``, the first ``top`` of those. Order and ranks are kept: a rank is always the one in the whole ladder.

    Raises:
        LeagueError: ``top < 1``.
    """
    if top is not None and top < 1:
        raise LeagueError(f"--top must be at least 1, not {top}")
    if run is not None:
        rows = [r for r in rows if r.run == run or r.kind == "bot"]
    return rows if top is None else rows[:top]
