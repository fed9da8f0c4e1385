"""`marl train`: snapshots in the league with names and lineage, the ledger gets the games, clear errors."""

from __future__ import annotations

import json
import tempfile

import numpy as np
import pytest
from cli_helpers import run

from selfplay_cli.algos.ppo import PPOConfig
from selfplay_cli.cli import main
from selfplay_cli.league.store import League
from selfplay_cli.league.variants import variant_key
from selfplay_cli.play.seat_plan import OPPONENT
from selfplay_cli.policies.snapshot_policy import load_policy
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.loop import Trainer
from selfplay_cli.train.matchmaking import MatchmakerConfig

TINY = variant_key("pong", {"points_to_win": 1})  # the variant tiny runs play and are rated in


def tiny(**kw) -> TrainConfig:
    base = dict(env="pong", steps=12_288, games=16, snapshot_every=16, eval_games=4, run="t",
                env_options={"points_to_win": 1}, ppo=PPOConfig(rollout_steps=32, minibatches=2, update_epochs=1))
    base.update(kw)
    return TrainConfig(**base)


@pytest.mark.slow
def test_two_learners_snapshot_into_the_league_with_lineage(tmp_path):
    league = League.open(tmp_path / "league")
    cfg = tiny(agents=2, sharing="nops")
    league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
    report = Trainer(league, cfg).train()
    assert report.steps >= 12_288 and report.episodes > 16  # 60-70 measured on seeds 0-5: one-point games end fast
    snaps = [p for p in league.roster.players("pong", kind="snapshot")]
    names = [p.name for p in snaps]
    assert names[:2] == ["s0-left", "s0-right"]
    assert all(n.startswith(("ep", "s")) and n.endswith(("-left", "-right")) for n in names)
    assert len(names) == len(set(names)) >= 4
    by_id = {p.id: p for p in snaps}
    for seat in ("left", "right"):
        chain = [p for p in snaps if p.name.endswith(seat)]
        assert chain[0].parent_id is None
        for prev, cur in zip(chain, chain[1:], strict=False):
            assert cur.parent_id == prev.id and by_id[cur.parent_id].name.endswith(seat)
            assert cur.episode >= prev.episode and cur.step > prev.step
    # every snapshot file loads (checksum verified) and plays
    last = snaps[-1]
    policy = load_policy(league.home / last.path, expect_env="pong")
    assert policy.meta.seat == "right" and policy.meta.env_options == {"points_to_win": 1}
    # the ledger keeps the training games between the learners, but rates only games the snapshots played themselves
    everything, rated = league.ledger.games("pong", rated=False, variant=TINY), league.ledger.games("pong",
                                                                                                    variant=TINY)
    assert len(everything) > len(rated) > 0
    with league.session() as s:
        from selfplay_cli.league.models import Match

        kinds = {m.id: m.kind for m in s.query(Match).all()}
    assert {kinds[m] for m in rated.match_id.tolist()} == {"eval"}
    assert "training" in {kinds[m] for m in everything.match_id.tolist()}
    bots = {p.id for p in league.roster.players("pong", kind="bot")}
    for snap in snaps:  # every snapshot of both learners was rated against both scripted players
        for bot in bots:
            assert league.ledger.games("pong", players=[snap.id, bot], variant=TINY).game_id.size >= 2, (snap.name, bot)
    lines = (league.home / "runs" / "t" / "metrics.jsonl").read_text().splitlines()
    assert len(lines) >= 3 and "left/entropy" in json.loads(lines[-1])
    league.close()


