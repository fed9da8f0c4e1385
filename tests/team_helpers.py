"""Training a cooperative team through `marl train` and reading what its snapshots learned (tests/test_mappo.py,
tests/test_poca.py): the suite's duet and relay (tests/games), short rollouts so a test's budget holds many updates."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from cli_helpers import run_json

from selfplay_cli.policies.snapshot_policy import load_policy

DUET, RELAY = "tests.games.duet:parallel_env", "tests.games.relay:parallel_env"
ROLLOUT = "[ppo]\nrollout_steps = 16\n[mappo]\nrollout_steps = 16\n[poca]\nrollout_steps = 16\n"


def train_team(capsys: Any, home: Path, game: str, algo: str, sharing: str, seed: int, run: str,
               steps: int = 10_000) -> list[Path]:
    """``marl train GAME --algo ALGO --agents 2 --sharing SHARING`` (32 games, 16-step rollouts, no rating games);
    the final snapshots' files, one per learner in seat order."""
    config = home.parent / "rollout.toml"
    config.write_text(ROLLOUT)
    report = run_json(capsys, "train", game, "--algo", algo, "--agents", "2", "--sharing", sharing, "--steps",
                      str(steps), "--games", "32", "--eval-games", "0", "--seed", str(seed), "--run", run,
                      "--config", str(config))
    return [next((home / "snapshots" / run).glob(f"{f['snapshot'].split('/')[-1]}.*")) for f in report["final"]]


def right_answers(path: Path, obs: np.ndarray, answers: np.ndarray) -> np.ndarray:
    """The probability the snapshot's policy (sampling, as it trained) gives each of ``answers`` to ``obs``."""
    policy = load_policy(path, greedy=False)
    with torch.no_grad():
        logits, _ = policy.net(torch.as_tensor(obs))
    return torch.softmax(logits, -1).numpy()[np.arange(len(obs)), answers]


def duet_together(paths: list[Path], choices: int = 3) -> float:
    """The chance the duet's two singers both name their targets (averaged over targets and lucks; one network for
    both seats with FuPS)."""
    paths = paths * 2 if len(paths) == 1 else paths
    obs = np.zeros((2 * choices, choices + 1), dtype=np.float32)
    targets = np.repeat(np.arange(choices), 2)
    obs[np.arange(2 * choices), targets] = 1.0
    obs[:, -1] = np.tile([-1.0, 1.0], choices)
    return float(np.prod([right_answers(p, obs, targets).mean() for p in paths]))


def relay_scout_right(paths: list[Path], choices: int = 2) -> float:
    """The chance the relay's scout (seat 0) answers its signal."""
    obs = np.zeros((choices, choices + 2), dtype=np.float32)
    obs[np.arange(choices), np.arange(choices)] = 1.0
    obs[:, -2] = 1.0
    return float(right_answers(paths[0], obs, np.arange(choices)).mean())
