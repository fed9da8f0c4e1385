"""What `marl train` shows while it runs and when it ends: counts that move while every game is still under way,
plain lines at a steady pace without a terminal, a resumed run counted whole, no bar left above the summary."""

from __future__ import annotations

import io
import json
import re
import sys
import threading
from pathlib import Path

import pytest
from cli_helpers import run
from rich.console import Console

import selfplay_cli.commands.train_view as train_view
import selfplay_cli.train.progress as train_progress
from selfplay_cli.algos.ppo import PPOConfig, PPOLearner
from selfplay_cli.commands.train_view import TrainProgress, describe_games, describe_record, describe_run
from selfplay_cli.league.store import League
from selfplay_cli.league.variants import variant_key
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.loop import Trainer
from selfplay_cli.train.matchmaking import MatchmakerConfig
from selfplay_cli.train.progress import SnapshotRecord, Standing, TrainReport

FAST_PPO = PPOConfig(rollout_steps=32, minibatches=2, update_epochs=1)
ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))


def standing(**kw) -> Standing:
    base = dict(progress=0.0, steps=0, episodes=0, playing=16, game_steps=0.0, time_limit=1000, snapshots=2,
                rated=0, newest=(), session_steps=0, steps_per_second=None, remaining=None)
    base.update(kw)
    return Standing(**base)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.mark.slow
def test_progress_counts_what_moves_while_every_game_is_still_under_way(tmp_path):
    """Games to 21 points never end in 8,192 steps of 16 games: 'games finished' stays 0, so the progress says how
    far the games under way are, and how many snapshots were taken and rated, with the newest rated one's Elo. (A
    time limit of 2,000 steps, not pong's 18,000, keeps the rating games short; a game of the run reaches 512.)"""
    events = []
    cfg = TrainConfig(env="pong", run="t", steps=8192, games=16, snapshot_steps=2048, eval_games=2, eval="inline",
                      eval_playoff=0, ppo=FAST_PPO, env_options={"max_steps": 2000})
    with League.open(tmp_path / "league") as league:
        league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
        Trainer(league, cfg, on_progress=events.append).train()
    training = [e["standing"] for e in events if e["event"] == "training"]
    assert len(training) >= 2
    last = training[-1]
    assert last.episodes == 0 and last.playing == 16 and last.time_limit == 2_000  # the game's time limit
    assert last.game_steps == last.steps / 16 > 0  # every game began with the run: the steps are theirs, shared
    assert "games: 0 finished, 16 under way" in describe_games(last)
    assert f"{last.game_steps:,.0f} steps in on average, of at most 2,000" in describe_games(last)
    rated = [e["standing"] for e in events if e["event"] == "snapshot"]
    assert [s.rated for s in rated] == [2 * (i + 1) for i in range(len(rated))]  # two learners: 2 a moment
    assert rated[-1].snapshots == rated[-1].rated == 10  # s0 .. s8.19k, both learners, all rated inline
    assert {r.name for r in rated[-1].newest} == {"t/s8.19k-left", "t/s8.19k-right"}
    assert all(r.elo is not None and r.ci_low < r.elo < r.ci_high for r in rated[-1].newest)


def test_without_a_terminal_a_plain_line_comes_every_30_s_or_5_percent_whichever_is_rarer(monkeypatch):
    clock = Clock()
    buf = io.StringIO()
    monkeypatch.setattr(train_view, "err_console", Console(file=buf, width=300))  # not a terminal
    cfg = TrainConfig(env="pong", run="r", steps=1_000_000)
    progress = TrainProgress(cfg, bar=False, lines=True, clock=clock)
    lines = []

    def at(t: float, share: float) -> None:
        clock.t = 100.0 + t
        progress.update({"event": "training", "standing": standing(progress=share, steps=int(share * 1e6),
                                                                   session_steps=int(share * 1e6),
                                                                   steps_per_second=share * 1e6 / max(t, 1),
                                                                   remaining=60.0)})
        lines.append(buf.getvalue().count("\n"))

    at(10, 0.20)  # 20% of the budget, but only 10 s: no line
    at(29, 0.30)
    at(31, 0.31)  # 31 s and 31%: a line
    at(50, 0.33)  # 19 s since it
    at(62, 0.34)  # 31 s since, but only 3% more of the budget: a slow run waits for its 5%
    at(70, 0.37)  # 39 s and 6%: a line
    assert lines == [0, 0, 1, 1, 1, 2]
    first = buf.getvalue().splitlines()[0]
    assert first.startswith("r: 31% (310,000 of 1,000,000 steps, 10,000 steps/s); games: 0 finished, 16 under way")
    assert "snapshots: 2 taken, 0 rated" in first and first.endswith("0:00:31 elapsed, ~0:01:00 left")


