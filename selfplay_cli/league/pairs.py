"""Two players at a time: their record from the ledger (with game pairs), and the games a tournament still needs."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np

from selfplay_cli.league.store import League, LeagueError

__all__ = ["PairPlan", "head_to_head", "plan_tournament"]


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
