"""Team size by option for any game, and the kind of a game that does not declare one (issue 36).

PettingZoo's pursuit (SISL) changes its agents with ``n_pursuers`` and does not say that its pursuers are one team:
``marl train --kind cooperative`` makes them one, and a team trained with 3 pursuers flies 2 and 5 through
``--env-option n_pursuers=M``, a team of distinct networks seated by seed 001's rule (``resize_team``)."""

from __future__ import annotations

import pytest
from cli_helpers import run, run_json

from selfplay_cli.envs import get_env
from selfplay_cli.league.store import League
from selfplay_cli.policies.resize import describe_resize, resize_members

PURSUIT = "pettingzoo.sisl.pursuit_v5"


def resize_team(have: int, want: int, seed: int) -> tuple[int, ...]:
    return tuple(resize_members(have, want, seed))


SMALL = ["--env-option", "max_cycles=20", "--env-option", "x_size=8", "--env-option", "y_size=8",
         "--env-option", "n_evaders=4"]


def test_seed_001s_rule_keeps_the_first_two_and_draws_from_the_third_on():
    assert resize_team(4, 4, seed=0) == (0, 1, 2, 3)
    for seed in range(20):
        grown = resize_team(3, 5, seed)
        assert grown[:3] == (0, 1, 2) and grown[3:] == (2, 2)  # copies of the third, the only one from it on
        five = resize_team(5, 8, seed)
        assert five[:5] == (0, 1, 2, 3, 4) and set(five[5:]) <= {2, 3, 4}  # never a copy of the first two
        shrunk = resize_team(5, 3, seed)
        assert shrunk[:2] == (0, 1) and shrunk[2] in (2, 3, 4)  # the first two stay; one of the rest stays
        assert resize_team(4, 3, seed)[:2] == (0, 1) and list(resize_team(6, 4, seed)) == sorted(resize_team(6, 4,
                                                                                                         seed))
    assert len({resize_team(6, 4, seed) for seed in range(20)}) > 1  # the dropped ones are drawn
    assert resize_team(6, 4, seed=7) == resize_team(6, 4, seed=7)  # and the draw repeats
    assert resize_team(5, 2, 0) == (0, 1) and resize_team(5, 1, 0) == (0,)
    assert set(resize_team(2, 4, 0)[2:]) <= {0, 1} and resize_team(1, 3, 0) == (0, 0, 0)  # no third: any member
    with pytest.raises(ValueError):
        resize_team(3, 0, 0)


# (members, seats) -> the members (indices) the draw can give the extra seats, or drop, and how the words say it
GROWN = {(1, 3): ({0}, "it keeps its place; 2 more seats fly copies of it"),
         (2, 3): ({0, 1}, "both keep their places; 1 more seat flies a copy of the first or the second member, "
                          "drawn at random from S"),
         (2, 4): ({0, 1}, "both keep their places; 2 more seats fly copies of the first or the second member, "
                          "each drawn at random from S"),
         (3, 5): ({2}, "the 3 keep their places; 2 more seats fly copies of the third member"),
         (4, 7): ({2, 3}, "the 4 keep their places; 3 more seats fly copies of the third or the fourth member, "
                          "each drawn at random from S"),
         (6, 8): ({2, 3, 4, 5}, "the 6 keep their places; 2 more seats fly copies of members from the third to the "
                                "sixth, each drawn at random from S")}
SHRUNK = {(2, 1): ({1}, "the first member flies alone; the second is dropped"),
          (4, 1): ({1, 2, 3}, "the first member flies alone; the other 3 are dropped"),
          (3, 2): ({2}, "the first 2 keep their places; the third member is dropped"),
          (4, 2): ({2, 3}, "the first 2 keep their places; the third and the fourth members are dropped"),
          (4, 3): ({2, 3}, "the first 2 keep their places; 1 of the third and the fourth members is dropped, drawn "
                           "at random from S; the others keep their order"),
          (6, 4): ({2, 3, 4, 5}, "the first 2 keep their places; 2 of the members from the third to the sixth are "
                                 "dropped, drawn at random from S; the others keep their order")}


