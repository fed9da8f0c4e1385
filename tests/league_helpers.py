"""Leagues written by hand for the tests: games chosen so that every figure a test reads can be computed by hand."""

from __future__ import annotations

from typing import Any

from selfplay_cli.results import GameResult


def record_plan(lg: Any, ids: dict[str, int], plan: list[tuple[str, str, int, int]], env: str = "pong") -> None:
    """Record, as one match of ``env``, ``(x, y, wins, losses)`` games of each pair of the plan: x's wins, then its
    losses, seats alternating over the whole plan (x on seat 0 in even games), each win 21 to 0."""
    games, k = [], 0
    for x, y, wins, losses in plan:
        for score in [1.0] * wins + [0.0] * losses:
            a, b, sa = (ids[x], ids[y], score) if k % 2 == 0 else (ids[y], ids[x], 1.0 - score)
            games.append(GameResult(env=env, players=(a, b), seed=k, scores=(sa * 21, (1 - sa) * 21),
                                    outcome=(sa, 1.0 - sa), length=100, truncated=False))
            k += 1
    lg.ledger.record_games(lg.ledger.create_match(env, "match"), games)
