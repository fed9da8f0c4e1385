"""The one interface every player implements: scripted bots, network snapshots, learners."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class Policy(ABC):
    """Maps a batch of one seat's observations to a batch of actions.

    ``id`` names the player in results and the league (``cpu``, ``run1/ep90``); ``env`` is the game it plays;
    ``kind`` is ``bot`` or ``snapshot``. A policy sees only observations (never the game's internal state), so
    anything that can play can be matched, rated and recorded like anything else.
    """

    kind: str = "policy"

    def __init__(self, id: str, env: str) -> None:
        self.id = id
        self.env = env

    @abstractmethod
    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """``obs`` is ``(batch, *observation_shape)``; ``mask``, if given, ``(batch, n_actions)`` of allowed
        actions. Returns ``(batch,)`` integer actions."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.id!r}, env={self.env!r})"
