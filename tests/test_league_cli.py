"""The league from the command line: checkpoints, matches, SPRT, ratings, the ladder, tournaments and the gate."""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_helpers import run
from league_helpers import record_plan

from selfplay_cli.league.store import League
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot
from selfplay_cli.ratings.forecast import Forecaster


def make_snapshot(path: Path, name: str, seed: int, run: str = "r1", obs_shape=(8, 6)) -> Path:
    arch = Arch(hidden=(32, 32))
    net = build_network(obs_shape, 3, arch, seed=seed)
    save_snapshot(path, net, SnapshotMeta(env="pong", obs_shape=obs_shape, n_actions=3, arch=arch, run=run,
                                          name=name, algo="ppo", step=1000 * seed, episode=10 * seed))
    return path



def run_json(capsys, *args: str):
    code, out, err = run(capsys, *args, "--json")
    return code, json.loads(out)



# ---------------------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_checkpoint_import_list_show_tag_export_rm_round_trip(home, tmp_path, capsys):
    f1 = make_snapshot(tmp_path / "a.safetensors", "ep10", seed=1)
    f2 = make_snapshot(tmp_path / "b.safetensors", "ep20", seed=2)
    assert run(capsys, "checkpoint", "import", str(f1))[0] == 0
    code, row = run_json(capsys, "checkpoint", "import", str(f2))
    assert code == 0 and row["policy"] == "r1/ep20" and row["env"] == "pong"
    assert (home / "snapshots" / "r1" / "ep20.safetensors").exists()

    code, out, err = run(capsys, "checkpoint", "import", str(f2))
    assert code != 0 and "already in the league as r1/ep20" in err and err.count("\n") == 1

    code, rows = run_json(capsys, "checkpoint", "list")
    assert [r["policy"] for r in rows] == ["r1/ep10", "r1/ep20"]
    assert run(capsys, "checkpoint", "tag", "ep20", "champion")[0] == 0
    code, shown = run_json(capsys, "checkpoint", "show", "champion")
    assert shown["policy"] == "r1/ep20" and shown["tags"] == ["champion"]
    assert shown["file"]["arch"]["hidden"] == [32, 32] and shown["file"]["obs_space"]["shape"] == [8, 6]
    code, latest = run_json(capsys, "checkpoint", "show", "latest")
    assert latest["policy"] == "r1/ep20"

    out_file = tmp_path / "exported.safetensors"
    assert run(capsys, "checkpoint", "export", "r1/ep10", str(out_file))[0] == 0
    other = tmp_path / "other_home"
    code, row = run_json(capsys, "checkpoint", "import", str(out_file), "--run", "friend", "--home", str(other))
    assert code == 0 and row["policy"] == "friend/ep10"

    # rm keeps the games in the ledger
    assert run(capsys, "match", "ep10", "cpu", "--games", "4", "--quiet")[0] == 0
    code, out, err = run(capsys, "checkpoint", "rm", "ep10")
    assert code == 0 and "4 games stay in the ledger" in out
    assert not (home / "snapshots" / "r1" / "ep10.safetensors").exists()
    with League.open(home) as league:
        assert league.ledger.count_games("pong") == 4
    code, rows = run_json(capsys, "checkpoint", "list")
    assert [r["policy"] for r in rows] == ["r1/ep20"]


def test_name_errors_list_candidates_and_corrupt_files_are_refused(home, tmp_path, capsys):
    make_snapshot(tmp_path / "a.safetensors", "ep10", seed=1)
    make_snapshot(tmp_path / "b.safetensors", "ep10", seed=2, run="r2")
    run(capsys, "checkpoint", "import", str(tmp_path / "a.safetensors"))
    run(capsys, "checkpoint", "import", str(tmp_path / "b.safetensors"))
    code, out, err = run(capsys, "checkpoint", "show", "ep10")
    assert code == 2 and "ambiguous" in err and "r1/ep10" in err and "r2/ep10" in err
    code, out, err = run(capsys, "match", "ep99", "cpu")
    assert code == 2 and "no policy named 'ep99'" in err and "r1/ep10" in err

    bad = tmp_path / "corrupt.safetensors"
    data = bytearray((tmp_path / "a.safetensors").read_bytes())
    data[-10] ^= 0xFF
    bad.write_bytes(bytes(data))
    code, out, err = run(capsys, "checkpoint", "import", str(bad))
    assert code == 2 and str(bad) in err and "checksum" in err and err.count("\n") == 1
    wrong = make_snapshot(tmp_path / "wrong.safetensors", "ep5", seed=3, obs_shape=(4, 6))
    code, out, err = run(capsys, "checkpoint", "import", str(wrong))
    assert code == 2 and str(wrong) in err


