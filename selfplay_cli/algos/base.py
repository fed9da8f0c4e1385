"""The learner interface every algorithm implements, and what a learner is built from.

A learner drives some slots of the batched self-play games as a vectorised environment. Each step the trainer
calls, with one row per slot of the learner::

    actions = learner.act(obs, mask)                 # mask: (slots, n) bool or None
    ...the games step...
    if learner.record(rewards, dones, truncated=truncated, acting=acting, final_obs=final_obs):
        stats = learner.update(next_obs, progress)

* ``dones``: the slot's seat is done in its game on this step: the game ended (won, lost or cut short), or, in a
  game whose agents come and go, the seat's agent left it (it died, it finished) while the others play on. Nothing
  is bootstrapped past it: the step's reward is the seat's last in that game. A game that ended restarts at once,
  so ``next_obs`` of such a slot is the next game's first observation; a seat that left does not act again
  (``acting`` False) until its game restarts (or its agent rejoins).
* ``truncated``: the seat was cut short (a time limit): a subset of ``dones``. Its final observation
  (``final_obs``, rows read only where ``truncated``; ``final_mask`` likewise for a learner that needs it) is
  valued to bootstrap the return instead of counting the cut as the end of the game.
* ``acting``: the slots whose seat acted on this step (turn-based games, and games whose agents come and go: a seat
  not in its game does not act). A step where the seat did not act carries no decision: it is skipped, and its
  reward is credited to the seat's previous decision, up to the seat's next ``done``. None: all acted.

A learner may also be taught (kickstarting, :mod:`selfplay_cli.algos.kickstart`; PPO and SAC can, DQN cannot):
``learner.teach(obs, actions, mask)`` hands it a teacher's actions for observations of its slots, and
``learner.teacher_weight`` weights the imitation term in the updates that follow (0, the default: none).

A learner refuses to learn from a number that is NaN or infinite: the trainer checks what the game gives before a
learner sees it, and each update checks its own losses and gradient norms (:func:`check_steps`), raising
:class:`~selfplay_cli.errors.NonFiniteError` before a broken network can be saved.

Every optional argument left out gives the behaviour learners had before it existed (no truncation bootstrap,
every slot acting). Algorithms are registered by name in :data:`selfplay_cli.algos.LEARNERS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
import torch
from gymnasium import spaces

from ..envs import SeatSpace
from ..errors import MarlError, NonFiniteError
from ..policies.network import MLPNet, NetworkPolicy
from ..policies.spaces import ActionHead, SpaceError, describe_space


@runtime_checkable
class Learner(Protocol):
    """One algorithm's learner (see the module docstring for the calls and their arguments)."""

    name: ClassVar[str]  # the registry name, e.g. "ppo"
    config_class: ClassVar[type]  # its hyperparameter dataclass
    net: MLPNet  # the network it trains (saved as snapshots)
    n_slots: int
    cut: tuple[int, int] | None  # its last update, when a --minutes budget cut it: (gradient steps done, due)

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        """The head for a seat's actions, or one clear error if the algorithm cannot learn them (checked before a
        run is created)."""
        ...

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray: ...

    def record(self, rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray | None = None,
               acting: np.ndarray | None = None, final_obs: np.ndarray | None = None,
               final_mask: np.ndarray | None = None) -> bool: ...

    def update(self, next_obs: np.ndarray, progress: float = 0.0,
               final_obs: np.ndarray | None = None) -> dict[str, float]: ...

    def policy(self, id: str, env: str, greedy: bool = ...) -> NetworkPolicy: ...

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...

    def start_from(self, weights: dict[str, torch.Tensor]) -> None:
        """Start from a snapshot's network weights (``marl train --init-from``), everything else kept fresh."""
        ...


Share = tuple[np.ndarray, int]
"""An actor's rows of a learner's batch: ``(rows, total)``, this batch being rows ``rows`` of the learner's ``total``
slots (:mod:`selfplay_cli.train.shards`)."""


def padded(x: torch.Tensor, share: Share | None, fill: float | bool = 0) -> torch.Tensor:
    """``x`` (one row per slot of an actor's share) as rows ``share[0]`` of a batch of all ``share[1]`` slots, the
    others ``fill``; ``x`` itself without a share. A sampler run on the padded batch draws what it would draw for
    the whole batch, so each row's action is the same however the slots are split between actors."""
    if share is None:
        return x
    rows, total = share
    out = x.new_full((total, *x.shape[1:]), fill)
    out[torch.as_tensor(rows, device=x.device)] = x
    return out


