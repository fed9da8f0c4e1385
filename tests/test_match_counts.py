"""`marl match` says what its W/D/L count: games (two sides, in seat-swapped pairs; free-for-all, a result a game) or
comparisons of team returns (cooperative: two episodes each), in the text and in the JSON."""

from __future__ import annotations

import json

from arena_games import registered
from cli_helpers import run


def test_a_cooperative_match_counts_comparisons_not_games(capsys, home):
    code, out, err = run(capsys, "match", "heuristic", "random", "--env", "lander", "--games", "6", "--no-store")
    assert code == 0, err
    assert "lander: heuristic vs random, 6 games: 3 comparisons of team returns on shared seeds" in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("heuristic:"))
    w, d, lo = (int(x) for x in line.split()[1:6:2])
    assert w + d + lo == 3 and "L of 3 comparisons" in line
    data = json.loads(run(capsys, "match", "heuristic", "random", "--env", "lander", "--games", "6", "--no-store",
                          "--json")[1])
    assert data["games"] == 6 and data["results"] == 3 == data["wins"] + data["draws"] + data["losses"]
    assert data["result_unit"] == "comparison"


def test_two_sides_and_free_for_all_matches_count_games(capsys, home):
    data = json.loads(run(capsys, "match", "cpu", "random", "--env", "pong", "--games", "4", "--env-option",
                          "points_to_win=1", "--no-store", "--json")[1])
    assert data["results"] == data["games"] == 4 and data["result_unit"] == "game"
    code, out, err = run(capsys, "match", "cpu", "random", "--env", "pong", "--games", "4", "--env-option",
                         "points_to_win=1", "--no-store")
    assert "4 games in 2 seat-swapped pairs" in out and "L of 4 games" in out
    with registered():
        code, out, err = run(capsys, "match", "high", "low", "--env", "arena-ffa3", "--games", "6", "--no-store")
        assert code == 0, err
        assert "6 games, every rotation of the seating on each seed (a result a game" in out and "pairs" not in out
        assert "high: 6 W  0 D  0 L of 6 games" in out
        data = json.loads(run(capsys, "match", "high", "low", "--env", "arena-ffa3", "--games", "6", "--no-store",
                              "--json")[1])
        assert data["results"] == data["games"] == 6 and data["result_unit"] == "game"