def test_quiet_prints_no_progress_line_and_json_keeps_stdout_for_the_json(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(train_view, "PLAIN_LINE_SECONDS", 0.0)  # a line at every 5% of this short budget
    args = ["train", "pong", "--steps", "4096", "--games", "16", "--env-option", "points_to_win=1", "--eval-games",
            "0", "--home", str(tmp_path / "h")]
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    assert json.loads(out)["steps"] >= 4096  # stdout: the JSON alone
    progress = [ln for ln in err.splitlines() if ln.startswith("pong-1: ")]
    assert progress and all("steps/s); games: " in ln for ln in progress)
    code, out, err = run(capsys, *args, "--quiet")
    assert code == 0 and err == "" and out.startswith("run pong-2: ")
    assert "budget of" not in out  # (a budget of steps ends at an update's end, as it always does)


@pytest.mark.slow
def test_a_minutes_budget_says_how_it_ended_training(tmp_path, capsys):
    args = ["train", "pong", "--minutes", "0.02", "--games", "16", "--env-option", "points_to_win=1",
            "--eval-games", "0", "--home", str(tmp_path / "h")]
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    end = json.loads(out)["budget_end"]
    assert end["seconds"] == 1.2 and end["last_update"] in ("cut", "not begun", "whole") and end["overrun_seconds"] >= 0
    assert (end["unlearned_steps"] > 0) == (end["last_update"] == "not begun")
    assert bool(end["cut"]) == (end["last_update"] == "cut")
    code, out, err = run(capsys, *args, "--quiet")
    assert code == 0 and re.search(r"^  budget of 1.2 s: training ended \d+\.\d s past it, ", out, re.M), out


def _screen(text: str) -> list[str]:
    """What a terminal shows after ``text``: lines, with carriage return, cursor up and erase line obeyed."""
    rows, row, col = [""], 0, 0
    for token in re.findall(r"\x1b\[[0-9;?]*[A-Za-z]|\r|\n|[^\x1b\r\n]+", text):
        if token == "\n":
            row, col = row + 1, 0
            rows += [""] * (row + 1 - len(rows))
        elif token == "\r":
            col = 0
        elif token == "\x1b[2K":
            rows[row] = ""
        elif re.fullmatch(r"\x1b\[\d*A", token):
            row = max(row - int(token[2:-1] or 1), 0)
        elif not token.startswith("\x1b"):
            rows[row] = rows[row][:col] + token + rows[row][col + len(token):]
            col += len(token)
    return [r for r in rows if r.strip()]


def test_the_bar_is_gone_when_the_run_ends_and_the_rated_lines_stay(monkeypatch):
    buf = io.StringIO()
    monkeypatch.setattr(train_view, "err_console", Console(file=buf, force_terminal=True, width=200))
    cfg = TrainConfig(env="pong", run="r", steps=1000)
    rec = SnapshotRecord("r/s0", "learner", 0, {"random": (2, 0, 0)}, 1100.0, 900.0, 1300.0)
    with TrainProgress(cfg, bar=True, lines=True) as progress:
        progress.update({"event": "training", "standing": standing(progress=0.5, steps=500, session_steps=500,
                                                                   steps_per_second=100.0, remaining=5.0)})
        progress.progress.refresh()
        progress.update({"event": "snapshot", "records": [rec],
                         "standing": standing(progress=1.0, steps=1000, rated=2, newest=(rec,))})
        progress.progress.refresh()
        assert any(ln.startswith("train r ") for ln in _screen(buf.getvalue()))  # the bar, while it runs
        assert any("newest rated s0 Elo 1100 [900, 1300]" in ln for ln in _screen(buf.getvalue()))
    screen = _screen(buf.getvalue())
    assert not any(ln.startswith(("train r ", "games: ")) for ln in screen), screen  # the bar and its status: gone
    shown = "".join(screen)  # the rated line stays (wrapped at the terminal's width)
    assert shown.startswith("r: 100% (1,000 of 1,000 steps") and "rated s0 (step 0): random 100% of 2, Elo 1100 " \
        "[900, 1300]" in shown, screen


def _stop_after(monkeypatch, steps: int) -> None:
    """Ctrl-C as the run's progress passes ``steps`` (the first session of a resumed run)."""
    update = TrainProgress.update

    def stopping(self, event):
        update(self, event)
        if event["standing"].steps >= steps and event["event"] == "snapshot":
            raise KeyboardInterrupt

    monkeypatch.setattr(TrainProgress, "update", stopping)


RESUMABLE = ["train", "pong", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps", "2048",
             "--steps", "12288", "--eval-games", "2", "--eval-inline", "--run", "r"]


@pytest.mark.slow
def test_a_resumed_run_reports_the_whole_run_and_this_sessions_rate(tmp_path, capsys, monkeypatch):
    home = str(tmp_path / "h")
    with monkeypatch.context() as m:
        _stop_after(m, 6000)
        code, out, err = run(capsys, *RESUMABLE, "--home", home)
    assert code == 130 and "marl train --resume r" in err
    with League.open(home) as league:
        before = [p.full_name for p in league.roster.players("pong", kind="snapshot")]
        games_before = league.ledger.count_games("pong")
    assert 4 <= len(before) < 12

    code, out, err = run(capsys, "train", "--resume", "r", "--home", home, "--json")
    assert code == 0, err
    data = json.loads(out)
    with League.open(home) as league:
        snapshots = [p.full_name for p in league.roster.players("pong", kind="snapshot")]
        # the gauntlets' games, rated in the run's variant (training games are not rated)
        rating_games = len(league.ledger.games("pong", variant=variant_key("pong", {"points_to_win": 1})))
    assert data["sessions"] == 2 and data["snapshots"] == snapshots and len(snapshots) > len(before)
    assert data["steps"] >= 12_288 and 0 < data["session_steps"] <= 12_288 - 4096
    assert data["seconds"] > data["session_seconds"] > 0
    assert data["session_rating_games"] < data["rating_games"] == rating_games
    assert games_before > 0 and data["episodes"] > 0
    # a rated moment of the resumed session, before its first update, shows the rate it has, not 0
    lines = [ln for ln in err.splitlines() if ln.startswith("r: ")]
    assert lines and not any(re.search(r"\b0(/s| steps/s)", ln) for ln in lines), lines


@pytest.mark.slow
def test_a_resumed_session_counts_only_the_rating_games_it_stored(tmp_path, capsys, monkeypatch):
    """Ctrl-C as a moment's gauntlet has just finished: the run state saved with that moment still owes it, so the
    resumed session plays it again, stores nothing of it (its matchups are in the ledger) and must not count its
    games as its own. The session's figure is what the ledger gained while it ran."""
    home = str(tmp_path / "h")
    variant = variant_key("pong", {"points_to_win": 1})
    args = [*RESUMABLE[:RESUMABLE.index("--steps")], "--steps", "8192", *RESUMABLE[RESUMABLE.index("--steps") + 2:]]
    with monkeypatch.context() as m:
        _stop_after(m, 2048)
        code, out, err = run(capsys, *args, "--home", home)
    assert code == 130, err
    with League.open(home) as league:
        before = len(league.ledger.games("pong", variant=variant))
    assert before > 0  # the first session's gauntlets: stored before the Ctrl-C

    data = json.loads(run(capsys, "train", "--resume", "r", "--home", home, "--json")[1])
    with League.open(home) as league:
        after = len(league.ledger.games("pong", variant=variant))
    assert data["sessions"] == 2 and data["rating_games"] == after
    assert data["session_rating_games"] == after - before > 0


def test_the_summary_of_a_resumed_run_states_the_whole_run():
    report = TrainReport("pong-1", 6_000_128, 256, seconds=95.4, eval_games=444, snapshots=["a"] * 14, finals=[],
                         sessions=2, session_steps=524_288, session_seconds=13.2, train_seconds=10.0,
                         session_eval_games=40, eval_seconds=9.0, wait_seconds=3.0)
    assert describe_run(report) == (
        "run pong-1: 6,000,128 game steps in 2 sessions, 95 s in all (this session: 524,288 steps in 13 s, 10 s of "
        "training at 52,429 steps/s), 256 episodes, 14 snapshots; 444 rating games (40 of them this session, "
        "beside training: 9 s, 3 s of it waited for at the end)")
    assert "10 s of training at 52,429 steps/s on 2 Ray actors)" in describe_run(report, actors=2)  # --executor ray
    report.session_steps, report.train_seconds = 0, 0.0  # resumed after its budget was spent: nothing to train
    assert "(this session: 0 steps in 13 s, no training left to do)" in describe_run(report)


@pytest.mark.slow
def test_a_repeated_run_says_its_snapshots_are_another_runs_weights_not_that_it_waited_for_games(tmp_path):
    """The same command and seed twice in one league (every opponent a bot): the second run's snapshots are the
    first's weights, already rated, so it needs no rating games; its summary says so, and says no time was waited
    for games that were never played."""
    cfg = TrainConfig(env="pong", run="a", steps=1024, games=8, agents=1, eval_games=2, eval="inline",
                      eval_playoff=0, ppo=FAST_PPO, env_options={"points_to_win": 1},
                      opponents=MatchmakerConfig(bots={"random": 1.0}))
    reports = []
    with League.open(tmp_path / "league") as league:
        for name in ("a", "b"):
            run_cfg = TrainConfig.from_dict({**cfg.to_dict(), "run": name})
            league.roster.create_run(name, "pong", run_cfg.to_dict(), algo="ppo")
            reports.append(Trainer(league, run_cfg).train())
    first, second = reports
    assert first.eval_games > 0 and first.same_weights == {}
    assert second.eval_games == second.session_eval_games == 0
    assert second.same_weights == {f"b/{n.split('/')[1]}": n for n in first.snapshots}
    line = describe_run(second, "inline")
    assert "; 0 rating games (none needed: its snapshots are the same weights as run a's, already rated" in line
    assert "waited for" not in line
    for rec in second.finals:  # each final's line says whose games its figures are
        assert rec.same_as == second.same_weights[rec.name]
        said = f"{rec.name} (the same weights as {rec.same_as}: one player, its games): "
        assert describe_record(rec).startswith(said)
        assert rec.to_json()["same_weights_as"] == rec.same_as
    assert all(rec.to_json()["same_weights_as"] is None for rec in first.finals if not rec.same_as)


def test_a_snapshot_that_holds_an_earlier_ones_weights_says_whose_games_its_figures_are():
    """A budget that ends before the next update leaves the last snapshot a copy of the one before it (the lander at
    30,016 steps: s30k holds s10k's weights, taken at 16,384): one player, so its line shows that player's games."""
    rec = SnapshotRecord("l/s30k-lander_0", "lander_0", 30_016, {"heuristic": (0, 0, 1)}, 270.0, -278.0, 819.0,
                         unit="comparisons", same_as="l/s10k-lander_0")
    assert describe_record(rec) == ("l/s30k-lander_0 (the same weights as l/s10k-lander_0: one player, its games): "
                                    "Elo 270 [-278, 819]; vs heuristic 0% [0%, 79%] of 1 comparisons")
    assert describe_record(SnapshotRecord("l/s10k", "x", 1, {})) == "l/s10k: not rated (--eval-games 0)"


def _zero(**kw) -> TrainReport:
    base = dict(run="k-2", steps=20_000, episodes=8_904, seconds=8.0, eval_games=0, snapshots=["k-2/s0", "k-2/s20k"],
                finals=[], sessions=1, session_steps=20_000, session_seconds=8.0, train_seconds=6.0,
                session_eval_games=0, eval_seconds=1.0, wait_seconds=3.0,
                same_weights={"k-2/s0": "k-1/s0", "k-2/s20k": "k-1/s20k"})
    base.update(kw)
    return TrainReport(**base)


def test_a_session_without_rating_games_says_why_and_what_its_time_went_to():
    """Issue 48: '0 rating games (beside training: 1 s, 3 s of it waited for at the end)'."""
    assert describe_run(_zero()).endswith(
        "; 0 rating games (none needed: its snapshots are the same weights as run k-1's, already rated; 3 s at the "
        "end waiting for the rating worker to find that)")
    assert describe_run(_zero(wait_seconds=0.2)).endswith(
        "; 0 rating games (none needed: its snapshots are the same weights as run k-1's, already rated)")
    assert describe_run(_zero(eval_seconds=1.4, wait_seconds=0.0), "inline").endswith(
        "(none needed: its snapshots are the same weights as run k-1's, already rated; 1 s inline to find that)")
    # a resumed session whose gauntlets had all been stored by the session before it
    resumed = _zero(eval_games=470, sessions=2, same_weights={}, wait_seconds=2.0)
    assert describe_run(resumed).endswith("; 470 rating games (none of them this session: its gauntlets had nothing "
                                          "left to play; 2 s at the end waiting for the rating worker to find that)")
    off = describe_run(_zero(rating=False, eval_seconds=0.0, wait_seconds=0.0, same_weights={}))
    assert off.endswith("; 0 rating games (--eval-games 0)")


@pytest.mark.parametrize("ended, text", [(False, "16 under way"), (True, "16 left unfinished")])
def test_games_under_way_are_named_as_they_are(ended, text):
    assert text in describe_games(standing(ended=ended, game_steps=12.5))


# the run each docs page's commands name, and the `marl train` command that makes it (flags that change names)
README_RUNS = {"pong-1": ("pong", {"agents": 2}), "tennis-1": ("tennis", {"agents": 2}),
               "lander-1": ("lander", {"agents": 2, "sharing": "fups"}),
               "lander-2": ("lander", {"agents": 2, "sharing": "nops", "algo": "dqn"}),
               "connect_four_v3-1": ("pettingzoo.classic.connect_four_v3", {"sharing": "fups"})}


def _learners_of(env: str, flags: dict) -> list[str]:
    """The learners (so the snapshot suffixes) of `marl train ENV` with ``flags``, from the game's own training
    defaults as `marl train` applies them."""
    from selfplay_cli.envs import get_env
    from selfplay_cli.train.learners import learner_names
    from selfplay_cli.train.settings import new_settings

    spec = get_env(env)
    cfg = TrainConfig.from_dict({**new_settings(env, flags), "run": "x"})
    return learner_names(spec.agents, cfg.seat_plan().home, cfg.sharing)


def test_readme_names_only_snapshots_its_runs_make():
    """A shared network's snapshots have no seat suffix (tennis's default run: s0, not s0-player_0); a run of one
    network per seat names a moment's team (s6M) or one member (s6M-left)."""
    from cli_helpers import docs_text

    from selfplay_cli.envs import admit, get_env

    text = docs_text()
    for env, _ in README_RUNS.values():
        admit(env)  # the README's games (connect four: a game of your own, named by its commands)
    named = re.findall(r"marl \w+(?: \w+)? .*?\b((?:pong|tennis|lander|connect_four_v3)-\d+)/([\w.-]+)", text)
    assert len(named) >= 8
    for run_name, snap in named:
        env, flags = README_RUNS[run_name]
        learners = _learners_of(env, flags)
        agents = get_env(env).agents
        seat = next((a for a in agents if snap.endswith(f"-{a}")), None)
        assert re.fullmatch(r"(s\d+(\.\d+)?[kM]?|latest|best)", snap.removesuffix(f"-{seat}") if seat else snap), snap
        if learners == ["learner"]:
            assert seat is None, f"{run_name}/{snap}: that run trains one shared network, its snapshots have no seat"
        else:
            assert seat is None or seat in learners, f"{run_name}/{snap}"


def test_a_seat_suffix_on_a_shared_networks_snapshot_is_answered_with_its_name(tmp_path):
    from selfplay_cli.errors import MarlError
    from selfplay_cli.ratings.names import resolve

    cfg = TrainConfig(env="pong", run="t", steps=1024, games=8, sharing="fups", eval_games=0, ppo=FAST_PPO)
    with League.open(tmp_path / "league") as league:
        league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
        Trainer(league, cfg).train()
        league.roster.ensure_bots("lander", ["heuristic", "random"])  # a second game's players: its own random
        assert resolve(league, "t/s0").name == "s0"
        for typed, hint in (("t/s0-left", "name it t/s0"), ("s0-right", "name it s0")):
            with pytest.raises(MarlError) as e:
                resolve(league, typed)
            assert f"t/s0 is one network for every seat (its run shares one), so its name has no seat: {hint}" \
                in str(e.value)
            assert str(e.value).count("random") == 1  # every game's random player, named once


# -- a --minutes budget on a slow game: the test's clock (tests.games.slow.CLOCK), moved on by the game's steps and
# by the learner's minibatches, never by waiting

SLOW = "tests.games.slow:parallel_env"
LONG_UPDATE = PPOConfig(rollout_steps=16, minibatches=4, update_epochs=4)  # 16 minibatches an update


def _slow_run(tmp_path, monkeypatch, *, step: float, minibatch: float, on_progress=None, during=None):
    """A one-minute run of the slow game, 4 games at once (a step of all of them: ``4 * step`` seconds on the
    clock), each minibatch of an update taking ``minibatch`` seconds (``during(clock)`` called in each); its
    report and the clock's time when training began."""
    from tests.games.slow import CLOCK

    real = PPOLearner._minibatch_step

    def slow_minibatch(self, *args, **kwargs):
        CLOCK.advance(minibatch)
        if during is not None:
            during(CLOCK)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(PPOLearner, "_minibatch_step", slow_minibatch)
    cfg = TrainConfig(env=SLOW, run="s", minutes=1, games=4, sharing="fups", eval_games=0, ppo=LONG_UPDATE,
                      env_options={"seconds": step})
    with League.open(tmp_path / "league") as league:
        league.roster.create_run("s", SLOW, cfg.to_dict(), algo="ppo")
        began = CLOCK()
        report = Trainer(league, cfg, on_progress=on_progress, clock=CLOCK).train()
    return report, began


@pytest.mark.parametrize(("step", "minibatch", "most"), [
    (0.25, 5.0, 5.0),  # rollouts of 16 s, updates of 80 s: the update under way at the deadline ends at its next
    # minibatch (issue 48: a POCA lander trained 85 s of a minute, a pistonball 255 s)
    (5.0, 0.0, 20.0),  # a rollout of 320 s: it ends at the step under way at the deadline
])
def test_a_minutes_budget_ends_within_one_minibatch_or_step_of_its_deadline(tmp_path, monkeypatch, step, minibatch,
                                                                           most):
    report, _ = _slow_run(tmp_path, monkeypatch, step=step, minibatch=minibatch)
    assert 60.0 <= report.train_seconds <= 60.0 + most, report.train_seconds
    assert report.steps > 0 and report.snapshots == ["s/s0", f"s/s{report.steps}"]
    end = report.budget_end
    if minibatch:
        # one step of the 4 games takes 1 s: the first rollout (16 steps) ends at 16 s, its update's 16 minibatches
        # of 5 s each are asked before each whether the time is up: after 9 of them (61 s) it is
        assert (end.update, list(end.cut.values()), end.overrun, end.unlearned) == ("cut", [(9, 16)], 1.0, 0)
        assert end.describe() == ("budget of 60 s: training ended 1.0 s past it, its last update cut after 9 of 16 "
                                  "gradient steps")
    else:  # steps of 20 s: 3 of them (12 game steps) by 60 s, the rollout of 16 far from full
        assert (end.update, end.cut, end.overrun, end.unlearned) == ("not begun", {}, 0.0, 12)
        assert end.describe() == ("budget of 60 s: training ended 0.0 s past it, an update not begun: the last 12 "
                                  "game steps played (since the last update, or the start) are not learned from")


def test_a_minutes_budget_cuts_an_off_policy_update_after_the_gradient_step_under_way():
    """DQN's and SAC's updates (many gradient steps where the replay ratio is high, or a Ray run's fragment) end at
    the gradient step under way when the time is up, at least one made; the steps not made stay due."""
    import numpy as np
    from gymnasium import spaces

    from selfplay_cli.algos.dqn import DQNConfig, DQNLearner
    from selfplay_cli.algos.sac import SACConfig, SACLearner
    from selfplay_cli.envs import SeatSpace
    from selfplay_cli.signals import deadline
    from tests.games.slow import Clock

    clock = Clock()
    seat = SeatSpace(spaces.Box(-1.0, 1.0, (3,), np.float32), spaces.Discrete(2))
    dqn = DQNLearner(seat, 4, DQNConfig(learning_starts=8, batch_size=4, n_step=1), seed=0)
    obs = np.zeros((4, 3), np.float32)
    for _ in range(4):
        dqn.act(obs)
        dqn.record(np.ones(4, np.float32), np.zeros(4, np.float32))
    real_step = dqn.opt.step
    dqn.opt.step = lambda *a, **k: (clock.advance(1.0), real_step(*a, **k))[1]  # each gradient update: 1 s
    dqn.credit = 10.25
    with deadline(clock() + 3.5, clock):
        dqn.update(obs)
    # asked before each update: 0 s, 1, 2, 3 go on; 4 s is past 3.5
    assert (dqn.grad_steps, dqn.cut, dqn.credit) == (4, (4, 10), 6.25)
    dqn.credit = 2.0
    with deadline(clock() - 1.0, clock):  # past already: one update all the same
        dqn.update(obs)
    assert (dqn.grad_steps, dqn.cut) == (5, (1, 2))
    dqn.credit = 2.0
    dqn.update(obs)  # no budget: whole
    assert (dqn.grad_steps, dqn.cut) == (7, None)

    sac_seat = SeatSpace(spaces.Box(-1.0, 1.0, (3,), np.float32), spaces.Box(-1.0, 1.0, (2,), np.float32))
    sac = SACLearner(sac_seat, 4, SACConfig(batch_size=8, learning_starts=8), seed=0)
    rng = np.random.default_rng(0)
    sac.buffer.add(rng.normal(size=(32, 3)).astype(np.float32), rng.uniform(-1, 1, (32, 2)).astype(np.float32),
                   rng.normal(size=32).astype(np.float32), rng.normal(size=(32, 3)).astype(np.float32),
                   np.zeros(32, np.float32), 0.99)
    real_gradient_step = sac._gradient_step
    sac._gradient_step = lambda *a: (clock.advance(1.0), real_gradient_step(*a))[1]
    sac.credit = 10.0
    with deadline(clock() + 2.5, clock):
        sac.update()
    assert (sac.grad_steps, sac.cut, sac.credit) == (3, (3, 10), 7.0)


def test_progress_is_told_while_a_long_update_runs_and_a_log_line_comes_on_time(tmp_path, monkeypatch):
    """Every minibatch of an update waits until progress events have come in while it ran (the run's heartbeat,
    told to beat every 10 ms here): a display hears of the run while the main thread is busy in one long update,
    its percentage is the time spent over the budget, and a log's plain line comes 30 s in (within the minibatch
    under way then), not at the next rollout's end (issue 48: 4:16 in, reading '53% ... ~0:00:00 left')."""
    from tests.games.slow import CLOCK

    monkeypatch.setattr(train_progress, "HEARTBEAT_SECONDS", 0.01)
    buf = io.StringIO()
    monkeypatch.setattr(train_view, "err_console", Console(file=buf, width=400))  # a log, not a terminal
    display = TrainProgress(TrainConfig(env=SLOW, run="s", minutes=1), bar=False, lines=True, clock=CLOCK)
    told: list[Standing] = []
    came = threading.Condition()

    def on_progress(event):
        display.update(event)
        if event["event"] == "training":
            with came:
                told.append(event["standing"])
                came.notify_all()

    heard = []  # per minibatch: (the clock, the standing told while it waited; None: none came)

    def during(clock):
        with came:  # the second event from now was made while this minibatch waits (the first may be older)
            mark = len(told)
            ok = came.wait_for(lambda: len(told) >= mark + 2, timeout=30)  # (a guard: it takes milliseconds)
            heard.append((clock(), told[-1] if ok else None))

    report, began = _slow_run(tmp_path, monkeypatch, step=0.25, minibatch=5.0, on_progress=on_progress,
                              during=during)
    assert heard and all(s is not None for _, s in heard), f"{sum(s is None for _, s in heard)} of {len(heard)} " \
        "minibatches heard nothing"
    for at, standing in heard:  # the share of the budget told: the time spent at that moment
        assert standing.progress == pytest.approx(min((at - began) / 60.0, 1.0)), (at - began, standing.progress)
    first = buf.getvalue().splitlines()[0]
    m = re.fullmatch(r"s: (\d+)% \(.*; 0:00:(\d\d) elapsed, ~0:00:(\d\d) left", first)
    assert m and 30 <= int(m[2]) <= 35, first  # 30 s in, at the minibatch under way then
    # its share and time left as the clock had them when its standing was taken: then, or one minibatch before
    assert abs(int(m[1]) - 100 * int(m[2]) / 60) <= 100 * 5 / 60 + 1 and abs(60 - int(m[2]) - int(m[3])) <= 5, first


def test_while_the_last_gauntlets_are_played_the_eta_says_how_many_are_left(monkeypatch):
    """Training is over: the ETA of the bar does not stand at a figure, it says the run waits for its rating
    games and how many gauntlets are left; a log says the same."""
    buf = io.StringIO()
    monkeypatch.setattr(train_view, "err_console", Console(file=buf, width=300))
    clock = Clock()
    cfg = TrainConfig(env="pong", run="r", minutes=1)
    waiting = {"event": "evaluating", "snapshots": ["r/s1k-left", "r/s1k-right"], "gauntlets": 1, "games": 19,
               "queue": None, "standing": standing(progress=1.0, steps=1000, ended=True, remaining=None)}
    with TrainProgress(cfg, bar=True, lines=True, clock=clock) as progress:
        progress.update(waiting)
        assert progress.progress.tasks[0].fields["eta"] == ("waiting for its rating games: 1 gauntlet left (Ctrl-C: "
                                                            "queue them)")
    plain = TrainProgress(cfg, bar=False, lines=True, clock=clock)
    clock.t += 31
    plain.update({**waiting, "snapshots": ["r/s1k", "r/s2k"], "gauntlets": 2})
    assert buf.getvalue().splitlines()[-1] == (
        "r: training done (1,000 steps); waiting for its rating games: 2 gauntlets left (s1k, s2k), 19 played in "
        "this session so far; 0:00:31 elapsed; Ctrl-C leaves them to the league's queue")
    # a gauntlet done meanwhile: its rated line, without the training's figures (they stand still by now)
    rec = SnapshotRecord("r/s1k", "learner", 1000, {"random": (2, 0, 0)}, 1100.0, 900.0, 1300.0)
    plain.update({"event": "snapshot", "records": [rec],
                  "standing": standing(progress=1.0, steps=1000, ended=True, snapshots=3, rated=2)})
    assert buf.getvalue().splitlines()[-1] == (
        "r: training done (1,000 steps); snapshots: 3 taken, 2 rated; rated s1k (step 1,000): random 100% of 2, "
        "Elo 1100 [900, 1300]; 0:00:31 elapsed")


@pytest.mark.slow
def test_once_training_has_ended_no_time_left_is_claimed(tmp_path):
    """The standing of a run whose training has ended (its final gauntlets still to come) estimates no time left:
    a figure there would stand still while the gauntlets are played."""
    events = []
    cfg = TrainConfig(env="pong", run="t", steps=2048, games=16, eval_games=2, eval="inline", eval_playoff=0,
                      ppo=FAST_PPO, env_options={"points_to_win": 1})
    with League.open(tmp_path / "league") as league:
        league.roster.create_run("t", "pong", cfg.to_dict(), algo="ppo")
        Trainer(league, cfg, on_progress=events.append).train()
    ended = [e["standing"] for e in events if e["standing"].ended]
    assert ended and all(s.remaining is None for s in ended)


@pytest.mark.slow
def test_a_final_snapshot_that_holds_its_predecessors_weights_is_no_rival_and_says_whose_games_it_shows(
        tmp_path, capsys):
    """The lander's first update comes at 16,384 steps, so with snapshots every 10,000 steps and a 30,000-step
    budget the final snapshot (step 30,016) holds s10k's weights (taken at 16,384). One set of weights is one
    player: the playoff does not take it for a rival, the run's best is not "not separated" from it, and its
    summary line says whose games its figures are."""
    from sqlalchemy import select

    from selfplay_cli.league.models import Match

    home = tmp_path / "h"
    # (--eval-precision 0: 4 games a matchup, so the best is not separated by the gauntlets alone and a playoff runs)
    code, out, err = run(capsys, "train", "lander", "--agents", "2", "--steps", "30000", "--snapshot-steps", "10000",
                         "--eval-games", "4", "--eval-precision", "0", "--home", str(home))
    assert code == 0, err
    for k in (0, 1):
        assert (f"lander-1/s30k-lander_{k} (the same weights as lander-1/s10k-lander_{k}: one player, its games): "
                in out)
    (best,) = [line for line in out.splitlines() if line.strip().startswith("best of lander-1:")]
    assert "s30k" not in best and "not separated" not in best
    with League.open(home) as league, league.session(readonly=True) as s:
        params = [p for (p,) in s.execute(select(Match.params))]
    playoff = [json.dumps(p) for p in params if p.get("playoff")]
    assert playoff and not any("s30k" in p for p in playoff)  # never s10k's rival: the same player