def unpadded(x: torch.Tensor, share: Share | None) -> torch.Tensor:
    """The share's rows of a padded batch (:func:`padded`)."""
    return x if share is None else x[torch.as_tensor(share[0], device=x.device)]


def share_draw(draw: Callable[[int], np.ndarray], n: int, share: Share | None) -> np.ndarray:
    """``draw(total)`` (a numpy generator's draw of one value per slot) at the share's rows: the values the whole
    batch would get at them."""
    return draw(n) if share is None else draw(share[1])[share[0]]


def learner_args(seat: SeatSpace, n_slots: Any, config: Any, config_class: type) -> tuple[SeatSpace, int, Any]:
    """The (seat, slots, config) a learner is built from, checked: ``seat`` a :class:`SeatSpace`, at least one
    slot, and ``config`` an instance of ``config_class`` (None: its defaults)."""
    if not isinstance(seat, SeatSpace):
        raise TypeError(f"a learner is built from a SeatSpace, not {type(seat).__name__}")
    if not isinstance(n_slots, (int, np.integer)) or isinstance(n_slots, bool) or n_slots < 1:
        raise ValueError(f"a learner needs at least one slot, not {n_slots!r}")
    if config is None:
        config = config_class()
    elif not isinstance(config, config_class):
        raise TypeError(f"expected a {config_class.__name__}, not {type(config).__name__}")
    return seat, int(n_slots), config


def action_head(algo: str, space: spaces.Space, only: tuple[str, str] | None = None, advice: str = "") -> ActionHead:
    """The head for a seat's actions, or one clear :class:`MarlError` naming the algorithm and the space; ``only``
    (an :class:`ActionHead` kind and how to name it, e.g. ``("box", "Box (continuous)")``) refuses every other kind,
    with ``advice`` (which algorithm to use instead)."""
    try:
        head = ActionHead.of(space)
    except SpaceError as e:
        raise MarlError(f"{algo} cannot learn this seat's actions: {e}") from None
    if only is not None and head.kind != only[0]:
        raise MarlError(f"{algo} learns {only[1]} actions only; this game's seat acts in {describe_space(space)}: "
                        f"{advice}")
    return head


def as_bool(values: Any, n: int, what: str) -> np.ndarray:
    a = np.asarray(values).reshape(-1)
    if a.shape != (n,):
        raise ValueError(f"{what} has {a.size} entries for {n} slots")
    return a.astype(bool, copy=False)


def fix_mask(mask: np.ndarray | None, head: ActionHead, n: int) -> np.ndarray | None:
    """A learner's mask as a ``(n, width)`` bool array; rows that allow nothing (a seat that does not act on this
    step) allow everything instead, so sampling stays defined (such a step is never learned from)."""
    if mask is None:
        return None
    m = head.check_mask(mask, n)
    if head.kind == "discrete":
        empty = ~m.any(axis=1)
        if empty.any():
            m = m.copy()
            m[empty] = True
        return m
    offset, out = 0, None
    for size in head.nvec:
        empty = ~m[:, offset:offset + size].any(axis=1)
        if empty.any():
            out = m.copy() if out is None else out
            out[empty, offset:offset + size] = True
        offset += size
    return m if out is None else out


def values_of(net: MLPNet, obs: np.ndarray, device: torch.device) -> torch.Tensor:
    """V(obs) from the network's value head, without gradients (observations of any dtype: the network reads an
    image's uint8 itself)."""
    with torch.no_grad():
        x = obs if isinstance(obs, torch.Tensor) else torch.as_tensor(np.asarray(obs))
        _, value = net(x.to(device).reshape(len(obs), -1))
    assert value is not None
    return value


def check_steps(rows: torch.Tensor, names: Sequence[str], step: Callable[[int], str]) -> None:
    """Refuse an update whose figures are not all finite: ``rows`` holds one row per gradient step of the update
    (its losses and gradient norm, as ``names`` call them), checked at once (one device sync an update, not one a
    gradient step). A :class:`NonFiniteError` names the first step at fault (``step(row)`` says which) and what in
    it is NaN or infinite: the first figure in ``names``' order (losses first: a figure after it, such as the gradient
    norm, follows from it), and a loss that breaks spoils the weights of every step after it, so the first step is
    where it began."""
    finite = torch.isfinite(rows)
    if rows.numel() == 0 or bool(finite.all()):
        return
    r, c = (int(i) for i in (~finite).nonzero()[0])  # row-major: the first step, then its first figure
    value = float(rows[r, c])
    kind = "NaN" if math.isnan(value) else "inf" if value > 0 else "-inf"
    raise NonFiniteError(f"{names[c]} is {kind} in {step(r)}")
