"""Ranks, rows and tiers from claims about pairs (selfplay_cli.stats.ranks), by hand."""

from __future__ import annotations

import numpy as np

from selfplay_cli.stats.ranks import claims_order, tiers


def _above(m: int, claims: list[tuple[int, int]]) -> np.ndarray:
    out = np.zeros((m, m), dtype=bool)
    for a, b in claims:
        out[a, b] = True
    return out


def test_nobody_stands_over_a_player_that_is_above_it_beyond_doubt():
    """Ratings 2211, 2200, 2100, 1800; claims: 1 above 0 (head to head), 2 above 1, and 0, 1, 2 each above 3. Ranks:
    0 and 1 have one player above them (2), 2 none (1), 3 three (4). By rank, then rating, 0 would stand over 1,
    which is above it beyond doubt: the rows go 2, 1, 0, 3 instead. The one tier boundary falls over 3, above which
    everyone is above it."""
    above = _above(4, [(1, 0), (2, 1), (0, 3), (1, 3), (2, 3)])
    order, ranks, circles = claims_order(above, [2211.0, 2200.0, 2100.0, 1800.0])
    assert ranks == [2, 2, 1, 4] and order == [2, 1, 0, 3] and circles == {}
    assert tiers(above, order) == [1, 1, 1, 2]


def test_without_claims_the_rows_go_by_rating_and_a_circle_stands_together_and_is_said():
    """No claims: by rating. A circle beyond doubt (0 above 1 above 2 above 0: rock, paper, scissors, measured) and
    2 above 3: no order keeps every claim of the circle, so its players stand together by rating, over 3 (every claim
    between the circle and 3 is kept), each with a shortest circle through it; no tier boundary inside the circle."""
    order, ranks, circles = claims_order(np.zeros((3, 3), dtype=bool), [1.0, 3.0, 2.0])
    assert order == [1, 2, 0] and ranks == [1, 1, 1] and circles == {}
    circle = _above(4, [(0, 1), (1, 2), (2, 0), (2, 3)])
    order, ranks, circles = claims_order(circle, [1100.0, 1000.0, 1200.0, 1500.0])
    assert ranks == [2, 2, 2, 2] and order == [2, 0, 1, 3]  # 3, rated highest, is below 2 beyond doubt
    assert circles == {0: (0, 1, 2), 1: (1, 2, 0), 2: (2, 0, 1)}
    assert tiers(circle, order) == [1, 1, 1, 1]
    chain = _above(3, [(0, 1), (0, 2), (1, 2)])
    assert tiers(chain, claims_order(chain, [3.0, 2.0, 1.0])[0]) == [1, 2, 3]
    # two circles, one above the other (every claim across them kept): 0-1 go round, 2-3 go round, 1 above 2
    two = _above(4, [(0, 1), (1, 0), (2, 3), (3, 2), (1, 2)])
    assert claims_order(two, [1.0, 2.0, 3.0, 4.0])[0] == [1, 0, 3, 2]
