"""Every snapshot is rated: the gauntlet after each snapshot (opponents, seat-swapped pairs, fewer games where the
result is already clear), the end-of-run summary equal to the ledger, progress lines without a terminal."""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
import pytest
from cli_helpers import run

from selfplay_cli.evaluation.gauntlet import GauntletConfig, play_gauntlet
from selfplay_cli.evaluation.gauntlet_plan import best_snapshot, choose_opponents, run_history
from selfplay_cli.league.store import League
from selfplay_cli.league.variants import variant_key
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.ratings.pairs import head_to_head
from selfplay_cli.ratings.verdicts import verdict_lines
from selfplay_cli.results import GameResult


def snapshot_rows(league: League, run: str, n: int, learners=("left", "right")) -> list:
    """n snapshot moments of a two-learner run (files are never read: the tests below seat bots only)."""
    league.roster.create_run(run, "pong", {}, algo="ppo")
    latest = {name: None for name in learners}
    rows = []
    for k in range(n):
        for name in learners:
            row = league.roster.add_snapshot(env="pong", run=run, name=f"ep{k}-{name}", path=f"x/{k}{name}",
                                             sha256="0" * 64,
                                             step=1000 * k, parent_id=latest[name], meta={"learner": name})
            latest[name] = row.id
            rows.append(row)
    return rows


def test_gauntlet_opponents_predecessor_partner_best_older_and_bots(tmp_path):
    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    rows = snapshot_rows(league, "r", 6)
    by_name = {r.name: r for r in rows}
    new = [by_name["ep5-left"], by_name["ep5-right"]]
    best = by_name["ep2-right"]
    pairs = choose_opponents(league, new, older=2, best=best)
    met = defaultdict(list)
    for a, b in pairs:
        met[a.name].append(b.name)
    assert met["ep5-left"][:3] == ["ep4-left", "ep5-right", "ep2-right"]
    assert met["ep5-left"][-2:] == ["random", "cpu"]
    older = met["ep5-left"][3:-2]
    assert len(older) == 2 and "ep0-left" in older  # spread over the run, oldest first
    # the two new snapshots meet once; the right one has its own predecessor, the best, older ones, the bots
    assert "ep5-left" not in met["ep5-right"] and met["ep5-right"][:2] == ["ep4-right", "ep2-right"]
    assert len({frozenset((a.id, b.id)) for a, b in pairs}) == len(pairs)
    # the first snapshots of a run have no history: only each other and the bots
    first = choose_opponents(league, [by_name["ep0-left"], by_name["ep0-right"]], older=2)
    assert [(a.name, b.name) for a, b in first][:1] == [("ep0-left", "ep0-right")]
    league.close()


def test_a_moments_gauntlet_knows_only_what_came_before_it(tmp_path):
    """A rating worker that fell behind (snapshots ep2 and ep3 already taken when ep1's gauntlet starts), a user's
    match and another run's gauntlet filed meanwhile change nothing of what ep1's gauntlet plays: its opponents
    are the snapshots taken before it and the bots, its 'best so far' is fitted from the run's earlier gauntlets
    alone."""
    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    rows = snapshot_rows(league, "r", 4)
    other = snapshot_rows(league, "q", 1)
    by = {r.name: r for r in rows}
    bots = {p.name: p for p in league.roster.players("pong", kind="bot")}

    def games(kind, params, a, b, n, a_wins=True):
        mid = league.ledger.create_match("pong", kind, params)
        league.ledger.record_games(mid, [GameResult("pong", (a.id, b.id), seed=i, scores=(1, 0) if a_wins else (0, 1),
                                                    outcome=(1.0, 0.0) if a_wins else (0.0, 1.0), length=10,
                                                    truncated=False) for i in range(n)])

    gauntlet = {"gauntlet": True}
    games("eval", gauntlet, by["ep0-left"], bots["random"], 8)
    games("eval", gauntlet, by["ep0-left"], by["ep0-right"], 6)
    games("eval", gauntlet, by["ep0-right"], bots["random"], 4)
    games("eval", gauntlet, bots["random"], by["ep0-right"], 4)
    # filed meanwhile: a user's match and another run's gauntlet, both crowning ep0-right
    games("match", {}, by["ep0-right"], by["ep0-left"], 40)
    games("eval", gauntlet, other[0], by["ep0-left"], 30)
    games("eval", gauntlet, by["ep0-right"], other[1], 30)
    new = [by["ep1-left"], by["ep1-right"]]
    history = run_history(league, new)
    assert [p.name for p in history.snapshots] == ["ep0-left", "ep0-right"]
    assert len(history.table) == 22  # the run's own gauntlets only
    assert best_snapshot(history).name == "ep0-left"
    pairs = choose_opponents(league, new, older=2, best=best_snapshot(history), history=history)
    met = {p.name for pair in pairs for p in pair}
    assert met == {"ep0-left", "ep0-right", "ep1-left", "ep1-right", "random", "cpu"}
    assert not met & {"ep2-left", "ep2-right", "ep3-left", "ep3-right", "ep0-left_q"}
    league.close()


