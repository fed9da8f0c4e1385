"""The run's learners as its settings make them: each one's name (:func:`learner_names`: its snapshots end in it),
the seat space it learns (:func:`run_learners`), and the learners themselves, built for a layout of seats
(:func:`make_learners`). One learner's seat and settings are :func:`~.config.learner_setup`'s (the settings check
the networks it makes before a run exists).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from ..algos import get_learner
from ..algos.joint import JointLearner
from ..envs import EnvSpec, SeatSpace
from ..envs.team import team_spec
from ..play.seat_plan import learner_spaces
from .config import TrainConfig, learner_setup
from .state import SavedAs


def learner_names(agents: tuple[str, ...], home: tuple[int, ...], sharing: str) -> list[str]:
    """Each learner's name: with one network per learner, the seat (agent) it holds first (``left``, ``right``);
    with one network for all, ``learner``."""
    n = max(home) + 1
    if sharing == "fups" or n == 1:
        return ["learner"]
    return [agents[home.index(i)] for i in range(n)]


def run_learners(cfg: TrainConfig) -> tuple[list[str], list[SeatSpace]]:
    """The run's learners as the trainer builds them: each one's name (its snapshots end in it) and the seat space
    it learns (before its frame stack: :func:`~.config.learner_setup`)."""
    spec = cfg.game()
    game = spec.config(**cfg.env_options)
    plan = cfg.seat_plan()
    layout = cfg.layout(plan)
    names = cfg.league.names() if cfg.league is not None else learner_names(spec.agents, plan.home, cfg.sharing)
    roles = spec.seat_roles(game)
    spaces = learner_spaces(spec, spec.seat_spaces(game), layout, roles if len(set(roles)) > 1 else None)
    return names, list(spaces)


def make_learners(cfg: TrainConfig, spec: EnvSpec, spaces: list[SeatSpace], device: torch.device, layout: np.ndarray,
                  roles: list[str | None]) -> tuple[list[Any], SavedAs]:
    """The run's learners, and what their snapshots say of them: one agent over the team's joint observation
    and action (``--sharing sa``), or one learner per name, each seeded by its index."""
    learner_cls, algo_cfg = get_learner(cfg.algo), getattr(cfg, cfg.algo)
    if cfg.sharing == "sa":
        sa = JointLearner(learner_cls, spaces[0], spec.n_seats, cfg.games, algo_cfg, seed=cfg.seed,
                          device=device)
        return [sa], SavedAs([sa.joint_seat], roles, {"seats": spec.n_seats, "base": sa.base})
    setups = [learner_setup(cfg, space) for space in spaces]
    team: Callable[[int], dict[str, Any]] = lambda i: {}  # noqa: E731
    if getattr(learner_cls, "centralised", False):  # a critic of the whole team: what it reads of the team
        game_cfg = spec.config(**cfg.env_options)
        seat_spaces = [learner_setup(cfg, s)[0] for s in spec.seat_spaces(game_cfg)]
        team = lambda i: {"team": team_spec(spec, game_cfg, seat_spaces, layout, i)}  # noqa: E731
    learners = [learner_cls(seat, int((layout == i).sum()), section, seed=cfg.seed + i, device=device,
                            **team(i)) for i, (seat, section) in enumerate(setups)]
    return learners, SavedAs(spaces, roles, None)
