"""Seats that see and act differently: a snapshot belongs to the role it learned and plays only there.

The suite's chase game (``tests/games/chase.py``) is two sides whose seats differ: a hunter that reads 3 values and
has 3 actions, a runner that reads 5 and has 5. It is trained with gauntlets on (each snapshot rated, each on its
own side only), then matched, refused, put in a tournament, recorded and laddered (one table per side, each with
its own anchor), as issue 29 found ``mpe2.simple_push_v3`` failing; the rules behind it (roles, seatings, the
per-side table, random on any seat, old files without a recorded role) are checked on their own below.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from cli_helpers import run, run_json

from selfplay_cli.cli import main
from selfplay_cli.envs import get_env
from selfplay_cli.envs.adapters.pettingzoo import adapt
from selfplay_cli.envs.contract import EnvError
from selfplay_cli.league.game_table import GameTable
from selfplay_cli.league.store import League
from selfplay_cli.play import play
from selfplay_cli.play.replay import decode_actions
from selfplay_cli.play.schedule import CannotMeet, can_meet, round_of
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.policies.snapshot_format import SnapshotMeta, snapshot_roles
from selfplay_cli.results import Rules

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

from tests.games import chase, tictactoe  # noqa: E402

CHASE = "tests.games.chase:parallel_env"


# --------------------------------------------------------------------------------------------------------------
# Roles, and who may sit where


def test_roles_follow_the_seats_spaces_or_the_games_declaration():
    spec = get_env(CHASE)
    assert spec.seat_roles() == ("hunter", "runner")  # different spaces: two roles, named after their seats
    assert Rules.of(spec).roles == ("hunter", "runner") and Rules.of(spec).sides_differ
    assert Rules.of(get_env("pong")).roles is None and not Rules.of(get_env("pong")).sides_differ  # one role

    def declared(**metadata):
        def factory(**options):
            env = tictactoe.env(**options)
            env.metadata = {**env.metadata, **metadata}
            return env
        return factory

    # a board game whose colours the game says are roles (same spaces): two roles, by the declaration
    colours = adapt("ttt-colours", declared(marl_roles={"x": "first", "o": "second"}))
    assert colours.seat_roles() == ("first", "second") and Rules.of(colours).sides_differ
    assert Rules.of(adapt("ttt", declared())).roles is None  # undeclared, same spaces: one role

    def mislabelled(**options):
        env = chase.parallel_env(**options)
        env.metadata = {**env.metadata, "marl_roles": ["same", "same"]}
        return env

    with pytest.raises(EnvError, match="both of role 'same' but their spaces differ"):
        adapt("mislabelled", mislabelled)
    with pytest.raises(EnvError, match="marl_roles must give each agent"):
        adapt("bad", declared(marl_roles=["x"]))


def test_rounds_seat_each_policy_on_its_own_role_only():
    sided = Rules(roles=("hunter", "runner"))
    # a hunter against a player of any seat: one game a seed, the hunter on its side (no seat swap)
    assert [g.seats for g in round_of(sided, (0, 1), 7, {0: {"hunter"}, 1: None})] == [(0, 1)]
    assert [g.seats for g in round_of(sided, (0, 1), 7, {0: {"runner"}, 1: None})] == [(1, 0)]
    assert [g.seats for g in round_of(sided, (0, 1), 7, {0: None, 1: None})] == [(0, 1), (1, 0)]  # both anywhere
    with pytest.raises(CannotMeet):
        round_of(sided, (0, 1), 7, {0: {"hunter"}, 1: {"hunter"}})
    assert not can_meet(sided, {"runner"}, {"runner"}) and can_meet(sided, {"runner"}, {"hunter"})
    assert can_meet(Rules(), {"left"}, {"left"})  # pong: one role, anyone meets anyone
    # free-for-all of seats (x, x, y): a policy of role y takes the y seat, the other the x seats
    ffa = Rules(n_seats=3, kind="free-for-all", roles=("x", "x", "y"))
    assert [g.seats for g in round_of(ffa, (0, 1), 1, {0: {"y"}, 1: {"x"}})] == [(1, 1, 0)]
    assert [g.seats for g in round_of(ffa, (0, 1), 1, {0: {"x"}})] == [(0, 0, 1)]  # rotations that fit
    # cooperative: a policy of one role cannot fly the whole team alone (a crew flies, member by member)
    coop = Rules(n_seats=2, kind="cooperative", roles=("a", "b"))
    with pytest.raises(CannotMeet):
        round_of(coop, (0, 1), 0, {0: {"a"}})
    assert [g.seats for g in round_of(coop, ((0, 2), 1), 0, {0: {"a"}, 2: {"b"}})] == [(0, 2), (1, 1)]


def test_random_plays_every_seat_with_that_seats_actions():
    rnd_a, rnd_b = ScriptedPolicy(CHASE, "random", seed=1), ScriptedPolicy(CHASE, "random", seed=2)
    assert rnd_a.for_seat(1).act_space.n == 5 and rnd_a.for_seat(0) is rnd_a  # the runner's 5 actions
    games = [g for seed in range(20) for g in round_of(Rules.of(get_env(CHASE)), (0, 1), seed)]
    results = play(CHASE, [rnd_a, rnd_b], games, record_actions=True)
    assert len(results) == 40
    steps = np.concatenate([decode_actions(r.actions, 2, r.length) for r in results])  # (steps, seats)
    hunter, runner = steps[:, 0], steps[:, 1]
    assert hunter.max() == 2 and runner.max() == 4  # each seat's own action space, used in full


def test_a_snapshot_without_a_recorded_role_plays_the_role_its_spaces_fit():
    spec = get_env(CHASE)
    old = SnapshotMeta(env=CHASE, obs_space={"kind": "box", "shape": [5], "dtype": "float32", "low": None,
                                             "high": None}, act_space={"kind": "discrete", "n": 5}, name="old")
    assert old.role is None and snapshot_roles(old, spec) == frozenset({"runner"})
    named = SnapshotMeta(env=CHASE, obs_space=old.obs_space, act_space=old.act_space, name="new", role="runner")
    assert snapshot_roles(named, spec) == frozenset({"runner"})
    assert snapshot_roles(SnapshotMeta.from_dict({**old.to_dict(), "seat": "runner"}), spec) == {"runner"}
    pong = SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, name="p")
    assert snapshot_roles(pong, get_env("pong")) is None  # one role: any seat


def test_a_table_by_side_splits_the_players_who_played_both():
    t = GameTable.of_rows([(1, 1, 5, 7, 1.0, 0, 9, False, 0), (2, 1, 7, 5, 0.0, 0, 9, False, 0),
                           (3, 1, 5, 9, 0.5, 1, 9, False, 0)])
    sided, sides = t.by_side()
    assert sorted(sides.values()) == [(5, 0), (5, 1), (7, 0), (7, 1), (9, 1)]  # 9 played one side: one player
    assert 9 in sides and sides[9] == (9, 1)
    assert [sides[int(k)] for k in sided.player_a] == [(5, 0), (7, 0), (5, 0)]
    assert [sides[int(k)] for k in sided.player_b] == [(7, 1), (5, 1), (9, 1)]


# --------------------------------------------------------------------------------------------------------------
# A run of the chase game, and everything the commands do with it


@pytest.fixture(scope="module")
def chased(tmp_path_factory):
    """A league where ``marl train`` ran the chase game, two learners (a hunter, a runner), gauntlets on, a share
    of the games against the run's own snapshots: (home, its JSON report)."""
    home = tmp_path_factory.mktemp("chase") / "league"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SDL_VIDEODRIVER", "dummy")
        mp.delenv("MARL_DB", raising=False)
        out, err, code = _main("train", CHASE, "--agents", "2", "--steps", "3000", "--snapshot-steps", "1000",
                               "--games", "8", "--league-games", "0.5", "--opponents", "uniform", "--eval-games", "4",
                               "--eval-inline", "--run", "ch", "--seed", "1", "--home", str(home), "--json", "--quiet")
    assert code == 0, err
    return home, json.loads(out)