@pytest.mark.slow
def test_gauntlet_games_come_in_seat_swapped_pairs_all_at_once_whatever_the_history(tmp_path, monkeypatch):
    """Scripted players stand in for the snapshots (same league rows, no files): every matchup is stored in pairs,
    each seed once with either player on the left, and plays all its pairs, in one call of the runner: even one the
    predecessor already won 8-0 (no history cuts a matchup short, nor makes it wait on its first games)."""
    import selfplay_cli.evaluation.gauntlet as gauntlet_mod

    calls = []
    real_play = gauntlet_mod.play

    def counting_play(*args, **kwargs):
        calls.append(len(args[2]))
        return real_play(*args, **kwargs)

    monkeypatch.setattr(gauntlet_mod, "play", counting_play)
    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    rows = snapshot_rows(league, "r", 2, learners=("left",))
    old, new = rows
    bots = {p.name: p for p in league.roster.players("pong", kind="bot")}
    mid = league.ledger.create_match("pong", "eval", {"gauntlet": True})
    league.ledger.record_games(mid, [GameResult("pong", (old.id, bots["random"].id), seed=i, scores=(1, 0),
                                                outcome=(1.0, 0.0), length=10, truncated=False) for i in range(8)])
    stand_in = {old.id: "cpu", new.id: "cpu"}

    def fake_load(lg, row, device="cpu", greedy=None, seed=0):
        p = ScriptedPolicy("pong", stand_in.get(row.id, row.name), seed=seed)
        p.id = row.full_name
        return p

    monkeypatch.setattr(gauntlet_mod, "load_player", fake_load)
    pairs = [(new, old), (new, bots["random"]), (new, bots["cpu"])]
    ms = play_gauntlet(league, pairs, first_seed=500, config=GauntletConfig(pairs=2), policies=None)
    assert [m.pairs for m in ms] == [2, 2, 2] and calls == [12]  # 3 matchups x 2 pairs x 2 seatings, one batch
    table = league.ledger.games("pong")
    for m in ms:
        sub = table.select(np.isin(table.match_id, [m.match_id]))
        assert len(sub) == 2 * m.pairs == m.games
        seeds = defaultdict(list)
        for s, a in zip(sub.seed.tolist(), sub.player_a.tolist(), strict=True):
            seeds[s].append(a)
        assert all(sorted(v) == sorted([m.a.id, m.b.id]) for v in seeds.values())  # each seed, both seatings
        h = head_to_head(league, m.a.id, m.b.id)
        assert h["pairs"] >= m.pairs and (m.wins, m.draws, m.losses) == (h["wins"], h["draws"], h["losses"])
    league.close()


