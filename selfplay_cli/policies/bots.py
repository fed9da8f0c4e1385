"""Scripted players as policies: fixed anchors of the league."""

from __future__ import annotations

import numpy as np

from ..envs import get_env
from .base import Policy


class ScriptedPolicy(Policy):
    kind = "bot"

    def __init__(self, env: str, name: str, seed: int = 0) -> None:
        spec = get_env(env)
        if name not in spec.bots:
            known = ", ".join(sorted(spec.bots)) or "none"
            raise KeyError(f"{env} has no scripted player '{name}'; it has: {known}")
        super().__init__(name, env)
        self.bot = spec.bots[name]
        self.rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        return np.asarray(self.bot.rule(obs, self.rng), dtype=np.int64)