@pytest.mark.slow
def test_one_learner_meets_league_opponents_and_bots(tmp_path):
    league = League.open(tmp_path / "league")
    cfg = tiny(agents=1, opponents=MatchmakerConfig(mode="pfsp", bots={"cpu": 0.5}, latest_ratio=0.2))
    league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
    Trainer(league, cfg).train()
    snaps = league.roster.players("pong", kind="snapshot")
    assert [p.name for p in snaps][0] == "s0" and all("-" not in p.name for p in snaps)
    matches = {}
    with league.session() as s:
        from selfplay_cli.league.models import Match

        for m in s.query(Match).all():
            matches[m.id] = m.kind
    table = league.ledger.games("pong", rated=False, variant=TINY)
    cpu = league.roster.find_players("cpu", "pong")[0].id
    training = [i for i, m in enumerate(table.match_id.tolist()) if matches[m] == "training"]
    assert any(cpu in (table.player_a[i], table.player_b[i]) for i in training), "games vs cpu from the mix"
    league.close()


@pytest.mark.slow
def test_two_learners_with_league_games_meet_league_opponents_on_their_own_seats(tmp_path):
    """--league-games with --agents 2: that share of games seats one learner (on its own side) against an opponent
    drawn for *that* learner; the rest are learner against learner. The ledger and PFSP's win rates get them."""
    league = League.open(tmp_path / "league")
    cfg = tiny(agents=2, sharing="nops", league_games=0.5, steps=8192,
               opponents=MatchmakerConfig(mode="pfsp", bots={"cpu": 1.0}))
    league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
    trainer = Trainer(league, cfg)
    layout = trainer.games.layout
    assert (layout == OPPONENT).sum() == cfg.games // 2, "half the games have one opponent seat"
    league_games = np.flatnonzero((layout == OPPONENT).any(axis=0))
    for g in league_games.tolist():  # the left learner plays left, the right learner right, taking turns
        learner = int(layout.max(axis=0)[g])
        assert layout[learner, g] == learner and layout[1 - learner, g] == OPPONENT
    assert sorted(set(layout.max(axis=0)[league_games].tolist())) == [0, 1]
    trainer.train()
    cpu = league.roster.find_players("cpu", "pong")[0].id
    with league.session() as s:
        from selfplay_cli.league.models import Match

        training = {m.id for m in s.query(Match).all() if m.kind == "training"}
    snaps = {p.id: p for p in league.roster.players("pong", kind="snapshot")}
    table = league.ledger.games("pong", rated=False, variant=TINY)
    seen = set()
    for m, a, b in zip(table.match_id.tolist(), table.player_a.tolist(), table.player_b.tolist(), strict=True):
        if m in training and cpu in (a, b):
            seat = 0 if b == cpu else 1
            seen.add((seat, snaps[a if seat == 0 else b].meta["learner"]))
    assert seen == {(0, "left"), (1, "right")}, seen  # each learner met cpu, always on its own side
    assert {pair[0] for pair in trainer.opponents.rates.to_dict()["pairs"]} == {0, 1}, "win rates per learner (PFSP)"
    league.close()


def test_training_games_keep_their_actions_and_replay_exactly(tmp_path, capsys):
    """Training games go to the ledger with their actions and game options, so `marl record --game ID` re-renders a
    game two learners played exactly as it went (score and length checked by the replay itself)."""
    home = tmp_path / "h"
    code, out, err = run(capsys, "train", "pong", "--agents", "2", "--steps", "6144", "--games", "16", "--env-option",
                         "points_to_win=1", "--eval-games", "0", "--snapshot-every", "8", "--home", str(home))
    assert code == 0, err
    with League.open(home) as league:
        with league.session() as s:
            from selfplay_cli.league.models import Game, Match

            training = s.query(Game).join(Match, Game.match_id == Match.id).filter(Match.kind == "training").all()
            assert training and all(g.actions for g in training)
            gid = training[-1].id
        stored = league.ledger.game(gid)
    assert stored.match_params["env_options"] == {"points_to_win": 1}
    code, out, err = run(capsys, "record", "--game", str(gid), "--size", "96x48", "--hold", "0", "--home", str(home),
                         "--json")
    assert code == 0, err
    (rec,) = json.loads(out)
    assert rec["scores"] == [int(x) for x in stored.scores] and rec["length"] == stored.length


