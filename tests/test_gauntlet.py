"""Every snapshot is rated: the gauntlet after each snapshot (opponents, seat-swapped pairs, fewer games where the
result is already clear), the end-of-run summary equal to the ledger, progress lines without a terminal."""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
from cli_helpers import run

from selfplay_cli.arena import Game, play
from selfplay_cli.league.ladder import ladder
from selfplay_cli.league.pairs import head_to_head
from selfplay_cli.league.store import League
from selfplay_cli.league.variants import variant_key
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.rated.gauntlet import GauntletConfig, choose_opponents, clear, play_gauntlet
from selfplay_cli.results import GameResult


def snapshot_rows(league: League, run: str, n: int, learners=("left", "right")) -> list:
    """n snapshot moments of a two-learner run (files are never read: the tests below seat bots only)."""
    league.create_run(run, "pong", {}, algo="ppo")
    latest = {name: None for name in learners}
    rows = []
    for k in range(n):
        for name in learners:
            row = league.add_snapshot(env="pong", run=run, name=f"ep{k}-{name}", path=f"x/{k}{name}", sha256="0" * 64,
                                      step=1000 * k, parent_id=latest[name], meta={"learner": name})
            latest[name] = row.id
            rows.append(row)
    return rows


def test_gauntlet_opponents_predecessor_partner_best_older_and_bots(tmp_path):
    league = League.open(tmp_path / "league")
    league.ensure_bots("pong", ["random", "cpu"])
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


def test_clear_rule():
    assert clear(4, 0, 1.645) and not clear(3, 1, 1.645) and not clear(0, 0, 1.645) and clear(0, 9, 1.645)


def test_gauntlet_games_come_in_seat_swapped_pairs_and_fewer_where_clear(tmp_path, monkeypatch):
    """Scripted players stand in for the snapshots (same league rows, no files): every matchup is stored in pairs,
    each seed once with either player on the left; a matchup the predecessor already won clearly plays one pair."""
    import selfplay_cli.rated.gauntlet as gauntlet_mod

    league = League.open(tmp_path / "league")
    league.ensure_bots("pong", ["random", "cpu"])
    rows = snapshot_rows(league, "r", 2, learners=("left",))
    old, new = rows
    bots = {p.name: p for p in league.players("pong", kind="bot")}
    # the predecessor beat random 8-0 in stored games, so random is clear; cpu is not
    mid = league.create_match("pong", "eval")
    league.record_games(mid, [GameResult("pong", (old.id, bots["random"].id), seed=i, scores=(1, 0),
                                         outcome=(1.0, 0.0), length=10, truncated=False) for i in range(8)])
    stand_in = {old.id: "cpu", new.id: "cpu"}

    def fake_load(lg, row, device="cpu", greedy=None, seed=0):
        p = ScriptedPolicy("pong", stand_in.get(row.id, row.name), seed=seed)
        p.id = row.full_name
        return p

    monkeypatch.setattr(gauntlet_mod, "load_player", fake_load)
    pairs = [(new, old), (new, bots["random"]), (new, bots["cpu"])]
    cfg = GauntletConfig(pairs=2, clear_pairs=1, max_pairs=2)
    ms = play_gauntlet(league, pairs, first_seed=500, config=cfg, policies=None)
    assert [m.pairs for m in ms] == [2, 1, 2]
    table = league.games("pong")
    for m in ms:
        sub = table.select(np.isin(table.match_id, [m.match_id]))
        assert len(sub) == 2 * m.pairs == m.games
        seeds = defaultdict(list)
        for s, a in zip(sub.seed.tolist(), sub.player_a.tolist(), strict=True):
            seeds[s].append(a)
        assert all(sorted(v) == sorted([m.a.id, m.b.id]) for v in seeds.values())  # each seed, both seatings
        h = head_to_head(league, m.a.id, m.b.id)
        assert h["pairs"] >= m.pairs and (m.wins, m.draws, m.losses) == (
            h["wins"] - (8 if m.b.name == "random" and m.a.id == old.id else 0), h["draws"], h["losses"])
    league.close()


def test_open_matchups_go_on_in_the_same_batch(tmp_path, monkeypatch):
    """With max_pairs above pairs, a matchup whose result is still open gets more pairs, played in the same call of
    the runner (the schedule grows while it plays); a clear one stops."""
    import selfplay_cli.rated.gauntlet as gauntlet_mod

    calls = []
    real_play = gauntlet_mod.play

    def counting_play(*args, **kwargs):
        calls.append(1)
        return real_play(*args, **kwargs)

    monkeypatch.setattr(gauntlet_mod, "play", counting_play)
    league = League.open(tmp_path / "league")
    league.ensure_bots("pong", ["random", "cpu"])
    bots = {p.name: p for p in league.players("pong", kind="bot")}
    (snap,) = snapshot_rows(league, "r", 1, learners=("left",))

    def fake_load(lg, row, device="cpu", greedy=None, seed=0):
        p = ScriptedPolicy("pong", "random" if row.id == snap.id else row.name, seed=seed)
        p.id = row.full_name
        return p

    monkeypatch.setattr(gauntlet_mod, "load_player", fake_load)
    ms = play_gauntlet(league, [(snap, bots["random"]), (snap, bots["cpu"])], first_seed=0,
                       config=GauntletConfig(pairs=2, clear_pairs=1, max_pairs=8))
    vs_random, vs_cpu = ms
    assert len(calls) == 1
    assert vs_cpu.pairs == 2 and vs_cpu.losses == 4  # random against cpu: lost 4-0, clear after the first batch
    assert vs_random.pairs > 2 or clear(vs_random.wins, vs_random.losses, 1.645)  # random vs random: usually open
    assert len(league.games("pong")) == sum(m.games for m in ms)
    league.close()


