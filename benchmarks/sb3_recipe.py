"""marl against the PettingZoo standard recipe on the lander: Stable-Baselines3 PPO through SuperSuit, each library
with its own defaults, the same wall time, one core each.

Each round trains both at once, each pinned to a core of its own (``taskset``, torch at one thread), the cores
swapped from round to round, for ``--minutes``:

- marl: ``marl train lander --agents 2 --sharing fups --minutes M --eval-games 0 --seed R`` (its defaults: PPO, one
  network for both landers, 256 games at once);
- the recipe (PettingZoo's SB3 tutorial): ``black_death_v3`` (a lander that has landed or crashed stays in the
  vector as a zero observation; mended: SuperSuit 3.11 never ends a game whose agents terminate, below),
  ``pettingzoo_env_to_vec_env_v1``, ``concat_vec_envs_v1(..., 8, num_cpus=0,
  base_class="stable_baselines3")`` (8 games in this process: one core), ``PPO("MlpPolicy", env)`` with SB3's
  defaults (seeded by ``set_random_seed(R)``), stopped by a callback when the time is up.

Then each final policy flies the same ``--games`` fresh games (seeds 10,000 on, the PettingZoo view, both landers
by the policy, its most likely action) and the heuristic the same games as an anchor: mean return per lander with
its 95% interval. Prints each round's game steps/s (a game step: one step of one game, both landers) and the speed
ratio, then the returns. Needs the optional extra: ``pip install -e ".[compare]"``.

Run: python benchmarks/sb3_recipe.py [--minutes 5] [--rounds 2] [--games 50]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "SDL_VIDEODRIVER": "dummy"}
FIRST_SEED = 10_000
LANDERS = 2


def _env():
    from selfplay_cli.envs.lander.view import LanderParallelEnv

    return LanderParallelEnv(landers=LANDERS)


def train_sb3(out: Path, minutes: float, seed: int) -> None:
    """The recipe, in this process (run pinned to one core): writes the model to ``out`` and prints its figures."""
    import supersuit as ss
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.utils import set_random_seed

    torch.set_num_threads(1)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(_black_death(_env())), 8, num_cpus=0,
                                 base_class="stable_baselines3")

    class Until(BaseCallback):
        def __init__(self, at: float) -> None:
            super().__init__()
            self.at = at

        def _on_step(self) -> bool:
            return time.monotonic() < self.at

    set_random_seed(seed)  # (PPO(seed=...) would seed the vector env, which SuperSuit's ConcatVecEnv refuses)
    venv.venv.reset(seed=seed)  # the games' seeds (SuperSuit's SB3 wrapper's own reset(seed) calls the same seed())
    model = PPO("MlpPolicy", venv, device="cpu", verbose=0)
    model.set_logger(configure(str(out.with_suffix(".log")), []))  # (its default folder is left in the temp folder)
    began = time.monotonic()
    model.learn(total_timesteps=10**12, callback=Until(began + 60 * minutes))
    took = time.monotonic() - began
    model.save(out)
    steps = model.num_timesteps // LANDERS  # (each vector entry is one lander of one game)
    print(json.dumps({"steps": steps, "seconds": took, "steps_per_second": steps / took}))


def _black_death(env):
    """SuperSuit's ``black_death_v3`` with its end of game mended: it ends a game only when every agent is both
    terminated and truncated (``terminations & truncations``), so a game whose landers all landed or crashed (each
    terminated, none truncated) was stepped on past its end (SuperSuit 3.11)."""
    from supersuit.multiagent_wrappers.black_death import black_death_par

    class Mended(black_death_par):
        def step(self, actions):
            obs, rewards, dones, _, infos = super().step(actions)
            if not self.env.agents:  # the game is over: every lander done
                dones = dict.fromkeys(dones, True)
                self.agents.clear()
            return obs, rewards, dones, dones, infos

    return Mended(env)


def _returns(act, games: int) -> list[float]:
    """Mean return per lander of each of ``games`` fresh games, every lander played by ``act`` (obs batch ->
    actions)."""
    import numpy as np

    env, out = _env(), []
    for g in range(games):
        obs, _ = env.reset(seed=FIRST_SEED + g)
        total = 0.0
        while env.agents:
            agents = list(env.agents)
            actions = act(np.stack([obs[a] for a in agents]))
            obs, rewards, _, _, _ = env.step({a: int(x) for a, x in zip(agents, actions, strict=True)})
            total += sum(rewards.values())
        out.append(total / LANDERS)
    return out


def _interval(xs: list[float]) -> str:
    n = len(xs)
    mean = sum(xs) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in xs) / (n - 1)) if n > 1 else 0.0
    half = 1.96 * sd / math.sqrt(n)
    return f"{mean:.1f} [{mean - half:.1f}, {mean + half:.1f}]"


def fly_marl(path: Path, games: int) -> list[float]:
    from selfplay_cli.policies.snapshot_policy import policy_of
    from selfplay_cli.policies.snapshot_reader import read_snapshot

    policy = policy_of(read_snapshot(path, expect_env="lander"), path, greedy=True)
    return _returns(policy.act, games)


def fly_sb3(path: Path, games: int) -> list[float]:
    from stable_baselines3 import PPO

    model = PPO.load(path, device="cpu")
    return _returns(lambda obs: model.predict(obs, deterministic=True)[0], games)


def fly_heuristic(games: int) -> list[float]:
    from selfplay_cli.envs.lander.bots import heuristic_rule

    return _returns(heuristic_rule, games)


def _load() -> str:
    return f"load {os.getloadavg()[0]:.2f}"


def round_of(r: int, minutes: float, work: Path) -> dict:
    """One round: both trained at once, each on its core; returns their figures and where their policies are."""
    marl_core, sb3_core = (0, 1) if r % 2 == 0 else (1, 0)
    home, model = work / "league", work / f"sb3-{r}.zip"
    env = {**os.environ, **ONE_THREAD}
    marl = subprocess.Popen(
        ["taskset", "-c", str(marl_core), sys.executable, "-m", "selfplay_cli", "train", "lander", "--agents", "2",
         "--sharing", "fups", "--minutes", f"{minutes:g}", "--eval-games", "0", "--seed", str(r), "--run",
         f"marl-{r}", "--home", str(home), "--quiet", "--json"], env=env, stdout=subprocess.PIPE, text=True)
    sb3 = subprocess.Popen(["taskset", "-c", str(sb3_core), sys.executable, __file__, "--child-sb3", str(model),
                            "--minutes", f"{minutes:g}", "--seed", str(r)], env=env, stdout=subprocess.PIPE,
                           text=True)
    load_before = _load()
    outs = [p.communicate()[0] for p in (marl, sb3)]
    if marl.returncode or sb3.returncode:
        raise SystemExit(f"round {r + 1}: marl exited {marl.returncode}, the recipe {sb3.returncode}")
    m, s = json.loads(outs[0]), json.loads(outs[1].strip().splitlines()[-1])
    final = work / f"marl-{r}.safetensors"
    subprocess.run([sys.executable, "-m", "selfplay_cli", "checkpoint", "export", m["final"][0]["snapshot"], str(final),
                    "--home", str(home)], env=env, check=True, capture_output=True)
    print(f"round {r + 1} (marl on core {marl_core}, the recipe on core {sb3_core}; {load_before}, {_load()} at its "
          f"end): marl {m['steps_per_second']:,.0f} game steps/s ({m['steps']:,} steps), SB3 + SuperSuit "
          f"{s['steps_per_second']:,.0f} ({s['steps']:,}): marl {m['steps_per_second'] / s['steps_per_second']:.1f}x",
          flush=True)
    return {"marl": final, "sb3": model,
            "ratio": m["steps_per_second"] / s["steps_per_second"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=5.0, help="training time of each, per round")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--games", type=int, default=50, help="fresh games each final policy flies")
    ap.add_argument("--child-sb3", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child_sb3:
        train_sb3(args.child_sb3, args.minutes, args.seed)
        return
    try:
        import stable_baselines3  # noqa: F401
        import supersuit  # noqa: F401
    except ImportError as e:
        raise SystemExit(f"needs the optional extra: pip install -e \".[compare]\" ({e})") from None
    print(f"the lander, 2 landers, {args.minutes:g} minutes each a round, one core each; {os.cpu_count()} cores",
          flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        rounds = [round_of(r, args.minutes, Path(tmp)) for r in range(args.rounds)]
        ratios = [x["ratio"] for x in rounds]
        print(f"speed: marl / SB3 + SuperSuit game steps/s, median of {len(ratios)} rounds: "
              f"{statistics.median(ratios):.1f}x (rounds {', '.join(f'{x:.1f}' for x in ratios)})")
        print(f"final policies, mean return per lander over the same {args.games} fresh games (seeds "
              f"{FIRST_SEED:,}-{FIRST_SEED + args.games - 1:,}), 95% intervals:")
        for r, x in enumerate(rounds):
            print(f"  round {r + 1}: marl {_interval(fly_marl(x['marl'], args.games))}; SB3 + SuperSuit "
                  f"{_interval(fly_sb3(x['sb3'], args.games))}", flush=True)
        print(f"  anchor: the heuristic {_interval(fly_heuristic(args.games))}")


if __name__ == "__main__":
    if "--child-sb3" in sys.argv:
        main()
    else:
        from results_file import recorded

        with recorded():
            main()
