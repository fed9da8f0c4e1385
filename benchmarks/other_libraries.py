"""marl's games through PettingZoo's standard Stable-Baselines3 recipe: the steps a second of SuperSuit's
``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1(..., base_class="stable_baselines3")`` on each game, with 2
worker processes (``num_cpus=2``) and in this process (``num_cpus=0``), beside the bare PettingZoo view (one game,
this process). Random actions drawn beforehand; the lander behind :class:`selfplay_cli.envs.zoo.black_death` (its
landers end one by one). A game step: one step of one game, all its seats. Median of ``--rounds`` rounds of
``--steps`` vector steps each, the settings alternated within a round.

Needs the optional extra: ``pip install -e ".[compare]"``.

Run: python benchmarks/other_libraries.py [--games 8] [--steps 2000] [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

GAMES = [("pong", {}), ("lander", {}), ("lander", {"landers": 4}), ("tennis", {})]


def _parallel(game: str, options: dict):
    from selfplay_cli.envs import lander_v0, pong_v0, tennis_v0
    from selfplay_cli.envs.zoo import black_death

    env = {"pong": pong_v0, "lander": lander_v0, "tennis": tennis_v0}[game].parallel_env(**options)
    return black_death(env) if game == "lander" else env


def recipe_rate(game: str, options: dict, games: int, cpus: int, steps: int) -> float:
    """Game steps a second of the recipe's vector env (``games`` games over ``cpus`` workers)."""
    import supersuit as ss

    env = _parallel(game, options)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), games, num_cpus=cpus,
                                 base_class="stable_baselines3")
    try:
        space = venv.action_space
        space.seed(0)
        actions = [np.array([space.sample() for _ in range(venv.num_envs)]) for _ in range(steps)]
        venv.reset()
        began = time.perf_counter()
        for a in actions:
            venv.step(a)
        took = time.perf_counter() - began
    finally:
        venv.close()
    return games * steps / took


def view_rate(game: str, options: dict, steps: int) -> float:
    """Game steps a second of the bare PettingZoo view, one game, games reset as they end."""
    env = _parallel(game, options)
    agents = env.possible_agents
    space = env.action_space(agents[0])
    space.seed(0)
    actions = [[space.sample() for _ in agents] for _ in range(steps)]
    env.reset(seed=0)
    began = time.perf_counter()
    for row in actions:
        env.step(dict(zip(agents, row, strict=True)))
        if not env.agents:
            env.reset()
    return steps / (time.perf_counter() - began)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--games", type=int, default=8, help="games in the recipe's vector env")
    parser.add_argument("--steps", type=int, default=2000, help="vector steps a round")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    print(f"SuperSuit recipe (pettingzoo_env_to_vec_env_v1 + concat_vec_envs_v1, stable_baselines3), {args.games} "
          f"games, random actions; game steps/s, median of {args.rounds} rounds of {args.steps} vector steps")
    print(f"{'game':<18}{'2 workers':>12}{'in-process':>12}{'bare view':>12}{'2 workers / in-process':>25}")
    for game, options in GAMES:
        label = game + "".join(f" {k}={v}" for k, v in options.items())
        rates: dict[str, list[float]] = {"procs": [], "local": [], "view": []}
        for _ in range(args.rounds):
            rates["procs"].append(recipe_rate(game, options, args.games, 2, args.steps))
            rates["local"].append(recipe_rate(game, options, args.games, 0, args.steps))
            rates["view"].append(view_rate(game, options, args.steps * 4))
        procs, local, view = (statistics.median(rates[k]) for k in ("procs", "local", "view"))
        print(f"{label:<18}{procs:>12,.0f}{local:>12,.0f}{view:>12,.0f}{procs / local:>24.2f}x")
    print(f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