def test_play_takes_games_appended_while_it_plays():
    """The runner plays games that on_result appends to the schedule, in free slots of the same batch."""
    spec_policies = [ScriptedPolicy("pong", "cpu"), ScriptedPolicy("pong", "cpu")]  # deterministic players
    spec_policies[1].id = "cpu2"
    schedule = [Game(1, (0, 1))]

    def more(r):
        if len(schedule) < 5:
            schedule.extend([Game(10 + len(schedule), (1, 0)), Game(20 + len(schedule), (0, 1))])

    results = play("pong", spec_policies, schedule, env_options={"points_to_win": 2}, on_result=more, slots=8)
    assert len(results) == len(schedule) == 5 and [r.index for r in results] == list(range(5))
    alone = play("pong", spec_policies, schedule[3:4], env_options={"points_to_win": 2})
    assert (results[3].scores, results[3].length) == (alone[0].scores, alone[0].length)  # same game either way
    assert results[3].players == ("cpu2", "cpu") and results[4].players == ("cpu", "cpu2")


def test_every_snapshot_rated_and_the_summary_is_the_ledger(tmp_path, capsys):
    """A tiny two-learner run through the CLI without a terminal: every snapshot of both learners has gauntlet games
    (predecessor, partner, bots); the plain progress lines appear on stderr, one per snapshot moment; the final
    summary (JSON and text) states exactly the ledger's numbers for each learner's final snapshot."""
    home = tmp_path / "h"
    args = ["train", "pong", "--agents", "2", "--steps", "4096", "--games", "16", "--env-option", "points_to_win=1",
            "--snapshot-steps", "2048", "--snapshot-every", "0", "--eval-games", "4", "--home", str(home)]
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    data = json.loads(out)
    lines = [ln for ln in err.splitlines() if ln.startswith("pong-1: ") and " rated " in ln]
    assert len(lines) == 3 and "rated s0-left (step 0): random " in lines[0] and "elapsed" in lines[-1], err
    variant = variant_key("pong", {"points_to_win": 1})  # the run's options: its games are rated in that variant
    with League.open(home) as league:
        snaps = league.players("pong", kind="snapshot")
        bots = {p.name: p.id for p in league.players("pong", kind="bot")}
        assert len(snaps) == 6
        for s in snaps:
            for bot_id in bots.values():
                assert head_to_head(league, s.id, bot_id, variant=variant)["games"] >= 2, s.name
                assert head_to_head(league, s.id, bot_id)["games"] == 0  # none in the default game's ratings
            if s.parent_id is not None:
                assert head_to_head(league, s.id, s.parent_id, variant=variant)["pairs"] >= 1, s.name
        assert ladder(league, "pong", bootstrap=0) == []
        rows = {r.policy: r for r in ladder(league, "pong", bootstrap=0, variant=variant)}
        finals = data["final"]
        assert [f["snapshot"] for f in finals] == data["snapshots"][-2:]
        assert [f["learner"] for f in finals] == ["left", "right"]
        for f in finals:
            p = league.find_players(f["snapshot"], "pong")[0]
            for bot, rec in f["vs"].items():
                h = head_to_head(league, p.id, bots[bot], variant=variant)
                assert (rec["wins"], rec["draws"], rec["losses"], rec["games"]) == (
                    h["wins"], h["draws"], h["losses"], h["games"])
                assert rec["score"] == round(h["score"], 4)
            row = rows[f["snapshot"]]
            assert (f["elo"], f["ci_low"], f["ci_high"]) == (round(row.elo, 1), round(row.ci_low, 1),
                                                              round(row.ci_high, 1))
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
    assert "vs random" in left and "vs cpu" in right and "games)" in right


def test_a_clear_history_that_no_longer_holds_gets_the_full_pairs(tmp_path, monkeypatch):
    """The predecessor lost 0-8 to random; the new snapshot (cpu standing in) wins its first pair, against that
    history: the matchup goes on to the full number of pairs, in the same call of the runner."""
    import selfplay_cli.rated.gauntlet as gauntlet_mod

    league = League.open(tmp_path / "league")
    league.ensure_bots("pong", ["random", "cpu"])
    old, new = snapshot_rows(league, "r", 2, learners=("left",))
    rnd = league.find_players("random", "pong")[0]
    mid = league.create_match("pong", "eval")
    league.record_games(mid, [GameResult("pong", (rnd.id, old.id), seed=i, scores=(1, 0), outcome=(1.0, 0.0),
                                         length=10, truncated=False) for i in range(8)])

    def fake_load(lg, row, device="cpu", greedy=None, seed=0):
        p = ScriptedPolicy("pong", "cpu" if row.id == new.id else row.name, seed=seed)
        p.id = row.full_name
        return p

    monkeypatch.setattr(gauntlet_mod, "load_player", fake_load)
    (m,) = play_gauntlet(league, [(new, rnd)], first_seed=0, config=GauntletConfig(pairs=3, clear_pairs=1, max_pairs=3))
    assert m.expect == 0.0 and m.pairs == 3 and m.wins == 6, (m.pairs, m.wins)
    league.close()


def test_a_failing_gauntlet_in_the_worker_comes_back_as_one_error(tmp_path):
    """The rating worker reports a job's failure (here: a snapshot id the league does not have) instead of dying
    silently, and the trainer raises it as one line."""
    import pytest

    from selfplay_cli.errors import MarlError
    from selfplay_cli.train.evaluator import Evaluator, GauntletJob

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