@pytest.mark.parametrize("have, want", [*GROWN, *SHRUNK, (1, 1), (3, 3)])
def test_the_rule_in_words_names_the_members_the_draw_gives(have, want):
    """describe_resize says what resize_members does for every team size (issue 48: a team of 2 flown as 4 was said
    to draw from 'the third on', a member it does not have)."""
    words = describe_resize(have, want, "S")
    drawn = [resize_team(have, want, seed) for seed in range(40)]
    if want == have:
        assert drawn == [tuple(range(have))] * 40 and words.endswith("keeps its place")
        return
    assert words.startswith(f"{have} member{'s' * (have > 1)}, {want} seat{'s' * (want > 1)}: "), words
    if want > have:
        pool, said = GROWN[have, want]
        assert all(d[:have] == tuple(range(have)) for d in drawn)  # the team keeps its places
        assert {m for d in drawn for m in d[have:]} == pool  # the extra seats copy exactly these
    else:
        pool, said = SHRUNK[have, want]
        assert {m for d in drawn for m in set(range(have)) - set(d)} == pool  # the dropped come from these
        assert all(list(d) == sorted(d) for d in drawn)
    assert words.endswith(said), words
    if have < 3:
        assert "third" not in words  # no member a team of 1 or 2 does not have


def test_pursuits_agents_follow_its_option_and_its_kind_follows_the_kind_option():
    spec = get_env(PURSUIT)
    assert spec.kind == "free-for-all" and spec.kind_from == "agents" and spec.n_seats == 8
    team = spec.for_options(n_pursuers=3, kind="cooperative")
    assert team.agents == ("pursuer_0", "pursuer_1", "pursuer_2") and team.kind == "cooperative"
    assert team.kind_from == "option" and team.state_space() is not None  # a global state for a critic to read
    assert spec.variant_options({"n_pursuers": 3, "kind": "cooperative"}) == {"kind": "cooperative", "n_pursuers": 3}


@pytest.mark.slow
def test_a_pursuit_team_trained_with_3_flies_2_and_5(home, capsys):
    run_json(capsys, "train", PURSUIT, "--kind", "cooperative", "--env-option", "n_pursuers=3", *SMALL,
             "--agents", "3", "--sharing", "nops", "--steps", "400", "--snapshot-steps", "400", "--games", "2",
             "--eval-games", "2", "--run", "p3")
    members = [f"p3/s400-pursuer_{i}" for i in range(3)]
    for m in (2, 3, 5):
        r = run_json(capsys, "match", "p3/s400", "random", "--games", "4", "--env-option", f"n_pursuers={m}")
        assert r["a"] == "p3/s400" and r["kind"] == "cooperative" and r["results"] == 2  # team returns compared
        assert r["variant"] == {"kind": "cooperative", "max_cycles": 20, "n_evaders": 4, "n_pursuers": m,
                                "x_size": 8, "y_size": 8}  # rated in the variant of that size
        if m == 3:
            assert "seating" not in r  # the team as it trained
            continue
        assert r["seating"] == ([*members, members[2], members[2]] if m == 5 else members[:2])  # seed 001's rule
        league = League.open(home=home)
        try:
            seated = [[league.roster.get_player(p).full_name for p in league.ledger.game(i).players]
                      for i in r["game_ids"]]
        finally:
            league.close()
        assert [s for s in seated if "random" not in s] == [r["seating"]] * 2  # what flew is what it says
    code, out, _ = run(capsys, "match", "p3/s400", "random", "--games", "2", "--env-option", "n_pursuers=5")
    assert code == 0 and "p3/s400 flew 5 seats" in out and "2 more seats fly copies of the third member" in out
    rows = run_json(capsys, "league", "ladder", "--env", PURSUIT, "--env-option", "kind=cooperative",
                    "--env-option", "n_pursuers=5", *SMALL)
    assert {m for m in members} <= {x["policy"] for x in rows}  # the members, rated in the 5-pursuer ladder
    flown = [x["flown"] for x in rows if x["policy"] in members]
    assert flown and all(f["trained_seats"] == 3 and f["seats"] == 5 and f["team"] == "p3/s400" for f in flown)
    assert "copies of the third member" in flown[0]["rule"]  # the ladder states the rule that seated them
    code, out, _ = run(capsys, "league", "ladder", "--env", PURSUIT, "--env-option", "kind=cooperative",
                       "--env-option", "n_pursuers=5", *SMALL)
    assert code == 0 and "p3/s400: trained with 3 seats, flown here with 5" in out


