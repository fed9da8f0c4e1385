"""DQN (double DQN, Huber loss, target network, epsilon-greedy) for a learner that drives some slots of the games.

Reads top to bottom as CleanRL's dqn.py does: the hyperparameters with their meaning, the epsilon schedule, the TD
target, the learner (its replay buffer and n-step returns: :mod:`selfplay_cli.algos.replay`). Same interface as
:class:`~selfplay_cli.algos.ppo.PPOLearner`, so one trainer loop drives both::

    obs = games.observe()
    while ...:
        rewards, dones, _ = games.step([learner.act(obs)])
        obs = games.observe()
        if learner.record(rewards, dones):
            learner.update(obs, progress)

Units. A *transition* is one step of one slot (one game seat). A *learner step* is one ``act`` call, i.e.
``n_slots`` transitions. Everything that counts experience counts transitions (``buffer_size``,
``learning_starts``, the epsilon schedules), so a config means the same with 1 game or 256; ``target_period``
counts gradient updates. With one game per learner a transition is an env step.

Per transition collected, ``replay_ratio`` gradient updates are due (fractions carry over: 1/32 with 128
slots is 4 updates per learner step, with 1 slot one update every 32 steps). Each update samples ``batch_size``
transitions uniformly and minimises ``loss(Q(s, a), y)`` (Huber or MSE) with, for n-step returns
(``n_step`` = n; n = 1 is classic DQN) R = r_t + gamma r_{t+1} + ... + gamma^(n-1) r_{t+n-1} and s' = s_{t+n},
    y = R + gamma^n * (1 - done) * Q_target(s', argmax_a' Q(s', a'))     (double DQN)
    y = R + gamma^n * (1 - done) * max_a' Q_target(s', a')               (plain DQN)
Every ``target_period`` updates the target moves to ``tau * online + (1 - tau) * target`` (tau = 1: a copy).
A game that ends (won or lost) is a done: the value after it is not bootstrapped, and an n-step return stops at
it. A game cut short by a time limit (``truncated``, with its final observation) ends the return there too but
bootstraps from the final observation: s' is that observation and the discount gamma^k, k the steps up to it
(``bootstrap_truncated``; off, a truncation counts as an end).

Actions. DQN plays Discrete actions only (any other action space is refused, naming it: use PPO). With action
masks, exploration is uniform over the allowed actions, the greedy action the best allowed one, and the target's
max (or argmax) runs over the actions allowed in s': each transition keeps the mask of its s'.

Turns. In a turn-based game (``acting``) a transition runs from one of the seat's decisions to its next (or to the
end of the game), its reward the sum of the rewards in between; n-step returns chain n such decisions. A decision
waits in the learner until the seat's next one or the end of its game.

Auto-reset. The games restart a finished game at once, so the observation that follows a done is the *next*
game's first, and that is what lands in ``next_obs`` of a transition that ends its game. It is harmless: with
done = 1 the target ignores ``next_obs``. Transitions are completed lazily: ``act(obs)`` remembers (obs, actions),
``record`` stashes (rewards, dones), and the next observation (given to ``update`` or the next ``act``; with masks
only the next ``act``, which brings the mask of s') closes them and hands the whole batch of slots to the n-step
chains, whose completed transitions go into the ring buffer in one vectorised write.

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

from ..envs import SeatSpace
from ..policies.heads import MASKED
from ..policies.network import Arch, MLPNet, NetworkPolicy, build_network
from ..policies.spaces import ActionHead, uniform_allowed
from ..signals import past_deadline, stop_requested
from .base import Share, action_head, as_bool, check_steps, fix_mask, learner_args, share_draw
from .optim import FlatAdam, flatten
from .replay import NStepChains, ReplayBuffer, store_decisions

STEP_FIGURES = ("the TD loss", "the mean Q-value", "the gradient norm")  # a gradient step's figures, checked finite
EPS_SCHEDULES = ("linear", "exponential")
LOSSES = ("huber", "mse")


@dataclass
class DQNConfig:
    buffer_size: int = 100_000  # replay capacity in transitions; the oldest are overwritten
    batch_size: int = 512  # transitions per gradient update (512 costs ~1.15x a 256 batch here: fewer, larger steps)
    lr: float = 2.5e-4  # Adam learning rate
    gamma: float = 0.99  # discount
    n_step: int = 3  # n-step returns: bootstrap from the state n steps later (1: classic DQN)
    replay_ratio: float = 1 / 32  # gradient updates per transition (CleanRL: 1 / train_frequency); each is seen ~16x
    target_period: int = 125  # gradient updates between target-network updates (every 4,000 transitions)
    tau: float = 1.0  # target update: 1 copies the online net (hard update), < 1 is Polyak averaging
    learning_starts: int = 5_000  # updates start once the buffer holds this many transitions (and refilled)
    eps_schedule: str = "linear"  # "linear" (CleanRL) or "exponential" (--preset seed000)
    eps_start: float = 1.0  # epsilon at transition 0
    eps_end: float = 0.05  # final epsilon (the floor of the exponential schedule)
    eps_decay_steps: int = 100_000  # linear: transitions over which epsilon goes from eps_start to eps_end
    eps_decay: float = 0.995  # exponential: epsilon = max(eps_end, eps_start * eps_decay ** transitions)
    double_dqn: bool = True  # choose the next action with the online net, value it with the target net
    loss: str = "huber"  # "huber" (smooth L1) or "mse" (--preset seed000)
    max_grad_norm: float = 10.0  # gradient clipping; 0 turns it off
    bootstrap_truncated: bool = True  # a game cut short bootstraps from its final observation (False: an end)
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
    """The DQN of ``--preset seed000`` (where it comes from: docs/history/learners.md): a 512-512-256-128-64 MLP,
    one gradient update per transition (replay ratio 1), a target copied every 250 updates, learning from
    transition 2000, epsilon decayed by x0.995 per transition to 0.25 (the floor after 277 transitions, long before
    learning starts), plain (not double) DQN, MSE loss, no gradient clipping. It is slow with many games: one
    gradient update per transition.
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