def _main(*args: str) -> tuple[str, str, int]:
    """``marl ARGS`` outside a test's capsys (a module's fixture): stdout, stderr, exit code."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(args))
    return out.getvalue(), err.getvalue(), code


def _league(home: Path) -> League:
    return League.open(home=home)


@pytest.mark.slow
def test_training_rates_every_snapshot_each_on_its_own_side_only(chased):
    home, report = chased
    assert [f["snapshot"] for f in report["final"]] == ["ch/s3k-hunter", "ch/s3k-runner"]
    assert isinstance(report["best"], list) and {b["side"] for b in report["best"]} == {"hunter", "runner"}
    league = _league(home)
    try:
        snaps = [p for p in league.roster.players(env=CHASE, kind="snapshot")]
        assert len(snaps) == 8  # s0, s1k, s2k, s3k of each learner
        assert {p.meta.get("role") for p in snaps if p.name.endswith("-hunter")} == {"hunter"}
        table = league.ledger.games(env=CHASE)  # every rated result: player_a sat on the hunter's side
        names = {p.id: p.name for p in league.roster.players(env=CHASE)}
        firsts = {names[int(i)] for i in table.player_a}
        seconds = {names[int(i)] for i in table.player_b}
        assert all(n.endswith("-hunter") or n == "random" for n in firsts), firsts
        assert all(n.endswith("-runner") or n == "random" for n in seconds), seconds
        rated = set(table.player_a.tolist()) | set(table.player_b.tolist())
        same = league.ledger.same_weights(CHASE)  # (a snapshot no update changed is its predecessor's weights)
        assert {same.get(p.id, p.id) for p in snaps} <= rated  # every snapshot has rated games
        training = league.ledger.match_params(CHASE, kind="training")
        assert training  # the training games (half of them against the run's own snapshots) went fine too
    finally:
        league.close()


@pytest.mark.slow
def test_a_snapshot_plays_random_on_its_own_side(chased, capsys):
    home, _ = chased
    code, out, err = run(capsys, "match", "ch/s3k-runner", "random", "--games", "10", "--home", str(home), "--json")
    assert code == 0, err
    m = json.loads(out)
    assert m["games"] == 10 and m["paired"] is False and m["pentanomial"] == [0, 0, 0, 0, 0]
    assert m["wins"] + m["draws"] + m["losses"] == 10  # one result a game: chase always has a winner
    league = _league(home)
    try:
        runner = next(p.id for p in league.roster.players(env=CHASE) if p.name == "s3k-runner")
        assert all(league.ledger.game(g).players[1] == runner for g in m["game_ids"])  # always the runner's seat
    finally:
        league.close()
    code, out, err = run(capsys, "match", "random", "ch/s3k-hunter", "--games", "4", "--home", str(home), "--no-store")
    assert code == 0, err
    assert "4 games, one a seed: each plays only its own side" in out


@pytest.mark.slow
def test_two_snapshots_of_one_role_cannot_meet_one_line_exit_2(chased, capsys):
    home, _ = chased
    code, out, err = run(capsys, "match", "ch/s3k-hunter", "ch/s1k-hunter", "--home", str(home))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "cannot meet" in err and "ch/s3k-hunter (hunter)" in err, err
    code, _, err = run(capsys, "record", "--ckpt", "ch/s3k-runner", "--vs", "ch/s0-runner", "--home", str(home))
    assert code == 2 and err.count("\n") == 1 and "cannot meet" in err, err


@pytest.mark.slow
def test_a_tournament_plays_only_the_pairs_that_can_meet(chased, capsys):
    home, _ = chased
    code, out, err = run(capsys, "league", "tournament", "ch/s3k-hunter", "ch/s0-hunter", "ch/s3k-runner",
                         "--games-per-pair", "6", "--home", str(home), "--quiet")
    assert code == 0, err
    assert "1 pair cannot meet and were left out" in out
    league = _league(home)
    try:
        ids = {p.name: p.id for p in league.roster.players(env=CHASE)}
        hunters = [ids["s3k-hunter"], ids["s0-hunter"]]
        table = league.ledger.games(env=CHASE, players=hunters)
        assert not (np.isin(table.player_a, hunters) & np.isin(table.player_b, hunters)).any()  # they never met
        both = league.ledger.games(env=CHASE, players=[ids["s0-hunter"], ids["s3k-runner"]])
        assert len(both) >= 6  # the pairs that can meet have their games
    finally:
        league.close()


@pytest.mark.slow
def test_a_recording_seats_each_snapshot_on_its_own_seat(chased, capsys, tmp_path):
    home, _ = chased
    out = tmp_path / "runner.mp4"
    code, text, err = run(capsys, "record", "--ckpt", "ch/s3k-runner", "--vs", "random", "--seconds", "0",
                          "--out", str(out), "--home", str(home), "--json")
    assert code == 0, err
    (rec,) = json.loads(text)
    assert rec["players"] == ["random", "ch/s3k-runner"], rec  # the runner on the runner's seat
    frames = np.stack(list(iio.imiter(out)))
    assert frames.shape[0] >= 2 and frames.shape[-1] == 3


@pytest.mark.slow
def test_the_ladder_of_a_game_whose_sides_differ_has_one_table_per_side(chased, capsys):
    home, _ = chased
    rows = run_json(capsys, "league", "ladder", "--home", str(home), "--bootstrap", "0")
    sides = {r["side"] for r in rows}
    assert sides == {"hunter", "runner"}
    for side in sides:
        mine = [r for r in rows if r["side"] == side]
        assert mine[0]["rank"] == 1 and [r["rank"] for r in mine] == sorted(r["rank"] for r in mine)  # within the side
        anchor = [r for r in mine if r["anchor"]]
        assert [(a["policy"], a["elo"]) for a in anchor] == [("random", 1000.0)]  # its own anchor: random there
        snaps = [r["policy"] for r in mine if r["kind"] == "snapshot"]
        assert snaps and all(p.endswith(f"-{side}") for p in snaps)
        assert sum(r["best"] for r in mine) == 1  # the run's best of that side
    code, out, err = run(capsys, "league", "ladder", "--home", str(home), "--bootstrap", "0")
    assert code == 0, err
    assert "ladder: hunter side" in out and "ladder: runner side" in out
    assert "each side is rated on its own" in " ".join(out.split())
    assert "hunter side: best of ch:" in out and "runner side: best of ch:" in out


def test_training_seats_a_learner_on_one_role_only(home, capsys):
    # one learner for both sides would play two roles; a seat of a role no learner learns has nobody to play it
    code, _, err = run(capsys, "train", CHASE, "--agents", "1", "--steps", "100")
    assert code == 2 and err.count("\n") == 1 and "different spaces" in err, err
    code, _, err = run(capsys, "train", CHASE, "--seats", "1,-", "--steps", "100")
    assert code == 2 and err.count("\n") == 1 and "role runner, which no learner learns" in err, err


def test_marl_envs_shows_each_seats_role(home, capsys):
    rows = run_json(capsys, "envs", CHASE)
    chase_row = next(r for r in rows if r["name"] == CHASE)
    assert [(s["agent"], s["role"]) for s in chase_row["seats"]] == [("hunter", "hunter"), ("runner", "runner")]
    code, out, err = run(capsys, "envs", CHASE)
    assert code == 0, err
    assert "seats of 2 roles (hunter: hunter, runner: runner): a snapshot plays only seats of the role it learned; " \
           "rated per side" in " ".join(out.split())


@pytest.mark.slow
def test_best_is_per_side_where_the_sides_differ(chased, capsys):
    home, _ = chased
    code, out, err = run(capsys, "match", "best", "random", "--env", CHASE, "--home", str(home), "--no-store")
    assert code == 2 and err.count("\n") == 1 and "'best' is per side" in err, err
    assert "hunter side: " in err and "runner side: " in err


@pytest.mark.slow
def test_a_cooperative_crew_of_different_seats_flies_each_member_on_its_own_seat(home, capsys):
    report = run_json(capsys, "train", "tests.games.chase:cooperative_env", "--agents", "2", "--steps", "1000",
                      "--snapshot-steps", "500", "--games", "8", "--eval-games", "2", "--eval-inline", "--run", "crew")
    assert [f["snapshot"] for f in report["final"]] == ["crew/s1k-hunter", "crew/s1k-runner"]
    league = League.open(home=home)
    try:
        names = {p.id: p.name for p in league.roster.players(env="tests.games.chase:cooperative_env")}
        played = (league.ledger.game(i) for i in range(1, league.ledger.count_games() + 1))
        rated = [g for g in played if g.match_kind == "eval"]
        seatings = {tuple(names[p].rsplit("-", 1)[-1] for p in g.players) for g in rated}
    finally:
        league.close()
    # every rated episode: a crew (hunter on the hunter's seat, runner on the runner's) or a scripted player alone
    assert seatings == {("hunter", "runner"), ("random", "random")}, seatings


@pytest.mark.slow
def test_an_older_file_without_a_role_plays_the_role_its_spaces_fit(chased, home, capsys, tmp_path):
    from selfplay_cli.policies.snapshot_reader import export_snapshot, read_meta

    src = next((chased[0] / "snapshots" / "ch").glob("s3k-runner.*"))
    old = tmp_path / "old-runner.safetensors"
    export_snapshot(src, old, role=None, seat=None, run=None, extra={})  # as a file written before roles were
    assert read_meta(old).role is None and read_meta(old).seat is None
    code, _, err = run(capsys, "checkpoint", "import", str(old), "--run", "before")
    assert code == 0, err
    m = run_json(capsys, "match", "before/s3k-runner", "random", "--games", "6")
    assert m["games"] == 6 and m["paired"] is False
    league = League.open(home=home)
    try:
        me = next(p.id for p in league.roster.players(env=CHASE) if p.run == "before")
        assert all(league.ledger.game(g).players == (league.ledger.game(g).players[0],
                                                     me) for g in m["game_ids"])  # runner's seat
    finally:
        league.close()
