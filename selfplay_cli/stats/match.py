"""Head-to-head statistics of one match-up: score, Elo difference, confidence interval and likelihood of
superiority, with the per-game (trinomial) or per-game-pair (pentanomial) variance as fastchess reports it.

numpy and the standard library only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .elo import MAX_ELO, SCORE_CLIP, normal_quantile, score_to_elo

__all__ = ["MatchStats", "match_stats", "points_stats", "score_interval"]


@dataclass(frozen=True)
class MatchStats:
    """Summary of a head-to-head between A and B, from A's point of view.

    Attributes:
        games: ``wins + draws + losses``.
        wins, draws, losses: A's results.
        score: A's mean points per game ``(W + D/2) / games`` (0.5 if there were no games).
        elo: estimated Elo difference A - B, ``score_to_elo(score)``; if ``bounded`` it is
            ``score_to_elo((W + D/2 + 1/2) / (games + 1))`` (one virtual draw added), see
            :func:`match_stats`.
        elo_low, elo_high: confidence interval of the Elo difference (always finite, within
            ``+-MAX_ELO``).
        los: likelihood of superiority ``P(A stronger than B)`` in [0, 1], from the interval's own score and standard
            error (see :func:`match_stats`).
        bounded: True when the score is 0 or 1 (or there are no games), i.e. the maximum-likelihood
            Elo is infinite and ``elo`` / the interval are finite bounds, not an estimate.
        confidence: the two-sided confidence level of the interval.
        used_pentanomial: True when the interval used the game-pair (pentanomial) variance.
    """

    games: int
    wins: int
    draws: int
    losses: int
    score: float
    elo: float
    elo_low: float
    elo_high: float
    los: float
    bounded: bool
    confidence: float = 0.95
    used_pentanomial: bool = False


def _likelihood_of_superiority(s_est: float, se: float) -> float:
    """LOS = P(A stronger) ~= Phi((s - 1/2) / se) = (1 + erf((s - 1/2) / (se sqrt 2))) / 2: the normal model of
    the score that the interval is drawn from, with its score and standard error, so that the interval excludes 0
    exactly when the LOS lies beyond its confidence (0.5 at a score of 1/2)."""
    return 0.5 * (1.0 + math.erf((s_est - 0.5) / (se * math.sqrt(2.0))))


def _degenerate_se(games: int, pairs: int) -> float:
    """The standard error of a score whose sample shows no spread (all draws, or every pair one win and one loss):
    the sample's with one virtual result on either side of it (a pair 1.5-0.5 and one 0.5-1.5; a win and a loss),
    as a 0 % / 100 % score is given a virtual draw. It shrinks as games come in (4 pairs of 1-1: +-82 Elo at 95%)."""
    if pairs:
        var = 2 * 0.25**2 / (pairs + 2)
        return math.sqrt(var / (pairs + 2))
    var = 2 * 0.5**2 / (games + 2)
    return math.sqrt(var / (games + 2))


def _estimate(w: int, d: int, lo: int, penta: tuple[int, ...] | None, bounded: bool) -> tuple[float, float, bool]:
    """The score :func:`match_stats` reports its Elo from, its standard error, and whether the pentanomial gave it
    (see :func:`match_stats` for each formula)."""
    n = w + d + lo
    if bounded:
        n_eff, w_eff, d_eff, l_eff = n + 1, w, d + 1, lo
        s_est = (w_eff + 0.5 * d_eff) / n_eff
        var_g = (w_eff * (1 - s_est) ** 2 + d_eff * (0.5 - s_est) ** 2 + l_eff * s_est**2) / n_eff
        return s_est, math.sqrt(var_g / n_eff), False
    score = (w + 0.5 * d) / n
    use_penta = False
    pairs = sum(penta) if penta is not None else 0
    if penta is not None and pairs > 0:
        a = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
        p = np.asarray(penta, dtype=float) / pairs
        mu = float(p @ a)
        var_p = float(p @ (a - mu) ** 2)
        se = math.sqrt(var_p / pairs)
        use_penta = True
    else:
        var_g = (w * (1 - score) ** 2 + d * (0.5 - score) ** 2 + lo * score**2) / n
        se = math.sqrt(var_g / n)
    if se == 0.0:  # every pair (game) alike, e.g. 2 pairs of one win each: no spread observed is not certainty
        se = _degenerate_se(n, pairs if use_penta else 0)
    return score, se, use_penta


def match_stats(
    wins: int,
    draws: int,
    losses: int,
    pentanomial: tuple[int, int, int, int, int] | None = None,
    confidence: float = 0.95,
) -> MatchStats:
    """Score, Elo, confidence interval and LOS of one match-up (A vs B, A's point of view).

    Score: ``s = (W + D/2) / n`` with ``n = W + D + L``.

    Standard error of ``s``:

    * trinomial (no pentanomial given), games independent:
      ``var_g = [W (1-s)^2 + D (1/2-s)^2 + L s^2] / n`` per game, ``se = sqrt(var_g / n)``;
    * pentanomial, games played in colour-reversed pairs (as fastchess reports it): the counts
      ``(LL, LD, WL+DD, WD, WW)`` of the ``m`` pairs have pair-mean scores ``a = (0, 1/4, 1/2, 3/4, 1)``;
      ``mu = sum p_k a_k``, ``var_p = sum p_k (a_k - mu)^2`` with ``p_k = count_k / m`` and
      ``se = sqrt(var_p / m)``. This accounts for the correlation of the two games of a pair (the
      opening), which the trinomial variance ignores. The score itself still comes from W/D/L;
      the pentanomial only supplies the variance.

    Interval: the normal score interval ``s -+ z se`` with ``z = Phi^{-1}((1 + confidence) / 2)``
    (:func:`normal_quantile`), each endpoint clipped to ``[SCORE_CLIP, 1 - SCORE_CLIP]`` and mapped
    through :func:`score_to_elo` (endpoint transformation, not the delta method - this is what
    fastchess does, and it keeps the asymmetry of the logistic curve).

    0 % / 100 % scores (``bounded=True``): the ML Elo is infinite, so one virtual draw is added
    (``s' = (W + D/2 + 1/2) / (n + 1)``, trinomial variance of the record ``(W, D + 1, L)``); ``elo``
    and the interval are computed from ``s'`` and the interval endpoint on the open side is the
    clip, ``+-MAX_ELO``. With no games at all: ``score = 0.5``, ``elo = 0``, interval
    ``[-MAX_ELO, +MAX_ELO]``, ``bounded=True``.

    LOS: ``Phi((s - 1/2) / se)``, the score and standard error the interval was drawn from (the pentanomial's where
    pairs are given, the virtual draw's at 0 % / 100 %), 0.5 without games. One model for both: the interval
    excludes 0 exactly when the LOS lies above ``(1 + confidence) / 2`` or below ``(1 - confidence) / 2``. (The
    per-game ``Phi((W - L) / sqrt(W + L))`` treats the two games of a pair as independent and contradicted the
    pair interval: 96 pairs won and lost and 4 won twice are +0.6 to +27.3 Elo at 95 % and 97.9 % LOS, not 71.4 %.)

    Raises:
        ValueError: negative counts, a pentanomial that is not 5 non-negative counts, or
            ``confidence`` outside (0, 1).
    """
    w, d, lo = int(wins), int(draws), int(losses)
    if min(w, d, lo) < 0:
        raise ValueError("match_stats: counts must be non-negative")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"match_stats: confidence must be in (0, 1), got {confidence}")
    penta: tuple[int, ...] | None = None
    if pentanomial is not None:
        penta = tuple(int(c) for c in pentanomial)
        if len(penta) != 5 or min(penta) < 0:
            raise ValueError("match_stats: pentanomial must be 5 pair counts (LL, LD, WL+DD, WD, WW) >= 0")
    n = w + d + lo
    z = normal_quantile(0.5 + 0.5 * confidence)
    if n == 0:
        return MatchStats(0, 0, 0, 0, 0.5, 0.0, -MAX_ELO, MAX_ELO, 0.5, True, confidence, False)

    score = (w + 0.5 * d) / n
    bounded = w + 0.5 * d <= 0.0 or lo + 0.5 * d <= 0.0  # score exactly 0 or 1
    s_est, se, use_penta = _estimate(w, d, lo, penta, bounded)
    los = _likelihood_of_superiority(s_est, se)
    lo_s = min(max(s_est - z * se, SCORE_CLIP), 1.0 - SCORE_CLIP)
    hi_s = min(max(s_est + z * se, SCORE_CLIP), 1.0 - SCORE_CLIP)
    elo = score_to_elo(s_est)
    elo_low, elo_high = score_to_elo(lo_s), score_to_elo(hi_s)
    if bounded:  # the open side of a 0 % / 100 % result is unbounded: report the clip.
        if score >= 1.0:
            elo_high = MAX_ELO
        else:
            elo_low = -MAX_ELO
    return MatchStats(
        games=n, wins=w, draws=d, losses=lo, score=score, elo=elo, elo_low=min(elo_low, elo),
        elo_high=max(elo_high, elo), los=los, bounded=bounded, confidence=confidence,
        used_pentanomial=use_penta,
    )


def points_stats(round_points: Sequence[Sequence[float]], paired: bool, confidence: float = 0.95) -> MatchStats:
    """:func:`match_stats` of a match whose results are any points in [0, 1] (a game played for stakes: poker's hands
    are worth the chips they win, :class:`~selfplay_cli.results.Rules`), from A's points in each result, grouped in
    rounds (``paired``: each round a seat-swapped pair of games, whose mean is the unit of the variance, as the
    pentanomial's). Where every point is a win, a draw or a loss this is :func:`match_stats` of the record exactly;
    otherwise the score is the mean point, its standard error the spread of the rounds' means (of the results'
    without pairs), the interval and LOS drawn from them as :func:`match_stats` draws its own. W / D / L count the
    results above, at and below 1/2."""
    rounds = [np.asarray(r, dtype=np.float64) for r in round_points if len(r)]
    pts = np.concatenate(rounds) if rounds else np.zeros(0)
    w, d, lo = int((pts > 0.5).sum()), int((pts == 0.5).sum()), int((pts < 0.5).sum())
    whole = bool(np.all(np.isin(pts, (0.0, 0.5, 1.0))))
    if whole or not pts.size:
        penta = None
        if paired and rounds:  # (LL, LD, WL+DD, WD, WW): the pairs by A's points in them
            idx = np.rint(np.array([r.sum() for r in rounds]) * 2).astype(np.int64)
            penta = tuple(int(c) for c in np.bincount(idx, minlength=5)[:5])
        return match_stats(w, d, lo, pentanomial=penta, confidence=confidence)  # type: ignore[arg-type]
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"points_stats: confidence must be in (0, 1), got {confidence}")
    if np.any((pts < 0.0) | (pts > 1.0)):
        raise ValueError("points_stats: points must lie in [0, 1]")
    n = pts.size
    score = float(pts.mean())
    bounded = score >= 1.0 or score <= 0.0
    if bounded:  # one virtual draw, as match_stats
        s_est = (float(pts.sum()) + 0.5) / (n + 1)
        se = math.sqrt(float(np.mean(np.append(pts, 0.5) ** 2) - s_est**2) / (n + 1))
    else:
        s_est = score
        units = np.array([r.mean() for r in rounds]) if paired else pts
        se = float(units.std()) / math.sqrt(units.size)
        if se == 0.0:
            se = _degenerate_se(n, units.size if paired else 0)
    z = normal_quantile(0.5 + 0.5 * confidence)
    lo_s = min(max(s_est - z * se, SCORE_CLIP), 1.0 - SCORE_CLIP)
    hi_s = min(max(s_est + z * se, SCORE_CLIP), 1.0 - SCORE_CLIP)
    elo = score_to_elo(s_est)
    elo_low, elo_high = score_to_elo(lo_s), score_to_elo(hi_s)
    if bounded:
        if score >= 1.0:
            elo_high = MAX_ELO
        else:
            elo_low = -MAX_ELO
    return MatchStats(games=n, wins=w, draws=d, losses=lo, score=score, elo=elo, elo_low=min(elo_low, elo),
                      elo_high=max(elo_high, elo), los=_likelihood_of_superiority(s_est, se), bounded=bounded,
                      confidence=confidence, used_pentanomial=paired)


def score_interval(wins: int, draws: int, losses: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson interval of a score ``(W + D/2) / n``, a draw counted as half a success: honest at 0 % and 100 %
    and with a handful of games (0 of 4 is ``[0 %, 49 %]``, not a point). ``(0, 1)`` without games."""
    n = int(wins) + int(draws) + int(losses)
    if n == 0:
        return 0.0, 1.0
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"score_interval: confidence must be in (0, 1), got {confidence}")
    p = (wins + 0.5 * draws) / n
    z = normal_quantile(0.5 + 0.5 * confidence)
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)
