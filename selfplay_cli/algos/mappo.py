"""MAPPO: PPO whose value function reads the whole team (Yu et al. 2022, "The Surprising Effectiveness of PPO in
Cooperative Multi-Agent Games").

Each agent's actor is PPO's network without a value head: it reads its own seat's observation, and it alone is saved
as the snapshot (the same format as PPO's, so ``marl match``, ``record`` and the ladder play it unchanged). The critic
is trained beside it and lives only in the learner's state (what a resumed run restores): an MLP of

    [the game's global state, or, where the game has none, every seat's observation side by side (an absent seat's
     zeros); which seats are in the game; the agent's seat, one-hot]

(MAPPO's "agent-specific global state": one critic serves every seat, told whose value it gives), with hidden layers
of 64 and 64 (``critic_hidden``). Its first release had 128 and 128: a minibatch step then took about twice PPO's
(the lander, 4,096 rows: 24 ms against 11) and MAPPO 1.5-2x PPO's wall time per game step; 64 wide, the size of
PPO's own network, its steps take about PPO's time (the same function of its input as before, of a smaller network:
the one change to the critic; ``benchmarks/team_critics.py``). Everything else is
PPO's (:mod:`.ppo`): the rollout, GAE(lambda) over each seat's own decisions and ends, the clipped objective, the
value loss, the optimiser (Adam over the actor's and the critic's parameters together, their joint gradient norm
clipped). The critic's values of a rollout are taken at the update, in one batch, from the inputs kept each step
(the critic does not change during a rollout, so they are the values PPO would have taken while acting).

The team's view reaches the learner through the trainer (:mod:`selfplay_cli.envs.team`): ``centralised =
True`` asks for it, and ``see_team(step)`` hands it each step before ``record``. Only cooperative games whose seats
act together, with ``--sharing fups`` or ``nops`` (:func:`check_team_game`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch
from torch import nn

from ..envs import EnvSpec, SeatSpace
from ..envs.team import TeamSpec, TeamStep, TeamView
from ..errors import MarlError
from ..policies.network import Arch
from ..policies.spaces import ActionHead
from .base import action_head
from .optim import FlatAdam
from .ppo import PPOConfig, PPOLearner


@dataclass
class MAPPOConfig(PPOConfig):
    """PPO's settings (:class:`~.ppo.PPOConfig`), the actor without a value head, and the critic's layers."""

    critic_hidden: tuple[int, ...] = (64, 64)  # the centralised critic's hidden layers (its activation: the actor's;
    # 128 and 128 until the lander measured a critic of that size at 1.5-2x PPO's wall time per game step)
    arch: Arch = field(default_factory=lambda: Arch(hidden=(64, 64), activation="relu", value_head=False))

    def __post_init__(self) -> None:
        super().__post_init__()
        self.arch = replace(self.arch, value_head=False)  # the critic is separate; the actor is what is saved
        self.critic_hidden = tuple(int(h) for h in self.critic_hidden)
        if not self.critic_hidden or not all(h > 0 for h in self.critic_hidden):
            raise ValueError("critic_hidden must be one or more positive layer widths")

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["critic_hidden"] = list(self.critic_hidden)
        return d


def check_team_game(spec: EnvSpec, algo: str, sharing: str) -> None:
    """Refuse, in one line, a game a team critic makes no sense in: not cooperative, or taking turns; and one agent
    over the whole team (``--sharing sa``), which has no team to credit."""
    if spec.kind != "cooperative":
        raise MarlError(f"--algo {algo} trains a cooperative team with a critic of the whole team; {spec.name} is "
                        f"{spec.kind}: use --algo ppo")
    if spec.turns != "simultaneous":
        raise MarlError(f"--algo {algo} trains teams whose seats act together; {spec.name}'s seats take turns: use "
                        "--algo ppo")
    if sharing == "sa":
        raise MarlError(f"--algo {algo} gives each seat its own actor (--sharing fups or nops); --sharing sa makes "
                        "the team one agent, which has no team to credit")


def mlp(inputs: int, hidden: tuple[int, ...], outputs: int, activation: str) -> nn.Sequential:
    """Linear layers of widths ``hidden`` between ``inputs`` and ``outputs``, ``activation`` (relu or tanh) between."""
    act = nn.Tanh if activation == "tanh" else nn.ReLU
    layers: list[nn.Module] = []
    width = inputs
    for h in hidden:
        layers += [nn.Linear(width, h), act()]
        width = h
    layers.append(nn.Linear(width, outputs))
    return nn.Sequential(*layers)


class MAPPOLearner(PPOLearner):
    """PPO's learner over ``n_slots`` slots whose values come from a critic of the team ``team`` (the trainer's
    :func:`~selfplay_cli.envs.team.team_spec`)."""

    name = "mappo"
    config_class = MAPPOConfig
    centralised = True  # the trainer hands it the team's view of each step (see_team)

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        return action_head("MAPPO", seat.action)

    @classmethod
    def check_game(cls, spec: EnvSpec, sharing: str) -> None:
        """One clear :class:`MarlError` for a game or sharing a team critic cannot train (before a run exists)."""
        check_team_game(spec, cls.name, sharing)

    def __init__(self, seat: SeatSpace, n_slots: int, config: Any = None, *, seed: int = 0,
                 device: str | torch.device = "cpu", team: TeamSpec | None = None) -> None:
        if team is None:
            raise ValueError(f"{type(self).__name__} reads the whole team: build it with team= (a TeamSpec; the "
                             "trainer gives it)")
        super().__init__(seat, n_slots, config, seed=seed, device=device)
        if len(team.seats) != self.n_slots:
            raise ValueError(f"the team spec names seats for {len(team.seats)} slots; the learner has {self.n_slots}")
        self.team = team
        self.seats = torch.as_tensor(np.asarray(team.seats, dtype=np.int64), device=self.device)
        self._seat_onehot = np.eye(team.n_seats, dtype=np.float32)[np.asarray(team.seats, dtype=np.int64)]
        with torch.random.fork_rng(devices=[]):  # the critic's first weights from the learner's seed alone
            torch.manual_seed(seed + 7_919)
            self.critic = self._build_critic().to(self.device)
        self.opt = FlatAdam([*self.net.parameters(), *self.critic.parameters()], lr=self.cfg.lr, eps=1e-5,
                            max_grad_norm=self.cfg.max_grad_norm)
        self._after: TeamView | None = None  # the team's view after the last step seen (the rollout bootstraps)
        self._final: TeamView | None = None  # ... and of the games cut short on it, before they restarted
        self._init_team_buffers()

    # -- the critic ----------------------------------------------------------------------------------------------
    @property
    def critic_width(self) -> int:
        t = self.team
        return (t.state_width if t.state_width is not None else t.team_obs_width) + 2 * t.n_seats

    def _build_critic(self) -> nn.Module:
        return mlp(self.critic_width, self.cfg.critic_hidden, 1, self.cfg.arch.activation)

    def _init_team_buffers(self) -> None:
        self.extra["critic_in"] = torch.zeros((self.cfg.rollout_steps, self.n_slots, self.critic_width),
                                              device=self.device)

    def critic_input(self, view: TeamView) -> torch.Tensor:
        """The critic's input for each slot of ``view`` (see the module docstring)."""
        present = view.present.astype(np.float32)
        if view.state is not None and self.team.state_width is not None:
            seen = view.state.reshape(len(present), -1)
        else:
            seen = (view.obs * present[:, :, None]).reshape(len(present), -1)
        x = np.concatenate((seen, present, self._seat_onehot[:len(present)]), axis=1)
        return torch.as_tensor(x, dtype=torch.float32, device=self.device)

    def _critic_values(self, x: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return self.critic(x).squeeze(-1)

    # -- the team's view, each step -------------------------------------------------------------------------------
    def see_team(self, step: TeamStep) -> None:
        """The team's step the next ``record`` stores (:mod:`selfplay_cli.envs.team`)."""
        if len(step.reward) != self.n_slots:
            raise ValueError(f"a team step of {len(step.reward)} rows for {self.n_slots} slots")
        self._keep_team_step(step)
        self._after, self._final = step.after, step.final

    def _keep_team_step(self, step: TeamStep) -> None:
        self.extra["critic_in"][self.t] = self.critic_input(step.before)

    def _values(self, obs: torch.Tensor, extra: dict[str, torch.Tensor]) -> torch.Tensor:
        return self._critic_values(extra["critic_in"])

    def _next_values(self, next_obs: np.ndarray) -> torch.Tensor:
        if self._after is None:
            raise RuntimeError("update() before the team's view of the last step (see_team)")
        return self._critic_values(self.critic_input(self._after))

    def _final_values(self, final: np.ndarray, rows: np.ndarray) -> torch.Tensor:
        if self._final is None:
            raise RuntimeError("a seat was cut short but the team's final view was not given (see_team)")
        return self._critic_values(self.critic_input(self._final.rows(rows)))

    def _forward(self, batch: dict[str, Any], idx: torch.Tensor) -> tuple[torch.Tensor, Any]:
        logits, _ = self.net(batch["obs"].index_select(0, idx))
        return logits, self.critic(batch["critic_in"].index_select(0, idx)).squeeze(-1)

    def update(self, next_obs: np.ndarray, progress: float = 0.0,
               final_obs: np.ndarray | None = None) -> dict[str, float]:
        """PPO's update (:meth:`~.ppo.PPOLearner.update`), the rollout's values first taken from the critic."""
        if self.t == self.cfg.rollout_steps:
            self._value_rollout()
        return super().update(next_obs, progress, final_obs)

    def _value_rollout(self) -> None:
        """The critic's values of the rollout's steps, from the inputs kept each step."""
        x = self.extra["critic_in"]
        self.values.copy_(self._critic_values(x.reshape(-1, x.shape[-1])).reshape(self.values.shape))

    # -- saving ---------------------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """PPO's (the actor, the optimiser of both networks, ...) and the critic's weights."""
        return {**super().state_dict(), "critic": self.critic.state_dict()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.critic.load_state_dict(state["critic"])
        super().load_state_dict(state)
