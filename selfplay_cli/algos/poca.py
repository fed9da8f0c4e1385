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

The critic's maths and how it is computed. V and Q_i are the functions above, computed as one attention pass each
would give them (to float rounding: ``tests/test_poca.py`` keeps the first implementation, an
``nn.MultiheadAttention`` call for V and another for each seat's Q_i, as the oracle, on the same weights). What
changed (issue "speed where users feel it": the lander's POCA ran at a 16th of PPO's game steps/s, the critic's
steps 89% of its time):

* the critic is 48 wide (``critic_hidden = (48, 48)``: its tokens and its head's layer; 128 and 128 before): the one
  change to what it computes. The rest below (the same maths) took POCA from 11.5 to 2.8 times PPO's wall time
  per game step at 64 wide; 48 wide it is 2.4 (``benchmarks/team_critics.py``; the issue's target 2.5). The
  lander's 30-minute final snapshot (``benchmarks/team_study.py --parts critics``) flew 243.7 a lander over 50
  fresh games at 48 wide (6.7M steps), 238.3 at 64 wide (3.0M steps on a busy machine), 239.6 at 128 wide (1.5M
  steps); ``critic_hidden = [64, 64]`` under ``[poca]`` in a run's config gives the 64-wide critic;
* once per game step, not once per seat: the seats of a game a learner drives (``--sharing fups``: all of them)
  share the step's team view, so V(s_t) and G_t are computed once for the game and every seat's Q_i beside them
  (slots whose team rows over the whole rollout are byte for byte the same are one game: the same inputs, the same
  values);
* each step's tokens (every agent's observation token, observation-action token, and the state's) are embedded
  and projected to the attention's queries, keys and values once, and V's set and every seat's baseline set read
  them in place (views: no set is gathered nor copied, which cost as much as the matrix products on the CPU); the
  attention over two tokens in closed form (a sigmoid of the two keys' score difference), over a few written out
  token by token, forward and backward (no attention kernel, nor a batched matmul, of 2x2 matrices);
* the critic's loss, 0.5 ((V - G)^2 + (Q_i - G)^2) averaged over the decisions, is taken over minibatches of game
  steps, each V weighted by the decisions taken on its step and each Q_i by its seat's there, as many minibatches a
  pass over the rollout as the actors' and drawn by a generator of the critic's own, beside the actors'
  minibatches of decisions (which are PPO's, unchanged). Over a whole rollout it is the per-decision loss exactly;
  a minibatch now holds a game step's V and all its seats' baselines together instead of a random half of them.

Only cooperative games whose seats act together, with ``--sharing fups`` or ``nops``.
"""

from __future__ import annotations

import math
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

SMALL_SETS = 4  # sets of 3 and 4 tokens attend written out (FewTokenAttention), of 2 in closed form, larger by matmul
CHUNK = 8192  # game steps a no-gradient pass of the critic takes at once (its memory)


@dataclass
class POCAConfig(MAPPOConfig):
    """MAPPO's settings (:class:`~.mappo.MAPPOConfig`; ``critic_hidden``, (48, 48) here: the width of the critic's
    tokens, then its head's layers) and the attention's heads."""

    attention_heads: int = 4  # heads of the critic's self-attention (must divide critic_hidden[0])
    critic_hidden: tuple[int, ...] = (48, 48)  # the tokens' width, then the head's layers (128 and 128 until the
    # lander measured POCA at 11.5x PPO's wall time per game step; 64 and 64: 2.8x; 48 and 48: 2.4x, the target 2.5)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.attention_heads < 1 or self.critic_hidden[0] % self.attention_heads:
            raise ValueError(f"attention_heads must divide critic_hidden[0] ({self.critic_hidden[0]}), not "
                             f"{self.attention_heads}")


class FewTokenAttention(torch.autograd.Function):
    """Scaled dot-product attention over sets of a few tokens, token-major: ``q``, ``k``, ``v`` (tokens, sets,
    heads, head width), ``mask`` (tokens, sets) the keys in each set (at least one); out (tokens, sets, heads, head
    width). Written out pair by pair of tokens, forward and backward, on contiguous (sets, heads, head width) slices:
    a batched matmul of 2x2 matrices, or a broadcast product's backward, costs several times more on the CPU."""

    @staticmethod
    def forward(ctx: Any, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        n = q.shape[0]
        scale = 1.0 / math.sqrt(q.shape[-1])
        scores = torch.stack([torch.stack([(q[a] * k[b]).sum(-1) for b in range(n)]) for a in range(n)]) * scale
        scores = scores.masked_fill(~mask[None, :, :, None], float("-inf"))  # (queries, keys, sets, heads)
        p = scores.softmax(dim=1)
        out = torch.stack([sum(p[a, b, ..., None] * v[b] for b in range(n)) for a in range(n)])
        ctx.save_for_backward(q, k, v, p)
        return out

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, None]:
        q, k, v, p = ctx.saved_tensors
        n = q.shape[0]
        scale = 1.0 / math.sqrt(q.shape[-1])
        dp = torch.stack([torch.stack([(grad[a] * v[b]).sum(-1) for b in range(n)]) for a in range(n)])
        dv = torch.stack([sum(p[a, b, ..., None] * grad[a] for a in range(n)) for b in range(n)])
        ds = p * (dp - (p * dp).sum(dim=1, keepdim=True)) * scale
        dq = torch.stack([sum(ds[a, b, ..., None] * k[b] for b in range(n)) for a in range(n)])
        dk = torch.stack([sum(ds[a, b, ..., None] * q[a] for a in range(n)) for b in range(n)])
        return dq, dk, dv, None


class PairAttention(torch.autograd.Function):
    """:class:`FewTokenAttention` for sets of two tokens (two agents, no state: the lander's team), in closed form,
    each token's ``q``, ``k``, ``v`` (sets, heads, head width) a tensor of its own (views of the tokens' table: no
    set is copied out of it): query a's weight on key 0 is p_a = sigmoid(q_a . (k_0 - k_1) / sqrt(width)) (0 or 1
    where a key is masked: ``mask`` (2, sets)), its output v_1 + p_a (v_0 - v_1)."""

    @staticmethod
    def forward(ctx: Any, q0: torch.Tensor, q1: torch.Tensor, k0: torch.Tensor, k1: torch.Tensor, v0: torch.Tensor,
                v1: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        scale = 1.0 / math.sqrt(q0.shape[-1])
        dk, dv = k0 - k1, v0 - v1
        both = (mask[0] & mask[1])[:, None]
        fixed = mask[0][:, None].to(dk.dtype)
        p0 = torch.where(both, torch.sigmoid((q0 * dk).sum(-1) * scale), fixed)
        p1 = torch.where(both, torch.sigmoid((q1 * dk).sum(-1) * scale), fixed)
        ctx.save_for_backward(q0, q1, dk, dv, p0, p1, both)
        return torch.addcmul(v1, p0.unsqueeze(-1), dv), torch.addcmul(v1, p1.unsqueeze(-1), dv)

    @staticmethod
    def backward(ctx: Any, g0: torch.Tensor, g1: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        q0, q1, dk, dv, p0, p1, both = ctx.saved_tensors
        scale = 1.0 / math.sqrt(q0.shape[-1])
        d_v0 = torch.addcmul(p0.unsqueeze(-1) * g0, p1.unsqueeze(-1), g1)
        d_v1 = (g0 + g1).sub_(d_v0)
        dz0 = ((g0 * dv).sum(-1) * (p0 * (1 - p0) * both * scale)).unsqueeze(-1)
        dz1 = ((g1 * dv).sum(-1) * (p1 * (1 - p1) * both * scale)).unsqueeze(-1)
        d_k = torch.addcmul(dz0 * q0, dz1, q1)
        return dz0 * dk, dz1 * dk, d_k, -d_k, d_v0, d_v1, None


class TeamCritic(nn.Module):
    """The MA-POCA critic: V(s) and each agent's baseline Q_i(s, a_{-i}) through one self-attention over the present
    agents (see the module docstring). Its parameters are those of the tokens' layers, an
    :class:`~torch.nn.MultiheadAttention` (its projections: the attention is computed here), a layer norm and the
    head."""

    def __init__(self, n_seats: int, obs_width: int, act_width: int, state_width: int | None,
                 hidden: tuple[int, ...], heads: int, activation: str) -> None:
        super().__init__()
        h = hidden[0]
        self.n_seats, self.heads = n_seats, heads
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

    def _project(self, tokens: torch.Tensor) -> torch.Tensor:
        """The attention's queries, keys and values of ``tokens`` side by side (..., 3 width)."""
        return F.linear(tokens, self.attention.in_proj_weight, self.attention.in_proj_bias)

    def _attend(self, tokens: list[torch.Tensor], qkv: list[torch.Tensor], mask: torch.Tensor) -> torch.Tensor:
        """The value of each set of the tokens ``tokens`` (one (sets, width) tensor a place in the set) from their
        projections ``qkv`` ((sets, 3 width) each) and ``mask`` (places, sets) of the tokens in it: multi-head
        attention over the set's tokens, the residual, the layer norm, the mean over the set's tokens and the head (as
        ``nn.MultiheadAttention`` with a key padding mask, then the rest)."""
        k, (s, d) = len(tokens), tokens[0].shape
        heads, dh = self.heads, d // self.heads
        mask = mask | ~mask.any(dim=0, keepdim=True)  # a set with nobody in it (never learned from): defined
        if k == 2:
            (q0, k0, v0), (q1, k1, v1) = ((x.reshape(s, heads, dh) for x in p.split(d, dim=-1)) for p in qkv)
            attended = list(PairAttention.apply(q0, q1, k0, k1, v0, v1, mask))
        else:
            q, key, v = (x.reshape(k, s, heads, dh) for x in torch.stack(qkv).split(d, dim=-1))
            if k <= SMALL_SETS:
                both = FewTokenAttention.apply(q, key, v, mask)
            else:  # (sets, heads, queries, keys)
                scores = q.permute(1, 2, 0, 3) @ key.permute(1, 2, 3, 0) / math.sqrt(dh)
                scores = scores.masked_fill(~mask.t()[:, None, None, :], float("-inf"))
                both = (scores.softmax(dim=-1) @ v.permute(1, 2, 0, 3)).permute(2, 0, 1, 3)
            attended = list(both.unbind(0))
        m = mask.unsqueeze(-1).to(tokens[0].dtype)
        pooled = sum(self.norm(x + self.attention.out_proj(a.reshape(s, d))) * m[j]
                     for j, (x, a) in enumerate(zip(tokens, attended, strict=True)))
        return self.head(pooled / m.sum(dim=0)).squeeze(-1)

    def values_and_baselines(self, obs: torch.Tensor, actions: torch.Tensor | None, present: torch.Tensor,
                             state: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor | None]:
        """V(s) of each game step (``obs`` (steps, seats, width) of the agents, ``present`` (steps, seats), ``state``
        (steps, width) or None) and, given ``actions`` (steps, seats, width), every seat's baseline Q_i(s, a_{-i})
        (steps, seats), in one pass: each token (every step's observation tokens, observation-action tokens and
        state token) embedded and projected once, and the value's set and each seat's baseline set read from them
        whole (no gather by row, no copy of a set)."""
        n_seats = self.n_seats
        own = F.relu(self.obs_token(self._seated(obs)))  # (steps, seats, width)
        own_x, own_p = own.unbind(1), self._project(own).unbind(1)
        places = list(range(n_seats))
        sets = [([own_x[j] for j in places], [own_p[j] for j in places], present.t())]  # V's
        if actions is not None:
            others = F.relu(self.obs_action_token(self._seated(torch.cat((obs, actions), dim=-1))))
            oth_x, oth_p = others.unbind(1), self._project(others).unbind(1)
            for i in places:  # seat i's baseline: its own observation token, the others' observation-action tokens
                sets.append(([own_x[j] if j == i else oth_x[j] for j in places],
                             [own_p[j] if j == i else oth_p[j] for j in places],
                             (present | (torch.arange(n_seats, device=obs.device) == i)).t()))
        if self.state_token is not None and state is not None:  # the state's token, in every set
            s = F.relu(self.state_token(state))
            s_p = self._project(s)
            sets = [(x + [s], p + [s_p], torch.cat((m, torch.ones_like(m[:1])))) for x, p, m in sets]
        out = [self._attend(x, p, m) for x, p, m in sets]
        return out[0], (torch.stack(out[1:], dim=1) if actions is not None else None)

    def value(self, obs: torch.Tensor, present: torch.Tensor, state: torch.Tensor | None) -> torch.Tensor:
        """V(s) of each row: the present agents' observations (rows, seats, width), ``present`` (rows, seats)."""
        return self.values_and_baselines(obs, None, present, state)[0]

    def baseline(self, obs: torch.Tensor, actions: torch.Tensor, present: torch.Tensor, seat: torch.Tensor,
                 state: torch.Tensor | None) -> torch.Tensor:
        """Q_i(s, a_{-i}) of each row for agent ``seat`` (rows,): its own observation, the others' with their
        actions."""
        q = self.values_and_baselines(obs, actions, present, state)[1]
        assert q is not None
        return q.gather(1, seat[:, None]).squeeze(1)


TEAM_KEYS = ("team_obs", "present", "team_actions", "team_state")


class POCALearner(MAPPOLearner):
    """MAPPO's actor over ``n_slots`` slots with MA-POCA's critic and advantages (see the module docstring)."""

    name = "poca"
    config_class = POCAConfig
    centralised = True

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        return action_head("MA-POCA", seat.action)

    def __init__(self, seat: SeatSpace, n_slots: int, config: Any = None, *, seed: int = 0,
                 device: str | torch.device = "cpu", team: Any = None) -> None:
        super().__init__(seat, n_slots, config, seed=seed, device=device, team=team)
        # draws the critic's minibatches of game steps (the actors' come from the learner's generator, as PPO's)
        self.critic_gen = torch.Generator(device=self.device).manual_seed(seed + 7_919)
        self._critic: dict[str, Any] | None = None  # the rollout's rows for the critic's loss (_batch)

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

    def _games(self, after: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The games of the rollout: each slot's game (slots,) and one slot of each game (games,). Slots whose
        team rows (views, actions, rewards, ends, bootstraps and the view after the rollout) are byte for byte the
        same are one game: the seats of a game, which the critic values once."""
        buf, b = self.team_buf, self.n_slots
        parts = [buf[k].transpose(0, 1).reshape(b, -1).float() for k in (*TEAM_KEYS, "team_reward", "team_done",
                                                                           "team_boot") if k in buf]
        parts += [v.reshape(b, -1).float() for _, v in sorted(after.items())]
        rows = np.ascontiguousarray(torch.cat(parts, dim=1).cpu().numpy())
        keys = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel()
        _, first, game = np.unique(keys, return_index=True, return_inverse=True)
        return (torch.as_tensor(game.reshape(-1), device=self.device),
                torch.as_tensor(first, device=self.device))

    def _critic_pass(self, team: dict[str, torch.Tensor],
                     rows: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """V (steps,) and every seat's baseline (steps, seats) of the game steps ``rows`` of ``team`` (flat tensors;
        None: all), with gradients."""
        x = {k: (v if rows is None else v.index_select(0, rows)) for k, v in team.items()}
        v, q = self.critic.values_and_baselines(x["team_obs"], x["team_actions"], x["present"], x.get("team_state"))
        assert q is not None
        return v, q

    @torch.no_grad()
    def _batch(self, next_obs: np.ndarray) -> dict[str, Any]:
        """The decisions of the rollout (the steps each slot's agent acted on), with the team's lambda-returns and
        each decision's advantage over its agent's baseline; and the critic's rows (its game steps, each with the
        decisions taken on it, seat by seat)."""
        cfg, buf, dev = self.cfg, self.team_buf, self.device
        t, b, n_seats = cfg.rollout_steps, self.n_slots, self.team.n_seats
        if self._after is None:
            raise RuntimeError("update() before the team's view of the last step (see_team)")
        after = self._tensors(self._after)
        game, first = self._games(after)
        n_games = len(first)
        acted = (self.acting if self.acting is not None
                 else torch.ones((t, b), dtype=torch.bool, device=dev)).float()
        # decisions on each game step, seat by seat (a slot is a seat of a game)
        decided = torch.zeros((t, n_games * n_seats), device=dev).index_add_(1, game * n_seats + self.seats, acted)
        decided = decided.view(t * n_games, n_seats)
        team = {k: buf[k].index_select(1, first).reshape(t * n_games, *buf[k].shape[2:])
                for k in TEAM_KEYS if k in buf}
        values = torch.empty(t * n_games, device=dev)
        baselines = torch.empty((t * n_games, n_seats), device=dev)
        span = max(1, CHUNK // n_games) * n_games  # game steps a pass
        for s0 in range(0, t * n_games, span):
            rows = torch.arange(s0, min(t * n_games, s0 + span), device=dev)
            values[rows], baselines[rows] = self._critic_pass(team, rows)
        values = values.view(t, n_games)
        next_value = self._team_values({k: v.index_select(0, first) for k, v in after.items()})
        next_values = torch.cat((values[1:], next_value[None]))
        reward, done, boot = (buf[k].index_select(1, first) for k in ("team_reward", "team_done", "team_boot"))
        live = 1.0 - done
        deltas = reward + cfg.gamma * (next_values * live + boot) - values
        adv = torch.zeros_like(deltas)
        last = torch.zeros(n_games, device=dev)
        for k in reversed(range(t)):
            last = deltas[k] + cfg.gamma * cfg.gae_lambda * live[k] * last
            adv[k] = last
        returns = adv + values
        # the critic's rows: the game steps decided on
        weight = decided.sum(1)
        used = weight.nonzero().squeeze(-1)
        idx = acted.reshape(-1).nonzero().squeeze(-1)
        n = len(idx)
        self._critic = {"team": {k: v.index_select(0, used) for k, v in team.items()}, "v_weight": weight[used],
                        "q_weight": decided[used], "return": returns.reshape(-1)[used], "order": [],
                        "per_epoch": -(-n // max(1, n // cfg.minibatches)) if n else 1}  # the actors' minibatches
        # each decision: its game step's return and value, its seat's baseline there
        steps = torch.arange(t, device=dev)[:, None]
        at = (steps * n_games + game[None]).reshape(-1)  # each (step, slot)'s game step
        slot_return = returns.reshape(-1)[at]
        slot_baseline = baselines[at, self.seats.repeat(t)]
        out = {"obs": self.obs.reshape(t * b, -1), "actions": self.actions.reshape(t * b, *self.actions.shape[2:]),
               "logprobs": self.logprobs.reshape(-1), "values": values.reshape(-1)[at], "returns": slot_return,
               "adv": slot_return - slot_baseline,
               "masks": None if self.masks is None else self.masks.reshape(t * b, -1)}
        return {k: None if v is None else v.index_select(0, idx) for k, v in out.items()}

    def _critic_rows(self) -> torch.Tensor:
        """The next minibatch of the critic's game steps: each pass over them (an epoch: as many minibatches as
        the actors') in an order of the critic's generator."""
        c = self._critic
        assert c is not None
        if not c["order"]:
            perm = torch.randperm(len(c["v_weight"]), generator=self.critic_gen, device=self.device)
            c["order"] = list(torch.tensor_split(perm, c["per_epoch"]))[::-1]
        return c["order"].pop()

    def _forward(self, batch: dict[str, Any], idx: torch.Tensor) -> tuple[torch.Tensor, Any]:
        logits, _ = self.net(batch["obs"].index_select(0, idx))
        return logits, None

    def _value_loss(self, value: Any, batch: dict[str, Any], idx: torch.Tensor) -> torch.Tensor:
        """Both the team's value and the agents' baselines regress on the team's return: 0.5 ((V - G)^2 +
        (Q_i - G)^2) averaged over the decisions, on the critic's own minibatch of game steps (each V weighted by
        the decisions taken on its step, each Q_i by its seat's there)."""
        c = self._critic
        assert c is not None
        rows = self._critic_rows()
        if rows.numel() == 0:
            return torch.zeros((), device=self.device)
        v, q = self._critic_pass(c["team"], rows)
        w, g = c["v_weight"][rows], c["return"][rows]
        v_err = (w * (v - g).square()).sum()
        q_err = (c["q_weight"][rows] * (q - g[:, None]).square()).sum()
        return 0.5 * (v_err + q_err) / w.sum()

    def _value_rollout(self) -> None:
        """Nothing: the critic values the rollout in :meth:`_batch`."""

    def state_dict(self) -> dict[str, Any]:
        """MAPPO's and the critic's minibatch generator."""
        return {**super().state_dict(), "critic_gen": self.critic_gen.get_state()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        if "critic_gen" in state:  # (a state saved before the critic had minibatches of its own: a fresh one)
            self.critic_gen.set_state(state["critic_gen"])
        self._critic = None
