"""Two players at a time: their record from the ledger (with game pairs), the games a tournament still needs, and
the records and payoffs of every pair of a set of players (the score matrix, the Nash meta-game).

All read the ledger's pairwise results (:meth:`~selfplay_cli.league.ledger.Ledger.games`), so they work for every
kind of game: a two-sides game is one result, a cooperative comparison (two episodes on one seed) one, a
free-for-all game one per two players in it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.store import KIND_CODES, GameTable, League, LeagueError
from selfplay_cli.results import TWO_SIDES

__all__ = ["PAYOFFS", "PairPlan", "design_effect", "head_to_head", "pair_payoffs", "pair_records", "plan_tournament"]


@dataclass
class PairPlan:
    """One pair of a tournament: games already in the ledger (either seat order) and games still missing;
    ``meets`` False for a pair that cannot play (nothing missing, nothing to play)."""

    a_id: int
    b_id: int
    existing: int
    missing: int
    meets: bool = True


def plan_tournament(
    league: League, env: str, player_ids: list[int], games_per_pair: int, vs: int | None = None, variant: str = "",
    meets: Callable[[int, int], bool] | None = None,
) -> list[PairPlan]:
    """Games still needed so that every pair has ``games_per_pair`` games in ``env``, in its ``variant`` (the
    default unless given: games under other options count in their own variant only).

    Pairs: every unordered pair of ``player_ids`` (round robin, in list order), or with ``vs`` each player
    against ``vs`` only (gauntlet; ``a_id`` is the player, ``b_id`` is ``vs``). Existing games of a pair
    count in both seat orders (a cooperative comparison as its two episodes). Pairs with nothing missing are left
    out. ``meets(a, b)``: whether two players can play each other (in a game whose seats hold different roles,
    two snapshots of one role cannot); a pair that cannot is listed with ``meets=False`` and nothing missing.

    Raises:
        LeagueError: unknown player or one of another env, fewer than two players, negative games_per_pair.
    """
    if games_per_pair < 0:
        raise LeagueError(f"games per pair must be >= 0, got {games_per_pair}")
    ids = list(dict.fromkeys(int(p) for p in player_ids))
    check = ids + ([int(vs)] if vs is not None and int(vs) not in ids else [])
    for pid in check:
        p = league.roster.get_player(pid)
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
    same = league.ledger.same_weights(env)  # names of one set of weights: one player, whose games count under each
    unique: dict[frozenset[int], tuple[int, int]] = {}
    for x, y in pairs:
        if same.get(x, x) != same.get(y, y):
            unique.setdefault(frozenset((same.get(x, x), same.get(y, y))), (x, y))
    pairs = list(unique.values())
    table = league.ledger.games(env=env, players=check, variant=variant, pooled=same)
    counts: dict[tuple[int, int], int] = defaultdict(int)
    weight = np.where(table.kind == KIND_CODES["cooperative"], 2, 1).tolist()  # a comparison: two episodes
    for x, y, w in zip(table.player_a.tolist(), table.player_b.tolist(), weight, strict=True):
        counts[(min(x, y), max(x, y))] += w
    plan = []
    for x, y in pairs:
        if meets is not None and not meets(x, y):
            plan.append(PairPlan(a_id=x, b_id=y, existing=0, missing=0, meets=False))
            continue
        sx, sy = same.get(x, x), same.get(y, y)
        have = counts.get((min(sx, sy), max(sx, sy)), 0)
        missing = max(games_per_pair - have, 0)
        if missing > 0:
            plan.append(PairPlan(a_id=x, b_id=y, existing=have, missing=missing))
    return plan


def head_to_head(league: League, a_id: int, b_id: int, variant: str = "") -> dict[str, Any]:
    """Record of player ``a_id`` against ``b_id`` over their stored pairwise results in ``variant`` (the default
    unless given; training games left out, as in every rating).

    Returns a dict with ``a_id, b_id, games, results, wins, draws, losses, score`` (A's mean points, 0.5 without
    results), ``pentanomial`` and ``pairs``, ``unpaired``, and ``rounds``: A's points in each pair, then in each
    result outside a pair (what a game played for stakes, whose results are worth any points, is measured from).
    ``games`` counts the ledger's games (a cooperative comparison is two episodes), ``results`` the pairwise results
    W + D + L. Game pairs (two-sides games only): within one match, games with the same seed, one with A on the first
    side and one with A on the second (matched in game-id order). A pair's score is A's points in both games;
    ``pentanomial`` counts pairs scoring ``0, 0.5, 1, 1.5, 2``, i.e. ``[LL, LD, WL+DD, WD, WW]`` as
    :func:`~selfplay_cli.stats.sprt.sprt_llr` expects. Results outside pairs (cooperative comparisons, free-for-all
    results, unpaired games) count in W/D/L only.
    """
    a_id, b_id = int(a_id), int(b_id)
    if a_id == b_id:
        raise LeagueError(f"player {a_id} cannot be paired with itself")
    league.roster.get_player(a_id)
    league.roster.get_player(b_id)
    same = league.ledger.same_weights()  # a name of weights another snapshot holds: its games are the player's
    if same.get(a_id, a_id) == same.get(b_id, b_id):
        raise LeagueError(f"players {a_id} and {b_id} hold the same weights: one player, no record against itself")
    table = league.ledger.games(players=[a_id, b_id], variant=variant,
                                pooled=same)  # (filed under each one's first name)
    pts, rounds, penta, pairs = rounds_of(table, same.get(a_id, a_id))
    wins, draws, losses = int(np.sum(pts > 0.5)), int(np.sum(pts == 0.5)), int(np.sum(pts < 0.5))
    n = len(table)
    return {
        "a_id": a_id,
        "b_id": b_id,
        "games": table.games_played(),
        "results": n,
        "wins": wins,
        "draws": draws,
        "losses": losses,
        "score": float(pts.mean()) if n else 0.5,
        "pentanomial": penta,
        "pairs": pairs,
        "unpaired": n - 2 * pairs,
        "rounds": rounds,
    }


def design_effect(table: GameTable) -> float:
    """How many independent results one result of the ledger is worth, inverted: ``1 + (m - 1) rho``, Kish's design
    effect of results played in rounds (a seat-swapped pair on one seed, a free-for-all's rotations), with ``m`` the
    mean size of a round and ``rho`` the correlation of the results within a round, pooled over every pair of
    players (each result taken from its pair's mean; clipped to [0, 1)). Two games of one seed share its serve, its
    deal, its terrain: where a policy that wins one wins the other, 200 games say what 100 independent ones would, and
    every claim read from them as independent would be too sure. 1 where nothing is played in rounds (a cooperative
    comparison is one result of its seed) or the rounds show no such correlation."""
    if not len(table):
        return 1.0
    lo = np.minimum(table.player_a, table.player_b)
    hi = np.maximum(table.player_a, table.player_b)
    x = np.where(table.player_a == lo, table.score_a, 1.0 - table.score_a)  # the lower id's points
    pair = lo * (int(hi.max()) + 1) + hi
    _, pair_ix = np.unique(pair, return_inverse=True)
    mean = np.bincount(pair_ix, weights=x) / np.bincount(pair_ix)
    dev = x - mean[pair_ix]
    _, round_ix = np.unique(np.stack([pair, table.match_id, table.seed]), axis=1, return_inverse=True)
    round_ix = round_ix.ravel()
    size = np.bincount(round_ix)
    total = np.bincount(round_ix, weights=dev)
    squares = np.bincount(round_ix, weights=dev * dev)
    within = float(np.sum(total**2 - squares))  # sum over each round of its cross products, both orders
    var = float(np.sum(squares))
    pairs_in_rounds = float(np.sum(size * (size - 1)))
    if var <= 0.0 or pairs_in_rounds <= 0.0:
        return 1.0
    rho = (within / pairs_in_rounds) / (var / len(table))
    m = float(np.sum(size * size) / np.sum(size))  # the mean round size a result sits in
    return 1.0 + (m - 1.0) * min(max(rho, 0.0), 0.99)


def rounds_of(table: GameTable, a: int) -> tuple[np.ndarray, list[list[float]], list[int], int]:
    """Player ``a``'s results in ``table`` (every row one of its pairwise results): its points in each, then its
    rounds as :func:`head_to_head` counts them (game pairs of a two-sides game: within one match, the games of one
    seed with ``a`` on the first side and on the second, matched in game-id order; every other result a round of its
    own), their pentanomial counts and the number of pairs. ``(points, rounds, pentanomial, pairs)``."""
    first_side = table.player_a == a
    pts = np.where(first_side, table.score_a, 1.0 - table.score_a)
    groups: dict[tuple[int, int], tuple[list[float], list[float]]] = defaultdict(lambda: ([], []))
    two_sides = table.kind == KIND_CODES[TWO_SIDES]
    for m, sd, first, p, paired in zip(table.match_id.tolist(), table.seed.tolist(), first_side.tolist(),
                                       pts.tolist(), two_sides.tolist(), strict=True):
        if paired:
            groups[(m, sd)][0 if first else 1].append(p)
    penta = [0, 0, 0, 0, 0]
    pairs = 0
    rounds: list[list[float]] = []
    for as_first, as_second in groups.values():
        for p1, p2 in zip(as_first, as_second, strict=False):
            penta[min(max(int(round(2 * (p1 + p2))), 0), 4)] += 1
            pairs += 1
            rounds.append([p1, p2])
        k = min(len(as_first), len(as_second))
        rounds += [[p] for p in as_first[k:] + as_second[k:]]
    rounds += [[p] for p, paired in zip(pts.tolist(), two_sides.tolist(), strict=True) if not paired]
    return pts, rounds, penta, pairs


def pair_records(table: GameTable, ids: list[int]) -> tuple[npt.NDArray[np.int64], ...]:
    """W/D/L and sign-test units of every pair of ``ids`` from ``table`` (games with both players in ``ids``).

    Returns ``(games, wins, draws, losses, unit_wins)``, each ``n x n`` from the row player's side. Units: within
    one match, games of the same seed with the seats swapped are paired in game-id order (as
    :func:`~selfplay_cli.ratings.pairs.head_to_head` pairs them); a pair is won by the player with more than half of
    its two games' points, level pairs count for no one; a game without a partner is a unit of its own, and so is every
    result of a cooperative or free-for-all game (they come in no seat-swapped pairs).
    """
    n = len(ids)
    index = {int(pid): k for k, pid in enumerate(ids)}
    games = np.zeros((n, n), dtype=np.int64)
    wins = np.zeros((n, n), dtype=np.int64)
    draws = np.zeros((n, n), dtype=np.int64)
    units = np.zeros((n, n), dtype=np.int64)
    # (match, seed, lo, hi) -> lo's points in the games with lo on seat 0, and with lo on seat 1
    groups: dict[tuple[int, int, int, int], tuple[list[float], list[float]]] = {}
    single: list[tuple[int, int, float]] = []  # results that pair with none (cooperative, free-for-all): units
    for m, sd, pa, pb, sa, kind in zip(table.match_id.tolist(), table.seed.tolist(), table.player_a.tolist(),
                                       table.player_b.tolist(), table.score_a.tolist(), table.kind.tolist(),
                                       strict=True):
        i, j = index.get(pa), index.get(pb)
        if i is None or j is None or i == j:
            continue
        games[i, j] += 1
        games[j, i] += 1
        if sa > 0.5:
            wins[i, j] += 1
        elif sa < 0.5:
            wins[j, i] += 1
        else:
            draws[i, j] += 1
            draws[j, i] += 1
        lo, hi = min(i, j), max(i, j)
        pts = sa if i == lo else 1.0 - sa
        if kind != 0:
            single.append((lo, hi, pts))
            continue
        groups.setdefault((m, sd, lo, hi), ([], []))[0 if i == lo else 1].append(pts)
    for (_m, _sd, lo, hi), (first, second) in groups.items():
        k = min(len(first), len(second))
        for total in [p + q for p, q in zip(first[:k], second[:k], strict=True)]:
            if total > 1.0:
                units[lo, hi] += 1
            elif total < 1.0:
                units[hi, lo] += 1
        for p in first[k:] + second[k:]:
            if p > 0.5:
                units[lo, hi] += 1
            elif p < 0.5:
                units[hi, lo] += 1
    for lo, hi, p in single:
        if p > 0.5:
            units[lo, hi] += 1
        elif p < 0.5:
            units[hi, lo] += 1
    losses = wins.T.copy()
    return games, wins, draws, losses, units


PAYOFFS = ("points", "score")
"""Units of a meta-game's payoff (:func:`pair_payoffs`): ``points`` (win 1, draw 1/2, loss 0: the result, whatever
the margin) or ``score`` (the game's own scores: chips, goals, returns)."""


def pair_payoffs(table: GameTable, ids: list[int], payoff: str = "points",
                 records: tuple[npt.NDArray[np.int64], ...] | None = None) -> npt.NDArray[np.float64]:
    """The row player's mean payoff against the column player over the results of ``table`` between ``ids``, an
    antisymmetric ``n x n`` matrix (0 on the diagonal and for a pair without results): the symmetric zero-sum
    meta-game :func:`~selfplay_cli.stats.nash.symmetric_nash` solves.

    ``points``: mean points minus one half, ``(W + D/2) / G - 1/2``. ``score``: the mean of half the row player's
    score minus the column player's (:attr:`GameTable.margin_a`), which in a zero-sum game of two seats (Kuhn and Leduc
    poker's chips) is the row player's expected return, PSRO's meta-game payoff; in other games the half-margin
    keeps the matrix antisymmetric (the row player's gain is the column player's loss). ``records``: what
    :func:`pair_records` gave for ``table`` and ``ids``, where the caller has it (``points`` is read from it, not
    from the table again).

    Raises:
        LeagueError: an unknown ``payoff``; ``score`` for results stored without scores.
    """
    if payoff not in PAYOFFS:
        raise LeagueError(f"unknown payoff {payoff!r} (expected one of {', '.join(PAYOFFS)})")
    if payoff == "points":
        games, wins, draws, _, _ = records if records is not None else pair_records(table, ids)
        out = np.where(games > 0, (wins + 0.5 * draws) / np.maximum(games, 1), 0.5) - 0.5
        np.fill_diagonal(out, 0.0)
        return out
    n = len(ids)
    index = {int(pid): k for k, pid in enumerate(ids)}
    total = np.zeros((n, n))
    count = np.zeros((n, n))
    for pa, pb, margin in zip(table.player_a.tolist(), table.player_b.tolist(), table.margin_a.tolist(), strict=True):
        i, j = index.get(pa), index.get(pb)
        if i is None or j is None or i == j:
            continue
        if not np.isfinite(margin):
            raise LeagueError("a result without scores: the payoff in score units needs each seat's score")
        total[i, j] += margin
        total[j, i] -= margin
        count[i, j] += 1
        count[j, i] += 1
    return np.where(count > 0, total / np.maximum(count, 1), 0.0)
