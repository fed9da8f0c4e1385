"""PPO (clipped objective, GAE) for a learner that drives some slots of the batched self-play games.

Reads top to bottom as CleanRL's ppo.py does: the hyperparameters with their meaning, the rollout buffer, the
advantage estimate, the update. The learner does not own the games: the trainer steps the shared
:class:`~selfplay_cli.arena.selfplay.SelfPlayGames` and hands each learner its slots' observations, rewards and
dones, so two learners (one network per paddle) and one shared network use the same code.

Per update: ``rollout_steps`` steps of every slot are collected with the current policy (sampling), advantages
come from GAE(lambda) over the rollout, and ``update_epochs`` passes of ``minibatches`` minibatches optimise
    L = -min(r A, clip(r, 1 - eps, 1 + eps) A) + vf_coef * (V - R)^2 / 2 - ent_coef * H
with r the probability ratio of the new to the old policy. A game that ends (won, lost or truncated) is a
done: the value after it is not bootstrapped.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch

from ..policies.network import Arch, MLPNet, NetworkPolicy, build_network
from . import FlatAdam


@dataclass
class PPOConfig:
    rollout_steps: int = 128  # steps of every slot per update (CleanRL: num_steps)
    lr: float = 2e-3  # Adam learning rate (measured on pong; CleanRL's Atari value is 2.5e-4)
    anneal_lr: bool = True  # decay the learning rate linearly to 0 over the run
    gamma: float = 0.99  # discount
    gae_lambda: float = 0.95  # GAE lambda
    minibatches: int = 4  # minibatches per epoch
    update_epochs: int = 4  # passes over each rollout
    clip_coef: float = 0.2  # PPO clip epsilon
    norm_adv: bool = True  # normalise advantages per minibatch
    ent_coef: float = 0.01  # entropy bonus
    vf_coef: float = 0.5  # value loss weight
    max_grad_norm: float = 0.5  # gradient clipping
    arch: Arch = field(default_factory=lambda: Arch(hidden=(64, 64), activation="relu", value_head=True))

    def __post_init__(self) -> None:
        if isinstance(self.arch, dict):
            self.arch = Arch.from_dict(self.arch)
        for name in ("rollout_steps", "minibatches", "update_epochs"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")
        if not (0 < self.gamma <= 1 and 0 <= self.gae_lambda <= 1 and self.lr > 0 and self.clip_coef > 0):
            raise ValueError("gamma, gae_lambda, lr or clip_coef out of range")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["arch"] = self.arch.to_dict()
        return d


class PPOLearner:
    """One network, its optimiser and its rollout buffer over ``n_slots`` slots of the games."""

    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, n_slots: int, config: PPOConfig | None = None,
                 seed: int = 0, device: str | torch.device = "cpu") -> None:
        self.cfg = cfg = config or PPOConfig()
        self.device = torch.device(device)
        self.obs_shape = tuple(obs_shape)
        self.n_actions = n_actions
        self.n_slots = n_slots
        self.net: MLPNet = build_network(self.obs_shape, n_actions, cfg.arch, seed=seed).to(self.device)
        self.opt = FlatAdam(self.net.parameters(), lr=cfg.lr, eps=1e-5, max_grad_norm=cfg.max_grad_norm)
        self.gen = torch.Generator(device=self.device).manual_seed(seed)
        t, b, d = cfg.rollout_steps, n_slots, int(np.prod(self.obs_shape))
        self.obs = torch.zeros((t, b, d), device=self.device)
        self.actions = torch.zeros((t, b), dtype=torch.long, device=self.device)
        self.logprobs = torch.zeros((t, b), device=self.device)
        self.values = torch.zeros((t, b), device=self.device)
        self.rewards = torch.zeros((t, b), device=self.device)
        self.dones = torch.zeros((t, b), device=self.device)  # the game ended after this step
        # On the CPU, numpy views of the buffers: a step's arrays go in with one numpy copy, no tensor made.
        self._np = ({"obs": self.obs.numpy(), "rewards": self.rewards.numpy(), "dones": self.dones.numpy()}
                    if self.device.type == "cpu" else None)
        self.t = 0
        self.updates = 0

    # -- acting ---------------------------------------------------------------------------------------------
    def _tensor(self, obs: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.asarray(obs, dtype=np.float32), device=self.device).reshape(len(obs), -1)

    @torch.inference_mode()
    def act(self, obs: np.ndarray) -> np.ndarray:
        """Sample actions for this step's observations and remember what the update needs.

        Sampling is the inverse-CDF draw ``a = #{k : cdf_k <= u}`` with one uniform ``u`` per slot from the
        learner's generator (multinomial does the same draw several times slower on small batches); the count is a
        binary search in each row's cdf, written straight into the rollout buffer."""
        t = self.t
        x = self.obs[t]
        if self._np is not None:
            self._np["obs"][t] = obs.reshape(len(obs), -1)
        else:
            x.copy_(self._tensor(obs))
        logits, value = self.net(x)
        logp_all = torch.log_softmax(logits, dim=-1)
        u = torch.rand((x.shape[0], 1), generator=self.gen, device=self.device)
        cdf = logp_all.exp().cumsum_(dim=1)
        action = self.actions[t, :, None]
        torch.searchsorted(cdf, u, right=True, out=action).clamp_(max=self.n_actions - 1)
        torch.gather(logp_all, 1, action, out=self.logprobs[t, :, None])
        self.values[t] = value
        return self.actions[t].numpy().copy() if self.device.type == "cpu" else self.actions[t].cpu().numpy()

    def record(self, rewards: np.ndarray, dones: np.ndarray) -> bool:
        """Store this step's outcome; True when the rollout is full and :meth:`update` is due."""
        if self._np is not None:
            self._np["rewards"][self.t] = rewards
            self._np["dones"][self.t] = dones
        else:
            self.rewards[self.t] = torch.as_tensor(rewards, dtype=torch.float32, device=self.device)
            self.dones[self.t] = torch.as_tensor(dones, dtype=torch.float32, device=self.device)
        self.t += 1
        return self.t == self.cfg.rollout_steps

    # -- learning -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def _advantages(self, next_obs: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """GAE(lambda): A_t = delta_t + gamma * lambda * (1 - done_t) * A_{t+1},
        delta_t = r_t + gamma * (1 - done_t) * V(s_{t+1}) - V(s_t)."""
        cfg = self.cfg
        _, next_value = self.net(self._tensor(next_obs))
        next_values = torch.cat((self.values[1:], next_value[None]))  # V(s_{t+1}) for every t
        live = 1.0 - self.dones
        deltas = self.rewards + cfg.gamma * next_values * live - self.values  # all steps at once; only A is a recursion
        carry = cfg.gamma * cfg.gae_lambda * live
        adv = torch.zeros_like(self.rewards)
        last = torch.zeros(self.n_slots, device=self.device)
        for t in reversed(range(cfg.rollout_steps)):
            last = deltas[t] + carry[t] * last
            adv[t] = last
        return adv, adv + self.values

    def update(self, next_obs: np.ndarray, progress: float = 0.0) -> dict[str, float]:
        """One PPO update on the full rollout; ``progress`` in [0, 1] anneals the learning rate."""
        cfg = self.cfg
        if self.t != cfg.rollout_steps:
            raise RuntimeError("update() before the rollout is full")
        if cfg.anneal_lr:
            self.opt.lr = cfg.lr * max(0.0, 1.0 - progress)
        adv, returns = self._advantages(next_obs)
        b_obs = self.obs.reshape(-1, self.obs.shape[-1])
        b_act, b_logp = self.actions.reshape(-1), self.logprobs.reshape(-1)
        b_adv, b_ret, b_val = adv.reshape(-1), returns.reshape(-1), self.values.reshape(-1)
        n = b_obs.shape[0]
        mb = max(1, n // cfg.minibatches)
        stats = torch.zeros(5, device=self.device)  # policy loss, value loss, entropy, approx KL, clip fraction
        count = 0
        for _ in range(cfg.update_epochs):
            order = torch.randperm(n, generator=self.gen, device=self.device)
            for start in range(0, n, mb):
                idx = order[start:start + mb]
                logits, value = self.net(b_obs.index_select(0, idx))
                logp_all = torch.log_softmax(logits, dim=-1)
                logp = logp_all.gather(1, b_act.index_select(0, idx)[:, None]).squeeze(1)
                entropy = -(logp_all.exp() * logp_all).sum(-1).mean()
                log_ratio = logp - b_logp.index_select(0, idx)
                ratio = log_ratio.exp()
                a = b_adv.index_select(0, idx)
                if cfg.norm_adv and a.numel() > 1:
                    a = (a - a.mean()) / (a.std() + 1e-8)
                pg_loss = torch.max(-a * ratio, -a * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)).mean()
                v_loss = 0.5 * (value - b_ret.index_select(0, idx)).square().mean()
                loss = pg_loss + cfg.vf_coef * v_loss - cfg.ent_coef * entropy
                self.opt.zero_grad()
                loss.backward()
                self.opt.step()  # clips the gradient norm to max_grad_norm first
                with torch.no_grad():
                    stats += torch.stack((pg_loss, v_loss, entropy, (ratio - 1 - log_ratio).mean(),
                                          ((ratio - 1).abs() > cfg.clip_coef).float().mean()))
                count += 1
        self.t = 0
        self.updates += 1
        names = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac")
        out = {k: float(v) / count for k, v in zip(names, stats.tolist(), strict=True)}
        out["explained_variance"] = float(1 - torch.var(b_ret - b_val) / (torch.var(b_ret) + 1e-8))
        out["lr"] = self.opt.lr
        return out

    # -- playing and saving ---------------------------------------------------------------------------------
    def policy(self, id: str, env: str, greedy: bool = False) -> NetworkPolicy:
        """The live network as a policy (no copy): e.g. the 'self' opponent, or for evaluation games."""
        return NetworkPolicy(self.net, id, env, device=self.device, greedy=greedy)

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume: weights, optimiser, sampling generator, update count."""
        return {"net": self.net.state_dict(), "opt": self.opt.state_dict(), "gen": self.gen.get_state(),
                "updates": self.updates}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        self.gen.set_state(state["gen"])
        self.updates = int(state["updates"])
