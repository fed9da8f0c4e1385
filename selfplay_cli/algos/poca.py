"""MA-POCA: multi-agent posthumous credit assignment (Cohen et al. 2021, "On the Use and Misuse of Absorbing States
in Multi-agent Reinforcement Learning"; Unity ML-Agents' ``poca`` trainer).

The actors are MAPPO's (:mod:`.mappo`): PPO's network without a value head, reading the agent's own seat, saved as
the snapshot in PPO's format. The critic, trained beside them and kept only in the learner's state, is one attention
network over the agents present in the game (as many as there are, however many come and go):

* each present agent's observation (flat, with its seat one-hot) is embedded as a token, the game's global state
  (where it has one) as one more; one residual self-attention layer over the present tokens (absent agents masked),
  a mean over them and an MLP give the team's value V(s);
* agent i's baseline Q_i(s, a_{-i}) reads, through the same attention and MLP, agent i's observation token and the
  other present agents' observation-action tokens: what the team will get given what the others did, whatever i
  does.

The team's return is the lambda-return of V over the team's reward (the sum of its seats' rewards) up to the game's
end, not an agent's: G_t = r_t + gamma (1 - end_t) ((1 - lambda) V(s_{t+1}) + lambda G_{t+1}), a game cut short
bootstrapping from V of its final state. Agent i's advantage at a decision is G_t - Q_i(s_t, a_{-i,t}); both V and
Q_i regress on G_t. An agent that leaves the game (it died, it finished) stops acting, but its decisions' advantages
keep the team's later rewards until the game ends: it is credited for what its actions did for the team after it
left (the "posthumous" credit), which a learner that stops at its own end never sees. The policy's loss, the
optimiser and the rollout are PPO's (:mod:`.ppo`): only the decisions the agent took are learned from.

Only cooperative games whose seats act together, with ``--sharing fups`` or ``nops``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..envs import SeatSpace
from ..envs.team import TeamStep, TeamView
from ..policies.spaces import ActionHead
from .base import action_head
from .mappo import MAPPOConfig, MAPPOLearner, mlp


@dataclass
class POCAConfig(MAPPOConfig):
    """MAPPO's settings (:class:`~.mappo.MAPPOConfig`; ``critic_hidden``: the width of the critic's tokens, then
    its head's layers) and the attention's heads."""

    attention_heads: int = 4  # heads of the critic's self-attention (must divide critic_hidden[0])

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.attention_heads < 1 or self.critic_hidden[0] % self.attention_heads:
            raise ValueError(f"attention_heads must divide critic_hidden[0] ({self.critic_hidden[0]}), not "
                             f"{self.attention_heads}")


class TeamCritic(nn.Module):
    """The MA-POCA critic: V(s) and each agent's baseline Q_i(s, a_{-i}) through one self-attention over the present
    agents (see the module docstring)."""

    def __init__(self, n_seats: int, obs_width: int, act_width: int, state_width: int | None,
                 hidden: tuple[int, ...], heads: int, activation: str) -> None:
        super().__init__()
        h = hidden[0]
        self.n_seats = n_seats
        self.obs_token = mlp(obs_width + n_seats, (), h, activation)
        self.obs_action_token = mlp(obs_width + act_width + n_seats, (), h, activation)
        self.state_token = None if state_width is None else mlp(state_width, (), h, activation)
        self.attention = nn.MultiheadAttention(h, heads, batch_first=True)
        self.norm = nn.LayerNorm(h)
        self.head = mlp(h, hidden[1:], 1, activation)
        self.register_buffer("eye", torch.eye(n_seats), persistent=False)

    def _seated(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` (rows, seats, width) with each seat's one-hot appended."""
        return torch.cat((x, self.eye.expand(x.shape[0], -1, -1)), dim=-1)

    def _pool(self, tokens: torch.Tensor, mask: torch.Tensor, state: torch.Tensor | None) -> torch.Tensor:
        tokens = F.relu(tokens)
        if self.state_token is not None and state is not None:
            tokens = torch.cat((tokens, F.relu(self.state_token(state))[:, None]), dim=1)
            mask = torch.cat((mask, torch.ones_like(mask[:, :1])), dim=1)
        mask = mask | ~mask.any(dim=1, keepdim=True)  # a row with nobody in it (never learned from): defined
        attended, _ = self.attention(tokens, tokens, tokens, key_padding_mask=~mask, need_weights=False)
        z = self.norm(tokens + attended)
        m = mask.unsqueeze(-1).to(z.dtype)
        return self.head((z * m).sum(dim=1) / m.sum(dim=1)).squeeze(-1)

    def value(self, obs: torch.Tensor, present: torch.Tensor, state: torch.Tensor | None) -> torch.Tensor:
        """V(s) of each row: the present agents' observations (rows, seats, width), ``present`` (rows, seats)."""
        return self._pool(self.obs_token(self._seated(obs)), present, state)

    def baseline(self, obs: torch.Tensor, actions: torch.Tensor, present: torch.Tensor, seat: torch.Tensor,
                 state: torch.Tensor | None) -> torch.Tensor:
        """Q_i(s, a_{-i}) of each row for agent ``seat`` (rows,): its own observation, the others' with their
        actions."""
        own = self.obs_token(self._seated(obs))
        others = self.obs_action_token(self._seated(torch.cat((obs, actions), dim=-1)))
        is_self = F.one_hot(seat, self.n_seats).bool()
        tokens = torch.where(is_self.unsqueeze(-1), own, others)
        return self._pool(tokens, present | is_self, state)


