"""`marl train GAME --init-from SNAPSHOT_OR_TEAM` (issue 36): a run whose learners start from a snapshot's weights,
also at another team size: one snapshot or a FuPS network starts every learner, a NoPS team is resized by seed
001's rule (:func:`selfplay_cli.policies.resize.resize_members`), the parent is in the lineage, the optimiser is
fresh, and a resumed run keeps its own weights."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch
from cli_helpers import run, run_json

from selfplay_cli.cli import main
from selfplay_cli.league.store import League
from selfplay_cli.policies.resize import describe_resize, resize_members
from selfplay_cli.policies.snapshot_reader import load_snapshot
from selfplay_cli.train import init_from
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.loop import Trainer
from selfplay_cli.train.state import SnapshotMoments

TINY = ["--steps", "1000", "--snapshot-steps", "1000", "--games", "8", "--eval-games", "0", "--quiet"]
PPO = "[ppo]\nrollout_steps = 32\nupdate_epochs = 2\nminibatches = 2\n"  # a few updates in 1,000 steps


# -- the rule ---------------------------------------------------------------------------------------------------
def test_resize_members_keeps_the_first_seats_and_draws_from_the_third_on():
    assert resize_members(4, 4, 7) == [0, 1, 2, 3]
    for seed in range(20):
        shrunk = resize_members(4, 3, seed)
        assert shrunk[:2] == [0, 1] and shrunk[2] in (2, 3) and resize_members(4, 3, seed) == shrunk
        grown = resize_members(4, 7, seed)
        assert grown[:4] == [0, 1, 2, 3] and set(grown[4:]) <= {2, 3} and resize_members(4, 7, seed) == grown
        assert resize_members(3, 5, seed) == [0, 1, 2, 2, 2]  # the third member is the only one from the third on
        small = resize_members(2, 4, seed)  # no third member: copies of any member
        assert small[:2] == [0, 1] and set(small[2:]) <= {0, 1}
        kept = resize_members(6, 4, seed)
        assert kept[:2] == [0, 1] and len(kept) == 4 and kept == sorted(kept) and len(set(kept)) == 4
    assert {resize_members(4, 3, s)[2] for s in range(20)} == {2, 3}  # drawn, not fixed
    assert {x for s in range(20) for x in resize_members(4, 7, s)[4:]} == {2, 3}
    assert {x for s in range(20) for x in resize_members(2, 4, s)[2:]} == {0, 1}
    assert resize_members(4, 1, 3) == [0] and resize_members(2, 1, 3) == [0] and resize_members(5, 2, 3) == [0, 1]
    assert resize_members(1, 3, 0) == [0, 0, 0]
    with pytest.raises(ValueError):
        resize_members(0, 2, 0)
    assert "1 of the third and the fourth members is dropped" in describe_resize(4, 3)
    assert "2 more seats fly copies of the third member" in describe_resize(3, 5)
    assert "copy of the first or the second member" in describe_resize(2, 3)


# -- the parents, trained once ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def parents(tmp_path_factory):
    """A league with three lander runs of 1,000 steps: ``l4`` (4 landers, one network each), ``l3`` (3 landers, one
    network each) and ``l2f`` (2 landers, one shared network)."""
    root = tmp_path_factory.mktemp("parents")
    config = root / "ppo.toml"
    config.write_text(PPO)
    home = root / "h"
    for name, n, sharing in (("l4", 4, "nops"), ("l3", 3, "nops"), ("l2f", 2, "fups")):
        code = main(["train", "lander", "--agents", str(n), "--sharing", sharing, "--env-option", f"landers={n}",
                     "--config", str(config), "--run", name, "--seed", "11", "--home", str(home), *TINY])
        assert code == 0
    return root


@pytest.fixture
def home(parents, tmp_path, monkeypatch):
    """A copy of the parents' league, as MARL_HOME."""
    h = tmp_path / "h"
    shutil.copytree(parents / "h", h)
    monkeypatch.setenv("MARL_HOME", str(h))
    monkeypatch.delenv("MARL_DB", raising=False)
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    return h


@pytest.fixture
def ppo_toml(parents):
    return str(parents / "ppo.toml")


def weights(home: Path, full: str) -> dict[str, torch.Tensor]:
    run, name = full.split("/")
    tensors, _ = load_snapshot(home / "snapshots" / run / f"{name}.safetensors")
    return tensors


def same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def rows(home: Path, run: str) -> dict[str, object]:
    with League.open(home) as league:
        return {p.name: p for p in league.roster.players(env="lander", kind="snapshot") if p.run == run}


def fresh_optimisers(monkeypatch) -> list:
    """The learners' states at the run's first snapshot moment (its s0), captured as the moment writes them."""
    seen: list = []
    write_state = SnapshotMoments.write_state

    def capture(self, path, **kw):
        if not seen:
            seen.extend(
                {"net": {k: v.detach().clone() for k, v in learner.net.state_dict().items()},
                 "opt": {k: (v.detach().clone() if isinstance(v, torch.Tensor) else v)
                         for k, v in learner.opt.state_dict().items()}}
                for learner in self.learners)
        write_state(self, path, **kw)

    monkeypatch.setattr(SnapshotMoments, "write_state", capture)
    return seen


