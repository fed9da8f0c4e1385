"""PettingZoo games in marl: the adapter's batched core against the games played directly, loading games by name
(module:factory, modules, entry points), their options, and one clear error for every way a game can be wrong."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv

from selfplay_cli.envs import EnvError, IllegalActionError, UnknownEnvError, admit, env_names, get_env, loading
from selfplay_cli.envs.adapters.pettingzoo import adapt
from selfplay_cli.envs.adapters.pettingzoo_core import PettingZooCore

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the suite's games are tests.games.*
    sys.path.insert(0, str(ROOT))

from tests.games import rendezvous, tictactoe  # noqa: E402

TTT = "tests.games.tictactoe:env"
RDV = "tests.games.rendezvous:parallel_env"


# ---------------------------------------------------------------------------------------------------------------
# The declaration read from one instance
def test_an_aec_game_is_sequential_two_sides_with_masks():
    spec = get_env(TTT)
    assert spec.agents == ("x", "o") and spec.turns == "sequential" and spec.kind == "two-sides"
    assert spec.side_seats() == ((0,), (1,)) and spec.max_steps() == 9
    seats = spec.seat_spaces()
    assert all(s.mask and s.action == spaces.Discrete(9) for s in seats)
    assert seats[0].observation.shape == (27,) and seats[0].observation.dtype == np.float32
    assert spec.bots["random"].uses_mask and spec.make_renderer is not None
    assert get_env(TTT) is spec, "a game loaded by name is kept"


def test_a_parallel_game_is_simultaneous_and_its_kind_comes_from_metadata():
    spec = get_env(RDV)
    assert spec.turns == "simultaneous" and spec.kind == "cooperative" and spec.n_seats == 3
    assert spec.side_seats() == ((0, 1, 2),)
    assert spec.max_steps() == 50, "max_cycles is the time limit"
    assert spec.seat_spaces()[1].action == spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
    module = get_env("tests.games.rendezvous")  # a module: its parallel_env()
    assert module.turns == "simultaneous" and module.agents == spec.agents


def test_default_kinds_by_number_of_agents_and_declared_sides():
    def game(n, **md):
        class G(_Simple):
            metadata = {"name": "g", **md}
        return lambda **o: G(n=n, **o)

    assert adapt("two", game(2)).kind == "two-sides"
    assert adapt("solo", game(1)).kind == "cooperative"
    assert adapt("crowd", game(4)).kind == "free-for-all"
    teams = adapt("teams", game(4, marl_kind="two-sides", marl_sides=[["p0", "p2"], [1, 3]]))
    assert teams.side_seats() == ((0, 2), (1, 3))
    with pytest.raises(EnvError, match="marl_sides"):
        adapt("teams?", game(4, marl_kind="two-sides"))
    with pytest.raises(EnvError, match="marl_kind must be one of"):
        adapt("odd", game(2, marl_kind="zero-sum"))
    coop = adapt("coop", game(3, marl_kind="cooperative", marl_tie_tolerance=0.5))
    assert coop.tie_tolerance == 0.5


# ---------------------------------------------------------------------------------------------------------------
# The batched core against the game played directly
def test_parallel_core_plays_each_copy_exactly_as_the_game_alone():
    n, steps = 4, 60
    core = get_env(RDV).core(n)
    seeds = [11, 12, 13, 14]
    core.reset(np.arange(n), seeds)
    alone = [rendezvous.parallel_env() for _ in range(n)]
    direct = [env.reset(seed=s)[0] for env, s in zip(alone, seeds, strict=True)]
    totals = np.zeros((3, n))
    rng = np.random.default_rng(0)
    agents = ["a0", "a1", "a2"]
    for t in range(steps):
        obs = core.observe()
        for g in range(n):
            if alone[g].agents:
                for s, a in enumerate(agents):
                    assert np.array_equal(obs[s, g], direct[g][a])
        actions = rng.uniform(-1, 1, (3, n, 2)).astype(np.float32)
        running = core.to_act().any(axis=0)
        rewards = core.step(actions)
        for g in range(n):
            if not running[g]:
                assert (rewards[:, g] == 0).all(), "a finished game stands still"
                continue
            direct[g], rew, term, trunc, _ = alone[g].step({a: actions[s, g] for s, a in enumerate(agents)})
            totals[:, g] += [rew[a] for a in agents]
            assert rewards[:, g] == pytest.approx([rew[a] for a in agents])
            assert core.truncated[g] == (t == 49) and not core.terminated[g]
    assert core.score == pytest.approx(totals)
    assert (core.steps == 50).all() and not core.to_act().any(), "over after 50 steps, nobody acts"


def test_aec_core_takes_turns_masks_moves_and_scores_the_winner():
    core = get_env(TTT).core(2)
    core.reset([0, 1], [0, 1])
    assert core.to_act().tolist() == [[True, True], [False, False]], "x moves first"
    # game 0: x wins on the top row; game 1: x, o alternate into a draw
    game0 = [0, 3, 1, 4, 2]
    game1 = [0, 1, 2, 4, 3, 5, 7, 6, 8]
    for t in range(9):
        acting = core.to_act()
        seat = 0 if t % 2 == 0 else 1
        assert acting[seat, 1] and not acting[1 - seat, 1]
        masks = core.action_masks()
        board_taken = set(game1[:t])
        assert masks[seat][1].tolist() == [c not in board_taken for c in range(9)], "the mask is the empty cells"
        assert masks[1 - seat][1].all(), "a seat that does not act has every action allowed (ignored)"
        a = np.zeros((2, 2), dtype=np.int64)
        a[seat, 1] = game1[t]
        a[seat, 0] = game0[t] if t < len(game0) else 0
        rewards = core.step(a)
        if t == 4:
            assert rewards[:, 0].tolist() == [1.0, -1.0] and core.terminated[0] and not core.truncated[0]
            assert not core.to_act()[:, 0].any(), "a finished game has nobody to act"
        if t > 4:
            assert not core.terminated[0] and (rewards[:, 0] == 0).all()
    assert core.terminated[1] and core.score[:, 1].tolist() == [0.0, 0.0], "a draw"
    assert core.score[:, 0].tolist() == [1.0, -1.0] and core.steps.tolist() == [5, 9]
    obs = core.observe()
    assert obs.shape == (2, 2, 27) and obs.dtype == np.float32
    # x's last view of game 0 (its observation when it left): its 3 marks on the top row, o's 2 below
    assert obs[0, 0, :9].tolist() == [1, 1, 1, 0, 0, 0, 0, 0, 0] and obs[0, 0, 9:18].sum() == 2


def test_an_action_the_mask_forbids_is_refused_before_any_game_moves():
    core = get_env(TTT).core(3)
    core.reset([0, 1, 2], [0, 1, 2])
    core.step(np.array([[4, 4, 4], [0, 0, 0]]))
    boards = [env.board.copy() for env in core.envs]
    with pytest.raises(IllegalActionError) as e:
        core.step(np.array([[0, 0, 0], [1, 4, 2]]))  # o plays the taken centre in game 1
    assert (e.value.seat, e.value.game, e.value.action) == (1, 1, 4) and isinstance(e.value, ValueError)
    assert "forbidden by its action mask" in str(e.value)
    assert all(np.array_equal(env.board, b) for env, b in zip(core.envs, boards, strict=True)), "nothing moved"
    with pytest.raises(IllegalActionError, match="outside Discrete"):
        core.step(np.array([[0, 0, 0], [9, 1, 2]]))


def test_reset_by_seed_reproduces_a_game_and_other_seeds_differ():
    def play(seed):
        core = get_env(RDV).core(1)
        core.reset([0], [seed])
        out = [core.observe().copy()]
        for _ in range(10):
            core.step(np.full((3, 1, 2), 0.5, dtype=np.float32))
            out.append(core.observe().copy())
        return np.array(out), core.score.copy()

    a, b, c = play(5), play(5), play(6)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


class _Simple(ParallelEnv):
    """A configurable parallel game: ``n`` agents p0.. with Box observations; agent ``leaves`` (index) is done
    after ``leave_at`` steps (terminated, or truncated with ``cut``), the rest after ``end_at``."""

    metadata = {"name": "simple"}

    def __init__(self, n=2, leaves=None, leave_at=2, end_at=4, cut=False, act=None, obs=None, render_mode=None):
        self.possible_agents = [f"p{i}" for i in range(n)]
        self.agents = []
        self.leaves, self.leave_at, self.end_at, self.cut = leaves, leave_at, end_at, cut
        self._o = obs or spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._a = act or spaces.Discrete(3)
        self.t = 0
        self.seen = []

    def observation_space(self, agent):
        return self._o

    def action_space(self, agent):
        return self._a

    def _obs(self):
        return {a: np.full(2, self.t / 10, dtype=np.float32) for a in self.agents}

    def reset(self, seed=None, options=None):
        self.t = 0
        self.agents = self.possible_agents[:]
        return self._obs(), {a: {} for a in self.agents}

    def step(self, actions):
        self.seen.append(dict(actions))
        self.t += 1
        term = dict.fromkeys(self.agents, False)
        trunc = dict.fromkeys(self.agents, False)
        if self.leaves is not None and self.t == self.leave_at:
            a = self.possible_agents[self.leaves]
            (trunc if self.cut else term)[a] = True
        if self.t >= self.end_at:
            term = dict.fromkeys(self.agents, True)
        out = self._obs(), dict.fromkeys(self.agents, 1.0), term, trunc, {a: {} for a in self.agents}
        self.agents = [a for a in self.agents if not (term[a] or trunc[a])]
        return out


def test_agents_that_leave_early_no_longer_act_and_the_game_ends_when_all_are_done():
    spec = adapt("leavers", lambda **o: _Simple(n=3, leaves=1, leave_at=2, end_at=4, **o))
    core = spec.core(1)
    for t in range(4):
        acting = core.to_act()[:, 0].tolist()
        assert acting == ([True, True, True] if t < 2 else [True, False, True])
        core.step(np.ones((3, 1), dtype=np.int64))
        assert core.terminated[0] == (t == 3) and not core.truncated[0]
    assert core.envs[0].seen[-1] == {"p0": 1, "p2": 1}, "the agent that left is given no action"
    assert core.score[:, 0].tolist() == [4.0, 2.0, 4.0], "rewards while in the game"


def test_a_game_cut_by_truncation_is_truncated_not_terminated():
    spec = adapt("cut", lambda **o: _Simple(n=2, leaves=0, leave_at=1, end_at=3, cut=True, **o))
    core = spec.core(1)
    for _ in range(3):
        core.step(np.zeros((2, 1), dtype=np.int64))
    assert core.truncated[0] and not core.terminated[0]


def test_multidiscrete_and_offset_discrete_actions_reach_the_env_as_it_declares_them():
    spec = adapt("multi", lambda **o: _Simple(act=spaces.MultiDiscrete([3, 2], start=[1, 5]), **o))
    assert spec.seat_spaces()[0].action == spaces.MultiDiscrete([3, 2])
    core = spec.core(2)
    core.step([np.array([[2, 1], [0, 0]]), np.array([[1, 0], [2, 1]])])
    assert [a.tolist() for a in core.envs[0].seen[-1].values()] == [[3, 6], [2, 5]]
    with pytest.raises(IllegalActionError, match="outside MultiDiscrete"):
        core.step([np.array([[3, 0], [0, 0]]), np.zeros((2, 2), dtype=np.int64)])
    shifted = adapt("shifted", lambda **o: _Simple(act=spaces.Discrete(3, start=-1), **o))
    assert shifted.seat_spaces()[0].action == spaces.Discrete(3)
    core = shifted.core(1)
    core.step(np.array([[0], [2]]))
    assert core.envs[0].seen[-1] == {"p0": -1, "p1": 1}


def test_render_is_the_games_own_frame():
    spec = get_env(TTT)
    core = spec.core(2)
    core.step(np.array([[4, 0], [0, 0]]))
    frame = spec.make_renderer().draw(core, 0)
    assert frame.shape == (96, 96, 3) and frame.dtype == np.uint8
    assert np.array_equal(frame, core.envs[0].render())
    assert not np.array_equal(frame, spec.make_renderer().draw(core, 1))
    assert adapt("no-frames", lambda **o: _Simple(**o)).make_renderer is None


# ---------------------------------------------------------------------------------------------------------------
# Options
def test_env_options_reach_the_factory_and_are_checked():
    spec = get_env(RDV)
    cfg = spec.config(max_cycles=5)
    assert spec.max_steps(cfg) == 5 and cfg.options == {"max_cycles": 5}
    core = spec.make_core(2, cfg)
    for _ in range(5):
        core.step(np.zeros((3, 2, 2), dtype=np.float32))
    assert core.truncated.all()
    with pytest.raises(ValueError, match="does not take the options colour"):
        spec.config(colour="red")
    with pytest.raises(ValueError, match="max_cycles"):
        spec.config(max_cycles=0)


class _Tupled(_Simple):
    """_Simple seeing a Tuple of its step (Discrete(5)) and a Box: what the adapter reads as one-hot then the Box."""

    def _obs(self):
        return {a: (self.t, np.full(2, self.t / 10, dtype=np.float32)) for a in self.agents}


def test_a_tuple_observation_is_read_one_hot_then_box_by_the_core():
    space = spaces.Tuple([spaces.Discrete(5), spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)])
    spec = adapt("tupled", lambda **o: _Tupled(obs=space, **o))
    (seat, _) = spec.seat_spaces(spec.config())
    assert seat.observation.shape == (7,)
    core = spec.core(2)
    assert core.observe()[0, 0].tolist() == [1, 0, 0, 0, 0, 0, 0]  # step 0: one-hot at 0, then (0, 0)
    core.step([np.zeros(2, np.int64), np.zeros(2, np.int64)])
    np.testing.assert_allclose(core.observe()[1, 1], [0, 1, 0, 0, 0, 0.1, 0.1])


def test_options_that_change_the_seats_make_the_game_at_that_size():
    spec = adapt("sized", lambda n=2, **o: _Simple(n=n, **o))
    assert spec.config(n=2).layout.agents == ("p0", "p1") and spec.for_options(n=2) is spec
    three = spec.for_options(n=3)
    assert three.agents == ("p0", "p1", "p2") and three.n_seats == 3
    assert three.kind == "free-for-all" and three.kind_from == "agents"  # undeclared: by the number of agents
    assert len(three.seat_spaces()) == 3 and len(set(three.seat_roles())) == 1  # its own config's seats, one role
    assert len(spec.seat_spaces(spec.config(n=3))) == 3  # the base declaration asked of a config of 3
    core = three.core(2, n=3)
    assert core.n_seats == 3 and core.observe().shape[:2] == (3, 2)
    team = spec.for_options(n=3, kind="cooperative")
    assert team.kind == "cooperative" and team.kind_from == "option" and team.side_seats() == ((0, 1, 2),)
    assert spec.variant_options({"n": 3, "kind": "cooperative"}) == {"kind": "cooperative", "n": 3}
    assert spec.variant_options({"kind": "two-sides"}) == {}  # the kind it has without the option
    with pytest.raises(ValueError, match="two-sides game of other than 2 agents needs its sides"):
        spec.for_options(n=3, kind="two-sides")
    with pytest.raises(ValueError, match="kind must be one of"):
        spec.config(kind="teams")


class _Declared(_Simple):
    metadata = {"name": "declared", "marl_kind": "free-for-all"}


def test_a_game_that_declares_its_kind_keeps_it():
    spec = adapt("declared", lambda **o: _Declared(n=3, **o))
    assert spec.kind == "free-for-all" and spec.kind_from == "metadata"
    assert spec.for_options(kind="free-for-all").kind == "free-for-all"  # said again: nothing to choose
    with pytest.raises(ValueError, match=r"declares its kind in its metadata \(free-for-all\)"):
        spec.config(kind="cooperative")


# ---------------------------------------------------------------------------------------------------------------
# Clear errors
def _seat_error(obs=None, act=None):
    with pytest.raises(EnvError) as e:
        adapt("bad", lambda **o: _Simple(obs=obs, act=act, **o))
    return str(e.value)


def test_unsupported_spaces_are_refused_naming_the_seat_and_why():
    msg = _seat_error(obs=spaces.Tuple([spaces.Discrete(2), spaces.Text(3)]))
    assert "seat 'p0'" in msg and "Text" in msg and "no fixed size" in msg
    msg = _seat_error(act=spaces.Box(-np.inf, np.inf, (2,)))
    assert "seat 'p0'" in msg and "finite bounds" in msg
    msg = _seat_error(obs=spaces.Dict({"observation": spaces.Box(0, 1, (2,)), "action_mask": spaces.MultiBinary(3)}),
                      act=spaces.Box(-1, 1, (2,)))
    assert "action_mask needs a Discrete action space" in msg
    msg = _seat_error(obs=spaces.Dict({"observation": spaces.Box(0, 1, (2,)), "action_mask": spaces.MultiBinary(4)}))
    assert "one entry per action of Discrete(3)" in msg
    assert "MultiBinary" in _seat_error(act=spaces.MultiBinary(2))


def test_a_game_whose_spaces_change_between_copies_is_refused():
    made = []

    def factory(**o):
        made.append(1)
        return _Simple(obs=spaces.Box(-1.0, 1.0, (2 if len(made) < 3 else 3,), dtype=np.float32), **o)

    spec = adapt("shifty", factory)
    with pytest.raises(EnvError, match="copy 1 has observation space .* for seat 'p0'.* same spaces"):
        spec.core(3)


def test_a_factory_that_does_not_make_a_pettingzoo_env_is_refused():
    with pytest.raises(EnvError, match="returned a builtins.dict, not a PettingZoo env"):
        adapt("d", lambda **o: {})
    with pytest.raises(EnvError, match="is not callable"):
        adapt("c", 42)
    with pytest.raises(EnvError, match="calling its factory failed: RuntimeError: no display"):
        adapt("r", lambda **o: (_ for _ in ()).throw(RuntimeError("no display")))


def test_names_that_are_not_games_each_get_one_clear_error():
    assert isinstance(EnvError("x", "y"), UnknownEnvError)
    cases = {
        "no_such_module_xyz:env": "there is no module named 'no_such_module_xyz'",
        "tests.games.tictactoe:nope": "module tests.games.tictactoe has no 'nope'",
        "tests.games.tictactoe:CELL": "is a int, not a function that returns a PettingZoo env",
        "tests.games:env": "has no 'env'",
        "tests.games": "has neither parallel_env() nor env()",
        "json:dumps": "calling its factory failed: TypeError",
        "bad name!:x": "a game of your own is named module:factory",
    }
    for name, why in cases.items():
        admit(name)  # each named by the user, as the CLI's game argument and --env are
        with pytest.raises(EnvError) as e:
            get_env(name)
        assert why in str(e.value), (name, str(e.value))
        assert "\n" not in str(e.value)
    with pytest.raises(EnvError, match="game 'not_named_xyz:env' is not imported: .*MARL_GAMES=not_named_xyz:env"):
        get_env("not_named_xyz:env")  # named by no one here (a league's row): refused, nothing imported
    with pytest.raises(UnknownEnvError, match="unknown env 'pongg'; registered: lander, pong"):
        get_env("pongg")


def test_an_import_error_inside_the_users_module_is_named(tmp_path, monkeypatch):
    (tmp_path / "broken_game_mod.py").write_text("import not_installed_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    admit("broken_game_mod:env")
    with pytest.raises(EnvError, match="importing broken_game_mod failed: No module named "
                                       "'not_installed_dependency_xyz'"):
        get_env("broken_game_mod:env")


# ---------------------------------------------------------------------------------------------------------------
# Entry points
@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """An installed package (a dist-info on sys.path) registering games under selfplay_cli.envs."""
    (tmp_path / "ttt_plugin_pkg.py").write_text(
        "from tests.games.tictactoe import env\n"
        "from selfplay_cli.envs.adapters.pettingzoo import adapt\n"
        "SPEC = adapt('whatever', env)\n"
        "NOT_A_GAME = 3\n")
    info = tmp_path / "ttt_plugin_pkg-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: ttt-plugin-pkg\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[selfplay_cli.envs]\n"
        "plugged-ttt = ttt_plugin_pkg:env\n"
        "plugged-spec = ttt_plugin_pkg:SPEC\n"
        "plugged-bad = ttt_plugin_pkg:NOT_A_GAME\n"
        "plugged-missing = no_such_plugin_module_xyz:env\n"
        "pong = ttt_plugin_pkg:env\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    loading.load_plugins(reload=True)
    yield tmp_path
    monkeypatch.undo()
    loading.load_plugins(reload=True)


def test_installed_packages_register_games_by_entry_point(plugin):
    names = env_names()
    assert {"plugged-ttt", "plugged-spec", "pong"} <= set(names)
    assert "plugged-bad" not in names and "plugged-missing" not in names
    assert get_env("plugged-ttt").turns == "sequential"
    spec = get_env("plugged-spec")
    assert spec.name == "plugged-spec", "an EnvSpec takes the entry point's name"
    assert get_env("pong").agents == ("left", "right"), "a plugin cannot take a built-in game's name"
    errors = loading.plugin_errors()
    assert "not a function that returns a PettingZoo env" in str(errors["plugged-bad"])
    assert "no_such_plugin_module_xyz" in str(errors["plugged-missing"])
    assert "taken by another game" in str(errors["pong"])
    with pytest.raises(EnvError, match="loading entry point"):
        get_env("plugged-missing")
    from selfplay_cli.commands.envs import env_rows

    rows = {r["name"]: r for r in env_rows()}
    assert rows["plugged-ttt"]["kind"] == "two-sides" and "error" in rows["plugged-bad"]


# ---------------------------------------------------------------------------------------------------------------
# marl envs
def _marl(*args):
    return subprocess.run([sys.executable, "-m", "selfplay_cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)


@pytest.mark.slow
def test_marl_envs_shows_kind_turns_and_per_seat_spaces_of_named_games():
    out = _marl("envs", "--json", "pong", TTT, RDV)
    assert out.returncode == 0, out.stderr
    rows = {r["name"]: r for r in json.loads(out.stdout)}
    assert rows["pong"]["kind"] == "two-sides" and rows["pong"]["turns"] == "simultaneous"
    ttt = rows[TTT]
    assert ttt["turns"] == "sequential" and ttt["max_steps"] == 9
    given = "Dict(action_mask: Box(0, 1, (9,), int8), observation: Box(0, 1, (27,), float32))"  # as the game gives it
    assert ttt["seats"] == [{"agent": a, "role": "x/o", "observation": "Box(0, 1, (27,), float32)",
                             "action": "Discrete(9)", "mask": True, "given": given}
                            for a in ("x", "o")]  # one role: x or o
    assert rows[RDV]["kind"] == "cooperative" and len(rows[RDV]["seats"]) == 3
    table = _marl("envs", TTT)
    assert table.returncode == 0 and "sequential" in table.stdout and "Discrete(9) masked" in table.stdout


@pytest.mark.slow
def test_marl_envs_refuses_a_bad_game_in_one_line_with_exit_2():
    out = _marl("envs", "no_such_module_xyz:env")
    assert out.returncode == 2
    assert out.stderr.strip().startswith("marl: error: unknown env 'no_such_module_xyz:env'")
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


def test_aec_and_parallel_classes_are_what_the_factories_make():
    assert isinstance(tictactoe.env(), AECEnv) and isinstance(rendezvous.parallel_env(), ParallelEnv)
    assert isinstance(get_env(TTT).core(1), PettingZooCore)