TEAM_KEYS = ("team_obs", "present", "team_actions", "team_state")


class POCALearner(MAPPOLearner):
    """MAPPO's actor over ``n_slots`` slots with MA-POCA's critic and advantages (see the module docstring)."""

    name = "poca"
    config_class = POCAConfig
    centralised = True

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        return action_head("MA-POCA", seat.action)

    def _build_critic(self) -> nn.Module:
        t, cfg = self.team, self.cfg
        return TeamCritic(t.n_seats, t.obs_width, t.act_width, t.state_width, cfg.critic_hidden,
                          cfg.attention_heads, cfg.arch.activation)

    def _init_team_buffers(self) -> None:
        t, b, team = self.cfg.rollout_steps, self.n_slots, self.team
        z = {"device": self.device}
        self.team_buf: dict[str, torch.Tensor] = {
            "team_obs": torch.zeros((t, b, team.n_seats, team.obs_width), **z),
            "present": torch.zeros((t, b, team.n_seats), dtype=torch.bool, device=self.device),
            "team_actions": torch.zeros((t, b, team.n_seats, team.act_width), **z),
            "team_reward": torch.zeros((t, b), **z), "team_done": torch.zeros((t, b), **z),
            "team_boot": torch.zeros((t, b), **z)}  # V(final state) of games cut short on the step, else 0
        if team.state_width is not None:
            self.team_buf["team_state"] = torch.zeros((t, b, team.state_width), **z)

    def _tensors(self, view: TeamView) -> dict[str, torch.Tensor]:
        d = self.device
        out = {"team_obs": torch.as_tensor(view.obs, device=d), "present": torch.as_tensor(view.present, device=d)}
        if self.team.state_width is not None and view.state is not None:
            out["team_state"] = torch.as_tensor(view.state, device=d)
        return out

    def _team_values(self, view: dict[str, torch.Tensor]) -> torch.Tensor:
        with torch.no_grad():
            return self.critic.value(view["team_obs"], view["present"], view.get("team_state"))

    def _keep_team_step(self, step: TeamStep) -> None:
        t, buf = self.t, self.team_buf
        for k, v in self._tensors(step.before).items():
            buf[k][t] = v
        buf["team_actions"][t] = torch.as_tensor(step.actions, device=self.device)
        buf["team_reward"][t] = torch.as_tensor(step.reward * np.float32(self.cfg.reward_scale), device=self.device)
        buf["team_done"][t] = torch.as_tensor(step.done, dtype=torch.float32, device=self.device)
        buf["team_boot"][t] = 0.0
        if step.final is not None and self.cfg.bootstrap_truncated and step.cut.any():
            rows = np.flatnonzero(step.cut)
            v = self._team_values(self._tensors(step.final.rows(rows)))
            buf["team_boot"][t, torch.as_tensor(rows, device=self.device)] = v

    # POCA's returns run over the team's steps, not a seat's: PPO's per-seat bootstraps are not used
    def _final_values(self, final: np.ndarray, rows: np.ndarray) -> torch.Tensor:
        return torch.zeros(len(rows), device=self.device)

    @torch.no_grad()
    def _batch(self, next_obs: np.ndarray) -> dict[str, Any]:
        """The decisions of the rollout (the steps each slot's agent acted on), with the team's lambda-returns and
        each decision's advantage over its agent's baseline."""
        cfg, buf = self.cfg, self.team_buf
        t, b = cfg.rollout_steps, self.n_slots
        flat = {k: buf[k].reshape(t * b, *buf[k].shape[2:]) for k in TEAM_KEYS if k in buf}
        seats = self.seats.repeat(t)
        values = self.critic.value(flat["team_obs"], flat["present"], flat.get("team_state")).reshape(t, b)
        if self._after is None:
            raise RuntimeError("update() before the team's view of the last step (see_team)")
        next_value = self._team_values(self._tensors(self._after))
        next_values = torch.cat((values[1:], next_value[None]))
        live = 1.0 - buf["team_done"]
        deltas = buf["team_reward"] + cfg.gamma * (next_values * live + buf["team_boot"]) - values
        adv = torch.zeros_like(deltas)
        last = torch.zeros(b, device=self.device)
        for k in reversed(range(t)):
            last = deltas[k] + cfg.gamma * cfg.gae_lambda * live[k] * last
            adv[k] = last
        returns = (adv + values).reshape(-1)
        baselines = self.critic.baseline(flat["team_obs"], flat["team_actions"], flat["present"], seats,
                                         flat.get("team_state"))
        acted = (self.acting.reshape(-1) if self.acting is not None
                 else torch.ones(t * b, dtype=torch.bool, device=self.device))
        idx = acted.nonzero().squeeze(-1)
        out = {"obs": self.obs.reshape(t * b, -1), "actions": self.actions.reshape(t * b, *self.actions.shape[2:]),
               "logprobs": self.logprobs.reshape(-1), "values": values.reshape(-1), "returns": returns,
               "adv": returns - baselines, "seat": seats,
               "masks": None if self.masks is None else self.masks.reshape(t * b, -1), **flat}
        return {k: None if v is None else v.index_select(0, idx) for k, v in out.items()}

    def _forward(self, batch: dict[str, Any], idx: torch.Tensor) -> tuple[torch.Tensor, Any]:
        logits, _ = self.net(batch["obs"].index_select(0, idx))
        rows = {k: batch[k].index_select(0, idx) for k in (*TEAM_KEYS, "seat") if batch.get(k) is not None}
        value = self.critic.value(rows["team_obs"], rows["present"], rows.get("team_state"))
        baseline = self.critic.baseline(rows["team_obs"], rows["team_actions"], rows["present"], rows["seat"],
                                        rows.get("team_state"))
        return logits, (value, baseline)

    def _value_loss(self, value: Any, batch: dict[str, Any], idx: torch.Tensor) -> torch.Tensor:
        """Both the team's value and the agent's baseline regress on the team's return."""
        v, q = value
        r = batch["returns"].index_select(0, idx)
        return 0.5 * ((v - r).square().mean() + (q - r).square().mean())

    def _value_rollout(self) -> None:
        """Nothing: the critic values the rollout in :meth:`_batch`."""
