"""Exact exploitability of a policy over an OpenSpiel game's whole tree, by OpenSpiel's own best response.

The policy comes as a function ``probabilities(tensors, masks) -> (B, n_actions)``: what a seat sees at a decision
(the tensor marl's adapter gives it there, :mod:`.openspiel`: the player's ``information_state_tensor``, else its
``observation_tensor``) and its legal-action mask, in batches, to the probability of each action. One policy plays
every player, as in self-play (OpenSpiel games through marl have one role for all their seats), or one function per
player plays its own seat (a team of per-seat networks). This module imports nothing of marl's policies: a caller
wraps a network or a scripted player in such a function.

How: the game tree is walked once (every history, chance outcomes included), stopping with an error past
:data:`MAX_NODES` histories (tic-tac-toe has 549,946, Leduc poker 9,457, Kuhn poker 58; chess is refused within
seconds); at each new information state of the player to move the function is asked, in batches of
:data:`BATCH`, for the probabilities there. The resulting table (keyed by ``information_state_string``, as
OpenSpiel's tabular policies are) becomes a ``pyspiel.TabularPolicy``; each player's best-response value against
the others playing it is ``pyspiel.TabularBestResponse(...).value_from_state(root)`` and the on-policy values
``pyspiel.expected_returns``. NashConv is the sum over players of best-response value minus on-policy value;
exploitability is NashConv divided by the number of players, which for a two-player zero-sum game is OpenSpiel's
``exploitability`` (the mean of the two best-response values). All figures are in the game's own units (its
returns: chips in poker).

A mixture of policies (each player draws policy i with probability ``w_i`` before the game and plays it throughout)
is asked the same way, each policy at every information state, then made the one behaviour policy that plays as the
mixture does by OpenSpiel's ``PolicyAggregator`` (each policy's probabilities weighted by ``w_i`` times the
player's own reach of the information state under it), whose exploitability is the mixture's. The aggregator walks
the tree once more per player in Python: fine for poker, tens of seconds for tic-tac-toe.

OpenSpiel's tabular best response walks turn-based games only: a simultaneous-move game is refused in one line, as is
a game without ``information_state_string`` (the key of its policies).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..contract import EnvError
from .openspiel import PREFIX, _load, _playable

__all__ = ["BATCH", "MAX_NODES", "ProbabilitiesFn", "TreeFigures", "check_walkable", "tree_figures"]

MAX_NODES = 1_000_000
"""The most histories (game-tree nodes, chance and terminal ones included) walked before a game is refused as too big
for an exact computation (a few tens of seconds on one core at this size)."""

BATCH = 4096
"""Information states handed to the probabilities function at once."""

ProbabilitiesFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(tensors (B, *shape) float32, masks (B, n_actions) bool) -> (B, n_actions)`` action probabilities, zero where
the mask is False, each row summing to 1."""


@dataclass(frozen=True)
class TreeFigures:
    """The exact figures of one policy playing every player of a game (see the module docstring)."""

    game: str
    players: tuple[str, ...]
    best_response: tuple[float, ...]  # per player: its value when it best-responds and the others play the policy
    on_policy: tuple[float, ...]  # per player: its value when every player plays the policy
    info_states: int  # information states at which the policy was asked
    nodes: int  # histories walked

    @property
    def improvements(self) -> tuple[float, ...]:
        return tuple(b - o for b, o in zip(self.best_response, self.on_policy, strict=True))

    @property
    def nash_conv(self) -> float:
        return float(sum(self.improvements))

    @property
    def exploitability(self) -> float:
        return self.nash_conv / len(self.players)


def check_walkable(name: str) -> Any:
    """The OpenSpiel game ``name`` (``openspiel:GAME``) if its tree can be walked for an exact best response; else
    an :class:`EnvError` in one line: not an OpenSpiel game, OpenSpiel missing, a game marl cannot play, a
    simultaneous-move game, no information-state strings."""
    if not name.startswith(PREFIX):
        raise EnvError(name, f"--exact needs a game OpenSpiel can walk: {PREFIX}GAME, not {name!r}")
    game = _load(name, name[len(PREFIX):].strip())
    _playable(name, game)
    kind = game.get_type()
    if str(kind.dynamics).endswith("SIMULTANEOUS"):
        raise EnvError(name, f"--exact cannot compute {name}: it is a simultaneous-move game, and OpenSpiel's tabular "
                             "best response walks turn-based games only")
    if not kind.provides_information_state_string:
        raise EnvError(name, f"--exact cannot compute {name}: it provides no information_state_string, the key of "
                             "OpenSpiel's tabular policies")
    return game


