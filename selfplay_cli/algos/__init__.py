"""Learners behind one interface (:class:`Learner`, :mod:`.base`), registered by name in :data:`LEARNERS`: each
algorithm one file that reads top to bottom (:mod:`.ppo`, :mod:`.dqn`, :mod:`.sac`; :mod:`.mappo` and :mod:`.poca`,
PPO with a critic of the whole cooperative team), and what they share: the replay buffer and n-step returns of the
off-policy learners (:mod:`.replay`), the flat Adam optimiser (:mod:`.optim`), kickstarting from a teacher
(:mod:`.kickstart`) and any learner as one agent for a cooperative team (:mod:`.joint`, ``--sharing sa``).

A learner is built from its seat's spaces and its config dataclass: ``LEARNERS[name](seat, n_slots, config,
seed=..., device=...)``, ``seat`` a :class:`selfplay_cli.envs.SeatSpace`.
"""

from __future__ import annotations

from ..errors import MarlError
from .base import Learner
from .dqn import DQNConfig, DQNLearner
from .mappo import MAPPOConfig, MAPPOLearner
from .optim import FlatAdam, flatten
from .poca import POCAConfig, POCALearner
from .ppo import PPOConfig, PPOLearner
from .sac import SACConfig, SACLearner

LEARNERS: dict[str, type] = {"ppo": PPOLearner, "dqn": DQNLearner, "sac": SACLearner, "mappo": MAPPOLearner,
                             "poca": POCALearner}
"""Algorithm name -> learner class (each has ``name`` and ``config_class``)."""


def get_learner(name: str) -> type:
    """The learner class registered as ``name``; a :class:`MarlError` listing the known ones otherwise."""
    try:
        return LEARNERS[name]
    except KeyError:
        raise MarlError(f"unknown algorithm '{name}'; known: {', '.join(sorted(LEARNERS))}") from None


__all__ = ["LEARNERS", "DQNConfig", "DQNLearner", "FlatAdam", "Learner", "MAPPOConfig", "MAPPOLearner", "POCAConfig",
           "POCALearner", "PPOConfig", "PPOLearner", "SACConfig", "SACLearner", "flatten", "get_learner"]