@pytest.mark.slow
def test_every_snapshot_rated_and_the_summary_is_the_ledger(tmp_path, capsys):
    """A tiny two-learner run through the CLI without a terminal: every snapshot of both learners has gauntlet games
    (predecessor, partner, bots); the plain progress lines appear on stderr, one per snapshot moment; the final
    summary (JSON and text) states exactly the ledger's numbers for each learner's final snapshot."""
    home = tmp_path / "h"
    args = ["train", "pong", "--agents", "2", "--steps", "4096", "--games", "16", "--env-option", "points_to_win=1",
            "--snapshot-steps", "2048", "--snapshot-every", "0", "--eval-games", "4", "--eval-playoff", "0",
            "--home", str(home)]
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    data = json.loads(out)
    lines = [ln for ln in err.splitlines() if ln.startswith("pong-1: ") and " rated " in ln]
    assert len(lines) == 3 and "rated s0-left (step 0): random " in lines[0] and "elapsed" in lines[-1], err
    variant = variant_key("pong", {"points_to_win": 1})  # the run's options: its games are rated in that variant
    with League.open(home) as league:
        snaps = league.roster.players("pong", kind="snapshot")
        bots = {p.name: p.id for p in league.roster.players("pong", kind="bot")}
        assert len(snaps) == 6
        for s in snaps:
            for bot_id in bots.values():
                assert head_to_head(league, s.id, bot_id, variant=variant)["games"] >= 2, s.name
                assert head_to_head(league, s.id, bot_id)["games"] == 0  # none in the default game's ratings
            if s.parent_id is not None:
                assert head_to_head(league, s.id, s.parent_id, variant=variant)["pairs"] >= 1, s.name
        assert ladder(league, "pong", bootstrap=0) == []
        rows = {r.policy: r for r in ladder(league, "pong", variant=variant)}  # as marl league ladder fits it
        finals = data["final"]
        assert [f["snapshot"] for f in finals] == data["snapshots"][-2:]
        assert [f["learner"] for f in finals] == ["left", "right"]
        for f in finals:
            p = league.roster.find_players(f["snapshot"], "pong")[0]
            for bot, rec in f["vs"].items():
                h = head_to_head(league, p.id, bots[bot], variant=variant)
                assert (rec["wins"], rec["draws"], rec["losses"], rec["games"]) == (
                    h["wins"], h["draws"], h["losses"], h["games"])
                assert rec["score"] == round(h["score"], 4) and rec["games"] >= 32  # 8 x --eval-games against a bot
                assert rec["score_low"] <= rec["score"] <= rec["score_high"]
            row = rows[f["snapshot"]]
            assert (f["elo"], f["ci_low"], f["ci_high"]) == (round(row.elo, 1), round(row.ci_low, 1),
                                                              round(row.ci_high, 1))
        (best,) = [r for r in rows.values() if r.best and r.run == "pong-1"]  # the run's best, as the ladder has it
        assert data["best"]["policy"] == best.policy and data["best"]["tied"] == list(best.tied)
    # the ladder the summary points to (marl league ladder --run) is the run's variant's, with the same figures
    code, out, err = run(capsys, "league", "ladder", "--run", "pong-1", "--bootstrap", "0", "--home", str(home),
                         "--json")
    shown = {r["policy"]: r for r in json.loads(out)}
    assert code == 0 and all(r["variant"] == {"points_to_win": 1} for r in shown.values())
    assert [shown[f["snapshot"]]["elo"] for f in finals] == [f["elo"] for f in finals]
    # the run's rating curves were drawn into its folder, as `marl league plot` draws them
    import matplotlib.image

    png = home / "runs" / "pong-1" / "ratings.png"
    assert data["plot"] == str(png) and matplotlib.image.imread(png).shape[2] in (3, 4)
    # the same run as text: the summary names each learner's final snapshot with its measured figures
    code, out, err = run(capsys, *args[:-2], "--home", str(tmp_path / "h2"))
    assert code == 0, err
    left, right = (ln.strip() for ln in out.splitlines() if ln.strip().startswith("pong-1/s"))
    assert left.startswith(finals[0]["snapshot"] + ": Elo ") and right.startswith(finals[1]["snapshot"] + ": Elo ")
    assert "vs random" in left and "vs cpu" in right
    import re

    for line in (left, right):  # each score with its interval, of the 32 games a final plays against each bot
        for low, high in re.findall(r"vs \w+ \d+% \[(\d+)%, (\d+)%\] of 32 games", line):
            assert int(low) <= int(high)
        assert len(re.findall(r"of 32 games", line)) == 2, line
    assert any(ln.strip().startswith("best of pong-1: ") for ln in out.splitlines()), out


