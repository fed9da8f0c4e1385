"""What a team critic reads of a game (MAPPO, MA-POCA): the team's view, its step, and how actions are encoded.

A learner with a centralised critic (``centralised = True``, :mod:`selfplay_cli.algos.mappo`,
:mod:`selfplay_cli.algos.poca`) acts on its own seat's observation like any other; its critic, used only while it
trains, also reads what the whole team saw and did. The trainer hands it that, one row per slot of the learner in its
slot order, as a :class:`TeamStep` right before each ``record`` (``learner.see_team(step)``):

* ``before``: the :class:`TeamView` the step's actions were chosen in: every seat's observation of the slot's game
  (flat, zero-padded to the widest seat's, in seat order), which seats were in the game (``present``: in a game
  whose agents come and go, a seat that left or has not joined is absent), and the game's global state where it has
  one (:meth:`~selfplay_cli.envs.EnvSpec.state_space`; None otherwise);
* ``actions``: every seat's action on the step, encoded (Discrete: one-hot; MultiDiscrete: one-hots side by side;
  Box: its numbers), zero-padded to the widest seat's; an absent seat's are zeros;
* ``reward``: the team's reward on the step, the sum over the game's seats (as ``--sharing sa`` counts it);
  ``done``: the game ended on the step (the team's end, not a seat's); ``cut``: of those, the games cut short;
* ``after``: the view after the step (a game that ended: the next game's first), what the rollout's last step
  bootstraps from; ``final``: where any seat was cut short on the step, the view of its game before it restarted
  (rows elsewhere are not meaningful), what a cut step bootstraps from.

With one network for every seat (``--sharing fups``) the learner's slots are every seat of every game; with one
network per seat (``nops``) each learner's are its seat's, and every learner gets the same team rows for a game.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from ..errors import MarlError
from .contract import EnvSpec
from .seat_spaces import SeatSpace


def action_width(space: spaces.Space) -> int:
    """The width of a seat's encoded action (see the module docstring); a :class:`MarlError` for a space the team
    view cannot encode."""
    if isinstance(space, spaces.Discrete):
        return int(space.n)
    if isinstance(space, spaces.MultiDiscrete):
        return int(np.asarray(space.nvec).sum())
    if isinstance(space, spaces.Box):
        return int(np.prod(space.shape))
    raise MarlError(f"a centralised critic cannot read actions of {type(space).__name__}")


def encode_actions(space: spaces.Space, actions: np.ndarray, width: int) -> np.ndarray:
    """``(n, width)`` float32: the actions of one seat in ``n`` games, encoded and zero-padded."""
    a = np.asarray(actions)
    n = a.shape[0]
    out = np.zeros((n, width), dtype=np.float32)
    if isinstance(space, spaces.Discrete):
        out[np.arange(n), a.reshape(n).astype(np.int64) - int(space.start)] = 1.0
    elif isinstance(space, spaces.MultiDiscrete):
        offset = 0
        for d, size in enumerate(np.asarray(space.nvec).reshape(-1).tolist()):
            out[np.arange(n), offset + a.reshape(n, -1)[:, d].astype(np.int64)] = 1.0
            offset += int(size)
    else:
        flat = a.reshape(n, -1).astype(np.float32)
        out[:, :flat.shape[1]] = np.nan_to_num(flat)
    return out


@dataclass(frozen=True)
class TeamSpec:
    """What a learner's critic reads, known before the games exist: the seats, the widest seat's flat observation
    and encoded action, the global state's width (None: the game has none) and the seat of each of its slots."""

    n_seats: int
    obs_width: int
    act_width: int
    state_width: int | None
    seats: np.ndarray  # (slots,) int: the seat of each slot of the learner

    @property
    def team_obs_width(self) -> int:
        """The width of every seat's observation side by side."""
        return self.n_seats * self.obs_width


def team_spec(spec: EnvSpec, game_cfg: Any, seat_spaces: Sequence[SeatSpace], layout: np.ndarray,
              learner: int) -> TeamSpec:
    """The team a learner's critic reads (``layout``: the learner of every (seat, game) slot; ``seat_spaces`` as
    the learners read them, frame stacks included)."""
    state = spec.state_space(game_cfg)
    slots = np.flatnonzero(np.asarray(layout).ravel() == learner)
    return TeamSpec(n_seats=len(seat_spaces),
                    obs_width=max(int(np.prod(s.observation.shape)) for s in seat_spaces),
                    act_width=max(action_width(s.action) for s in seat_spaces),
                    state_width=None if state is None else int(np.prod(state.shape)),
                    seats=slots // np.asarray(layout).shape[1])


@dataclass
class TeamView:
    """The team's view of the games, one row a slot (see the module docstring)."""

    obs: np.ndarray  # (rows, n_seats, obs_width) float32
    present: np.ndarray  # (rows, n_seats) bool
    state: np.ndarray | None  # (rows, state_width) float32, or None

    def rows(self, index: Any) -> TeamView:
        return TeamView(self.obs[index], self.present[index], None if self.state is None else self.state[index])


@dataclass
class TeamStep:
    """One step of the team, one row a slot of a learner (see the module docstring)."""

    before: TeamView
    actions: np.ndarray  # (rows, n_seats, act_width) float32
    reward: np.ndarray  # (rows,) float32
    done: np.ndarray  # (rows,) bool
    cut: np.ndarray  # (rows,) bool
    after: TeamView
    final: TeamView | None