# -- across team sizes -------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_init_from_across_team_sizes_nops_4_to_3_and_3_to_5_by_the_rule(home, capsys, ppo_toml, monkeypatch):
    parent = weights(home, "l4/s1k-lander_3")
    assert not same(parent, weights(home, "l4/s0-lander_3")), "the parents learned: their weights are their own"
    seeds = {}  # two seeds whose draws drop different members of the four
    for seed in range(50):
        seeds.setdefault(resize_members(4, 3, seed)[2], seed)
    assert set(seeds) == {2, 3}
    for third, seed in sorted(seeds.items()):
        states = fresh_optimisers(monkeypatch)
        child = f"c{seed}"
        r = run_json(capsys, "train", "lander", "--agents", "3", "--env-option", "landers=3", "--init-from", "l4/s1k",
                     "--seed", str(seed), "--run", child, "--config", ppo_toml, *TINY)
        plan = r["init_from"]
        assert plan["source"] == "l4/s1k" and plan["members"] == [f"l4/s1k-lander_{i}" for i in range(4)]
        took = {name: e["member"] for name, e in plan["learners"].items()}
        assert took == {"lander_0": 0, "lander_1": 1, "lander_2": third}  # resize_members(4, 3, seed)
        mine = rows(home, child)
        for i, k in enumerate(took.values()):
            member = f"l4/s1k-lander_{k}"
            assert same(weights(home, f"{child}/s0-lander_{i}"), weights(home, member)), (child, i)
            assert same(states[i]["net"], weights(home, member))  # the learner itself, at its first moment
            assert int(states[i]["opt"]["steps"]) == 0 and not states[i]["opt"]["m"].any()  # a fresh optimiser
            assert not states[i]["opt"]["v"].any()
            assert mine[f"s0-lander_{i}"].parent_id == rows(home, "l4")[f"s1k-lander_{k}"].id  # the lineage
            assert mine[f"s1k-lander_{i}"].parent_id == mine[f"s0-lander_{i}"].id
        shown = run_json(capsys, "checkpoint", "show", f"{child}/s1k-lander_2")
        assert shown["lineage"][:2] == [f"{child}/s0-lander_2", f"l4/s1k-lander_{third}"]
        # the run's config and metrics say it too
        config = json.loads((home / "runs" / child / "config.json").read_text())
        assert config["init_from"] == "l4/s1k" and config["init_plan"] == plan
        first = json.loads((home / "runs" / child / "metrics.jsonl").read_text().splitlines()[0])
        assert first == {"step": 0, "init_from": plan}
    parent_state = torch.load(home / "runs" / "l4" / "state.pt", weights_only=True)
    assert int(parent_state["learners"][3]["opt"]["steps"]) > 0  # the parent's optimiser had moved: not taken over

    r = run_json(capsys, "train", "lander", "--agents", "5", "--env-option", "landers=5", "--init-from", "l3/s1k",
                 "--seed", "4", "--run", "g5", "--config", ppo_toml, *TINY)
    took = [e["member"] for e in r["init_from"]["learners"].values()]
    assert took == [0, 1, 2, 2, 2] == resize_members(3, 5, 4)
    assert "2 more seats fly copies of the third member" in r["init_from"]["rule"]
    for i, k in enumerate(took):
        assert same(weights(home, f"g5/s0-lander_{i}"), weights(home, f"l3/s1k-lander_{k}")), i


@pytest.mark.slow
def test_init_from_a_shared_network_at_another_size_and_from_a_config_file(home, capsys, tmp_path, ppo_toml):
    parent = weights(home, "l2f/s1k")
    config = tmp_path / "child.toml"
    config.write_text('init_from = "l2f/s1k"\n' + PPO)
    r = run_json(capsys, "train", "lander", "--agents", "3", "--sharing", "fups", "--env-option", "landers=3",
                 "--config", str(config), "--run", "f3", *TINY)  # FuPS 2 -> 3
    assert r["init_from"]["learners"] == {"learner": {"member": 0, "snapshot": "l2f/s1k",
                                                      "id": rows(home, "l2f")["s1k"].id}}
    assert same(weights(home, "f3/s0"), parent) and not same(weights(home, "f3/s1k"), parent)  # it learned on
    assert rows(home, "f3")["s0"].parent_id == rows(home, "l2f")["s1k"].id
    code, out, err = run(capsys, "train", "lander", "--agents", "4", "--env-option", "landers=4", "--init-from",
                         "l2f/s1k", "--run", "n4", "--config", ppo_toml, *TINY)  # one network -> NoPS: copies
    assert code == 0, err
    assert "started from l2f/s1k (one snapshot: every learner starts from it)" in out
    for i in range(4):
        assert same(weights(home, f"n4/s0-lander_{i}"), parent)
    r = run_json(capsys, "train", "lander", "--agents", "2", "--sharing", "fups", "--init-from", "l4/s1k",
                 "--run", "t1", "--config", ppo_toml, *TINY)  # a team into one shared network: its first member
    assert r["init_from"]["learners"]["learner"]["snapshot"] == "l4/s1k-lander_0"
    assert same(weights(home, "t1/s0"), weights(home, "l4/s1k-lander_0"))


