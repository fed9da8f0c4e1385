"""`marl match` on games cut short (truncated): a match whose games all or mostly ended at the cut says so in its
headline, with what such a game counts as, whatever the game's kind; a few truncated games get a line below; --json
carries the count and the step limit."""

from __future__ import annotations

from contextlib import contextmanager

from arena_games import FFACore, _const, _spec, registered
from cli_helpers import run, run_json
from gymnasium import spaces

from selfplay_cli.envs import register
from selfplay_cli.envs.loading import _REGISTRY

TWO_SIDES_RULE = "each truncated game is decided by the score at the cut: the side ahead wins it, level is a draw"


def test_a_pong_match_whose_every_game_was_cut_says_so_in_its_headline(capsys, home):
    """max_steps=60: a point needs a touch and then the ball across the court (~760 px at 10 px a step, 76 steps and
    more), so every game is 0-0 at the cut, and each is a draw: 0 W 4 D 0 L."""
    args = ("match", "cpu", "random", "--env", "pong", "--games", "4", "--seed", "0", "--env-option", "max_steps=60",
            "--no-store")
    code, out, err = run(capsys, *args)
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("pong: cpu vs random, 4 games in 2 seat-swapped pairs, all 4 truncated (cut "
                               "unfinished; step limit 60), "), lines[0]
    assert lines[1].strip() == TWO_SIDES_RULE
    assert "cpu: 0 W  4 D  0 L of 4 games" in lines[2]
    assert "truncated games" not in out  # said once, at the top
    data = run_json(capsys, *args)
    assert (data["truncated_games"], data["step_limit"], data["draws"], data["points_for"]) == (4, 60, 4, 0)
    assert data["game_steps"] == 4 * 60  # every game to its limit


def test_mostly_truncated_goes_in_the_headline_a_few_in_a_line_below(capsys, home):
    """points_to_win=1: a finished game is 1-0, so a draw is exactly a game cut at 0-0. With max_steps=150 most of 8
    games are cut (the headline says how many), with 200 a few (a line below the pairs says so, with the rule)."""
    for max_steps, mostly in ((150, True), (200, False)):
        args = ("match", "cpu", "random", "--env", "pong", "--games", "8", "--seed", "0", "--env-option",
                "points_to_win=1", "--env-option", f"max_steps={max_steps}", "--no-store")
        data = run_json(capsys, *args)
        cut = data["truncated_games"]
        assert cut == data["draws"] and data["step_limit"] == max_steps
        assert (cut * 2 > 8) is mostly and cut > 0, cut
        code, out, err = run(capsys, *args)
        assert code == 0, err
        lines = out.splitlines()
        said = f"{cut} of 8 truncated (cut unfinished; step limit {max_steps})"
        if mostly:
            assert said in lines[0] and lines[1].strip() == TWO_SIDES_RULE
        else:
            assert "truncated" not in lines[0]
            line = next(ln for ln in lines if "of 8 games truncated" in ln)
            assert line.strip() == f"{cut} of 8 games truncated (cut unfinished; step limit {max_steps}); " \
                + TWO_SIDES_RULE


def test_a_cooperative_match_of_truncated_episodes_says_what_a_comparison_of_them_is(capsys, home):
    """The lander cut at 20 steps (nobody lands in 20 steps): every episode truncated, its team return summed to the
    cut; arena-coop2 cuts itself after 5 steps without declaring a limit, and draws within 0.5."""
    code, out, err = run(capsys, "match", "heuristic", "random", "--env", "lander", "--games", "6", "--seed", "0",
                         "--env-option", "max_steps=20", "--no-store")
    assert code == 0, err
    lines = out.splitlines()
    assert "3 comparisons of team returns" in lines[0] and "all 6 truncated (cut unfinished; step limit 20)" in lines[0]
    assert lines[1].strip() == ("a truncated episode's team return is what it scored up to the cut, compared like any "
                                "other: the higher wins, level is a draw")
    with registered():
        code, out, err = run(capsys, "match", "high", "low", "--env", "arena-coop2", "--games", "6", "--no-store")
        assert code == 0, err
        lines = out.splitlines()
        assert "all 6 truncated (cut unfinished)," in lines[0], lines[0]
        assert lines[1].strip().endswith("the higher wins, within 0.5 is a draw")
        assert "high: 3 W  0 D  0 L of 3 comparisons" in out  # returns 10 (1 + 1) = 20 against 10 (-1 + 0) = -10
        data = run_json(capsys, "match", "high", "low", "--env", "arena-coop2", "--games", "6", "--no-store")
        assert data["truncated_games"] == 6 and data["step_limit"] is None


class _CutFFA(FFACore):
    """arena-ffa3's game, ended by a cut after its 4 steps (truncated) instead of finishing."""

    def step(self, actions):
        rewards = super().step(actions)
        self.truncated |= self.terminated
        self.terminated[:] = False
        return rewards


@contextmanager
def _ffa_cut():
    register(_spec("arena-ffa3-cut", _CutFFA, 3, 2, spaces.MultiDiscrete([3, 2]),
                   {"high": _const((2, 1)), "low": _const((0, 0))}, kind="free-for-all", time_limit=lambda cfg: 4))
    try:
        yield
    finally:
        _REGISTRY.pop("arena-ffa3-cut", None)


def test_a_free_for_all_match_of_truncated_games_says_they_are_ordered_at_the_cut(capsys, home):
    """high plays (2, 1) and scores 6 (2 + 3 * 1) = 30 a game, low 0: high is ahead at every cut, 6 W of 6."""
    with _ffa_cut():
        code, out, err = run(capsys, "match", "high", "low", "--env", "arena-ffa3-cut", "--games", "6", "--no-store")
        assert code == 0, err
        lines = out.splitlines()
        assert "every rotation of the seating" in lines[0] and "all 6 truncated (cut unfinished; step limit 4)" \
            in lines[0], lines[0]
        assert lines[1].strip() == ("each truncated game is ordered by the scores at the cut: the higher beats the "
                                    "lower, level is a draw")
        assert "high: 6 W  0 D  0 L of 6 games" in out
