"""marl's games in other libraries' hands (issue 52): the PettingZoo modules (``pong_v0``, ``lander_v0``,
``tennis_v0``), copies of the views (pickle, deepcopy: what SuperSuit's worker processes and RLlib's env runners
make), PettingZoo's standard Stable-Baselines3 recipe through SuperSuit with two worker processes (the games played
in the workers are the same seeded games played here, step for step), and RLlib's two PettingZoo wrappers."""

from __future__ import annotations

import copy
import pickle

import cloudpickle
import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

from selfplay_cli.envs import lander_v0, pong_v0, tennis_v0
from selfplay_cli.envs.zoo import black_death

MODULES = {"pong": pong_v0, "lander": lander_v0, "tennis": tennis_v0}
# Each game with its defaults and with options of its own (a game whose random play ends within a few hundred steps)
CASES = [
    pytest.param("pong", {}, marks=pytest.mark.slow, id="pong"),  # (a random game to 21: ~6,500 steps)
    pytest.param("pong", {"rules": "seed", "points_to_win": 2, "frame_stack": 4, "r_for_hit": 0.1}, id="pong-seed-2"),
    pytest.param("lander", {}, id="lander"),
    pytest.param("lander", {"landers": 3, "continuous": True, "enable_wind": True}, id="lander-3-continuous-wind"),
    pytest.param("tennis", {}, marks=pytest.mark.slow, id="tennis"),  # (a random game: ~1,250 steps)
    pytest.param("tennis", {"discrete": True, "points_to_win": 2, "serve_bounce": True, "hit_reward": 0.1},
                 id="tennis-discrete-2"),
]


def parallel(game: str, options: dict):
    """The game's ParallelEnv as a recipe takes it: the lander's landers end one by one, so it keeps its seats
    until the game ends (black_death), as SuperSuit's vector env of a fixed number of agents needs."""
    env = MODULES[game].parallel_env(**options)
    return black_death(env) if game == "lander" else env


def random_actions(space, steps: int, n: int, seed: int) -> np.ndarray:
    space = copy.deepcopy(space)
    space.seed(seed)
    return np.array([[space.sample() for _ in range(n)] for _ in range(steps)])


# --- the PettingZoo modules -------------------------------------------------------------------------------------


@pytest.mark.parametrize("game", MODULES)
def test_each_game_is_a_pettingzoo_module_with_its_factories_and_metadata(game):
    module = MODULES[game]
    assert module.metadata["name"] == f"marl_{game}_v0" and module.metadata["render_modes"] == ["rgb_array"]
    assert module.metadata["is_parallelizable"] is True and module.metadata["render_fps"] > 0
    options = {"pong": {"points_to_win": 2}, "lander": {"landers": 3}, "tennis": {"discrete": True}}[game]
    par = module.parallel_env(**options)
    assert par.metadata == module.metadata and all(getattr(par.config, k) == v for k, v in options.items())
    parallel_api_test(module.parallel_env(**options), num_cycles=300)
    aec = module.env(**options)
    api_test(aec, num_cycles=300)
    assert aec.unwrapped.possible_agents == par.possible_agents
    raw = module.raw_env(render_mode="rgb_array", **options)
    raw.reset(seed=0)
    assert raw.render().ndim == 3
    for factory in (module.parallel_env, module.raw_env, module.env):  # found by name, as PettingZoo's own are
        assert pickle.loads(pickle.dumps(factory)) is factory


@pytest.mark.parametrize(("game", "option", "value", "says"), [
    ("pong", "points_to_win", 0, "points_to_win must be at least 1"),
    ("lander", "landers", 9, "landers must lie between 1 and 8"),
    ("tennis", "discrete", "yes", "tennis option discrete wants true or false"),
    ("lander", "wings", 2, "unknown lander option"),
])
def test_a_bad_option_is_one_clear_error(game, option, value, says):
    for factory in (MODULES[game].parallel_env, MODULES[game].env, MODULES[game].raw_env):
        with pytest.raises(ValueError, match=says):
            factory(**{option: value})
    with pytest.raises(ValueError, match="renders only 'rgb_array'"):
        MODULES[game].parallel_env(render_mode="human")


# --- copies ---------------------------------------------------------------------------------------------------


def play(env, actions: np.ndarray) -> list:
    """Rewards and observations of the game played on with ``actions[t][seat]`` until it ends."""
    out = []
    for row in actions:
        if not env.agents:
            break
        obs, rewards, _, _, _ = env.step({a: row[i] for i, a in enumerate(env.possible_agents) if a in env.agents})
        out.append(({a: rewards[a] for a in sorted(rewards)}, {a: obs[a].tolist() for a in sorted(obs)}))
    return out