def test_a_shared_network_trained_with_3_flies_any_size(home, capsys):
    run_json(capsys, "train", PURSUIT, "--kind", "cooperative", "--env-option", "n_pursuers=3", *SMALL,
             "--agents", "3", "--sharing", "fups", "--steps", "200", "--snapshot-steps", "200", "--games", "2",
             "--eval-games", "0", "--run", "f3")
    for m in (1, 5):
        r = run_json(capsys, "match", "f3/s200", "random", "--games", "2", "--env-option", f"n_pursuers={m}")
        assert r["kind"] == "cooperative" and r["variant"]["n_pursuers"] == m and "seating" not in r


@pytest.mark.slow
def test_the_kind_is_refused_where_the_game_declares_it_or_it_is_no_kind(home, capsys):
    code, _, err = run(capsys, "train", "pong", "--kind", "cooperative", "--steps", "10")
    assert code == 2 and "pong declares its kind itself (two-sides)" in err and err.count("\n") == 1, err
    code, _, err = run(capsys, "train", "tests.games.rendezvous:parallel_env", "--kind", "free-for-all")
    assert code == 2 and "declares its kind in its metadata (cooperative)" in err and err.count("\n") == 1, err
    code, _, err = run(capsys, "train", PURSUIT, "--kind", "teams")
    assert code == 2 and "--kind must be one of two-sides, cooperative, free-for-all" in err, err
    code, _, err = run(capsys, "train", PURSUIT, "--kind", "two-sides")  # 8 pursuers: which are the sides?
    assert code == 2 and "needs its sides" in err and err.count("\n") == 1, err
    assert not (home / "runs").exists() or not any((home / "runs").iterdir())  # refused before a run exists
    (row,) = run_json(capsys, "envs", PURSUIT)
    assert row["kind"] == "free-for-all" and row["kind_from"] == "agents"
    assert ("kind", "free-for-all") in [(o["name"], o["default"]) for o in row["options"]]
    code, out, _ = run(capsys, "envs", PURSUIT)
    assert "free-for-all by default (8 agents; the game does not declare its kind)" in out
    (row,) = run_json(capsys, "envs", "tests.games.rendezvous:parallel_env")
    assert row["kind_from"] == "metadata" and "kind" not in [o["name"] for o in row["options"]]
    assert run_json(capsys, "envs", "pong")[0]["kind_from"] == "declared"


def test_the_kind_from_a_config_file_and_from_the_flag(tmp_path):
    from selfplay_cli.train.settings import new_settings

    toml = tmp_path / "run.toml"
    toml.write_text('kind = "cooperative"\n[env_options]\nn_pursuers = 3\n')
    settings = new_settings(PURSUIT, {}, config=toml)
    assert settings["env_options"] == {"kind": "cooperative", "n_pursuers": 3} and "kind" not in settings
    flagged = new_settings(PURSUIT, {"kind": "free-for-all"}, config=toml)  # the flag over the file
    assert flagged["env_options"]["kind"] == "free-for-all"


def test_a_lander_team_of_2_flown_as_4_says_what_seats_it(home, capsys):
    """Issue 48: `marl match lander-2/s... heuristic --env-option landers=4` said the copies were 'drawn from the
    third on' of a team of 2; the match says the rule as the team at hand has it."""
    run_json(capsys, "train", "lander", "--agents", "2", "--sharing", "nops", "--steps", "400", "--snapshot-steps",
             "400", "--games", "4", "--eval-games", "0", "--run", "l2")
    code, out, _ = run(capsys, "match", "l2/s400", "heuristic", "--games", "2", "--env-option", "landers=4")
    (line,) = [x for x in out.splitlines() if "flew 4 seats" in x]
    assert code == 0 and "third" not in line, line
    assert "2 more seats fly copies of the first or the second member" in line, line
    r = run_json(capsys, "match", "l2/s400", "heuristic", "--games", "2", "--env-option", "landers=4")
    assert r["seating"][:2] == ["l2/s400-lander_0", "l2/s400-lander_1"] and len(r["seating"]) == 4
    assert set(r["seating"][2:]) <= {"l2/s400-lander_0", "l2/s400-lander_1"}
    assert r["seating_rule"] == describe_resize(2, 4, f"the match's first seed ({r['first_seed']})")