class DQNLearner:
    """An online Q-network, its target copy, its optimiser and its replay buffer over ``n_slots`` slots.

    Built as ``DQNLearner(seat, n_slots, config, seed=0, device="cpu")`` from the seat's spaces (Discrete actions
    only: anything else is a :class:`~selfplay_cli.errors.MarlError` naming the space).
    """

    name = "dqn"
    config_class = DQNConfig
    synchronous = False  # rollout actors feed the replay with weights up to one fragment old

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        """The head for the seat's actions, or one clear :class:`MarlError` (DQN plays Discrete actions only)."""
        return action_head("DQN", seat.action, ("discrete", "Discrete"), "use --algo ppo")

    def __init__(self, seat: SeatSpace, n_slots: int, config: DQNConfig | None = None, *, seed: int = 0,
                 device: str | torch.device = "cpu") -> None:
        self.seat, n_slots, cfg = learner_args(seat, n_slots, config, DQNConfig)
        self.cfg = cfg
        self.head = self.check_seat(self.seat)
        self.device = torch.device(device)
        self.obs_shape = tuple(self.seat.observation.shape)
        self.n_actions = n_actions = self.head.nvec[0]
        self.n_slots = n_slots
        self.obs_dim = int(np.prod(self.obs_shape))
        self.net: MLPNet = build_network(self.seat.observation, self.seat.action, cfg.arch, seed=seed).to(self.device)
        self.target: MLPNet = copy.deepcopy(self.net).requires_grad_(False)
        self.opt = FlatAdam(self.net.parameters(), cfg.lr, max_grad_norm=cfg.max_grad_norm)
        self.target_flat = flatten(self.target.parameters())  # the target update is one operation on it
        self.rng = np.random.default_rng(seed)  # exploration and replay sampling
        self.share: Share | None = None  # in a rollout actor: its rows of the slots (draws stay the whole batch's)
        self.obs_dtype = np.dtype(self.seat.observation.dtype)  # an image's uint8 stays uint8 in the buffer
        self.buffer = ReplayBuffer(cfg.buffer_size, self.obs_dim, obs_dtype=self.obs_dtype)
        self.chains = NStepChains(cfg.n_step, cfg.gamma, n_slots, self.obs_dim, (), np.int64, self.obs_dtype)
        self.transitions = 0  # collected so far (drives epsilon)
        self.grad_steps = 0  # gradient updates so far (drives the target updates)
        self.updates = 0  # update() calls that made at least one gradient update
        self.cut: tuple[int, int] | None = None  # the last update, when a --minutes budget cut it: (gradient updates
        # done, due)
        self.credit = 0.0  # gradient updates due but not yet made (replay_ratio per transition)
        # The step in flight: obs, actions and mask from act(), rewards, dones and truncations from record().
        self._obs: np.ndarray | None = None
        self._actions: np.ndarray | None = None
        self._mask: np.ndarray | None = None
        self._rewards: np.ndarray | None = None
        self._dones: np.ndarray | None = None
        self._trunc: tuple[np.ndarray, np.ndarray | None, np.ndarray | None] | None = None  # (cut, final obs, mask)
        self._masked = False  # masks were given: transitions close at the next act(), which brings s' mask
        self._turns: dict[str, np.ndarray] | None = None  # turn-based games: decisions in flight (see _turn_step)
        self._held: dict[str, Any] | None = None  # turns: decisions ended by a truncation, awaiting final_obs
        del n_actions

    # -- acting ---------------------------------------------------------------------------------------------
    @property
    def epsilon(self) -> float:
        return epsilon_at(self.cfg, self.transitions)

    def _flat(self, obs: np.ndarray) -> np.ndarray:
        """Our own flat copy, in the observation's dtype (the n-step window keeps it, so the caller may reuse its
        array)."""
        return np.array(obs, dtype=self.obs_dtype, order="C").reshape(len(obs), self.obs_dim)

    def _check_final_given(self) -> None:
        if self._final_missing():
            raise ValueError("games were truncated on the last recorded step: pass their final observations "
                             "(final_obs) to record() or update()")

    def _final_missing(self) -> bool:
        return (self._trunc is not None and self._trunc[1] is None) or self._held is not None

    def _push(self, next_obs: np.ndarray, next_mask: np.ndarray | None = None) -> None:
        """Close the step in flight with the observations that followed it and store the n-step transitions it
        completes (:func:`~selfplay_cli.algos.replay.store_decisions`): s' is ``next_obs``, or where a game was cut
        short its final observation (and mask), with done 0."""
        if self._obs is None or self._rewards is None or self._turns is not None:
            return
        assert self._actions is not None and self._dones is not None
        dones, ended = self._dones, self._dones > 0
        if self._trunc is not None:
            cut, final, fmask = self._trunc
            assert final is not None
            next_obs, dones = next_obs.copy(), dones.copy()
            next_obs[cut], dones[cut] = final[cut], 0.0
            if fmask is not None:
                next_mask = np.ones_like(fmask) if next_mask is None else next_mask.copy()
                next_mask[cut] = fmask[cut]
        store_decisions(self.buffer, self.chains, np.arange(len(dones)), self._obs, self._actions, self._rewards,
                        next_obs, dones, ended, next_mask)
        self._obs = self._actions = self._rewards = self._dones = self._trunc = None

    @torch.no_grad()
    def decide(self, obs: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Epsilon-greedy actions for this step's observations, and what :meth:`take` keeps of them (the actions, the
        mask): with a mask, exploration is uniform over the allowed actions and the greedy action the best allowed
        one. With a :attr:`share` (a rollout actor's rows) the draws are the whole batch's."""
        self._check_final_given()
        x = np.asarray(obs, dtype=self.obs_dtype).reshape(len(obs), self.obs_dim)
        m = fix_mask(mask, self.head, len(x))
        if m is not None:
            self._masked = True
        elif self._masked:
            m = np.ones((len(x), self.n_actions), dtype=bool)
        n, share = len(x), self.share
        explore = share_draw(self.rng.random, n, share) < self.epsilon
        if m is None:
            actions = share_draw(lambda k: self.rng.integers(0, self.n_actions, size=k), n, share)
        else:
            actions = uniform_allowed(m, share_draw(self.rng.random, n, share))
        if not explore.all():
            q, _ = self.net(torch.from_numpy(x).to(self.device))
            if m is not None:
                q = q.masked_fill(~torch.from_numpy(m).to(self.device), MASKED)
            greedy = q.argmax(dim=1).cpu().numpy()
            actions = np.where(explore, actions, greedy)
        return actions, {"actions": actions, "mask": m}

    def take(self, obs: np.ndarray, taken: dict[str, Any]) -> None:
        """This step's observations and the actions :meth:`decide` chose (here or in a rollout actor): they complete
        the previous step, and wait for :meth:`record` to bring their own outcome."""
        self._check_final_given()
        x = self._flat(obs)
        m = taken.get("mask")
        if m is not None:
            self._masked = True
        self._push(x, m)
        if self._obs is not None and self._turns is None:  # an earlier step left without record() is dropped
            self.chains.clear()
        self._obs, self._actions, self._mask = x, np.asarray(taken["actions"]), m

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Epsilon-greedy actions for this step's observations, which also complete the previous step
        (:meth:`decide`, then :meth:`take`)."""
        played, taken = self.decide(obs, mask)
        self.take(obs, taken)
        return played

    def acting_state(self) -> dict[str, Any]:
        """What a rollout actor's copy needs to act as this learner does now: the online network's weights (on the
        CPU) and the transitions collected (epsilon follows them)."""
        return {"net": {k: v.detach().cpu() for k, v in self.net.state_dict().items()},
                "transitions": self.transitions}

    def load_acting_state(self, state: dict[str, Any]) -> None:
        """:meth:`acting_state` into a rollout actor's copy; ``noise_seed`` seeds its draws afresh."""
        self.net.load_state_dict(state["net"])
        self.transitions = int(state["transitions"])
        if "noise_seed" in state:
            self.rng = np.random.default_rng(int(state["noise_seed"]))

    def record(self, rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray | None = None,
               acting: np.ndarray | None = None, final_obs: np.ndarray | None = None,
               final_mask: np.ndarray | None = None) -> bool:
        """Stash this step's outcome; True when gradient updates are due (call :meth:`update`).

        ``truncated`` (a subset of ``dones``): games cut short, bootstrapped from ``final_obs`` (given here or to
        the :meth:`update` that follows) and ``final_mask`` (the mask there; all allowed if not given);
        ``acting``: the slots whose seat acted on this step (None: all)."""
        if self._obs is None:
            raise RuntimeError("record() without act()")
        self._check_final_given()
        rewards = np.asarray(rewards, dtype=np.float32).reshape(-1)
        dones = np.asarray(dones, dtype=np.float32).reshape(-1)
        n = len(rewards)
        cut = None
        if truncated is not None and self.cfg.bootstrap_truncated:
            cut = as_bool(truncated, n, "truncated")
            if not cut.any():
                cut = None
            elif not (dones[cut] > 0).all():
                raise ValueError("a truncated game must also be done (dones marks every game that ended)")
        acts = None if acting is None else as_bool(acting, n, "acting")
        if acts is not None and self._turns is None:  # a turn-based game: decision to decision from the start
            self._start_turns()
        if self._turns is not None:
            taken = int(acts.sum()) if acts is not None else n
            self._turn_step(rewards, dones, cut, acts if acts is not None else np.ones(n, dtype=bool),
                            final_obs, final_mask)
        else:
            taken = n
            self._rewards, self._dones = rewards, dones
            if cut is not None:
                self._trunc = (cut, None, None)
                if final_obs is not None:
                    self._give_final(final_obs, final_mask)
        self.transitions += taken
        if len(self.buffer) + taken >= self.cfg.learning_starts:  # counting the step being recorded
            self.credit += self.cfg.replay_ratio * taken
        return self.credit >= 1.0

    def _give_final(self, final_obs: np.ndarray, final_mask: np.ndarray | None) -> None:
        """The final observations (and masks) of the games truncated on the last recorded step."""
        final = self._flat(final_obs)
        fmask = None if final_mask is None else fix_mask(final_mask, self.head, len(final))
        if self._held is not None:
            self._release(final, fmask)
        elif self._trunc is not None:
            self._trunc = (self._trunc[0], final, fmask)

    # -- turn-based games -----------------------------------------------------------------------------------
    def _start_turns(self) -> None:
        """From now on, transitions run from decision to decision (on the first step that says who acted)."""
        b, d = self.n_slots, self.obs_dim
        self.chains.clear()
        self._turns = {"obs": np.zeros((b, d), self.obs_dtype), "act": np.zeros(b, np.int64),
                       "rew": np.zeros(b, np.float32), "valid": np.zeros(b, bool)}

    def _turn_step(self, rewards: np.ndarray, dones: np.ndarray, cut: np.ndarray | None, acts: np.ndarray,
                   final_obs: np.ndarray | None, final_mask: np.ndarray | None) -> None:
        """One step of a turn-based game: decisions completed by this step's decisions, new decisions, rewards
        credited to each slot's decision in flight, and decisions ended with their game."""
        p = self._turns
        assert p is not None and self._obs is not None and self._actions is not None
        close = np.flatnonzero(acts & p["valid"])
        if close.size:  # the seat decides again: its previous decision's s' is this observation
            store_decisions(self.buffer, self.chains, close, p["obs"][close], p["act"][close], p["rew"][close],
                            self._obs[close], np.zeros(close.size, np.float32), False,
                            None if self._mask is None else self._mask[close])
        p["obs"][acts], p["act"][acts], p["rew"][acts] = self._obs[acts], self._actions[acts], 0.0
        p["valid"] |= acts
        p["rew"] += np.where(p["valid"], rewards, 0.0).astype(np.float32)
        end = np.flatnonzero((dones > 0) & p["valid"])
        p["valid"][dones > 0] = False
        if end.size:
            boot = np.zeros(end.size, bool) if cut is None else cut[end]
            self._held = {"rows": end, "obs": p["obs"][end].copy(), "act": p["act"][end].copy(),
                          "rew": p["rew"][end].copy(), "boot": boot}
            if not boot.any():
                self._release(None, None)
            elif final_obs is not None:
                self._give_final(final_obs, final_mask)

    def _release(self, final: np.ndarray | None, fmask: np.ndarray | None) -> None:
        """Store the decisions that ended with their game (bootstrapped from the final observation if cut short)."""
        h = self._held
        assert h is not None
        rows, boot = h["rows"], h["boot"]
        next_obs = h["obs"].copy()  # never read where the game ended for good (done = 1)
        next_mask = None
        if final is not None:
            next_obs[boot] = final[rows][boot]
            if fmask is not None:
                next_mask = np.ones((rows.size, self.n_actions), dtype=bool)
                next_mask[boot] = fmask[rows][boot]
        if next_mask is None and self._masked:
            next_mask = np.ones((rows.size, self.n_actions), dtype=bool)
        self._held = None
        store_decisions(self.buffer, self.chains, rows, h["obs"], h["act"], h["rew"], next_obs,
                        (~boot).astype(np.float32), True, next_mask)

    # -- learning -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def td_target(self, rewards: torch.Tensor, dones: torch.Tensor, next_obs: torch.Tensor,
                  discounts: torch.Tensor | None = None, next_masks: torch.Tensor | None = None) -> torch.Tensor:
        """y = r + discount * (1 - done) * Q_target(s', a'), a' the online argmax (double) or the target's (plain)
        over the actions ``next_masks`` allows in s'; ``discounts`` default to gamma^n."""
        q_next_target, _ = self.target(next_obs)
        if self.cfg.double_dqn:
            q_next_online, _ = self.net(next_obs)
            if next_masks is not None:
                q_next_online = q_next_online.masked_fill(~next_masks, MASKED)
            best = q_next_online.argmax(dim=1, keepdim=True)
            q_next = q_next_target.gather(1, best).squeeze(1)
        else:
            if next_masks is not None:
                q_next_target = q_next_target.masked_fill(~next_masks, MASKED)
            q_next = q_next_target.max(dim=1).values
        discount = self.cfg.gamma ** self.cfg.n_step if discounts is None else discounts
        return rewards + discount * (1.0 - dones) * q_next

    def _sync_target(self) -> None:
        if self.cfg.tau >= 1.0:
            self.target_flat.copy_(self.opt.flat)
        else:
            self.target_flat.lerp_(self.opt.flat, self.cfg.tau)

    def update(self, next_obs: np.ndarray, progress: float = 0.0,
               final_obs: np.ndarray | None = None) -> dict[str, float]:
        """Make the gradient updates due (none before the buffer holds ``learning_starts`` transitions).

        ``next_obs`` (the observations after the recorded step) completes the step in flight so the updates
        see it (with masks, the next ``act`` does, as it brings s' mask); ``final_obs``: the final observations of
        games truncated on the last recorded step, if not given to :meth:`record`; ``progress`` is accepted for
        the trainer's sake and unused (epsilon follows transitions).
        """
        cfg = self.cfg
        if final_obs is not None and self._final_missing():
            self._give_final(final_obs, None)
        self._check_final_given()
        if not self._masked:
            self._push(self._flat(next_obs))
        k = int(self.credit) if len(self.buffer) >= max(1, cfg.learning_starts) else 0
        self.credit -= k
        loss_mean = q_mean = float("nan")
        if k:
            batches = self.buffer.sample(self.rng, (k, cfg.batch_size))  # all k batches in one draw
            obs, actions, rewards, next_o, dones, discounts = (
                torch.from_numpy(batches[key]).to(self.device)
                for key in ("obs", "actions", "rewards", "next_obs", "dones", "discounts"))
            masks = batches.get("next_masks")
            next_masks = None if masks is None else torch.from_numpy(masks).to(self.device)
            loss_fn = nn.functional.smooth_l1_loss if cfg.loss == "huber" else nn.functional.mse_loss
            rows = []  # per gradient step: its loss, mean Q and gradient norm
            for i in range(k):
                # the process is stopping (SIGTERM, Ctrl-C): this update is thrown away; the run's time is up (a
                # --minutes budget): the gradient updates done so far, at least one, are the update
                if stop_requested() or (rows and past_deadline()):
                    break
                y = self.td_target(rewards[i], dones[i], next_o[i], discounts[i],
                                   None if next_masks is None else next_masks[i])
                q_all, _ = self.net(obs[i])
                q = q_all.gather(1, actions[i, :, None]).squeeze(1)
                loss = loss_fn(q, y)
                self.opt.zero_grad()
                loss.backward()
                grad_norm = self.opt.step()  # clips the gradient norm to max_grad_norm first (0: no clipping)
                self.grad_steps += 1
                if self.grad_steps % cfg.target_period == 0:
                    self._sync_target()
                rows.append(torch.stack((loss.detach(), q.detach().mean(), grad_norm)))
            self.cut = (len(rows), k) if len(rows) < k and not stop_requested() else None
            self.credit += k - len(rows)  # (the updates a budget cut stay due: a resumed run makes them)
            k = len(rows)  # fewer when stopped
            if k:
                figures = torch.stack(rows)
                first = self.grad_steps - k + 1
                check_steps(figures, STEP_FIGURES, lambda r: f"gradient step {first + r:,}")
                loss_mean, q_mean = (v / k for v in figures[:, :2].sum(0).tolist())
            self.updates += 1
        return {"loss": loss_mean, "q_mean": q_mean,
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

    def start_from(self, weights: dict[str, torch.Tensor]) -> None:
        """Start from a snapshot's weights (``marl train --init-from``): the online network takes them and the target
        network is synced to it; the optimiser stays as it is, fresh in a new learner."""
        self.net.load_state_dict(weights)
        self.target.load_state_dict(self.net.state_dict())

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.target.load_state_dict(state["target"])
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
        self.transitions = int(state["transitions"])
        self.grad_steps = int(state["grad_steps"])
        self.updates = int(state["updates"])
        self.credit = float(state["credit"])
        self._obs = self._actions = self._mask = self._rewards = self._dones = self._trunc = None
        self.chains.clear()
        self._held = None
        if self._turns is not None:
            self._start_turns()