@pytest.mark.parametrize("game", MODULES)
def test_copies_of_a_fresh_view_play_games_of_their_own_and_a_reset_view_copies_with_its_game(game):
    """A view never reset copies as its options (each copy draws games of its own: the copies SuperSuit makes of
    one env do not all play the same game); a reset one copies with its seed generator and its game."""
    env = MODULES[game].parallel_env(render_mode="rgb_array")
    env.render()  # (a renderer made is not copied)
    copies = [copy.deepcopy(env), pickle.loads(pickle.dumps(env)), cloudpickle.loads(cloudpickle.dumps(env))]
    assert all(type(c) is type(env) and c.config == env.config and c.render_mode == "rgb_array" for c in copies)
    for c in copies:
        c.reset()
    assert len({c.game_seed for c in copies}) == 3

    env.reset(seed=11)
    acts = random_actions(env.action_space(env.possible_agents[0]), 400, len(env.possible_agents), seed=1)
    twin = pickle.loads(pickle.dumps(env))  # right after reset: every game, the lander's too
    assert twin.game_seed == 11 and play(twin, acts) == play(env, acts)
    env.reset()  # (a game drawn from the generator seeded by 11: the copy draws the same next)
    twin = copy.deepcopy(env)
    assert play(twin, acts[:50]) == play(env, acts[:50])
    if env.agents and game != "lander":  # a game under way that gives its state copies exactly, where it stands
        twin = cloudpickle.loads(cloudpickle.dumps(env))
        assert twin.agents == env.agents and np.array_equal(twin.state(), env.state())
        assert play(twin, acts[50:]) == play(env, acts[50:])
        twin.reset(), env.reset()
        assert twin.game_seed == env.game_seed


def test_a_lander_under_way_is_not_copied_and_one_over_copies_ready_for_reset():
    env = lander_v0.parallel_env(landers=2)
    env.reset(seed=3)
    env.step({a: 0 for a in env.agents})
    with pytest.raises(TypeError, match=r"a lander view cannot be copied \(pickled\) with a game under way"):
        pickle.dumps(env)
    while env.agents:
        env.step({a: 2 for a in env.agents})
    twin = pickle.loads(pickle.dumps(env))
    assert twin.agents == [] and twin.game_seed == 3
    with pytest.raises(RuntimeError, match="call reset"):
        twin.step({})
    twin.reset(), env.reset()
    assert twin.game_seed == env.game_seed


# --- SuperSuit + Stable-Baselines3 ------------------------------------------------------------------------------

SEED, STEPS = 5, 400


def in_process(game: str, options: dict, seed: int, actions: np.ndarray) -> tuple[list, list, list]:
    """One game of the recipe's vector played here, as MarkovVectorEnv plays it: rewards, dones and observations
    per step, a new game begun (unseeded: drawn from the game's generator) as one ends."""
    env = parallel(game, options)
    obs, _ = env.reset(seed=seed)
    agents = env.possible_agents
    rewards, dones, observations = [], [], []
    for row in actions:
        obs, rew, term, trunc, _ = env.step({a: row[i] for i, a in enumerate(agents)})
        done = [term[a] or trunc[a] for a in agents]
        rewards.append(np.array([rew[a] for a in agents], np.float32))
        dones.append(done)
        if not env.agents:
            obs, _ = env.reset()
        observations.append(np.stack([obs[a] for a in agents]))
    return rewards, dones, observations


@pytest.mark.parametrize(("game", "options"), CASES)
def test_supersuits_recipe_with_worker_processes_plays_the_games_played_here(game, options):
    """``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1(num_cpus=2)``: two worker processes, each with a
    copy of the env (cloudpickle). Reset with seed s, worker i plays game s + i: its rewards, dones and
    observations, step by step, are those of the same seeded game played in this process with the same actions."""
    import supersuit as ss

    env = parallel(game, options)
    n = len(env.possible_agents)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), num_vec_envs=2, num_cpus=2,
                                 base_class="stable_baselines3")
    try:
        assert venv.num_envs == 2 * n and venv.observation_space == env.observation_space(env.possible_agents[0])
        assert len(venv.venv.procs) == 2 and all(p.is_alive() for p in venv.venv.procs)
        first, _ = venv.venv.reset(seed=SEED)  # (SB3's wrapper's reset(seed) calls a seed() SuperSuit lacks)
        assert first.shape == (2 * n, *venv.observation_space.shape)
        steps = {"pong": 8000, "tennis": 3000}.get(game, STEPS) if not options else STEPS
        actions = random_actions(venv.action_space, steps, 2 * n, seed=0)
        got = [venv.step(a) for a in actions]
    finally:
        venv.close()
    assert not any(p.is_alive() for p in venv.venv.procs)
    obs = np.stack([g[0] for g in got])
    rewards = np.stack([g[1] for g in got])
    dones = np.stack([g[2] for g in got])
    assert obs.shape == (len(actions), 2 * n, *venv.observation_space.shape) and np.isfinite(obs).all()
    assert rewards.shape == dones.shape == (len(actions), 2 * n) and np.isfinite(rewards).all()
    assert dones.dtype == bool and (rewards != 0).any()
    for g in range(2):  # each worker's game: it ended (every seat at once) and began anew
        mine = slice(g * n, (g + 1) * n)
        ends = dones[:, mine]
        assert ends.any() and (ends.all(axis=1) == ends.any(axis=1)).all(), (g, ends.sum())
        want_rewards, want_dones, want_obs = in_process(game, options, SEED + g, actions[:, mine])
        assert np.array_equal(rewards[:, mine], np.stack(want_rewards))
        assert np.array_equal(ends, np.array(want_dones))
        assert np.array_equal(obs[:, mine], np.stack(want_obs))
    assert not np.array_equal(rewards[:, :n], rewards[:, n:])  # (two games, not one twice)


