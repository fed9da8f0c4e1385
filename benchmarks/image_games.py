"""A PettingZoo butterfly game with image observations, trained for a set number of minutes and rated.

The game is PettingZoo's ``cooperative_pong_v6`` (two paddles keep one ball in play together; each sees the whole
court as a 280x480x3 uint8 frame; Discrete(3) actions; cooperative). Its frames are taken every ``--stride``-th pixel
(default 4: 70x120x3, a sixteenth of the pixels), because the default Nature-CNN on the full frame has ~111,000
features after its convolutions (a 7 M-parameter first linear layer) and trains at a few steps a second on 2 CPU
cores; at stride 4 the ball (8 px) and the paddles stay 2 px or more wide. The stride is this module's game option
(``benchmarks.image_games:cooperative_pong``, ``stride=1`` for the full frame).

It prints: the game's own speed through marl's adapter with random actions (env steps/s: one step of one game, both
paddles acting), the run's training speed (game steps/s, as ``marl train`` reports it, network and learning
included), and the final snapshot team's return against ``random``'s on the same seeds (``marl match``: the mean
team return of each with its 95% interval). The run: ``marl train --agents 2`` (one network per paddle), PPO with
its defaults, ``--eval-games 0`` (rated at the end here instead).

Run from the repository's root: python benchmarks/image_games.py [--minutes 3] [--stride 4] [--games 8]
[--sharing nops|fups] [--lr X]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

ROOT = Path(__file__).resolve().parents[1]
GAME = "benchmarks.image_games:cooperative_pong"


class Strided(ParallelEnv):
    """A PettingZoo parallel game whose image observations are taken every ``stride``-th pixel on both sides."""

    def __init__(self, env: Any, stride: int) -> None:
        if int(stride) != stride or not 1 <= stride <= 16:
            raise ValueError(f"stride must be a whole number from 1 to 16, not {stride!r}")
        self.env, self.stride = env, int(stride)
        self.metadata = {**env.metadata, "marl_kind": "cooperative",
                         "marl_description": f"PettingZoo's cooperative_pong_v6, frames every {stride}th pixel"}
        self.possible_agents = list(env.possible_agents)
        self.render_mode = getattr(env, "render_mode", None)
        self._spaces = {}
        for agent in self.possible_agents:
            box = env.observation_space(agent)
            h, w, c = box.shape
            self._spaces[agent] = spaces.Box(0, 255, (-(-h // self.stride), -(-w // self.stride), c), np.uint8)

    @property
    def agents(self) -> list[str]:
        return self.env.agents

    def observation_space(self, agent: str) -> spaces.Space:
        return self._spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self.env.action_space(agent)

    def _shrink(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        k = self.stride
        return {a: np.ascontiguousarray(o[::k, ::k]) for a, o in obs.items()}

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        return self._shrink(obs), infos

    def step(self, actions: dict):
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        return self._shrink(obs), rewards, terms, truncs, infos

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()


def cooperative_pong(stride: int = 4, max_cycles: int = 900, render_mode: str | None = None) -> Strided:
    """``cooperative_pong_v6`` with frames every ``stride``-th pixel (its own ``max_cycles``, ``render_mode``)."""
    from pettingzoo.butterfly import cooperative_pong_v6

    return Strided(cooperative_pong_v6.parallel_env(max_cycles=max_cycles, render_mode=render_mode), stride)


def marl(home: Path, *args: str) -> str:
    env = dict(os.environ, MARL_HOME=str(home), COLUMNS="140", SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy",
               MARL_GAMES=GAME)  # the game named, for the commands after marl train
    out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env=env, capture_output=True, text=True,
                         cwd=ROOT)  # this module is benchmarks.image_games, importable from the repository's root
    if out.returncode != 0:
        raise SystemExit(f"marl {' '.join(args)} failed ({out.returncode}): {out.stderr.strip()}")
    return out.stdout


def env_speed(stride: int, games: int, seconds: float = 10.0) -> float:
    """Game steps a second through marl's adapter (its batched core), both paddles acting at random."""
    sys.path.insert(0, str(ROOT))
    from selfplay_cli.envs import admit, get_env

    admit(GAME)
    spec = get_env(f"{GAME}")
    core = spec.core(games, stride=stride)
    rng = np.random.default_rng(0)
    steps, t0 = 0, time.perf_counter()
    seed = games
    while time.perf_counter() - t0 < seconds:
        core.observe()
        core.step([rng.integers(0, 3, games) for _ in range(spec.n_seats)])
        steps += games
        done = np.flatnonzero(core.terminated | core.truncated)
        if done.size:
            core.reset(done, np.arange(seed, seed + done.size))
            seed += done.size
    return steps / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=3.0)
    p.add_argument("--stride", type=int, default=4)
    p.add_argument("--games", type=int, default=8, help="games played at once while training")
    p.add_argument("--match-games", type=int, default=20, help="games of the final match (seed pairs x 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sharing", default="nops", help="nops (a network a paddle) or fups (one for both)")
    p.add_argument("--lr", type=float, help="PPO's learning rate (default: marl's)")
    p.add_argument("--keep", type=Path, help="folder to keep the league in (default: a temporary one)")
    args = p.parse_args()
    speed = env_speed(args.stride, args.games)
    print(f"{GAME} stride={args.stride}: env {speed:,.0f} steps/s through the adapter ({args.games} games, random "
          "actions)")
    with tempfile.TemporaryDirectory() as tmp:
        home = args.keep or Path(tmp)
        report = json.loads(marl(home, "train", GAME, "--env-option", f"stride={args.stride}", "--agents", "2",
                                 "--minutes", str(args.minutes), "--games", str(args.games), "--seed", str(args.seed),
                                 "--eval-games", "0", "--run", "pong-images", "--sharing", args.sharing,
                                 *(("--lr", str(args.lr)) if args.lr else ()), "--quiet", "--json"))
        print(f"training: {report['steps']:,} game steps in {args.minutes:g} min, {report['steps_per_second']:,} "
              f"steps/s, {report['episodes']:,} games")
        final = report["final"][0]["snapshot"]  # fups: one snapshot for both paddles; nops: the moment's team
        team = final if len(report["final"]) == 1 else final.rsplit("-", 1)[0]
        m = json.loads(marl(home, "match", team, "random", "--games", str(args.match_games), "--seed", "1000000",
                            "--json"))
        for who, (mean, half, n) in team_returns(home, m["game_ids"]).items():
            print(f"  {who}: mean team return {mean:+.2f} +- {half:.2f} (95%, {n} games)")
        print(f"  {team} vs random: {m['wins']} W {m['draws']} D {m['losses']} L of {m['results']} comparisons on "
              f"shared seeds, Elo {m['elo']:+.0f} [{m['elo_low']:+.0f}, {m['elo_high']:+.0f}]")


def team_returns(home: Path, game_ids: list[int]) -> dict[str, tuple[float, float, int]]:
    """Per team (the random players, or the run's snapshots) the mean return of its games with a 95% normal
    interval's half-width, from the ledger's scores (a team's return: its seats' scores summed)."""
    import sqlite3

    with sqlite3.connect(home / "league.db") as db:
        rows = db.execute(f"SELECT s.game_id, p.kind, s.score FROM game_seats s JOIN players p ON p.id = s.player_id "
                          f"WHERE s.game_id IN ({','.join('?' * len(game_ids))})", game_ids).fetchall()
    by_game: dict[int, list[Any]] = {}
    for game, kind, score in rows:
        by_game.setdefault(game, [kind, 0.0])[1] += score
    out = {}
    for kind, who in (("snapshot", "final team"), ("bot", "random")):
        x = np.array([r for k, r in by_game.values() if k == kind])
        out[who] = (float(x.mean()), float(1.96 * x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else float("nan"),
                    int(x.size))
    return out


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
