"""AlphaStar's league roles (``--league alphastar``): each role's opponent rule against its stated distribution
(chi-square), the snapshot rule (beaten targets after the minimum, or the step limit), the restarts at a snapshot,
and `marl train --league alphastar` end to end on the suite's tic-tac-toe and race, killed and resumed."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from cli_helpers import run
from scipy.stats import chisquare

from selfplay_cli.envs import get_env
from selfplay_cli.league.store import League
from selfplay_cli.play.seat_plan import OPPONENT, league_layout, plan_seats
from selfplay_cli.policies.snapshot_reader import load_snapshot
from selfplay_cli.train.config import TrainConfig
from selfplay_cli.train.league_roles import LeagueConfig, LeagueRoles, Past, live
from selfplay_cli.train.loop import Trainer
from selfplay_cli.train.state import SnapshotMoments
from selfplay_cli.train.win_rates import WinRates

TTT = "tests.games.tictactoe:env"
DRAWS = 20_000


def book(rates: dict[tuple[int, int], float]) -> WinRates:
    """A win-rate book holding exactly these win rates (no prior: one game of that many points each)."""
    out = WinRates(decay=0.99, prior=0.0)
    for (i, opponent), p in rates.items():
        out.update(i, opponent, p)
    return out


def roles_of(config: LeagueConfig, pool: list[tuple[int, int]], seed: int = 0) -> LeagueRoles:
    roles = LeagueRoles(config, [1.0 / len(config.roles())] * len(config.roles()), np.random.default_rng(seed))
    roles.set_pool([Past(pid, learner) for pid, learner in pool])
    return roles


def assert_drawn_as(draws: np.ndarray, expected: dict[int, float]) -> None:
    """The draws fall only on ``expected``'s ids, at its probabilities (chi-square, p > 0.001)."""
    assert abs(sum(expected.values()) - 1.0) < 1e-12
    ids = sorted(expected)
    assert set(np.unique(draws).tolist()) <= set(ids), set(np.unique(draws).tolist()) - set(ids)
    seen = [int((draws == i).sum()) for i in ids]
    if len(ids) == 1:
        assert seen == [len(draws)]
        return
    result = chisquare(seen, [expected[i] * len(draws) for i in ids])
    assert result.pvalue > 1e-3, (dict(zip(ids, seen, strict=True)), expected)


def normalised(weights: dict[int, float]) -> dict[int, float]:
    total = sum(weights.values())
    return {k: v / total for k, v in weights.items()}


def mix(*parts: tuple[float, dict[int, float]]) -> dict[int, float]:
    out: dict[int, float] = {}
    for share, dist in parts:
        for k, v in dist.items():
            out[k] = out.get(k, 0.0) + share * v
    return out


# learners of the default league: 0 main, 1 main exploiter, 2 and 3 league exploiters. Past players by id: 10-13 the
# four s0 snapshots, 20 and 30 the main agent's later ones, 21 the main exploiter's.
POOL = [(10, 0), (11, 1), (12, 2), (13, 3), (20, 0), (21, 1), (30, 0)]


def test_a_main_agent_that_an_exploiter_beats_draws_pfsp_verification_against_it_and_self_play():
    rates = book({(0, 10): 0.9, (0, 11): 0.8, (0, 13): 0.6, (0, 20): 0.4, (0, 21): 0.2, (0, 30): 0.7})  # 12 unseen
    draws = roles_of(LeagueConfig(), POOL).sample(0, DRAWS, rates)
    p = {10: 0.9, 11: 0.8, 12: 0.5, 13: 0.6, 20: 0.4, 21: 0.2, 30: 0.7}
    pfsp_squared = normalised({k: (1 - x) ** 2 for k, x in p.items()})  # 50%: every past player, (1 - p)^2
    exploiters = normalised({11: 0.2**2, 21: 0.8**2})  # 15%: 21 is beaten less than 30% of the time: all of theirs
    assert_drawn_as(draws, mix((0.5, pfsp_squared), (0.15, exploiters), (0.35, {live(0): 1.0})))  # 35%: itself