# -- refusals ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("extra", "toml", "needle"), [
    (["--init-from", "nope"], "", "--init-from: no policy named 'nope' in lander"),
    (["--init-from", "heuristic"], "", "heuristic is a scripted player, not a snapshot"),
    (["--init-from", "l4/s1k"], "[ppo.arch]\nhidden = [32]\n",
     "l4/s1k-lander_0's network (mlp 64x64 relu +value) does not fit learner lander_0's (mlp 32 relu +value)"),
    (["--init-from", "l4/s1k", "--env-option", "continuous=true"], "",
     "l4/s1k-lander_0 plays Discrete(4); learner lander_0 of this run plays Box(-1, 1, (2,), float32)"),
    (["--init-from", "l4/s1k", "--frame-stack", "2"], "",
     "l4/s1k-lander_0 reads observations of shape [8]; learner lander_0 of this run reads [16]"),
    (["--init-from", "l4/s1k", "--algo", "dqn"], "", "l4/s1k-lander_0 was trained by ppo; this run learns with dqn"),
    (["--init-from", "l4/s1k", "--sharing", "sa"], "", "one agent over the whole team (--sharing sa)"),
    ([], 'init_plan = {learners = {}}\n', "init_plan is written by marl when a run is created"),
])
def test_refusals_are_one_line_and_leave_no_run(home, capsys, tmp_path, extra, toml, needle):
    config = tmp_path / "bad.toml"
    config.write_text(toml)
    code, out, err = run(capsys, "train", "lander", "--agents", "2", "--run", "bad", "--config", str(config),
                         *extra, *TINY)
    assert code == 2 and needle in err and err.count("\n") == 1 and "Traceback" not in err, err
    with League.open(home) as league:
        assert league.roster.get_run("bad") is None


def test_resume_cannot_change_init_from(home, capsys):
    code, out, err = run(capsys, "train", "--resume", "l4", "--init-from", "l3/s1k")
    assert code == 2 and "--init-from cannot change it" in err and err.count("\n") == 1, err


# -- a resumed run ----------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_resumed_run_keeps_its_own_weights(home, capsys, monkeypatch, ppo_toml):
    write = SnapshotMoments.write

    def stopped_after_s1k(self, trigger, which=None):
        write(self, trigger, which)
        if trigger == "steps":
            raise KeyboardInterrupt  # as Ctrl-C would, right after the moment

    monkeypatch.setattr(SnapshotMoments, "write", stopped_after_s1k)
    args = ["train", "lander", "--agents", "3", "--env-option", "landers=3", "--init-from", "l3/s1k", "--run", "k",
            "--config", ppo_toml, "--steps", "2000", "--snapshot-steps", "1000", "--games", "8", "--eval-games", "0",
            "--quiet"]
    code, out, err = run(capsys, *args)
    assert code == 130 and "marl train --resume k" in err, err
    monkeypatch.setattr(SnapshotMoments, "write", write)
    own = [weights(home, f"k/s1k-lander_{i}") for i in range(3)]
    assert not any(same(own[i], weights(home, f"l3/s1k-lander_{i}")) for i in range(3)), "it learned for 1,000 steps"

    def never(*a, **kw):
        raise AssertionError("a resumed run loaded its parent's weights again")

    monkeypatch.setattr(init_from, "load_init", never)
    with League.open(home) as league:  # restored: the learners are the run's own s1k
        trainer = Trainer(league, TrainConfig.from_dict(league.roster.get_run("k").config))
        trainer.restore()
        trainer._unlock()
        for learner, mine in zip(trainer.learners, own, strict=True):
            assert same({k: v.detach().cpu() for k, v in learner.net.state_dict().items()}, mine)
    r = run_json(capsys, "train", "--resume", "k")
    assert r["steps"] == 2000 and r["sessions"] == 2 and r["init_from"]["source"] == "l3/s1k"
    lines = (home / "runs" / "k" / "metrics.jsonl").read_text().splitlines()
    assert sum("init_from" in json.loads(line) for line in lines) == 1  # started once, resumed once


def test_a_run_not_yet_started_needs_the_snapshot_it_starts_from(home, capsys, monkeypatch, ppo_toml):
    def interrupted(self):
        raise KeyboardInterrupt  # stopped before its first snapshot moment

    monkeypatch.setattr(Trainer, "train", interrupted)
    code, out, err = run(capsys, "train", "lander", "--agents", "2", "--init-from", "l2f/s1k", "--run", "w",
                         "--config", ppo_toml, *TINY)
    assert code == 130, err
    code, out, err = run(capsys, "checkpoint", "rm", "l2f/s1k")
    assert code == 2 and "needed by run 'w' (--init-from: its learners start from it" in err, err
    code, out, err = run(capsys, "checkpoint", "rm", "l2f/s0")  # not its parent: removed
    assert code == 0, err