def test_a_final_moment_meeting_every_earlier_snapshot_stands_alone(tmp_path):
    """A moment whose snapshots meet every earlier snapshot they may meet (a run's final, up to 24 of them) chooses
    nothing from the run's games: no best so far, every earlier snapshot once in the run's order, then the bots; so
    its plan is the same whatever its earlier gauntlets said, and it may be played before they are all in. One
    snapshot fewer than it could meet and it needs the best so far again."""
    from selfplay_cli.evaluation.gauntlet_plan import plan_moment, stands_alone

    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    rows = snapshot_rows(league, "r", 4)
    by = {r.name: r for r in rows}
    final = [by["ep3-left"].id, by["ep3-right"].id]
    # each meets its partner and predecessor, and the 5 other earlier snapshots
    assert stands_alone(league, final, 5) and stands_alone(league, final, 24)
    assert not stands_alone(league, final, 4)
    assert stands_alone(league, [by["ep1-left"].id, by["ep1-right"].id], 1)  # (ep0 of the other side only)
    before = plan_moment(league, final, 24)
    met = [b.name for a, b in before.pairs if a.name == "ep3-left"]
    assert met == ["ep2-left", "ep3-right", "ep0-left", "ep0-right", "ep1-left", "ep1-right", "ep2-right",
                   "random", "cpu"]
    _gauntlet_games(league, by["ep1-right"], by["ep0-left"], [1] * 12)  # the earlier gauntlets come in: a best
    _gauntlet_games(league, by["ep2-left"], by["ep1-right"], [1] * 12)
    assert best_snapshot(run_history(league, [by["ep3-left"]])).name == "ep2-left"
    after = plan_moment(league, final, 24)
    assert [(a.id, b.id) for a, b in after.pairs] == [(a.id, b.id) for a, b in before.pairs]
    # with fewer older opponents than there are earlier snapshots, the best so far is chosen: right after the
    # predecessor (ep3-right met ep3-left in the left one's list)
    fewer = plan_moment(league, final, 2)
    assert [b.name for a, b in fewer.pairs if a.name == "ep3-right"][:2] == ["ep2-right", "ep2-left"]
    assert len([b for a, b in fewer.pairs if a.name == "ep3-right"]) == 2 + 2 + 2  # pred, best, 2 older, 2 bots
    league.close()


@pytest.mark.slow
def test_a_failing_gauntlet_in_the_worker_comes_back_as_one_error(tmp_path):
    """The rating worker reports a job's failure (here: a snapshot id the league does not have) instead of dying
    silently, and the trainer raises it as one line."""
    import pytest

    from selfplay_cli.errors import MarlError
    from selfplay_cli.evaluation.executors.base import GauntletJob
    from selfplay_cli.evaluation.executors.local import Evaluator

    league = League.open(tmp_path / "league")
    with Evaluator(league, "cpu", background=True) as ev:
        ev.submit(GauntletJob((424242,), 0, 4, 2))
        with pytest.raises(MarlError, match="rating games failed: .*424242"):
            ev.wait()
    with Evaluator(league, "cpu", background=True) as ev:  # jobs queued behind the failing one: its error, still
        for k in range(3):
            ev.submit(GauntletJob((424242 + k,), 0, 4, 2))
        with pytest.raises(MarlError, match="rating games failed: .*424242"):
            ev.wait()
    league.close()


def _stand_ins(monkeypatch, module, league, who):
    """Scripted players stand in for snapshots (``who``: player id -> bot name); no files are read."""

    def fake_load(lg, row, device="cpu", greedy=None, seed=0):
        p = ScriptedPolicy("pong", who.get(row.id, row.name), seed=seed)
        p.id = row.full_name
        return p

    monkeypatch.setattr(module, "load_player", fake_load)


def _gauntlet_games(league, a, b, a_points):
    """Gauntlet games of A against B, one per entry of ``a_points`` (1, 0.5, 0)."""
    mid = league.ledger.create_match("pong", "eval", {"gauntlet": True})
    league.ledger.record_games(mid, [GameResult("pong", (a.id, b.id), seed=i, scores=(p, 1 - p), outcome=(p, 1 - p),
                                                length=10, truncated=False) for i, p in enumerate(a_points)])


