"""Ladders: Bradley-Terry ratings of a whole population, derived from the game ledger or a results CSV.

Nothing here is stored: every ladder is refitted from the games (:func:`ladder` from the league's
ledger, :func:`fit_csv` from a ``player_a,player_b,result`` file), so it always agrees with the ledger.

* :func:`fit_table` is the generic core: maximum-likelihood Bradley-Terry ratings anchored at one player
  (:func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`), a confidence interval per player and
  Chatbot-Arena ranks (:func:`~selfplay_cli.stats.bradley_terry.rank_by_ci`: ``1 + #players whose lower bound
  is above my upper bound``, so overlapping players share a rank).
* :func:`ladder` fits the 2-seat games of one env of the league.
* :func:`read_results_csv` / :func:`fit_csv` rate an external results file.
* :func:`plan_tournament` says how many games each pair of a round robin / gauntlet still needs.
* :func:`head_to_head` gives W/D/L and pentanomial (game-pair) counts of two players.

Confidence intervals
--------------------
``bootstrap > 0``: the percentile bootstrap of :func:`~selfplay_cli.stats.bradley_terry.bootstrap_ci` (games
resampled with replacement, ``bootstrap`` replicates, seeded). ``bootstrap == 0``: a normal approximation
from the observed Fisher information, i.e. the negative Hessian of the Bradley-Terry log-likelihood at the
fit. In natural-log units it is the weighted graph Laplacian ``L_ii = sum_j c_ij, L_ij = -c_ij`` with
``c_ij = N_ij p_ij (1 - p_ij)``; with the anchor's row and column removed (the anchor is fixed) it is
invertible on the anchor's connected component, and ``se_i = sqrt((L^-1)_ii) * 400 / ln 10`` Elo, interval
``r_i -+ z se_i`` with ``z = Phi^-1((1 + confidence) / 2)``. Either way the intervals are relative to the
anchor (whose interval is the single point ``anchor_rating``). Flagged players get an open side instead: a
``perfect`` player's upper end and a ``zero`` player's lower end are ``rating +- MAX_ELO``; disconnected and
unrated players get ``rating -+ MAX_ELO`` on both sides (normal approximation); standard errors are capped at
``MAX_ELO``. Every number in a :class:`LadderRow` is finite.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.stats.bradley_terry import (
    FLAG_DISCONNECTED,
    FLAG_PERFECT,
    FLAG_UNRATED,
    FLAG_ZERO,
    bootstrap_ci,
    fit_bradley_terry,
    rank_by_ci,
    reachable,
)
from selfplay_cli.stats.elo import MAX_ELO, NAT_TO_ELO, normal_quantile

__all__ = [
    "CSV_HEADER",
    "LadderRow",
    "PairPlan",
    "fit_csv",
    "fit_table",
    "head_to_head",
    "ladder",
    "plan_tournament",
    "read_results_csv",
]

CSV_HEADER = ("player_a", "player_b", "result")
"""The header a results CSV must have (whitespace around the names tolerated)."""

_JSON_KEYS = ("policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses", "rank",
              "score", "step", "flag", "anchor")


# --------------------------------------------------------------------------------------------------
# Rows
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LadderRow:
    """One player of a ladder.

    Attributes:
        policy: display name (bot name, ``run/name`` of a snapshot, or the CSV name).
        player_id: league player id (None for CSV players).
        kind: ``"bot"``, ``"snapshot"`` or ``"player"`` (CSV).
        step: training step of a snapshot (None for bots / CSV players).
        elo: fitted Bradley-Terry rating (finite; a bound for flagged players).
        ci_low, ci_high: confidence interval of the rating, relative to the anchor.
        games, wins, draws, losses: the player's record in the fitted games.
        score: mean points per game.
        rank: Chatbot-Arena rank, ``1 + #players whose ci_low > this ci_high``.
        flag: None, or the fit's flag: ``perfect``, ``zero``, ``disconnected``, ``unrated``.
        anchor: True for the anchor player.
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

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict: ``policy, kind, elo, ci_low, ci_high, games, wins, draws, losses, rank`` then
        ``score, step, flag, anchor`` (Elo values rounded to 0.1, the score to 1e-4; never NaN / inf)."""
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
            "score": round(float(self.score), 4),
            "step": None if self.step is None else int(self.step),
            "flag": self.flag,
            "anchor": bool(self.anchor),
        }
        assert tuple(out) == _JSON_KEYS
        return out


# --------------------------------------------------------------------------------------------------
# Generic fit
# --------------------------------------------------------------------------------------------------


def _normal_ci(
    ratings: npt.NDArray[np.float64], flags: list[str | None], a: npt.NDArray[np.int64], b: npt.NDArray[np.int64],
    n_players: int, anchor: int, confidence: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Normal-approximation intervals from the observed Fisher information (see the module docstring)."""
    nmat = np.zeros((n_players, n_players))
    np.add.at(nmat, (a, b), 1.0)
    nmat = nmat + nmat.T
    se = np.full(n_players, MAX_ELO)
    se[anchor] = 0.0
    idx = np.flatnonzero(reachable(nmat > 0, anchor) & (np.arange(n_players) != anchor))
    if idx.size:
        theta = (ratings - ratings[anchor]) / NAT_TO_ELO
        p = 0.5 * (1.0 + np.tanh(0.5 * (theta[:, None] - theta[None, :])))
        c = nmat * p * (1.0 - p)
        lap = -c[np.ix_(idx, idx)]
        lap[np.diag_indices_from(lap)] += c[idx].sum(axis=1)
        try:
            cov = np.linalg.inv(lap)
        except np.linalg.LinAlgError:
            cov = np.linalg.pinv(lap)
        var = np.diag(cov)
        sub = np.sqrt(np.where(np.isfinite(var) & (var > 0.0), var, 0.0)) * NAT_TO_ELO
        sub[~np.isfinite(var) | (var < 0.0)] = MAX_ELO
        se[idx] = np.minimum(sub, MAX_ELO)
    z = normal_quantile(0.5 + 0.5 * confidence)
    low, high = ratings - z * se, ratings + z * se
    return low, high