def test_snapshots_by_steps_when_games_are_long(tmp_path):
    """--snapshot-steps: a snapshot every N game steps even when no game ends (good players rally long), named by
    the step of the schedule it stands for (the final one by the budget), each with the previous one as parent."""
    league = League.open(tmp_path / "league")
    cfg = tiny(agents=1, snapshot_every=10**6, snapshot_steps=4096, steps=12_288, eval_games=0,
               env_options={"points_to_win": 21})
    league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
    Trainer(league, cfg).train()
    snaps = sorted(league.roster.players("pong", kind="snapshot"), key=lambda p: p.id)
    assert [p.step for p in snaps] == [0, 4096, 8192, 12_288]
    assert [p.name for p in snaps] == ["s0", "s4.1k", "s8.19k", "s12.3k"]
    assert [p.parent_id for p in snaps] == [None] + [p.id for p in snaps[:-1]]
    league.close()


@pytest.mark.slow
def test_a_run_repeats_exactly_with_learners_updating_in_threads(tmp_path, monkeypatch):
    """Two learners update side by side in threads; each draws only from its own generator, so the same seed gives
    bit-identical snapshots, and the same as updating one after the other."""
    import selfplay_cli.train.loop as loop
    from selfplay_cli.train.team import LearnerTeam

    def weights(home, threads):
        monkeypatch.setattr(loop, "LearnerTeam", lambda learners: LearnerTeam(learners, threads=threads))
        league = League.open(home)
        cfg = tiny(agents=2, sharing="nops", steps=4096, eval_games=0)
        league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
        Trainer(league, cfg).train()
        out = {p.name: p.meta["weights_sha256"] for p in league.roster.players("pong", kind="snapshot")}
        league.close()
        return out

    threaded = weights(tmp_path / "a", True)
    assert len(threaded) >= 4 and threaded == weights(tmp_path / "b", True) == weights(tmp_path / "c", False)


def test_train_flag_defaults_are_the_config_defaults():
    """The command spells its defaults out (so `marl train --help` needs no torch import); they must be TrainConfig's,
    or `--help` would show one budget and a run use another."""
    import inspect

    from selfplay_cli.commands.train import train

    cfg, mm = TrainConfig(env="pong"), MatchmakerConfig()
    params = inspect.signature(train).parameters
    flags = {"agents": cfg.agents, "algo": cfg.algo, "sharing": cfg.sharing, "steps": cfg.steps, "seed": cfg.seed,
             "games": cfg.games, "snapshot_every": cfg.snapshot_every, "snapshot_steps": cfg.snapshot_steps,
             "swap_every": cfg.swap_every, "league_games": cfg.league_games, "eval_games": cfg.eval_games,
             "eval_older": cfg.eval_older, "eval_inline": cfg.eval_inline, "eval": cfg.eval, "eval_wait": cfg.eval_wait,
             "eval_actors": cfg.eval_actors,
             "opponents": mm.mode, "window": mm.window, "latest_ratio": mm.latest_ratio, "device": cfg.device}
    assert {k: params[k].default for k in flags} == flags



@pytest.mark.slow
def test_train_command_runs_and_reports(tmp_path, capsys):
    code, out, err = run(capsys, "train", "pong", "--agents", "2", "--steps", "4096", "--games", "16",
                         "--env-option", "points_to_win=1", "--snapshot-every", "32", "--home",
                         str(tmp_path / "h"), "--json")
    assert code == 0, err
    data = json.loads(out)
    assert data["run"] == "pong-1" and data["steps"] >= 4096 and data["snapshots"][:2] == ["pong-1/s0-left",
                                                                                           "pong-1/s0-right"]
    config = json.loads((tmp_path / "h" / "runs" / "pong-1" / "config.json").read_text())
    assert config["agents"] == 2 and config["env_options"] == {"points_to_win": 1}
    with League.open(tmp_path / "h") as league:
        assert league.roster.get_run("pong-1").status == "finished"