def test_a_main_agent_that_forgets_verifies_against_its_own_past_and_falls_back_on_pfsp_variance():
    rates = book({(0, 11): 0.5, (0, 21): 0.4, (0, 10): 0.6, (0, 20): 0.8, (0, 30): 0.5, (0, 12): 0.5, (0, 13): 0.5,
                  (0, live(0)): 0.2})  # (itself as it is now beats it: self-play gives way to its snapshots)
    draws = roles_of(LeagueConfig(), POOL).sample(0, DRAWS, rates)
    p = {10: 0.6, 11: 0.5, 12: 0.5, 13: 0.5, 20: 0.8, 21: 0.4, 30: 0.5}
    pfsp_squared = normalised({k: (1 - x) ** 2 for k, x in p.items()})
    # its own past 0.6, 0.8, 0.5: the falling suffix (30) goes; 0.6 < 0.7 so it verifies on 10 and 20, (1 - p)^2
    forgetting = normalised({10: 0.4**2, 20: 0.2**2})
    variance = normalised({10: 0.6 * 0.4, 20: 0.8 * 0.2, 30: 0.5 * 0.5})  # its own snapshots, p(1 - p)
    assert_drawn_as(draws, mix((0.5, pfsp_squared), (0.15, forgetting), (0.35, variance)))


def test_a_main_exploiter_plays_the_main_agents_it_can_beat_and_pfsp_variance_over_the_others_snapshots():
    config = LeagueConfig(main=2)  # learners 0, 1 main; 2 the main exploiter; 3, 4 league exploiters
    pool = [(10, 0), (11, 1), (20, 0), (21, 1), (31, 1), (12, 2)]
    rates = book({(2, live(0)): 0.15, (2, live(1)): 0.05, (2, 11): 0.3, (2, 21): 0.1, (2, 31): 0.6})
    draws = roles_of(config, pool).sample(2, DRAWS, rates)
    variance = normalised({11: 0.3 * 0.7, 21: 0.1 * 0.9, 31: 0.6 * 0.4})  # main agent 1's snapshots
    assert_drawn_as(draws, mix((0.5, {live(0): 1.0}), (0.5, variance)))  # each main agent half the time


def test_a_main_exploiter_that_beats_the_main_agent_plays_it_as_it_is_now():
    draws = roles_of(LeagueConfig(), POOL).sample(1, 1000, book({(1, live(0)): 0.11}))
    assert (draws == live(0)).all()


def test_a_league_exploiter_draws_every_past_player_weighted_min_half_one_minus_p():
    rates = book({(2, 10): 0.1, (2, 11): 0.6, (2, 12): 0.3, (2, 13): 0.9, (2, 20): 0.45, (2, 21): 0.99})
    draws = roles_of(LeagueConfig(), POOL).sample(2, DRAWS, rates)
    p = {10: 0.1, 11: 0.6, 12: 0.3, 13: 0.9, 20: 0.45, 21: 0.99, 30: 0.5}
    assert_drawn_as(draws, normalised({k: min(0.5, 1 - x) for k, x in p.items()}))


def test_before_any_snapshot_every_role_plays_the_main_agent_as_it_is_now():
    roles = roles_of(LeagueConfig(), [])
    for i in range(4):
        assert (roles.sample(i, 50, book({})) == live(0)).all()


def test_a_snapshot_is_due_when_the_targets_are_beaten_after_the_minimum_or_at_the_step_limit():
    config = LeagueConfig(min_steps=100, max_steps=300)
    roles = LeagueRoles(config, [0.5, 0.25, 0.125, 0.125], np.random.default_rng(0))
    roles.set_pool([Past(10, 0), Past(11, 1)])
    beaten = {(0, 10): 0.8, (0, 11): 0.75, (1, live(0)): 0.71, (2, 10): 0.9, (2, 11): 0.65, (3, 10): 0.5}
    rates = book(beaten)
    assert roles.due(199, rates) == []  # the main agent has played 99 steps of its own: not yet
    assert roles.due(200, rates) == [0]  # 100 of its own, and it beats every past player more than 70%
    assert roles.due(400, rates) == [0, 1]  # the main exploiter beats the main agent as it is now
    assert roles.due(2399, rates) == [0, 1]  # league exploiter 2 does not beat 11 (0.65), nor 3 anyone yet
    assert roles.due(2400, rates) == [0, 1, 2, 3]  # both at their step limit: 300 of their own (1/8 of 2,400)
    assert roles.taken([0], 300) == []  # a main agent does not restart; its clock starts again
    assert roles.due(400, rates) == [1] and roles.due(500, rates) == [0, 1]


@pytest.fixture
def tictactoe_trainer(tmp_path):
    """A league run of tic-tac-toe built (not trained), its first moment taken."""
    league = League.open(tmp_path / "h")
    cfg = TrainConfig.from_dict({"env": TTT, "run": "r", "games": 8, "eval_games": 0, "league": {}})
    league.roster.create_run("r", cfg.env, cfg.to_dict(), algo=cfg.algo)
    trainer = Trainer(league, cfg)
    trainer.moments.write("start")
    yield trainer, league
    league.close()