def _open_flagged_sides(ratings: np.ndarray, flags: list[str | None], low: np.ndarray, high: np.ndarray,
                        anchor: int) -> None:
    """Intervals of players without a maximum-likelihood rating are open on the unknown side (whatever
    interval method was used): a perfect score has no upper limit, a zero score no lower one, and a player not
    connected to the anchor neither. The open side is drawn at +-MAX_ELO from the bound. The anchor's rating
    is fixed by definition, so its interval stays a point."""
    for i, flag in enumerate(flags):
        if i == anchor:
            continue
        if flag in (FLAG_PERFECT, FLAG_DISCONNECTED, FLAG_UNRATED):
            high[i] = max(high[i], ratings[i] + MAX_ELO)
        if flag in (FLAG_ZERO, FLAG_DISCONNECTED, FLAG_UNRATED):
            low[i] = min(low[i], ratings[i] - MAX_ELO)


def _sort_rows(rows: list[LadderRow]) -> list[LadderRow]:
    return sorted(rows, key=lambda r: (r.rank, -r.elo, r.policy))


def _rerank(rows: list[LadderRow]) -> list[LadderRow]:
    """Recompute the CI ranks among ``rows`` only (after some rows were hidden) and sort."""
    if not rows:
        return []
    ranks = rank_by_ci([r.elo for r in rows], [r.ci_low for r in rows], [r.ci_high for r in rows])
    return _sort_rows([replace(r, rank=int(k)) for r, k in zip(rows, ranks, strict=True)])


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
) -> list[LadderRow]:
    """Fit a ladder from games given as index arrays into ``names``.

    Bradley-Terry maximum likelihood anchored at ``anchor`` (its rating is ``anchor_rating``), intervals by
    a ``bootstrap``-replicate percentile bootstrap (``bootstrap=0``: normal approximation from the Fisher
    information, see the module docstring), ranks by :func:`rank_by_ci`. One row per name (players without
    games are flagged ``unrated``), sorted by ``(rank, -elo, name)``. ``kinds`` / ``steps`` / ``player_ids``
    (keyed by name) fill the corresponding columns (default kind ``"player"``).

    Raises:
        LeagueError: anchor not among the names, no games, bad indices or options.
    """
    names = [str(n) for n in names]
    if len(set(names)) != len(names):
        raise LeagueError("duplicate player names in the rating table")
    if anchor not in names:
        shown = ", ".join(names[:20]) + (", ..." if len(names) > 20 else "")
        raise LeagueError(f"anchor '{anchor}' is not a rated player; players: {shown or '(none)'}")
    if bootstrap < 0:
        raise LeagueError(f"bootstrap must be >= 0, got {bootstrap}")
    if not 0.0 < confidence < 1.0:
        raise LeagueError(f"confidence must be between 0 and 1, got {confidence}")
    ai = np.asarray(a, dtype=np.int64).ravel()
    bi = np.asarray(b, dtype=np.int64).ravel()
    sc = np.asarray(score_a, dtype=np.float64).ravel()
    if ai.size == 0:
        raise LeagueError("no games to rate")
    n = len(names)
    k = names.index(anchor)
    try:
        fit = fit_bradley_terry(ai, bi, sc, n, anchor=k, anchor_rating=anchor_rating)
        if bootstrap > 0:
            low, high = bootstrap_ci(ai, bi, sc, n, anchor=k, anchor_rating=anchor_rating, n_boot=bootstrap,
                                     confidence=confidence, seed=seed)
        else:
            low, high = _normal_ci(fit.ratings, fit.flags, ai, bi, n, k, confidence)
    except ValueError as exc:
        raise LeagueError(f"cannot fit ratings: {exc}") from exc
    ratings = np.asarray(fit.ratings, dtype=np.float64)
    low = np.minimum(np.asarray(low, dtype=np.float64), ratings)
    high = np.maximum(np.asarray(high, dtype=np.float64), ratings)
    _open_flagged_sides(ratings, list(fit.flags), low, high, k)
    if not (np.all(np.isfinite(ratings)) and np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise AssertionError("rating fit produced a non-finite value")  # pragma: no cover
    ranks = rank_by_ci(ratings, low, high)
    kinds, steps, player_ids = kinds or {}, steps or {}, player_ids or {}
    rows = [
        LadderRow(
            policy=name, player_id=player_ids.get(name), kind=kinds.get(name, "player"), step=steps.get(name),
            elo=float(ratings[i]), ci_low=float(low[i]), ci_high=float(high[i]), games=int(fit.games[i]),
            wins=int(fit.wins[i]), draws=int(fit.draws[i]), losses=int(fit.losses[i]), score=float(fit.score[i]),
            rank=int(ranks[i]), flag=fit.flags[i], anchor=i == k,
        )
        for i, name in enumerate(names)
    ]
    return _sort_rows(rows)


# --------------------------------------------------------------------------------------------------
# Ladder of the league
# --------------------------------------------------------------------------------------------------


def _envs_in_order(league: League) -> list[str]:
    """Envs that have 2-seat games in the ledger, in order of their first game."""
    table = league.games()
    if len(table) == 0:
        return []
    env_of = {p.id: p.env for p in league.players(include_removed=True)}
    envs: dict[str, None] = {}
    for pid in table.player_a.tolist():
        e = env_of.get(int(pid))
        if e is not None:
            envs.setdefault(e, None)
    return list(envs)


def _pick_env(league: League, env: str | None) -> str:
    if env is not None:
        return env
    envs = _envs_in_order(league)
    if not envs:
        raise LeagueError("the league has no games yet: play some first (marl match / marl tournament)")
    if len(envs) > 1:
        raise LeagueError(f"several envs in the league ({', '.join(envs)}): pass --env")
    return envs[0]


def _default_anchor(population: list[PlayerRow], games: dict[int, int]) -> PlayerRow:
    """``random`` bot if it played, else the first bot (by id) that played, else the most active player."""
    bots = [p for p in population if p.is_bot]
    for p in bots:
        if p.name == "random":
            return p
    if bots:
        return bots[0]
    live = [p for p in population if not p.removed] or population
    return max(live, key=lambda p: (games[p.id], -p.id))


def ladder(
    league: League,
    env: str | None = None,
    anchor: str | None = None,
    anchor_rating: float = 1000.0,
    bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    include_removed: bool = False,
) -> list[LadderRow]:
    """The ladder of ``env``: a :func:`fit_table` over all 2-seat games of that env in the ledger.

    ``env=None`` uses the ledger's only env (LeagueError if it has several, or no games at all); an env
    without games gives an empty list. Only players with games appear. The default anchor is the env's
    ``random`` bot if it played, else the first bot (lowest id) that played, else the (non-removed) player
    with the most games; ``anchor`` may name any player (resolved with :func:`names.resolve`) that has games
    in the env. Removed snapshots are fitted (their games count) but left out of the result unless
    ``include_removed``; ranks are then recomputed among the rows shown.
    """
    env = _pick_env(league, env)
    table = league.games(env=env)
    if len(table) == 0:
        return []
    ids, a, b = table.indexed()
    known = {p.id: p for p in league.players(env=env, include_removed=True)}
    population = [known[int(i)] if int(i) in known else league.get_player(int(i)) for i in ids.tolist()]
    games = dict(zip(ids.tolist(), (np.bincount(a, minlength=ids.size) + np.bincount(b, minlength=ids.size))
                     .tolist(), strict=True))
    if anchor is None:
        anchor_player = _default_anchor(population, games)
    else:
        from selfplay_cli.league.names import resolve

        anchor_player = resolve(league, anchor, env)
        if anchor_player.id not in games:
            raise LeagueError(f"anchor '{anchor}' ({anchor_player.full_name}) has no games in {env}")
    names = [p.full_name for p in population]
    rows = fit_table(
        names, a, b, table.score_a, anchor=anchor_player.full_name, anchor_rating=anchor_rating,
        bootstrap=bootstrap, confidence=confidence, seed=seed,
        kinds={p.full_name: p.kind for p in population},
        steps={p.full_name: p.step for p in population if not p.is_bot},
        player_ids={p.full_name: p.id for p in population},
    )
    removed = {p.id for p in population if p.removed}
    if include_removed or not removed:
        return rows
    return _rerank([r for r in rows if r.player_id not in removed])


# --------------------------------------------------------------------------------------------------
# Results CSV
# --------------------------------------------------------------------------------------------------


def _parse_result(text: str) -> float | None:
    t = text.strip()
    if t == "1/2":
        return 0.5
    try:
        v = float(t)
    except ValueError:
        return None
    return v if v in (0.0, 0.5, 1.0) else None


def read_results_csv(path: str | Path) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Read a results file ``player_a,player_b,result`` (result: A's points, ``1``, ``0.5`` or ``0``).

    The first non-blank, non-comment line must be exactly the header (spaces around names tolerated);
    blank lines and lines starting with ``#`` are skipped; fields may be quoted (CSV rules).

    Returns:
        ``(names, a, b, score_a)``: names in order of first appearance, the index arrays of each game's
        players and A's points.

    Raises:
        LeagueError: ``"<path>:<line>: <problem>"`` for a bad header, a wrong number of fields, an empty
            name, a player against itself or a bad result; also for an unreadable or empty file.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise LeagueError(f"cannot read {path}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise LeagueError(f"cannot read {path}: not UTF-8 text") from exc
    index: dict[str, int] = {}
    a: list[int] = []
    b: list[int] = []
    s: list[float] = []
    header_seen = False
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        try:
            fields = [f.strip() for f in next(csv.reader([stripped], skipinitialspace=True))]
        except csv.Error as exc:
            raise LeagueError(f"{path}:{lineno}: malformed CSV line ({exc})") from exc
        if not header_seen:
            if tuple(fields) != CSV_HEADER:
                raise LeagueError(f"{path}:{lineno}: bad header {stripped!r}: expected {','.join(CSV_HEADER)}")
            header_seen = True
            continue
        if len(fields) != 3:
            raise LeagueError(f"{path}:{lineno}: expected 3 fields (player_a,player_b,result), got {len(fields)}")
        pa, pb, res = fields
        if not pa or not pb:
            raise LeagueError(f"{path}:{lineno}: empty player name")
        if pa == pb:
            raise LeagueError(f"{path}:{lineno}: '{pa}' cannot play against itself")
        value = _parse_result(res)
        if value is None:
            raise LeagueError(f"{path}:{lineno}: bad result {res!r}: expected 1, 0.5 or 0 (player_a's points)")
        a.append(index.setdefault(pa, len(index)))
        b.append(index.setdefault(pb, len(index)))
        s.append(value)
    if not header_seen:
        raise LeagueError(f"{path}: empty file (expected the header {','.join(CSV_HEADER)} and one game a line)")
    if not a:
        raise LeagueError(f"{path}: no games after the header")
    return (list(index), np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64),
            np.asarray(s, dtype=np.float64))


def fit_csv(
    path: str | Path,
    anchor: str | None = None,
    anchor_rating: float = 1000.0,
    bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
) -> list[LadderRow]:
    """Ladder of a results CSV (:func:`read_results_csv`); the default anchor is the file's first player.

    Rows have kind ``"player"`` and no id / step.
    """
    names, a, b, s = read_results_csv(path)
    return fit_table(names, a, b, s, anchor=names[0] if anchor is None else anchor, anchor_rating=anchor_rating,
                     bootstrap=bootstrap, confidence=confidence, seed=seed)


# --------------------------------------------------------------------------------------------------
# Tournament planning and head-to-head
# --------------------------------------------------------------------------------------------------


@dataclass
class PairPlan:
    """One pair of a tournament: games already in the ledger (either seat order) and games still missing."""

    a_id: int
    b_id: int
    existing: int
    missing: int


def plan_tournament(
    league: League, env: str, player_ids: list[int], games_per_pair: int, vs: int | None = None
) -> list[PairPlan]:
    """Games still needed so that every pair has ``games_per_pair`` games in ``env``.

    Pairs: every unordered pair of ``player_ids`` (round robin, in list order), or with ``vs`` each player
    against ``vs`` only (gauntlet; ``a_id`` is the player, ``b_id`` is ``vs``). Existing games of a pair
    count in both seat orders. Pairs with nothing missing are left out.

    Raises:
        LeagueError: unknown player or one of another env, fewer than two players, negative games_per_pair.
    """
    if games_per_pair < 0:
        raise LeagueError(f"games per pair must be >= 0, got {games_per_pair}")
    ids = list(dict.fromkeys(int(p) for p in player_ids))
    check = ids + ([int(vs)] if vs is not None and int(vs) not in ids else [])
    for pid in check:
        p = league.get_player(pid)
        if p.env != env:
            raise LeagueError(f"player {pid} ({p.full_name}) belongs to env {p.env}, not {env}")
    if vs is not None:
        vs = int(vs)
        pairs = [(p, vs) for p in ids if p != vs]
        if not pairs:
            raise LeagueError("a gauntlet needs at least one player besides the opponent")
    else:
        if len(ids) < 2:
            raise LeagueError("a round robin needs at least two players")
        pairs = [(ids[i], ids[j]) for i in range(len(ids)) for j in range(i + 1, len(ids))]
    table = league.games(env=env, players=check)
    counts: dict[tuple[int, int], int] = defaultdict(int)
    for x, y in zip(table.player_a.tolist(), table.player_b.tolist(), strict=True):
        counts[(min(x, y), max(x, y))] += 1
    plan = []
    for x, y in pairs:
        have = counts.get((min(x, y), max(x, y)), 0)
        missing = max(games_per_pair - have, 0)
        if missing > 0:
            plan.append(PairPlan(a_id=x, b_id=y, existing=have, missing=missing))
    return plan


def head_to_head(league: League, a_id: int, b_id: int) -> dict[str, Any]:
    """Record of player ``a_id`` against ``b_id`` over all stored 2-seat games.

    Returns a dict with ``a_id, b_id, games, wins, draws, losses, score`` (A's mean points, 0.5 without
    games), ``pentanomial`` and ``pairs``, ``unpaired``. Game pairs: within one match, games with the same
    seed, one with A in seat 0 and one with A in seat 1 (matched in game-id order). A pair's score is A's
    points in both games; ``pentanomial`` counts pairs scoring ``0, 0.5, 1, 1.5, 2``, i.e.
    ``[LL, LD, WL+DD, WD, WW]`` as :func:`~selfplay_cli.stats.sprt.sprt_llr` expects. Unpaired games
    count in W/D/L only.
    """
    a_id, b_id = int(a_id), int(b_id)
    if a_id == b_id:
        raise LeagueError(f"player {a_id} cannot be paired with itself")
    league.get_player(a_id)
    league.get_player(b_id)
    table = league.games(players=[a_id, b_id])
    seat0 = table.player_a == a_id
    pts = np.where(seat0, table.score_a, 1.0 - table.score_a)
    wins, draws, losses = int(np.sum(pts > 0.5)), int(np.sum(pts == 0.5)), int(np.sum(pts < 0.5))
    groups: dict[tuple[int, int], tuple[list[float], list[float]]] = defaultdict(lambda: ([], []))
    for m, sd, first, p in zip(table.match_id.tolist(), table.seed.tolist(), seat0.tolist(), pts.tolist(),
                               strict=True):
        groups[(m, sd)][0 if first else 1].append(p)
    penta = [0, 0, 0, 0, 0]
    pairs = 0
    for as_first, as_second in groups.values():
        for p1, p2 in zip(as_first, as_second, strict=False):
            penta[min(max(int(round(2 * (p1 + p2))), 0), 4)] += 1
            pairs += 1
    n = len(table)
    return {
        "a_id": a_id,
        "b_id": b_id,
        "games": n,
        "wins": wins,
        "draws": draws,
        "losses": losses,
        "score": float(pts.mean()) if n else 0.5,
        "pentanomial": penta,
        "pairs": pairs,
        "unpaired": n - 2 * pairs,
    }