@pytest.mark.slow
def test_match_plays_pairs_stores_games_and_reports(home, capsys):
    code, rep = run_json(capsys, "match", "cpu", "random", "--env", "pong", "--games", "20", "--seed", "5")
    assert code == 0
    assert rep["games"] == 20 and rep["wins"] == 20 and rep["losses"] == 0
    assert rep["pentanomial"] == [0, 0, 0, 0, 10]
    assert rep["elo_low"] > 400 and rep["los"] > 0.999 and rep["match_id"] == 1
    with League.open(home) as league:
        table = league.ledger.games("pong")
        assert len(table) == 20
        assert sorted(table.seed.tolist()) == sorted([5 + i // 2 for i in range(20)])
        cpu = league.roster.find_players("cpu", "pong")[0]
        assert (table.player_a == cpu.id).sum() == 10, "each seed once in each seat order"
    code, rep = run_json(capsys, "match", "cpu", "random", "--games", "6", "--no-store")
    with League.open(home) as league:
        assert league.ledger.count_games("pong") == 20 and rep["match_id"] is None


@pytest.mark.slow
def test_sprt_exit_codes(home, capsys):
    code, rep = run_json(capsys, "match", "cpu", "random", "--sprt", "--elo0", "0", "--elo1", "100",
                         "--max-games", "400", "--no-store")
    assert code == 0 and rep["sprt"]["decision"] == "H1" and rep["sprt"]["llr"] >= rep["sprt"]["upper"]
    assert rep["games"] < 400, "stops as soon as the LLR crosses a bound"
    code, rep = run_json(capsys, "match", "random", "cpu", "--sprt", "--elo0", "0", "--elo1", "100",
                         "--max-games", "400", "--no-store")
    assert code == 1 and rep["sprt"]["decision"] == "H0"
    code, rep = run_json(capsys, "match", "cpu", "random", "--sprt", "--elo0", "2000", "--elo1", "2010",
                         "--max-games", "4", "--no-store")
    assert code == 3 and rep["sprt"]["decision"] is None and rep["games"] == 4


def test_elo_fit_on_a_results_file_matches_hand_computed_ratings(tmp_path, capsys):
    f = tmp_path / "results.csv"
    f.write_text("player_a,player_b,result\n" + "a,b,1\n" * 7 + "a,b,0\n" * 3)
    # --prior 0: the maximum-likelihood fit, E(d) = 7/10.
    code, rows = run_json(capsys, "elo", "fit", "--results", str(f), "--anchor", "b=1000", "--bootstrap", "0",
                          "--prior", "0")
    assert code == 0
    by = {r["policy"]: r for r in rows}
    assert by["a"]["elo"] == pytest.approx(1000 + 400 * math.log10(7 / 3), abs=0.1)  # 1147.2
    # Default: BayesElo's prior, 2 virtual draws between the two: E(d) = (7 + 1) / 12 = 2/3.
    code, rows = run_json(capsys, "elo", "fit", "--results", str(f), "--anchor", "b=1000", "--bootstrap", "0")
    assert code == 0 and {r["policy"]: r for r in rows}["a"]["elo"] == pytest.approx(1000 + 400 * math.log10(2),
                                                                                      abs=0.1)  # 1120.4
    assert list(rows[0])[:10] == ["policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses",
                                  "rank"]
    bad = tmp_path / "bad.csv"
    bad.write_text("player_a,player_b,result\na,b,1\na,b,2\n")
    code, out, err = run(capsys, "elo", "fit", "--results", str(bad))
    assert code == 2 and f"{bad}:3:" in err and err.count("\n") == 1


@pytest.mark.slow
def test_ladder_gate_and_tournament(home, tmp_path, capsys):
    run(capsys, "checkpoint", "import", str(make_snapshot(tmp_path / "a.safetensors", "ep10", seed=1)))
    code, rows = run_json(capsys, "league", "tournament", "cpu", "random", "ep10", "--games-per-pair", "10",
                          "--bootstrap", "50")
    assert code == 0
    with League.open(home) as league:
        assert league.ledger.count_games("pong") == 30
    assert rows[0]["policy"] == "cpu" and rows[0]["rank"] == 1
    assert {r["policy"] for r in rows} == {"cpu", "random", "r1/ep10"}
    assert all(r["games"] == 20 for r in rows)
    # A second run finds nothing missing and plays nothing.
    run_json(capsys, "league", "tournament", "cpu", "random", "ep10", "--games-per-pair", "10")
    with League.open(home) as league:
        assert league.ledger.count_games("pong") == 30

    code, ladder = run_json(capsys, "league", "ladder", "--bootstrap", "50")
    assert code == 0 and [r["policy"] for r in ladder][0] == "cpu"
    anchor = next(r for r in ladder if r["anchor"])
    assert anchor["policy"] == "random" and anchor["elo"] == 1000.0
    code, out, err = run(capsys, "league", "ladder", "--csv", "--bootstrap", "0")
    assert out.splitlines()[0].startswith("policy,kind,elo,ci_low,ci_high,games,wins,draws,losses,rank")

    code, verdict = run_json(capsys, "elo", "gate", "cpu", "--vs", "random", "--min-diff", "200", "--games", "10")
    assert code == 0 and verdict["passed"] and verdict["played_games"] == 0 and verdict["stored_games"] == 10
    code, verdict = run_json(capsys, "elo", "gate", "random", "--vs", "cpu", "--min-diff", "0", "--games", "16")
    assert code == 1 and not verdict["passed"] and verdict["played_games"] == 6


# ---------------------------------------------------------------------------------------------------------------
# The ladder answers at a glance: prior, --run, --top, best marker, records against the bots, help


def seed_ladder(home: Path) -> dict[str, int]:
    """A league with two runs and the pong bots; games written straight to the ledger (results chosen by hand).

    Returns the player ids by name."""

    with League.open(home) as lg:
        lg.roster.ensure_bots("pong", ["random", "cpu"])
        for run in ("r1", "r2"):
            lg.roster.create_run(run, "pong", {})
        bots = {p.name: p.id for p in lg.roster.players("pong", kind="bot")}
        ids = dict(bots)
        for run, name, step in (("r1", "ep1", 1000), ("r1", "ep2", 2000), ("r2", "ep1", 1000)):
            p = lg.roster.add_snapshot(env="pong", run=run, name=name, path=f"/x/{run}/{name}.safetensors",
                                       sha256="0" * 64, step=step)
            ids[f"{run}/{name}"] = p.id
        plan = [("cpu", "random", 14, 2), ("r1/ep1", "random", 16, 0), ("r1/ep1", "cpu", 10, 6),
                ("r1/ep2", "cpu", 14, 2), ("r1/ep2", "r1/ep1", 12, 4), ("r2/ep1", "random", 16, 0)]
        record_plan(lg, ids, plan)
    return ids


@pytest.mark.slow
def test_ladder_prior_run_top_best_and_bot_columns(home, capsys):
    seed_ladder(home)
    code, rows = run_json(capsys, "league", "ladder", "--bootstrap", "0")
    assert code == 0
    assert list(rows[0]) == ["policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses",
                             "rank", "tier", "score", "step", "flag", "anchor", "run", "best", "margin",
                             "best_margin", "tied", "copy_of", "copies", "vs", "league_role", "exploitability",
                             "circle", "variant"]
    assert all(r["league_role"] is None and r["exploitability"] is None for r in rows)  # none measured, no role
    assert all(r["variant"] == {} for r in rows)  # the default variant: the game as declared
    # rank: 1 + the players above beyond doubt, so never decreasing down the order, and the first is 1
    assert [r["rank"] for r in rows] == sorted(r["rank"] for r in rows) and rows[0]["rank"] == 1
    assert all(r["rank"] <= place + 1 for place, r in enumerate(rows))
    assert [r["elo"] for r in rows] == sorted((r["elo"] for r in rows), reverse=True)
    by = {r["policy"]: r for r in rows}
    assert set(by) == {"random", "cpu", "r1/ep1", "r1/ep2", "r2/ep1"}
    # The prior: r2/ep1 won all its 16 games: finite and unflagged.
    assert all(r["flag"] is None for r in rows) and by["r2/ep1"]["elo"] > by["random"]["elo"]
    # Best snapshot of each run: r1/ep2 (beat r1/ep1 12-4), r2/ep1 (alone); bots never.
    assert by["r1/ep2"]["elo"] > by["r1/ep1"]["elo"]
    assert {r["policy"] for r in rows if r["best"]} == {"r1/ep2", "r2/ep1"}
    # Records against the scripted players, as recorded.
    assert by["r1/ep1"]["vs"] == {"random": {"score": 1.0, "games": 16}, "cpu": {"score": 0.625, "games": 16}}
    assert by["r1/ep2"]["vs"] == {"random": {"score": None, "games": 0}, "cpu": {"score": 0.875, "games": 16}}
    assert by["cpu"]["vs"]["random"] == {"score": 0.875, "games": 16} and by["cpu"]["vs"]["cpu"]["games"] == 0
    assert by["r1/ep1"]["run"] == "r1" and by["cpu"]["run"] is None
    ranks = {r["policy"]: r["rank"] for r in rows}

    # --run: that run's snapshots plus the bots, ranks of the whole ladder; --top: the first rows.
    code, only = run_json(capsys, "league", "ladder", "--bootstrap", "0", "--run", "r1")
    assert code == 0 and [r["policy"] for r in only] == [r["policy"] for r in rows if r["policy"] != "r2/ep1"]
    assert all(r["rank"] == ranks[r["policy"]] for r in only)
    code, top = run_json(capsys, "league", "ladder", "--bootstrap", "0", "--top", "2")
    assert code == 0 and top == rows[:2]
    code, both = run_json(capsys, "league", "ladder", "--bootstrap", "0", "--run", "r1", "--top", "1")
    assert code == 0 and both == only[:1]

    # --prior 0: the exact maximum-likelihood fit: perfect scores are flagged bounds again.
    code, ml = run_json(capsys, "league", "ladder", "--bootstrap", "0", "--prior", "0")
    ml_by = {r["policy"]: r for r in ml}
    assert ml_by["r2/ep1"]["flag"] == "perfect" and ml_by["cpu"]["flag"] is None
    from selfplay_cli.stats.bradley_terry import fit_bradley_terry

    with League.open(home) as league:
        table = league.ledger.games("pong")
        ids, a, b = table.indexed()
        name_of = {p.id: p.full_name for p in league.roster.players("pong")}
    anchor = [name_of[int(i)] for i in ids].index("random")
    exact = fit_bradley_terry(a, b, table.score_a, ids.size, anchor=anchor, anchor_rating=1000.0)
    for i, pid in enumerate(ids.tolist()):
        assert ml_by[name_of[pid]]["elo"] == round(float(exact.ratings[i]), 1)

    # The table: best marked, one column per bot with score and games, blank when none.
    code, out, err = run(capsys, "league", "ladder", "--bootstrap", "0")
    assert code == 0 and err == ""
    assert "r1/ep2 (best" in out and "r2/ep1 (best)" in out and "r1/ep1 (best" not in out
    best = next(r for r in rows if r["policy"] == "r1/ep2")
    m = best["best_margin"]
    with League.open(home) as league:  # the pair's own figure, as marl league predict reads it
        pair = Forecaster.of_league(league, "pong").belief("r1/ep2", "r1/ep1")
    assert m["over"] == "r1/ep1" and m["elo"] == round(pair.mean, 1)
    assert (m["low"], m["high"]) == tuple(round(x, 1) for x in pair.interval())
    said = "" if m["separated"] else " by Elo, not separated from r1/ep1"
    assert f"best of r1: r1/ep2{said}" in " ".join(out.split())  # who is best, and by how much, under the table
    assert "best of r2: r2/ep1 (the run's only rated snapshot)" in " ".join(out.split())
    assert "vs random" in out and "vs cpu" in out and "100% of 16" in out and "88% of 16" in out
    assert "random (anchor)" in out and "prior of 2 virtual draws" in out
    line = next(x for x in out.splitlines() if "r1/ep2 (best)" in x)
    assert "% of" in line and line.count("% of") == 1  # no games against random: that cell is blank
    code, out, err = run(capsys, "league", "ladder", "--bootstrap", "0", "--csv")
    header = out.splitlines()[0].split(",")
    assert header[:10] == ["policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses", "rank"]
    assert header[-4:] == ["vs_random_score", "vs_random_games", "vs_cpu_score", "vs_cpu_games"]

    # The anchor is any name marl understands, resolved by names.resolve.
    code, rows2 = run_json(capsys, "league", "ladder", "--bootstrap", "0", "--anchor", "best=1500")
    best_anchor = next(r for r in rows2 if r["anchor"])
    assert best_anchor["elo"] == 1500.0 and best_anchor["policy"] == max(rows, key=lambda r: r["elo"])["policy"]


def test_ladder_option_errors_are_one_line(home, capsys):
    seed_ladder(home)
    with League.open(home) as lg:
        lg.roster.create_run("r9", "lander", {})
    for args, needle in (
        (["league", "ladder", "--run", "nope"], "no run named 'nope'"),
        (["league", "ladder", "--run", "r9", "--env", "pong"], "run 'r9' plays lander, not pong"),
        (["league", "ladder", "--top", "0"], "--top must be at least 1"),
        (["league", "ladder", "--prior", "-1"], "--prior must be"),
        (["league", "ladder", "--prior", "nan"], "--prior must be"),
        (["elo", "fit", "--prior", "-0.5"], "--prior must be"),
        (["league", "ladder", "--anchor", "nobody=1000"], "no policy named 'nobody'"),
    ):
        code, out, err = run(capsys, *args)
        assert code == 2, (args, out, err)
        assert needle in err and err.startswith("marl: error: ") and err.count("\n") == 1, (args, err)


def test_ladder_and_fit_help_explain_without_losing_brackets(capsys):
    code, out, err = run(capsys, "league", "ladder", "--help")
    assert code == 0
    text = " ".join(out.split())
    for words in ("--prior 0 gives the plain maximum-likelihood fit", "default 2, BayesElo's default",
                  "Rank: 1 + the players above it beyond doubt", "Tier: a boundary falls only where",
                  "ranks and tiers stay those of the whole ladder",
                  "perfect or zero, only with --prior 0", "disconnected: no chain of games", "unrated: no games",
                  "(best) in bold for the best snapshot of each run", "vs BOT", "[default: 2.0]", "--run", "--top"):
        assert words in text, words
    assert "[]" not in out and "[ ]" not in out
    code, out, err = run(capsys, "elo", "fit", "--help")
    text = " ".join(out.split())
    assert code == 0 and "--prior" in text and "[default: 2.0]" in text and "[]" not in out


def test_bad_option_values_give_one_line_errors(home, capsys):
    for args, needle in (
        (["match", "cpu", "random", "--env", "chess"], "unknown env 'chess'"),
        (["match", "cpu", "random", "--games", "0"], "--games"),
        (["match", "cpu", "random", "--sprt", "--elo0", "5", "--elo1", "1"], "--elo0"),
        (["elo", "fit", "--anchor", "random"], "--anchor"),
        (["elo", "fit", "--results", "/no/such/file.csv"], "file.csv"),
        (["match", "cpu", "cpu"], "two different players"),
    ):
        code, out, err = run(capsys, *args)
        assert code == 2, args
        assert needle in err and err.count("\n") == 1 and "Traceback" not in err, (args, err)


# ---------------------------------------------------------------------------------------------------------------
# Several processes, and a process killed midway
def marl_proc(home: Path, *args: str) -> subprocess.Popen:
    env = dict(os.environ, MARL_HOME=str(home))
    return subprocess.Popen([sys.executable, "-m", "selfplay_cli", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.slow
def test_two_match_processes_share_one_sqlite_league(home):
    procs = [marl_proc(home, "match", "cpu", "random", "--env", "pong", "--games", "200", "--parallel", "16",
                       "--env-option", "points_to_win=5", "--seed", str(1000 * i), "--json") for i in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, outs, strict=True):
        assert p.returncode == 0, err
        assert "locked" not in err
        assert json.loads(out)["games"] == 200
    with League.open(home) as league:
        assert league.ledger.count_games("pong") == 400
        assert len({m for m in league.ledger.games("pong", variant=None).match_id.tolist()}) == 2


@pytest.mark.slow
def test_a_match_killed_midway_leaves_a_consistent_ledger(home):
    p = marl_proc(home, "match", "cpu", "random", "--env", "pong", "--games", "100000", "--parallel", "32")
    db = home / "league.db"
    deadline = time.time() + 120
    stored = 0
    while time.time() < deadline and stored < 64:
        time.sleep(0.2)
        if db.exists():
            with sqlite3.connect(db) as con:
                try:
                    stored = con.execute("select count(*) from games").fetchone()[0]
                except sqlite3.OperationalError:
                    stored = 0
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=30)
    assert stored >= 64
    with sqlite3.connect(db) as con:
        assert con.execute("pragma integrity_check").fetchone()[0] == "ok"
        games = con.execute("select count(*) from games").fetchone()[0]
        seats = con.execute("select count(*) from game_seats").fetchone()[0]
    assert games % 32 == 0, "only whole chunks of games are stored"
    assert seats == 2 * games
    with League.open(home) as league:
        table = league.ledger.games("pong")
        assert len(table) == games
        before = {p.name: p.elo for p in league.roster.players("pong")}
        league.ledger.recompute_online_elo("pong")
        assert {p.name: p.elo for p in league.roster.players("pong")} == pytest.approx(before)