def weights(net: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in net.state_dict().items()}


def trained(learner) -> dict[str, torch.Tensor]:
    """Move the learner's weights away from its first ones (as training would); the weights it has now."""
    with torch.no_grad():
        for p in learner.net.parameters():
            p.add_(0.5)
    return weights(learner.net)


def saved_weights(league: League, name: str) -> dict[str, torch.Tensor]:
    (row,) = [p for p in league.roster.players(kind="snapshot") if p.name == name]
    tensors, _ = load_snapshot(league.home / row.path)
    return tensors


def test_a_main_exploiter_restarts_from_its_first_weights_at_its_snapshot(tictactoe_trainer):
    trainer, league = tictactoe_trainer
    main, mainx = trainer.learners[0], trainer.learners[1]
    first = weights(mainx.net)
    taught, main_taught = trained(mainx), trained(main)
    trainer.state.steps = 3000
    trainer.moments.write("roles", [0, 1])
    for k, v in saved_weights(league, "s3k-mainx").items():  # the snapshot first: what it had learned
        assert torch.equal(v, taught[k]), k
    for k, v in weights(mainx.net).items():  # then the restart
        assert torch.equal(v, first[k]), k
    for k, v in weights(main.net).items():  # a main agent keeps learning from where it stands
        assert torch.equal(v, main_taught[k]), k
    rows = {p.name: p for p in league.roster.players(kind="snapshot")}
    assert rows["s3k-mainx"].meta["league_role"] == "main_exploiter" and rows["s3k-main"].meta["league_role"] == "main"
    assert "s3k-leaguex1" not in rows, "only the learners whose snapshot was due"
    assert trainer.roles.since == [3000, 3000, 0, 0]


def seed_whose_first_draw(below: bool) -> int:
    return next(s for s in range(100) if (np.random.default_rng(s).random() < 0.25) == below)


@pytest.mark.parametrize("restarts", [True, False])
def test_a_league_exploiter_restarts_with_probability_a_quarter(tictactoe_trainer, restarts):
    trainer, league = tictactoe_trainer
    exploiter = trainer.learners[2]
    first = weights(exploiter.net)
    taught = trained(exploiter)
    trainer.roles.rng = np.random.default_rng(seed_whose_first_draw(below=restarts))
    trainer.state.steps = 3000
    trainer.moments.write("roles", [2])
    expect = first if restarts else taught
    assert all(torch.equal(v, expect[k]) for k, v in weights(exploiter.net).items())
    assert all(torch.equal(v, taught[k]) for k, v in saved_weights(league, "s3k-leaguex1").items())


def test_the_league_layout_gives_each_learner_its_games_one_seat_each_alternating():
    two_sides = league_layout(plan_seats(get_env(TTT), 1), 8, 4)
    assert two_sides.tolist() == [[0, 1, 2, 3, -1, -1, -1, -1], [-1, -1, -1, -1, 0, 1, 2, 3]]
    race = get_env("tests.games.race:parallel_env")
    ffa = league_layout(plan_seats(race, 1), 12, 4)  # three seats: each learner's games go round them
    assert ((ffa != OPPONENT).sum(axis=0) == 1).all()
    for i in range(4):
        seats = sorted(int(s) for s in np.nonzero(ffa == i)[0])
        assert seats == [0, 1, 2] and (ffa == i).any(axis=0).tolist() == [g % 4 == i for g in range(12)]


def league_rows(home) -> list:
    with League.open(home) as league:
        return league.roster.players(kind="snapshot")


