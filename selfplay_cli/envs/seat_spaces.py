"""What one seat of a game is to a policy, and which gymnasium spaces `marl` plays.

:class:`SeatSpace` is a seat's observation (the Box a policy reads), action space and masks. :func:`seat_space_of`
makes one from a game's own gymnasium spaces (any observation space of a fixed size, read as
:mod:`selfplay_cli.envs.obs_spaces` reads it; Discrete, MultiDiscrete and Box actions) or refuses them with a
:class:`SpaceError` that says why; :func:`check_seat_space` checks a seat a game declares itself. :func:`describe_space`
is the short text every message and listing gives a space in, and :func:`space_key` what decides whether one network
can play two seats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium import spaces

from ..errors import MarlError
from .obs_spaces import SeatObs, image_layout


@dataclass(frozen=True)
class SeatSpace:
    """What one seat's policy sees and does.

    ``observation``: the Box a policy reads (float32 arrays of its shape, or an image's own dtype, uint8; for a
    Dict observation space, its ``observation`` part). ``action``: Discrete (actions ``0 .. n-1``), MultiDiscrete or
    Box. ``mask``: whether the seat has action masks (Discrete only). ``given``: the observation space as the game
    declares it, where the policy reads it otherwise (flattened, or its ``action_mask`` taken out); None where the
    two are one."""

    observation: spaces.Box
    action: spaces.Space
    mask: bool = False
    given: spaces.Space | None = field(default=None, compare=False)

    def to_json(self) -> dict[str, Any]:
        out = {"observation": describe_space(self.observation), "action": describe_space(self.action),
               "mask": self.mask}
        if self.given is not None:
            out["given"] = describe_space(self.given)
        return out


def describe_space(space: spaces.Space) -> str:
    """A short text for a space: ``Discrete(3)``, ``Box(-1, 1, (8, 6), float32)``, ``MultiDiscrete([3 3])``."""
    if isinstance(space, spaces.Discrete):
        return f"Discrete({space.n})" if int(space.start) == 0 else f"Discrete({space.n}, start={space.start})"
    if isinstance(space, spaces.Box) and space.low.size:
        lo, hi = space.low.min(), space.high.max()
        return f"Box({lo:g}, {hi:g}, {space.shape}, {space.dtype})"
    if isinstance(space, spaces.MultiDiscrete):
        return f"MultiDiscrete({space.nvec.tolist()})"
    if isinstance(space, spaces.Dict):
        return "Dict(" + ", ".join(f"{k}: {describe_space(v)}" for k, v in space.spaces.items()) + ")"
    if isinstance(space, spaces.Tuple):
        return "Tuple(" + ", ".join(describe_space(v) for v in space.spaces) + ")"
    return str(space)


class SpaceError(MarlError, ValueError):
    """A space marl cannot play, or a space description that is not one (the message says which and why; the caller
    adds the game and the seat). Both a user's mistake (:class:`~selfplay_cli.errors.MarlError`: exit code 2) and a
    ValueError, as the checks of the game contract and of snapshot files (:mod:`selfplay_cli.policies.spaces`) raise
    it."""


def check_action(space: spaces.Space) -> spaces.Space:
    """``space`` if marl plays it as an action space, else a :class:`SpaceError` saying why not."""
    if isinstance(space, spaces.Discrete):
        if int(space.n) < 1:
            raise SpaceError(f"action space {describe_space(space)} has no actions")
        return space
    if isinstance(space, spaces.MultiDiscrete):
        if space.nvec.ndim != 1 or space.nvec.size == 0:
            raise SpaceError(f"action space {describe_space(space)}: MultiDiscrete actions must be one flat vector")
        if (space.nvec < 1).any():
            raise SpaceError(f"action space {describe_space(space)} has a dimension without actions")
        return space
    if isinstance(space, spaces.Box):
        if not np.issubdtype(space.dtype, np.floating):
            raise SpaceError(f"action space {describe_space(space)}: Box actions must be floating point")
        if not (np.isfinite(space.low).all() and np.isfinite(space.high).all()):
            raise SpaceError(f"action space {describe_space(space)}: Box actions need finite bounds (a policy "
                             "samples within them)")
        if space.shape == () or math.prod(space.shape) == 0:
            raise SpaceError(f"action space {describe_space(space)}: Box actions need at least one dimension")
        return space
    raise SpaceError(f"action space {describe_space(space)} ({type(space).__name__}) is not supported: marl plays "
                     "Discrete, MultiDiscrete and Box actions")


def _check_observation(space: spaces.Space) -> spaces.Box:
    if not isinstance(space, spaces.Box):
        raise SpaceError(f"observation space {describe_space(space)} ({type(space).__name__}) is not supported: "
                         "marl reads Box, Discrete, MultiDiscrete, MultiBinary, and Tuples and Dicts of them")
    if space.shape is None or math.prod(space.shape) == 0:
        raise SpaceError(f"observation space {describe_space(space)} is empty")
    return space


def seat_space_of(observation: spaces.Space, action: spaces.Space) -> SeatSpace:
    """The :class:`SeatSpace` of a seat with these gymnasium spaces, or :class:`SpaceError` saying why not.

    Any observation space of a fixed size is read (:class:`~selfplay_cli.envs.obs_spaces.SeatObs`): a Box as it is,
    anything else (Discrete, MultiDiscrete, MultiBinary, Tuples and Dicts of them, nested) flattened in a stated
    order. A top-level Dict's ``action_mask`` (MultiBinary(n) or a Box of n zeros and ones, for a Discrete(n) action
    space) is the seat's action mask; a Dict of ``observation`` and ``action_mask`` (PettingZoo's classic games) is
    read as its ``observation``. The observation a policy reads is a float32 Box, except an image
    (:func:`~selfplay_cli.envs.obs_spaces.image_layout`), which keeps its shape and dtype (uint8 frames stay uint8)."""
    try:
        seat_obs = SeatObs(observation)
    except ValueError as e:
        raise SpaceError(f"observation space {describe_space(observation)}: {e}") from None
    m = seat_obs.mask_space
    if m is not None:
        if not isinstance(action, spaces.Discrete):
            raise SpaceError(f"an action_mask needs a Discrete action space, not {describe_space(action)}")
        size = (int(m.n) if isinstance(m, spaces.MultiBinary) and np.ndim(m.n) == 0
                else (m.shape[0] if isinstance(m, spaces.Box) and len(m.shape) == 1 else None))
        if size != int(action.n):
            raise SpaceError(f"action_mask {describe_space(m)} must be MultiBinary({action.n}) or a Box of "
                             f"shape ({action.n},), one entry per action of {describe_space(action)}")
    box = _check_observation(seat_obs.box)
    check_action(action)
    if isinstance(action, spaces.Discrete) and int(action.start) != 0:  # policies play 0 .. n-1
        action = spaces.Discrete(int(action.n))
    elif isinstance(action, spaces.MultiDiscrete) and np.any(action.start != 0):
        action = spaces.MultiDiscrete(action.nvec)
    if box.dtype != np.float32 and image_layout(box) is None:
        box = spaces.Box(box.low.astype(np.float32), box.high.astype(np.float32), dtype=np.float32)
    return SeatSpace(box, action, seat_obs.mask, None if observation is box else observation)


def check_seat_space(seat: SeatSpace) -> None:
    """Raise :class:`SpaceError` if a declared seat does not keep the contract."""
    _check_observation(seat.observation)
    check_action(seat.action)
    if seat.mask and not isinstance(seat.action, spaces.Discrete):
        raise SpaceError(f"action masks need a Discrete action space, not {describe_space(seat.action)}")


def space_key(seat: SeatSpace) -> tuple[Any, ...]:
    """What decides whether one network can play two seats: the observation's shape, the action space, the masks."""
    return tuple(seat.observation.shape), describe_space(seat.action), seat.mask