@pytest.mark.parametrize("args, needle", [
    (["train", "chess"], "unknown env 'chess'"),
    (["train", "pong", "--steps", "-5"], "--steps"),
    (["train", "pong", "--agents", "1", "--sharing", "fups"], "--sharing fups"),
    (["train", "pong", "--agents", "3"], "--agents"),
    (["train", "pong", "--algo", "sac"], "--algo"),
    (["train", "pong", "--env-option", "points=3"], "unknown pong option"),
    (["train", "pong", "--bots", "cpu=2"], "bot probabilities"),
    (["train", "pong", "--league-games", "1.5"], "--league-games"),
    (["train", "pong", "--agents", "1", "--league-games", "0.3"], "--league-games is for --agents 2"),
])
def test_bad_train_options_are_one_line_errors(tmp_path, capsys, args, needle):
    code, out, err = run(capsys, *args, "--home", str(tmp_path / "h"))
    assert code == 2 and needle in err and err.count("\n") == 1, err


@pytest.mark.slow
def test_a_run_killed_with_sigkill_resumes_from_its_last_snapshot(tmp_path, capsys):
    import os
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    home = tmp_path / "h"
    args = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-every",
            "16", "--steps", "60000", "--eval-games", "0", "--run", "r", "--home", str(home), "--quiet"]
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=dict(os.environ))
    db = home / "league.db"
    snapshots = 0
    deadline = time.time() + 120
    while time.time() < deadline and snapshots < 6:
        time.sleep(0.2)
        if db.exists():
            try:
                with sqlite3.connect(db) as con:
                    snapshots = con.execute("select count(*) from players where kind='snapshot'").fetchone()[0]
            except sqlite3.OperationalError:
                pass
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert snapshots >= 6, proc.stderr.read().decode()
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "running", "killed, not finished"
        before = [p.name for p in league.roster.players("pong", kind="snapshot")]

    code = main(["train", "--resume", "r", "--home", str(home), "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    report = json.loads(out.out)
    assert report["steps"] >= 60_000
    with League.open(home) as league:
        assert league.roster.get_run("r").status == "finished"
        snaps = league.roster.players("pong", kind="snapshot")
        names = [p.name for p in snaps]
        assert names[: len(before)] == before and len(names) == len(set(names)) > len(before)
        for seat in ("left", "right"):
            chain = [p for p in snaps if p.name.endswith(seat)]
            assert all(cur.parent_id == prev.id for prev, cur in zip(chain, chain[1:], strict=False)), seat
            assert all(cur.step > prev.step for prev, cur in zip(chain, chain[1:], strict=False)), seat
    with sqlite3.connect(db) as con:
        assert con.execute("pragma integrity_check").fetchone()[0] == "ok"
        games, seats = con.execute("select count(*), (select count(*) from game_seats) from games").fetchone()
        assert seats == 2 * games


def test_resume_errors_are_one_line(tmp_path, capsys):
    code, out, err = run(capsys, "train", "--resume", "nope", "--home", str(tmp_path / "h"))
    assert code == 2 and "no run named 'nope'" in err
    code, out, err = run(capsys, "train", "--home", str(tmp_path / "h"))
    assert code == 2 and "marl train pong" in err


@pytest.mark.slow
def test_dqn_and_the_seed000_preset_train_through_the_same_loop(tmp_path, capsys):
    home = str(tmp_path / "h")
    code, out, err = run(capsys, "train", "pong", "--agents", "1", "--algo", "dqn", "--steps", "6000", "--games", "16",
                         "--env-option", "points_to_win=1", "--eval-games", "4", "--eval-playoff", "0", "--home", home,
                         "--json")
    assert code == 0, err
    assert json.loads(out)["snapshots"][0] == "pong-1/s0"
    code, out, err = run(capsys, "train", "pong", "--preset", "seed000", "--steps", "2000", "--games", "8",
                         "--env-option", "points_to_win=1", "--eval-games", "0", "--home", home, "--json")
    assert code == 0, err
    snap = json.loads(out)["snapshots"][-1]
    with League.open(home) as league:
        run_cfg = league.roster.get_run("pong-2").config
        assert run_cfg["algo"] == "dqn" and run_cfg["dqn"]["lr"] == 1e-3 and run_cfg["dqn"]["batch_size"] == 64
        row = [p for p in league.roster.players("pong", kind="snapshot") if p.full_name == snap][0]
        policy = load_policy(league.home / row.path)
    assert policy.meta.algo == "dqn" and list(policy.meta.arch.hidden) == [512, 512, 256, 128, 64]
    code, out, err = run(capsys, "train", "pong", "--preset", "seed001", "--home", home)
    assert code == 2 and "--preset" in err


@pytest.mark.slow
def test_config_file_sets_every_section_and_typed_options_win(tmp_path, capsys):
    cfg_file = tmp_path / "run.toml"
    cfg_file.write_text('agents = 1\nsteps = 3000\ngames = 16\neval_games = 0\nsnapshot_every = 50\n'
                        '[ppo]\nlr = 0.001\nrollout_steps = 16\n[opponents]\nmode = "uniform"\nbots = { cpu = 0.25 }\n'
                        '[env_options]\npoints_to_win = 1\n')
    home = tmp_path / "h"
    code, out, err = run(capsys, "train", "pong", "--config", str(cfg_file), "--games", "8", "--home", str(home),
                         "--json")
    assert code == 0, err
    saved = json.loads((home / "runs" / "pong-1" / "config.json").read_text())
    assert saved["agents"] == 1 and saved["steps"] == 3000 and saved["games"] == 8, "typed --games beats the file"
    assert saved["ppo"]["lr"] == 0.001 and saved["ppo"]["rollout_steps"] == 16 and saved["ppo"]["gamma"] == 0.99
    assert saved["opponents"]["mode"] == "uniform" and saved["opponents"]["bots"] == {"cpu": 0.25}
    assert saved["env_options"] == {"points_to_win": 1}
    for text, needle in (("agnts = 2\n", "unknown training setting(s) agnts"),
                         ("[ppo]\nlearning_rate = 2\n", "unknown [ppo] setting(s) learning_rate"),
                         ("agents = \n", "not valid TOML"),
                         ("[env_options]\nspeed = 3\n", "unknown pong option")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        code, out, err = run(capsys, "train", "pong", "--config", str(bad), "--home", str(home))
        assert code == 2 and needle in err and err.count("\n") == 1, (text, err)


def test_swap_every_keeps_each_slot_on_its_opponent_until_the_swap(tmp_path):
    """ML-Agents' swap_steps: with --swap-every a game slot replays the opponent it drew until the next swap."""
    league = League.open(tmp_path / "league")
    cfg = tiny(agents=1, steps=8192, eval_games=0, swap_every=10**9,
               opponents=MatchmakerConfig(mode="self", latest_ratio=0.0, bots={"cpu": 0.5, "random": 0.5}))
    league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
    trainer = Trainer(league, cfg)
    first = [trainer.games.policies[k].id for k in trainer.games.opponent_of.tolist()]
    assert set(first) == {"cpu", "random"}, "both bots drawn across the slots"
    trainer.train()
    after = [trainer.games.policies[k].id for k in trainer.games.opponent_of.tolist()]
    assert trainer.state.episodes > cfg.games and after == first, "no swap within the budget: every slot kept its draw"
    league.close()


def test_tensorboard_gets_the_metrics_or_a_clear_install_hint(tmp_path, capsys, monkeypatch):
    import sys
    import types

    home = str(tmp_path / "h")
    args = ["train", "pong", "--agents", "2", "--steps", "4096", "--games", "16", "--env-option", "points_to_win=1",
            "--eval-games", "0", "--tensorboard", "--home", home]
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # not installed
    code, out, err = run(capsys, *args)
    assert code == 2 and "pip install tensorboard" in err and err.count("\n") == 1
    with League.open(home) as league:
        assert league.roster.list_runs() == [], "refused before the run was created"

    written = []

    class Writer:
        def __init__(self, log_dir):
            written.append(("dir", log_dir))

        def add_scalar(self, tag, value, global_step):
            written.append((tag, value, global_step))

        def close(self):
            written.append(("closed",))

    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", types.SimpleNamespace(SummaryWriter=Writer))
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    assert written[0] == ("dir", str(tmp_path / "h" / "runs" / "pong-1" / "tensorboard"))
    tags = {w[0] for w in written[1:-1]}
    assert {"left/policy_loss", "right/entropy", "steps_per_second", "episodes"} <= tags
    assert written[-1] == ("closed",)


def test_resume_refuses_a_run_another_live_process_is_training(tmp_path, capsys):
    import subprocess
    import sys

    home = tmp_path / "h"
    code, out, err = run(capsys, "train", "pong", "--agents", "2", "--steps", "2048", "--games", "16", "--env-option",
                         "points_to_win=1", "--eval-games", "0", "--run", "r", "--home", str(home))
    assert code == 0, err
    assert not (home / "runs" / "r" / "lock").exists(), "a finished run releases its lock"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (home / "runs" / "r" / "lock").write_text(str(sleeper.pid))  # as if that process were training it
        code, out, err = run(capsys, "train", "--resume", "r", "--home", str(home))
        assert code == 2 and f"being trained by process {sleeper.pid}" in err
    finally:
        sleeper.kill()
        sleeper.wait()
    code, out, err = run(capsys, "train", "--resume", "r", "--home", str(home), "--json")  # a dead pid: taken over
    assert code == 0, err


def test_run_status_after_a_refused_device_an_interrupt_and_a_crash(tmp_path, capsys, monkeypatch):
    home = str(tmp_path / "h")
    code, out, err = run(capsys, "train", "pong", "--device", "tpu", "--home", home)
    assert code == 2 and "unknown device 'tpu'" in err
    with League.open(home) as league:
        assert league.roster.list_runs() == [], "refused before the run was created"

    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(Trainer, "train", interrupted)
    args = ["train", "pong", "--games", "8", "--eval-games", "0", "--home", home]
    code, out, err = run(capsys, *args, "--run", "a")
    assert code == 130 and "marl train --resume a" in err and "Traceback" not in err

    def crashed(self):
        raise RuntimeError("boom")

    monkeypatch.setattr(Trainer, "train", crashed)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where the crash report goes
    code, out, err = run(capsys, *args, "--run", "b")  # a crash: one line saying it is a bug, exit 5
    assert code == 5 and "internal error" in err and "RuntimeError: boom" in err and err.count("\n") == 1
    assert len(list(tmp_path.glob("marl-crash-*.txt"))) == 1
    with League.open(home) as league:
        assert league.roster.get_run("a").status == "stopped"
        assert league.roster.get_run("b").status == "failed"


def test_a_new_runs_settings_resolve_without_the_cli(tmp_path):
    """train/settings layers a run's settings: the defaults, the game's own, a preset, the config file, then the
    options typed; a game's default that a lone learner cannot use is dropped, the same setting typed is refused."""
    from selfplay_cli.errors import MarlError
    from selfplay_cli.train.settings import new_settings

    conf = tmp_path / "run.toml"
    conf.write_text('steps = 5000\n[sac]\nlr = 1e-4\n[sac.arch]\nactivation = "tanh"\n')
    s = new_settings("tennis", {"agents": 1, "lr": 2e-4}, config=conf)
    assert (s["algo"], s["steps"], s["agents"]) == ("sac", 5000, 1)  # the game's learner, the file's budget, typed
    assert s["sac"]["arch"]["hidden"] == [256, 256] and s["sac"]["arch"]["activation"] == "tanh"  # game, then file
    assert s["sac"]["lr"] == s["ppo"]["lr"] == 2e-4  # --lr over the file's [sac] lr, for every learner
    assert s["opponents"]["bots"] == {"serve-bot": 0.75} and s["teacher"]["player"] == "serve-bot"  # the game's
    assert s["sharing"] == "nops" and s["league_games"] == 0.0  # tennis's shared network and league share: dropped
    both = new_settings("tennis", {"agents": 2})
    assert both["sharing"] == "fups" and both["league_games"] == 0.5  # kept where every seat learns
    with pytest.raises(MarlError, match="--sharing fups"):
        new_settings("tennis", {"agents": 1, "sharing": "fups"})  # typed: checked, not dropped
    seed = new_settings("pong", {}, preset="seed000")
    assert seed["algo"] == "dqn" and seed["dqn"]["lr"] == 1e-3 and seed["dqn"]["arch"]["hidden"][0] == 512
    opponents = new_settings("pong", {"opponents": "uniform", "bots": "cpu=0.25"})["opponents"]
    assert opponents["mode"] == "uniform" and opponents["bots"] == {"cpu": 0.25}  # --opponents is [opponents] mode
    team = tmp_path / "team.toml"
    team.write_text("[poca]\nlr = 3e-4\n")
    critic = new_settings("lander", {"algo": "mappo"}, config=team)  # PPO with a team critic: the game's PPO too
    for algo in ("mappo", "poca"):
        assert (critic[algo]["gamma"], critic[algo]["reward_scale"], critic[algo]["rollout_steps"]) == (0.999, 0.01,
                                                                                                         256)
    assert (critic["mappo"]["lr"], critic["poca"]["lr"]) == (1e-3, 3e-4)  # the file's [poca] over the game's [ppo]


def test_the_gauntlets_precision_is_a_setting_each_job_carries(tmp_path, capsys):
    """--eval-precision (0.3 by default: a matchup of two snapshots plays on until its record predicts a 200-game
    match within 30 points) is a setting of the run that its gauntlet jobs carry to whoever plays them (a worker
    beside training, the league's queue); a job without one (queued by an older marl) plays its games exactly;
    outside [0, 1) the flag is refused in one line."""
    from selfplay_cli.evaluation.executors.base import GauntletJob
    from selfplay_cli.evaluation.executors.local import _spec
    from selfplay_cli.train.settings import new_settings

    assert TrainConfig("pong", run="x").eval_precision == 0.3
    assert new_settings("pong", {"eval_precision": 0.0})["eval_precision"] == 0.0
    for bad in ("1.5", "-0.1"):
        code = main(["train", "pong", "--eval-precision", bad, "--steps", "10", "--home", str(tmp_path)])
        assert code == 2 and capsys.readouterr().err.count("\n") == 1
    assert _spec(GauntletJob((1,), 0, 8, 2, precision=0.2))["precision"] == 0.2
    assert GauntletJob((1,), 0, 8, 2).precision == 0.0


def test_every_moment_plays_the_pairs_its_precision_asks_for(tmp_path):
    """Every moment's matchups play the pairs the precision asks for (at 0.3, 4 times --eval-games' pairs), all at
    once; the final's bots play --eval-games x 8; without a precision (--opponents nash: a payoff matrix's cells),
    --eval-games exactly."""
    from selfplay_cli.evaluation.gauntlet_jobs import _config

    with League.open(tmp_path / "h") as league:
        league.roster.ensure_bots("pong", ["cpu"])
        (bot,) = league.roster.players("pong")
        spec = {"snapshot_ids": [bot.id], "games": 8, "older": 2, "precision": 0.3}
        moment, final = _config(league, spec), _config(league, {**spec, "full": True})
        exact = _config(league, {**spec, "full": True, "precision": 0.0})
    assert (moment.pairs, moment.bot_pairs, moment.older) == (16, 0, 2)
    assert (final.pairs, final.bot_pairs, final.older) == (16, 32, 24)
    assert (exact.pairs, exact.bot_pairs) == (4, 32)