def _tables(name: str, game: Any, policies: Sequence[Sequence[ProbabilitiesFn]], max_nodes: int,
            tick: Callable[[int], None] | None) -> tuple[list[dict[str, list[tuple[int, float]]]], int]:
    """Walk the tree; each policy's ``{information_state_string: [(action, probability), ...]}`` (a policy is one
    function per player, asked at that player's information states) and the histories walked."""
    info = bool(game.get_type().provides_information_state_tensor)
    n_actions = int(game.num_distinct_actions())
    tables: list[dict[str, list[tuple[int, float]]]] = [{} for _ in policies]
    pending: list[tuple[str, int, list[float], list[int]]] = []

    def ask() -> None:
        keys, players, tensors, masks = zip(*pending, strict=True)
        mask = np.array(masks, dtype=bool)
        x = np.array(tensors, dtype=np.float32)
        player = np.array(players)
        for per_player, table in zip(policies, tables, strict=True):
            for p in np.unique(player).tolist():
                rows = np.flatnonzero(player == p)
                probs = np.asarray(per_player[p](x[rows], mask[rows]), dtype=np.float64)
                if probs.shape != (len(rows), n_actions) or not np.isfinite(probs).all():
                    raise ValueError(f"a policy gave probabilities of shape {probs.shape} (finite: "
                                     f"{bool(np.isfinite(probs).all())}), not {(len(rows), n_actions)}")
                for i, row in zip(rows.tolist(), probs, strict=True):
                    table[keys[i]] = [(int(a), float(row[a])) for a in np.flatnonzero(mask[i])]
        pending.clear()

    seen: set[str] = set()
    stack = [game.new_initial_state()]
    nodes = 0
    while stack:
        state = stack.pop()
        nodes += 1
        if nodes > max_nodes:
            raise EnvError(name, f"--exact cannot compute {name}: its game tree has more than {max_nodes:,} histories "
                                 "(an exact best response walks them all; tic-tac-toe has 549,946)")
        if tick is not None and nodes % 10_000 == 0:
            tick(10_000)
        if state.is_terminal():
            continue
        if state.is_chance_node():
            stack.extend(state.child(a) for a, _ in state.chance_outcomes())
            continue
        p = state.current_player()
        key = state.information_state_string(p)
        if key not in seen:
            seen.add(key)
            tensor = state.information_state_tensor(p) if info else state.observation_tensor(p)
            pending.append((key, p, tensor, state.legal_actions_mask(p)))
            if len(pending) >= BATCH:
                ask()
        stack.extend(state.child(a) for a in state.legal_actions())
    if pending:
        ask()
    return tables, nodes


def _mixed(game: Any, tables: list[dict[str, list[tuple[int, float]]]],
           weights: Sequence[float]) -> dict[str, list[tuple[int, float]]]:
    """The one behaviour policy that plays as the mixture does (each player picks policy i with probability
    ``weights[i]`` once, before the game, and plays it throughout): at each information state, the policies'
    probabilities averaged with weights ``weights[i]`` times the player's own reach of it under policy i. Computed by
    OpenSpiel's ``PolicyAggregator``."""
    from open_spiel.python import policy as policy_lib
    from open_spiel.python.algorithms.policy_aggregator import PolicyAggregator

    class Table(policy_lib.Policy):
        def __init__(self, table: dict[str, list[tuple[int, float]]]) -> None:
            super().__init__(game, list(range(game.num_players())))
            self.table = table

        def action_probabilities(self, state: Any, player_id: int | None = None) -> dict[int, float]:
            p = state.current_player() if player_id is None else player_id
            return dict(self.table[state.information_state_string(p)])

    players = list(range(game.num_players()))
    pool = [Table(t) for t in tables]
    mixed = PolicyAggregator(game).aggregate(players, [pool for _ in players], [list(weights) for _ in players])
    return {key: sorted(probs.items()) for per_player in mixed.policy for key, probs in per_player.items()}


def tree_figures(name: str, policies: Sequence[tuple[ProbabilitiesFn | Sequence[ProbabilitiesFn], float]],
                 max_nodes: int = MAX_NODES, tick: Callable[[int], None] | None = None) -> TreeFigures:
    """The exact best-response values, NashConv and exploitability of a policy playing every player of
    ``openspiel:GAME`` (``name``): ``policies`` is ``[(probabilities, 1.0)]`` for one, or a mixture
    ``[(probabilities_i, weight_i), ...]`` (weights summing to 1: :func:`_mixed`). A policy is one function that
    plays every player, or a sequence of one function per player (a team of per-seat networks). ``tick(n)`` is told
    of every n histories walked (a progress bar).

    Raises :class:`EnvError` (one line) for what :func:`check_walkable` refuses and a tree of more than ``max_nodes``
    histories."""
    game = check_walkable(name)
    import pyspiel

    weights = [float(w) for _, w in policies]
    if not policies or min(weights) < 0 or abs(sum(weights) - 1.0) > 1e-9:
        raise ValueError(f"a mixture's weights must be at least 0 and sum to 1, not {weights}")
    n = int(game.num_players())
    per_player = [[f] * n if callable(f) else list(f) for f, _ in policies]
    if any(len(fs) != n for fs in per_player):
        raise ValueError(f"a policy of {name} is one function, or one per player ({n})")
    tables, nodes = _tables(name, game, per_player, max_nodes, tick)
    table = tables[0] if len(tables) == 1 else _mixed(game, tables, weights)
    policy = pyspiel.TabularPolicy(table)
    root = game.new_initial_state()
    best = tuple(float(pyspiel.TabularBestResponse(game, p, policy).value_from_state(root)) for p in range(n))
    on = tuple(float(v) for v in pyspiel.expected_returns(root, policy, -1, True))
    return TreeFigures(name, tuple(f"player_{p}" for p in range(n)), best, on, len(table), nodes)
