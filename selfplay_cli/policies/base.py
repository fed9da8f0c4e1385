"""The one interface every player implements: scripted bots, network snapshots, learners."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np


class Policy(ABC):
    """Maps a batch of one seat's observations to a batch of actions.

    ``id`` names the player in results and the league (``cpu``, ``run1/ep90``); ``env`` is the game it plays;
    ``kind`` is ``bot`` or ``snapshot``; ``obs_space`` and ``act_space`` are the gymnasium spaces of the seat it
    plays (None when a policy does not know them). A policy sees only observations (never the game's internal
    state), so anything that can play can be matched, rated and recorded like anything else. ``frame_stack`` is
    how many of its seat's last observations it reads at once (1: the current one; the game loop keeps the others, see
    :mod:`selfplay_cli.play.frames`).
    """

    kind: str = "policy"
    frame_stack: int = 1

    def __init__(self, id: str, env: str, obs_space: Any = None, act_space: Any = None) -> None:
        self.id = id
        self.env = env
        self.obs_space = obs_space
        self.act_space = act_space

    @abstractmethod
    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """``obs`` is ``(batch, *observation_shape)`` float32 (an image's uint8); ``mask``, if given, the
        ``(batch, n_actions)`` bool array of allowed actions (MultiDiscrete: each dimension's mask side by side).
        Returns the seat's actions: ``(batch,)`` int64 (Discrete), ``(batch, k)`` int64 (MultiDiscrete) or
        ``(batch, *shape)`` float32 within the bounds (Box). A policy never returns an action its mask forbids."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.id!r}, env={self.env!r})"
