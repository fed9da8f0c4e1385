"""A league player as a policy that plays: a scripted player, or a network loaded from its snapshot's file (checked
to be the file its row registered), playing greedily or sampling as its algorithm and game mean it to, seeded from
what it plays; and the checks that players fit the game they are seated in (:func:`env_options_of`,
:func:`check_fits`). Rated play, training's opponents, recordings and exploitability all load players here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..envs import get_env
from ..envs.obs_spaces import stacked_space
from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..play.matches import frame_stack_of
from ..policies import Policy, ScriptedPolicy
from ..results import COOPERATIVE

__all__ = ["check_fits", "env_options_of", "load_player", "mix_seed", "plays_greedy"]


def plays_greedy(row: PlayerRow) -> bool:
    """How a snapshot plays, in every game it is rated by: as its algorithm and its game mean it to be used.

    * DQN takes the action of highest value; SAC its mean action (tanh of the Gaussian's mean: SAC samples only to
      explore, and is evaluated by its mean, as in its paper).
    * PPO in a game against others (two sides, free-for-all) samples from its policy: a stochastic policy may be a
      mixed strategy, which is what PPO optimises there, and its argmax is another, untrained player (in pong it
      loops in endless rallies against a deterministic opponent).
    * PPO in a cooperative game (a control task: the lander) takes its most likely action, the usual evaluation of a
      control policy (what one deploys): the sampling noise only costs. Measured on the lander: a FuPS snapshot
      after 6M steps 197 per lander greedy, 137 sampling, which fires engines at random once down and rarely comes
      to rest.
    """
    if row.algo in ("dqn", "sac"):
        return True
    try:
        return get_env(row.env).kind == COOPERATIVE
    except (KeyError, MarlError):  # a game that cannot be loaded now: its games cannot be played anyway
        return False


def mix_seed(*parts: int) -> int:
    """A policy's sampling seed from the seeds of what it plays (a match's first seed, a player id): policies that
    sample (PPO snapshots, random) play different moves in every match, so a deterministic game (a board game) does
    not repeat the same games under new seeds and count them twice as evidence."""
    return int(np.random.SeedSequence([int(p) for p in parts]).generate_state(1, np.uint64)[0] >> 1)


def load_player(league: League, row: PlayerRow, device: str = "cpu", greedy: bool | None = None,
                seed: int = 0) -> Policy:
    """The policy a league player stands for: a scripted bot, or a network loaded from its snapshot file, playing
    as :func:`plays_greedy` says unless ``greedy`` is given; ``seed`` seeds its sampling.

    The file is the one in the league home, or, where this machine has none (a database opened from another
    machine, or without a home), the snapshot's blob fetched from the league into the local cache
    (:func:`~selfplay_cli.players.files.snapshot_path`). It is validated in full before anything is built from it
    (:func:`~selfplay_cli.policies.snapshot_reader.read_snapshot`) and must be the file the row registered
    (:func:`~selfplay_cli.players.files.read_row_snapshot`): a file copied over it, or edited, is refused with an error
    naming it, so no game is ever played or stored under the wrong identity. A row whose ``meta`` cannot be read
    (:attr:`~selfplay_cli.league.roster.PlayerRow.unusable`) is refused in one line."""
    if row.unusable is not None:
        raise MarlError(f"{row.full_name}: its row in the league cannot be read ({row.unusable}): it is not played")
    if row.is_bot:
        return ScriptedPolicy(row.env, row.name, seed=seed)
    from ..policies.snapshot_policy import policy_of  # torch is imported only when a network is needed
    from .files import read_row_snapshot

    _inference_threads(device)
    if row.removed:
        raise MarlError(f"{row.full_name} was removed from the league; its games stay in the ledger")
    snap, path = read_row_snapshot(league, row)
    return policy_of(snap, path, id=row.full_name, device=device,
                     greedy=plays_greedy(row) if greedy is None else greedy, seed=seed)


def _inference_threads(device: str) -> None:
    """Small networks evaluated in batches run fastest on one CPU thread: torch's default of one thread per
    core costs more in synchronisation than it gains (measured 55 ms vs 0.8 ms per 1000-observation batch)."""
    import torch

    if device in ("cpu", "auto") and not torch.cuda.is_available():
        torch.set_num_threads(1)


def env_options_of(*policies: Policy) -> dict[str, Any]:
    """The game options the players were trained with (frame stack, rules...); they must agree."""
    found: dict[str, Any] | None = None
    owner = ""
    for p in policies:
        opts = getattr(getattr(p, "meta", None), "env_options", None)
        if opts is None:
            continue
        if found is not None and opts != found:
            raise MarlError(f"{owner} and {p.id} were made for different game options ({found} vs {opts})")
        found, owner = dict(opts), p.id
    return found or {}


def check_fits(spec: Any, options: dict[str, Any], *policies: Policy) -> None:
    """Every network among ``policies`` reads the observations and plays the actions of the seats the game has
    with ``options`` (a :class:`MarlError` naming the policy and both shapes otherwise)."""
    seats = spec.seat_spaces(spec.config(**options))
    for p in policies:
        obs, act = getattr(p, "obs_space", None), getattr(p, "act_space", None)
        if obs is None or act is None or getattr(p, "kind", "") == "bot":
            continue
        team = getattr(p, "seats", None)  # a joint (SA) policy flies exactly its team's number of seats
        if team is not None and team != len(seats):
            raise MarlError(f"{p.id} is one agent for a team of {team} seats (--sharing sa); with the options {options}"
                            f" {spec.name} has {len(seats)}: a joint agent flies only the team it was trained as")
        k = frame_stack_of(p)  # a policy reading its last k observations reads them stacked
        fits = [s for s in seats
                if tuple(stacked_space(s.observation, k).shape) == tuple(obs.shape) and s.action == act]
        if not fits:
            stacked = f" (its last {k} stacked)" if k > 1 else ""
            raise MarlError(f"{p.id} reads observations of shape {tuple(obs.shape)}{stacked} and plays {act}, but with "
                            f"the options {options} every seat of {spec.name} is {seats[0].observation} / "
                            f"{seats[0].action}")