def test_the_playoff_separates_the_best_and_stops_there(tmp_path, monkeypatch):
    """A 3-1 lead after the gauntlet names no best beyond doubt; the playoff plays the two (cpu against random
    standing in) round after round until the ladder separates them, well before its cap, and not again after."""
    import selfplay_cli.evaluation.gauntlet as gauntlet_mod
    from selfplay_cli.evaluation.playoff import PlayoffConfig, playoff

    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    old, new = snapshot_rows(league, "r", 2, learners=("left",))
    bots = {p.name: p for p in league.roster.players("pong", kind="bot")}
    _gauntlet_games(league, new, old, [1, 1, 1, 0])
    _gauntlet_games(league, new, bots["random"], [1] * 4)
    _gauntlet_games(league, old, bots["random"], [1] * 4)
    assert not ladder(league, "pong", bootstrap=0)[0].margin.separated
    _stand_ins(monkeypatch, gauntlet_mod, league, {new.id: "cpu", old.id: "random"})
    played = playoff(league, [new.id], first_seed=1000, config=PlayoffConfig(max_games=200, round_games=10))
    assert 0 < played < 200 and played % 10 == 0, played  # whole rounds, stopped once separated
    rows = ladder(league, "pong", bootstrap=0)
    best = next(r for r in rows if r.best)
    assert best.policy == "r/ep1-left" and best.best_margin.separated and best.tied == ()
    h = head_to_head(league, new.id, old.id)
    assert h["games"] == 4 + played and h["pairs"] >= played // 2  # seat-swapped pairs, on fresh seeds
    table = league.ledger.games("pong")
    playoff_matches = [m for m, p in league.ledger.match_params("pong").items() if p.get("playoff")]
    assert playoff_matches and all(league.ledger.match_info(m)[1]["gauntlet"] for m in playoff_matches)
    assert playoff(league, [new.id], first_seed=5000, config=PlayoffConfig(max_games=200, round_games=10)) == 0
    assert len(league.ledger.games("pong")) == len(table)
    league.close()


@pytest.mark.slow
def test_a_playoff_between_equals_stops_at_its_cap_and_the_ladder_says_tied(tmp_path, monkeypatch):
    import selfplay_cli.evaluation.gauntlet as gauntlet_mod
    from selfplay_cli.evaluation.playoff import PlayoffConfig, playoff

    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    a, b = snapshot_rows(league, "r", 1)
    rnd = league.roster.find_players("random", "pong")[0]
    _gauntlet_games(league, a, b, [1, 0, 1, 0])
    _gauntlet_games(league, a, rnd, [1] * 4)
    _gauntlet_games(league, b, rnd, [1] * 4)
    _stand_ins(monkeypatch, gauntlet_mod, league, {a.id: "random", b.id: "random"})
    played = playoff(league, [a.id, b.id], first_seed=1000, config=PlayoffConfig(max_games=24, round_games=10))
    assert played == 20, played  # 4 + 20 = 24 games between the two: the cap, in rounds of 10
    assert head_to_head(league, a.id, b.id)["games"] == 24
    rows = ladder(league, "pong", bootstrap=0)
    best = next(r for r in rows if r.best)  # random against random (fixed seeds): tied, and the ladder says so
    assert not best.best_margin.separated and len(best.tied) == 1
    assert f"best of r: {best.policy} by Elo, not separated from {best.tied[0]}" in "\n".join(verdict_lines(rows))
    league.close()


@pytest.mark.slow
def test_a_final_gauntlet_plays_the_bots_in_full_whatever_the_history(tmp_path, monkeypatch):
    """A run reports its final snapshots' scores against the bots: those matchups get ``bot_pairs``; the others keep
    the usual pairs, each on a seed range of its own."""
    import selfplay_cli.evaluation.gauntlet as gauntlet_mod

    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    old, new = snapshot_rows(league, "r", 2, learners=("left",))
    bots = {p.name: p for p in league.roster.players("pong", kind="bot")}
    _stand_ins(monkeypatch, gauntlet_mod, league, {old.id: "cpu", new.id: "cpu"})
    pairs = [(new, old), (new, bots["random"]), (new, bots["cpu"])]
    ms = play_gauntlet(league, pairs, first_seed=0, config=GauntletConfig(pairs=2, bot_pairs=16))
    assert [m.games for m in ms] == [4, 32, 32]
    assert len({s for s in league.ledger.games("pong").seed.tolist()}) >= 16 + 16 + 2  # disjoint seed ranges
    league.close()