@pytest.mark.slow
def test_marl_train_league_alphastar_end_to_end_killed_and_resumed(tmp_path, capsys, monkeypatch):
    home = str(tmp_path / "h")
    config = tmp_path / "league.toml"
    config.write_text("[league]\nmin_steps = 200\nmax_steps = 400\n")
    args = ["train", TTT, "--config", str(config), "--games", "16", "--steps", "6144", "--eval-games", "0",
            "--run", "r", "--home", home, "--quiet"]
    write = SnapshotMoments.write
    moments = []

    def killed_after_two_role_moments(self, trigger, which=None):
        write(self, trigger, which)
        moments.append(trigger)
        if moments.count("roles") == 2:
            raise KeyboardInterrupt  # as Ctrl-C would, right after the moment

    monkeypatch.setattr(SnapshotMoments, "write", killed_after_two_role_moments)
    code, out, err = run(capsys, *args)
    assert code == 130 and "marl train --resume r" in err, err
    monkeypatch.setattr(SnapshotMoments, "write", write)
    before = league_rows(home)
    assert {p.meta["league_role"] for p in before} == {"main", "main_exploiter", "league_exploiter"}
    assert sorted(p.name for p in before if p.step == 0) == ["s0-leaguex1", "s0-leaguex2", "s0-main", "s0-mainx"]

    state = torch.load(tmp_path / "h" / "runs" / "r" / "state.pt", weights_only=True)
    saved_roles = json.loads(state["roles"])
    assert saved_roles["since"] == [4096] * 4  # each learner at its step limit (400 of its own: a quarter of 1,600)
    # the first states are the run state's: a resumed learner restarts to what it saved, however it is built
    state["first"][1]["net"] = {k: v + 1.0 for k, v in state["first"][1]["net"].items()}
    torch.save(state, tmp_path / "h" / "runs" / "r" / "state.pt")
    with League.open(home) as league:
        cfg = TrainConfig.from_dict(league.roster.get_run("r").config)
        trainer = Trainer(league, cfg)
        trainer.restore()
        trainer._unlock()
        assert trainer.roles.since == saved_roles["since"]
        assert trainer.opponents.rates == WinRates.from_dict(json.loads(state["rates"]))
        assert len(trainer.opponents.rates) > 0
        for k, v in state["first"][1]["net"].items():
            assert torch.equal(trainer.moments.first[1]["net"][k], v)

    code, out, err = run(capsys, "train", "--resume", "r", "--home", home, "--json")
    assert code == 0, err
    assert json.loads(out)["steps"] == 6144
    rows = league_rows(home)
    assert [p.name for p in rows[: len(before)]] == [p.name for p in before]
    assert len(rows) > len(before)
    by_learner: dict[str, list] = {}
    for p in rows:
        by_learner.setdefault(p.meta["learner"], []).append(p)
    role = {"main": "main", "mainx": "main_exploiter", "leaguex1": "league_exploiter", "leaguex2": "league_exploiter"}
    assert set(by_learner) == set(role)
    for learner, chain in by_learner.items():
        assert all(p.name.endswith("-" + learner) and p.meta["league_role"] == role[learner] for p in chain)
        assert all(cur.parent_id == prev.id for prev, cur in zip(chain, chain[1:], strict=False)), learner
        assert [p.step for p in chain] == sorted({p.step for p in chain}), learner
        assert chain[-1].step == 6144


def test_a_free_for_all_game_trains_a_league(tmp_path, capsys):
    home = str(tmp_path / "h")
    code, out, err = run(capsys, "train", "tests.games.race:parallel_env", "--league", "alphastar",
                         "--league-league-exploiters", "1", "--games", "9", "--steps", "603", "--eval-games", "0",
                         "--run", "r", "--home", home, "--json")
    assert code == 0, err
    roles = {p.name: p.meta["league_role"] for p in league_rows(home)}
    assert roles == {"s0-main": "main", "s0-mainx": "main_exploiter", "s0-leaguex": "league_exploiter",
                     "s603-main": "main", "s603-mainx": "main_exploiter", "s603-leaguex": "league_exploiter"}


@pytest.mark.parametrize(("args", "needle"), [
    (["tests.games.reach:parallel_env", "--league", "alphastar"], "cooperative games have no exploiters"),
    ([TTT, "--league", "alphastar", "--sharing", "fups"], "--sharing fups does not apply"),
    ([TTT, "--league", "alphastar", "--agents", "2"], "--agents does not apply with --league alphastar"),
    ([TTT, "--league", "alphastar", "--seats", "1,-"], "--seats does not apply"),
    ([TTT, "--league-main", "2"], "--league-main sizes a league of roles: it needs --league alphastar"),
    ([TTT, "--league", "psro"], "--league must be one of alphastar, not 'psro'"),
    ([TTT, "--league", "alphastar", "--games", "7"], "--games must be at least 8 with --league alphastar: each of its "
                                                      "4 learners plays a game in each of the game's 2 sides"),
])
def test_a_league_that_makes_no_sense_is_one_line(tmp_path, capsys, args, needle):
    code, out, err = run(capsys, "train", *args, "--home", str(tmp_path / "h"))
    assert code == 2 and needle in err and err.count("\n") == 1, err
    assert not (tmp_path / "h" / "runs").exists()