@pytest.mark.parametrize("game", MODULES)
def test_stable_baselines3_ppo_learns_through_the_recipe(game, tmp_path, monkeypatch):
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path))  # (SB3's logger makes a folder, by default in the system's /tmp)
    import supersuit as ss
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import set_random_seed

    options = {"pong": {"points_to_win": 1}, "lander": {"landers": 3}, "tennis": {"discrete": True}}[game]
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(parallel(game, options)), num_vec_envs=2,
                                 num_cpus=2, base_class="stable_baselines3")
    try:
        set_random_seed(0)  # (PPO(seed=0) calls the vector env's seed(), which SuperSuit 3.11's lacks)
        model = PPO("MlpPolicy", venv, n_steps=32, batch_size=32, n_epochs=2, device="cpu")
        before = [p.detach().clone() for p in model.policy.parameters()]
        model.learn(64)
        assert model.num_timesteps >= 64
        assert any(not np.array_equal(a.numpy(), b.detach().numpy()) for a, b in zip(before, model.policy.parameters(),
                                                                                      strict=True))
        obs = venv.reset()
        action, _ = model.predict(obs, deterministic=True)
        assert action.shape == (venv.num_envs, *venv.action_space.shape) and venv.action_space.contains(action[0])
    finally:
        venv.close()


# --- RLlib ------------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(("game", "options"), CASES)
def test_rllibs_parallel_wrapper_plays_the_game_played_here(game, options):
    """``ParallelPettingZooEnv(parallel_env(...))``: per-seat Dict spaces, reset/step in RLlib's API, episodes end
    with ``__all__``; its rewards and observations are the bare view's for the same seed and actions."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    view = MODULES[game].parallel_env(**options)
    env = ParallelPettingZooEnv(MODULES[game].parallel_env(**options))
    agents = view.possible_agents
    assert set(env.observation_space.spaces) == set(agents) == set(env.action_space.spaces)
    assert all(env.observation_space[a] == view.observation_space(a) and env.action_space[a] == view.action_space(a)
               for a in agents)
    steps = 30_000 if not options and game == "pong" else 5000
    actions = random_actions(view.action_space(agents[0]), steps, len(agents), seed=2)
    obs, infos = env.reset(seed=SEED)
    want, _ = view.reset(seed=SEED)
    episodes = 0
    for row in actions:
        assert set(obs) == set(want) and all(np.array_equal(obs[a], want[a]) for a in obs)
        assert all(env.observation_space[a].contains(obs[a]) for a in obs)
        act = {a: row[agents.index(a)] for a in obs}
        obs, rew, term, trunc, infos = env.step(act)
        want, want_rew, _, _, _ = view.step(act)
        assert rew == want_rew and all(np.isfinite(r) for r in rew.values())
        if term["__all__"] or trunc["__all__"]:
            assert not view.agents
            episodes += 1
            if episodes == 2:
                break
            obs, _ = env.reset()
            want, _ = view.reset()
    assert episodes == 2


@pytest.mark.parametrize(("game", "options"), CASES)
def test_rllibs_aec_wrapper_plays_every_game_to_its_end(game, options):
    """``PettingZooEnv(env(...))``: one seat's observation at a time, its action stepped, episodes end with
    ``__all__`` once every seat is done (finite rewards all along, some of them not 0)."""
    from ray.rllib.env.wrappers.pettingzoo_env import PettingZooEnv

    view = MODULES[game].parallel_env(**options)
    env = PettingZooEnv(MODULES[game].env(**options))
    agents = view.possible_agents
    assert set(env.observation_space.spaces) == set(agents)
    rng_space = copy.deepcopy(view.action_space(agents[0]))
    rng_space.seed(3)
    obs, _ = env.reset(seed=SEED)
    returns = dict.fromkeys(agents, 0.0)
    for _ in range(60_000):
        agent = env.env.agent_selection  # (obs also holds the last one of a seat that ended and was stepped out)
        assert agent in obs and env.observation_space[agent].contains(obs[agent])
        obs, rew, term, trunc, _ = env.step({agent: rng_space.sample()})
        for a, r in rew.items():
            assert np.isfinite(r)
            returns[a] += r
        if term["__all__"] or trunc["__all__"]:
            break
    else:
        raise AssertionError("no episode ended")
    assert not env.env.agents
    assert all(np.isfinite(r) for r in returns.values())
    assert any(r != 0 for r in returns.values())