@pytest.mark.slow
def test_a_run_repeated_with_its_seed_is_the_same_players_rated_once(tmp_path, capsys):
    """The same command and seed twice in one league: bit-identical weights under new names. The second run plays
    no rating game its first already played (they would be the same games, counted twice), its snapshots show the
    first run's ratings, and a match of two names of one set of weights is refused in one line."""
    home = tmp_path / "h"
    args = ["train", "pong", "--agents", "2", "--steps", "4096", "--games", "16", "--env-option", "points_to_win=1",
            "--snapshot-steps", "2048", "--eval-games", "4", "--home", str(home), "--json"]
    code, out, err = run(capsys, *args)
    assert code == 0, err
    first = json.loads(out)
    code, out, err = run(capsys, *args)
    assert code == 0, err
    second = json.loads(out)
    assert (first["run"], second["run"]) == ("pong-1", "pong-2")
    with League.open(home) as league:
        same = league.ledger.same_weights("pong")
        snaps = {p.full_name: p for p in league.roster.players("pong", kind="snapshot")}
        assert {snaps[n].id for n in second["snapshots"]} == set(same)  # every snapshot of pong-2 is a copy
        assert {same[snaps[n].id] for n in second["snapshots"]} == {snaps[n].id for n in first["snapshots"]}
    assert second["rating_games"] == 0 and first["rating_games"] > 0
    for a, b in zip(first["final"], second["final"], strict=True):
        assert (a["elo"], a["ci_low"], a["ci_high"]) == (b["elo"], b["ci_low"], b["ci_high"])
    code, out, err = run(capsys, "match", "pong-1/s4.1k-left", "pong-2/s4.1k-left", "--home", str(home))
    assert code == 2 and "hold the same weights" in err and len(err.strip().splitlines()) == 1


def _rating_games(home):
    """Every rated game of a league, by the names of its players: what a run's gauntlets played, comparable across
    leagues (player ids and game ids are the league's own)."""
    with League.open(home) as league:
        names = {p.id: p.full_name for p in league.roster.players(include_removed=True)}
        t = league.ledger.games(variant=None, pooled=False)
        return sorted(zip((names[int(a)] for a in t.player_a), (names[int(b)] for b in t.player_b),
                          t.seed.tolist(), t.score_a.tolist(), t.length.tolist(), strict=True))


@pytest.mark.slow
def test_the_rating_games_repeat_with_the_seed_whatever_the_timing(tmp_path, capsys):
    """The same command and seed in two homes, once with the gauntlets in a worker beside training (which may fall
    behind) and once inline (never behind): the same weights, and the very same rating games, playoff included.
    (This is also the check that one command with one seed stores the same gauntlet games twice over, which
    test_worker.py ran on two more runs of its own.)"""
    base = ["train", "pong", "--agents", "2", "--steps", "4096", "--games", "16", "--env-option", "points_to_win=1",
            "--snapshot-steps", "2048", "--eval-games", "4", "--seed", "3", "--json"]
    code, out, err = run(capsys, *base, "--home", str(tmp_path / "worker"))
    assert code == 0, err
    worker = json.loads(out)
    code, out, err = run(capsys, *base, "--eval-inline", "--home", str(tmp_path / "inline"))
    assert code == 0, err
    inline = json.loads(out)
    games = _rating_games(tmp_path / "worker")
    assert games and games == _rating_games(tmp_path / "inline")
    assert worker["rating_games"] == inline["rating_games"] and worker["final"] == inline["final"]
    assert worker["best"] == inline["best"]


