"""DQN (double DQN, Huber loss, target network, epsilon-greedy) for a learner that drives some slots of the games.

Reads top to bottom as CleanRL's dqn.py does: the hyperparameters with their meaning, the epsilon schedule, the
replay buffer, the TD target, the learner. Same interface as :class:`~selfplay_cli.algos.ppo.PPOLearner`, so one
trainer loop drives both::

    obs = games.observe()
    while ...:
        rewards, dones, _ = games.step([learner.act(obs)])
        obs = games.observe()
        if learner.record(rewards, dones):
            learner.update(obs, progress)

Units. A *transition* is one step of one slot (one game seat). A *learner step* is one ``act`` call, i.e.
``n_slots`` transitions. Everything that counts experience counts transitions (``buffer_size``,
``learning_starts``, the epsilon schedules), so a config means the same with 1 game or 256; ``target_period``
counts gradient updates. With one game per learner, as in seed 000, a transition is an env step.

Per transition collected, ``replay_ratio`` gradient updates are due (fractions carry over: 1/32 with 128
slots is 4 updates per learner step, with 1 slot one update every 32 steps). Each update samples ``batch_size``
transitions uniformly and minimises ``loss(Q(s, a), y)`` (Huber or MSE) with, for n-step returns
(``n_step`` = n; n = 1 is classic DQN) R = r_t + gamma r_{t+1} + ... + gamma^(n-1) r_{t+n-1} and s' = s_{t+n},
    y = R + gamma^n * (1 - done) * Q_target(s', argmax_a' Q(s', a'))     (double DQN)
    y = R + gamma^n * (1 - done) * max_a' Q_target(s', a')               (plain DQN, seed 000)
Every ``target_period`` updates the target moves to ``tau * online + (1 - tau) * target`` (tau = 1: a copy).
A game that ends (won, lost or truncated) is a done: the value after it is not bootstrapped, and an n-step
return stops at it (the learner sees only dones, so a truncation counts as an end, as in PPO).

Auto-reset. The games restart a finished game at once, so the observation that follows a done is the *next*
game's first, and that is what lands in ``next_obs`` of a transition whose steps include a done. It is
harmless: with done = 1 the target ignores ``next_obs``. Transitions are completed lazily: ``act(obs)``
remembers (obs, actions), ``record`` stashes (rewards, dones), and the next observation (given to ``update`` or
the next ``act``) closes them and pushes the whole batch of slots into the ring buffer in one vectorised write.

Resume. :meth:`DQNLearner.state_dict` holds the online and target networks, the optimiser, the random generator
and the counters, but not the replay buffer (up to ~40 MB per learner; most DQN implementations do the same).
After a resume the buffer refills: gradient updates wait until it holds ``learning_starts`` transitions again,
while epsilon carries on from the restored transition count.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from ..policies.network import Arch, MLPNet, NetworkPolicy, build_network
from . import FlatAdam, flatten

EPS_SCHEDULES = ("linear", "exponential")
LOSSES = ("huber", "mse")


@dataclass
class DQNConfig:
    buffer_size: int = 100_000  # replay capacity in transitions; the oldest are overwritten
    batch_size: int = 512  # transitions per gradient update (512 costs ~1.15x a 256 batch here: fewer, larger steps)
    lr: float = 2.5e-4  # Adam learning rate
    gamma: float = 0.99  # discount
    n_step: int = 3  # n-step returns: bootstrap from the state n steps later (1: classic DQN, seed 000)
    replay_ratio: float = 1 / 32  # gradient updates per transition (CleanRL: 1 / train_frequency); each is seen ~16x
    target_period: int = 125  # gradient updates between target-network updates (every 4,000 transitions)
    tau: float = 1.0  # target update: 1 copies the online net (hard update), < 1 is Polyak averaging
    learning_starts: int = 5_000  # updates start once the buffer holds this many transitions (and refilled)
    eps_schedule: str = "linear"  # "linear" (CleanRL) or "exponential" (seed 000)
    eps_start: float = 1.0  # epsilon at transition 0
    eps_end: float = 0.05  # final epsilon (the floor of the exponential schedule)
    eps_decay_steps: int = 100_000  # linear: transitions over which epsilon goes from eps_start to eps_end
    eps_decay: float = 0.995  # exponential: epsilon = max(eps_end, eps_start * eps_decay ** transitions)
    double_dqn: bool = True  # choose the next action with the online net, value it with the target net
    loss: str = "huber"  # "huber" (smooth L1) or "mse" (seed 000)
    max_grad_norm: float = 10.0  # gradient clipping; 0 turns it off
    arch: Arch = field(default_factory=lambda: Arch(hidden=(64, 64), activation="relu", value_head=False))

    def __post_init__(self) -> None:
        if isinstance(self.arch, dict):
            self.arch = Arch.from_dict(self.arch)
        for name in ("buffer_size", "batch_size", "target_period", "n_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")
        if self.learning_starts < 0 or self.eps_decay_steps < 0 or self.max_grad_norm < 0:
            raise ValueError("learning_starts, eps_decay_steps and max_grad_norm must not be negative")
        if not (0 < self.gamma <= 1 and self.lr > 0 and 0 < self.tau <= 1 and self.replay_ratio > 0):
            raise ValueError("gamma, lr, tau or replay_ratio out of range")
        if not (0 <= self.eps_end <= 1 and 0 <= self.eps_start <= 1 and 0 < self.eps_decay <= 1):
            raise ValueError("eps_start, eps_end or eps_decay out of range")
        if self.eps_schedule not in EPS_SCHEDULES:
            raise ValueError(f"eps_schedule must be one of {', '.join(EPS_SCHEDULES)}, not {self.eps_schedule!r}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {', '.join(LOSSES)}, not {self.loss!r}")
        if self.arch.value_head:
            raise ValueError("a DQN network has no value head (arch value_head must be false)")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["arch"] = self.arch.to_dict()
        return d


def seed000_config() -> DQNConfig:
    """Seed 000's DQN exactly (``--preset seed000``): its network, optimiser, buffer and schedules.

    The seed trains once per env step (replay ratio 1), copies the target every 250 steps (= 250 updates),
    starts at step 2000, and decays epsilon by x0.995 per step to 0.25, which reaches the floor after 277
    steps, long before learning starts. Plain (not double) DQN, MSE loss, no gradient clipping. It is slow
    with many games: one gradient update per transition.
    """
    return DQNConfig(
        buffer_size=100_000, batch_size=64, lr=1e-3, gamma=0.99, n_step=1, replay_ratio=1.0, target_period=250, tau=1.0,
        learning_starts=2000, eps_schedule="exponential", eps_start=1.0, eps_end=0.25, eps_decay=0.995,
        double_dqn=False, loss="mse", max_grad_norm=0.0,
        arch=Arch(hidden=(512, 512, 256, 128, 64), activation="relu", value_head=False),
    )


def epsilon_at(cfg: DQNConfig, transitions: int) -> float:
    """The exploration rate after ``transitions`` transitions (see the config fields)."""
    if cfg.eps_schedule == "exponential":
        return max(cfg.eps_end, cfg.eps_start * cfg.eps_decay ** transitions)
    if cfg.eps_decay_steps == 0:
        return cfg.eps_end
    frac = min(1.0, transitions / cfg.eps_decay_steps)
    return cfg.eps_start + frac * (cfg.eps_end - cfg.eps_start)


class ReplayBuffer:
    """A ring of preallocated numpy arrays: obs and next_obs (float32, flattened), actions, rewards, dones.

    ``add`` writes a whole batch of slots at once; once full, each write overwrites the oldest entries, so the
    buffer always holds the newest ``capacity`` transitions. ``sample`` draws uniformly (with replacement)
    from the filled entries with the caller's generator.
    """

    def __init__(self, capacity: int, obs_dim: int) -> None:
        self.capacity = int(capacity)
        self.obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.dones = np.zeros(capacity, dtype=np.float32)
        self.pos = 0  # next entry to write
        self.size = 0  # filled entries

    def __len__(self) -> int:
        return self.size

    def add(self, obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray, next_obs: np.ndarray,
            dones: np.ndarray) -> None:
        n = len(actions)
        if n > self.capacity:  # only the newest fit
            obs, actions, rewards, next_obs, dones = (x[n - self.capacity:] for x in
                                                      (obs, actions, rewards, next_obs, dones))
            n = self.capacity
        end = self.pos + n
        if end <= self.capacity:  # one contiguous write (the common case)
            at: slice | np.ndarray = slice(self.pos, end)
        else:
            at = np.arange(self.pos, end) % self.capacity
        self.obs[at] = obs
        self.next_obs[at] = next_obs
        self.actions[at] = actions
        self.rewards[at] = rewards
        self.dones[at] = dones
        self.pos = end % self.capacity
        self.size = min(self.size + n, self.capacity)

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> dict[str, np.ndarray]:
        """``size`` transitions drawn uniformly from the filled entries; ``(k, batch)`` draws k batches at once."""
        if self.size == 0:
            raise RuntimeError("cannot sample from an empty replay buffer")
        idx = rng.integers(0, self.size, size=size)
        return {"obs": self.obs[idx], "actions": self.actions[idx], "rewards": self.rewards[idx],
                "next_obs": self.next_obs[idx], "dones": self.dones[idx]}


class DQNLearner:
    """An online Q-network, its target copy, its optimiser and its replay buffer over ``n_slots`` slots."""

    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, n_slots: int, config: DQNConfig | None = None,
                 seed: int = 0, device: str | torch.device = "cpu") -> None:
        self.cfg = cfg = config or DQNConfig()
        self.device = torch.device(device)
        self.obs_shape = tuple(obs_shape)
        self.n_actions = n_actions
        self.n_slots = n_slots
        self.obs_dim = int(np.prod(self.obs_shape))
        self.net: MLPNet = build_network(self.obs_shape, n_actions, cfg.arch, seed=seed).to(self.device)
        self.target: MLPNet = copy.deepcopy(self.net).requires_grad_(False)
        self.opt = FlatAdam(self.net.parameters(), cfg.lr, max_grad_norm=cfg.max_grad_norm)
        self.target_flat = flatten(self.target.parameters())  # the target update is one operation on it
        self.rng = np.random.default_rng(seed)  # exploration and replay sampling
        self.buffer = ReplayBuffer(cfg.buffer_size, self.obs_dim)
        self.transitions = 0  # collected so far (drives epsilon)
        self.grad_steps = 0  # gradient updates so far (drives the target updates)
        self.updates = 0  # update() calls that made at least one gradient update
        self.credit = 0.0  # gradient updates due but not yet made (replay_ratio per transition)
        # The step in flight: obs and actions from act(), rewards and dones from record().
        self._obs: np.ndarray | None = None
        self._actions: np.ndarray | None = None
        self._rewards: np.ndarray | None = None
        self._dones: np.ndarray | None = None
        self._window: list[tuple[np.ndarray, ...]] = []  # the last n_step - 1 completed steps (n-step returns)

    # -- acting ---------------------------------------------------------------------------------------------
    @property
    def epsilon(self) -> float:
        return epsilon_at(self.cfg, self.transitions)

    def _flat(self, obs: np.ndarray) -> np.ndarray:
        """Our own flat float32 copy (the n-step window keeps it, so the caller may reuse its array)."""
        return np.array(obs, dtype=np.float32, order="C").reshape(len(obs), self.obs_dim)

    def _push(self, next_obs: np.ndarray) -> None:
        """Close the step in flight with the observations that followed it; store the transitions it completes.

        With ``n_step`` > 1 the last n steps of every slot wait in a window; the oldest becomes the transition
        (s_t, a_t, R, s_{t+n}, done) with R = r_t + gamma r_{t+1} + ... cut after the first done in the window.
        """
        if self._obs is None or self._rewards is None:
            return
        self._window.append((self._obs, self._actions, self._rewards, self._dones))
        self._obs = self._actions = self._rewards = self._dones = None
        if len(self._window) < self.cfg.n_step:
            return
        obs, actions, ret, done = self._window.pop(0)
        ret, done = ret.copy(), done.copy()
        discount = 1.0
        for _, _, r, d in self._window:  # later steps count until the slot's game ends
            discount *= self.cfg.gamma
            ret += discount * (1.0 - done) * r
            np.maximum(done, d, out=done)
        self.buffer.add(obs, actions, ret, next_obs, done)

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        """Epsilon-greedy actions for this step's observations (which also complete the previous step)."""
        x = self._flat(obs)
        self._push(x)
        n = len(x)
        eps = self.epsilon
        explore = self.rng.random(n) < eps
        actions = self.rng.integers(0, self.n_actions, size=n)
        if not explore.all():
            q, _ = self.net(torch.from_numpy(x).to(self.device))
            greedy = q.argmax(dim=1).cpu().numpy()
            actions = np.where(explore, actions, greedy)
        if self._obs is not None:  # an earlier step left without record() is dropped, and breaks the window
            self._window.clear()
        self._obs, self._actions = x, actions
        return actions

    def record(self, rewards: np.ndarray, dones: np.ndarray) -> bool:
        """Stash this step's outcome; True when gradient updates are due (call :meth:`update`)."""
        if self._obs is None:
            raise RuntimeError("record() without act()")
        self._rewards = np.asarray(rewards, dtype=np.float32).reshape(-1)
        self._dones = np.asarray(dones, dtype=np.float32).reshape(-1)
        n = len(self._rewards)
        self.transitions += n
        if len(self.buffer) + n >= self.cfg.learning_starts:  # counting the step being recorded
            self.credit += self.cfg.replay_ratio * n
        return self.credit >= 1.0

    # -- learning -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def td_target(self, rewards: torch.Tensor, dones: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
        """y = r + gamma^n * (1 - done) * Q_target(s', a'), a' the online argmax (double) or the target's (plain)."""
        q_next_target, _ = self.target(next_obs)
        if self.cfg.double_dqn:
            q_next_online, _ = self.net(next_obs)
            best = q_next_online.argmax(dim=1, keepdim=True)
            q_next = q_next_target.gather(1, best).squeeze(1)
        else:
            q_next = q_next_target.max(dim=1).values
        return rewards + self.cfg.gamma ** self.cfg.n_step * (1.0 - dones) * q_next

    def _sync_target(self) -> None:
        if self.cfg.tau >= 1.0:
            self.target_flat.copy_(self.opt.flat)
        else:
            self.target_flat.lerp_(self.opt.flat, self.cfg.tau)

    def update(self, next_obs: np.ndarray, progress: float = 0.0) -> dict[str, float]:
        """Make the gradient updates due (none before the buffer holds ``learning_starts`` transitions).

        ``next_obs`` (the observations after the recorded step) completes the step in flight so the updates
        see it; ``progress`` is accepted for the trainer's sake and unused (epsilon follows transitions).
        """
        cfg = self.cfg
        self._push(self._flat(next_obs))
        k = int(self.credit) if len(self.buffer) >= max(1, cfg.learning_starts) else 0
        self.credit -= k
        loss_sum, q_sum = torch.zeros((), device=self.device), torch.zeros((), device=self.device)
        if k:
            batches = self.buffer.sample(self.rng, (k, cfg.batch_size))  # all k batches in one draw
            obs, actions, rewards, next_o, dones = (torch.from_numpy(batches[key]).to(self.device) for key in
                                                    ("obs", "actions", "rewards", "next_obs", "dones"))
            loss_fn = nn.functional.smooth_l1_loss if cfg.loss == "huber" else nn.functional.mse_loss
            for i in range(k):
                y = self.td_target(rewards[i], dones[i], next_o[i])
                q_all, _ = self.net(obs[i])
                q = q_all.gather(1, actions[i, :, None]).squeeze(1)
                loss = loss_fn(q, y)
                self.opt.zero_grad()
                loss.backward()
                self.opt.step()  # clips the gradient norm to max_grad_norm first (0: no clipping)
                self.grad_steps += 1
                if self.grad_steps % cfg.target_period == 0:
                    self._sync_target()
                loss_sum += loss.detach()
                q_sum += q.detach().mean()
            self.updates += 1
        return {"loss": float(loss_sum) / k if k else float("nan"), "q_mean": float(q_sum) / k if k else float("nan"),
                "epsilon": self.epsilon, "buffer_size": float(len(self.buffer)), "grad_steps": float(k),
                "lr": self.opt.lr}

    # -- playing and saving ---------------------------------------------------------------------------------
    def policy(self, id: str, env: str, greedy: bool = True) -> NetworkPolicy:
        """The live online network as a policy (no copy). Greedy is argmax Q (the DQN policy); non-greedy
        samples from softmax(Q), a Boltzmann policy, not epsilon-greedy."""
        return NetworkPolicy(self.net, id, env, device=self.device, greedy=greedy)

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume except the replay buffer (see the module docstring)."""
        return {"net": self.net.state_dict(), "target": self.target.state_dict(), "opt": self.opt.state_dict(),
                "rng": self.rng.bit_generator.state, "transitions": self.transitions,
                "grad_steps": self.grad_steps, "updates": self.updates, "credit": self.credit}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.target.load_state_dict(state["target"])
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
        self.transitions = int(state["transitions"])
        self.grad_steps = int(state["grad_steps"])
        self.updates = int(state["updates"])
        self.credit = float(state["credit"])
        self._obs = self._actions = self._rewards = self._dones = None
        self._window.clear()