def test_a_matchup_plays_the_games_an_even_record_needs_for_the_precision():
    """The width of a record's prediction against scipy's beta-binomial (the pair's score under a uniform prior,
    ``Beta(1 + W, 1 + L)``, then a 200-game match): 8-0 predicts [66%, 100%] (0.34 wide: ``Beta(9, 1)`` leaves the
    score anywhere above ``0.025 ** (1 / 9)``), 16-0 [80%, 100%], 5-3 [29%, 87%]. Draws narrow it: 16-16-0 is
    narrower than 24-0-8 of the same mean, and 8 draws of 8 do not predict a certain 50%. An even record is the
    widest, so a matchup plays (all at once) the rounds with which an even record would be narrow enough: at least
    --eval-games', at most 4 times as many; the cap at 0.3 (16-16 is 0.36 wide, 32-32 0.27); --eval-games exactly
    without a precision."""
    from scipy.stats import betabinom

    from selfplay_cli.evaluation.gauntlet_jobs import PRECISE_PAIRS, precise_pairs
    from selfplay_cli.stats.belief import record_prediction

    def width(w, d, lost):
        return record_prediction(w, d, lost, 200).width

    for w, lost in ((8, 0), (16, 0), (5, 3), (14, 2), (48, 16)):
        exact = betabinom(200, 1 + w, 1 + lost)
        assert width(w, 0, lost) == pytest.approx((exact.ppf(0.975) - exact.ppf(0.025)) / 200, abs=0.006)
    assert width(8, 0, 0) == pytest.approx(1.0 - 0.66, abs=0.006)
    assert width(16, 0, 0) == pytest.approx(0.20, abs=0.006)
    assert width(16, 16, 0) < width(24, 0, 8) - 0.05  # the same mean, without draws
    assert 0.2 < width(0, 8, 0) < width(4, 0, 4)  # all draws: narrower, not certain
    assert width(16, 0, 16) == pytest.approx(0.36, abs=0.006) and width(32, 0, 32) == pytest.approx(0.27, abs=0.006)

    assert PRECISE_PAIRS == 4
    assert precise_pairs(4, 2, 0.0) == 4  # no precision: --eval-games exactly
    assert precise_pairs(4, 2, 0.30) == 16  # 32 games (16-16) are still 0.36 wide: the cap
    assert precise_pairs(4, 2, 0.35) == 16 and precise_pairs(4, 2, 0.37) == 15  # 15-15 is 0.37 wide
    even = [(k, width(k, 0, k)) for k in range(4, 17)]  # (a pair is 2 games: k-k after k pairs)
    assert precise_pairs(4, 2, 0.46) == min(k for k, wd in even if wd <= 0.46) < 16
    assert precise_pairs(4, 2, 0.70) == 4  # 4-4 is 0.59 wide: --eval-games is enough
    assert precise_pairs(8, 1, 0.46) == min(g for g in range(8, 33) if width(g // 2, g % 2, g // 2) <= 0.46)
    assert precise_pairs(1, 2, 0.30) == 4 and precise_pairs(1, 1, 0.99) == 1


def test_a_playoff_round_plays_all_its_pairs_in_one_batch_each_to_its_own_size(tmp_path, monkeypatch):
    """Two rivals with different games left before the cap (20 and 6 of 24) play one round together, one batch
    (a round waits for its longest game, so a second batch would double the wait), each to its own size and on
    seeds of its own."""
    import selfplay_cli.evaluation.gauntlet as gauntlet_mod
    from selfplay_cli.evaluation.playoff import PlayoffConfig, playoff

    league = League.open(tmp_path / "league")
    league.roster.ensure_bots("pong", ["random", "cpu"])
    s0, s1, s2 = snapshot_rows(league, "r", 3, learners=("left",))
    rnd = league.roster.find_players("random", "pong")[0]
    _gauntlet_games(league, s2, s1, [1, 0, 1, 0])  # 4 games: 20 left
    _gauntlet_games(league, s2, s0, [1, 0] * 9)  # 18 games: 6 left
    for s, points in ((s0, [1, 0, 1, 0]), (s1, [1, 0, 1, 0]), (s2, [1, 1, 1, 0])):  # s2 the top, not separated
        _gauntlet_games(league, s, rnd, points)
    _stand_ins(monkeypatch, gauntlet_mod, league, {s0.id: "random", s1.id: "random", s2.id: "random"})
    batches = []
    real_play = gauntlet_mod.play
    monkeypatch.setattr(gauntlet_mod, "play", lambda *a, **k: batches.append(len(a[2])) or real_play(*a, **k))
    played = playoff(league, [s2.id], first_seed=1000,
                     config=PlayoffConfig(max_games=24, round_games=10, max_rounds=1))
    assert batches == [16] and played == 16  # 10 + 6 games, in one batch
    assert head_to_head(league, s2.id, s1.id)["games"] == 4 + 10
    assert head_to_head(league, s2.id, s0.id)["games"] == 18 + 6
    playoff_matches = [m for m, p in league.ledger.match_params("pong").items() if p.get("playoff")]
    firsts = sorted(league.ledger.match_info(m)[1]["first_seed"] for m in playoff_matches)
    assert len(playoff_matches) == 2 and firsts[0] == 1000 and firsts[1] in (1003, 1005)  # seeds of its own each
    league.close()
