"""SAC (twin critics, target critics, automatic entropy tuning) for a learner that drives some slots of the games.

Reads top to bottom as CleanRL's sac_continuous_action.py does: the hyperparameters with their meaning, the twin
critics, the soft TD target, the learner (its replay buffer and n-step returns: :mod:`selfplay_cli.algos.replay`).
Same interface as :class:`~selfplay_cli.algos.ppo.PPOLearner` and :class:`~selfplay_cli.algos.dqn.DQNLearner` (see
:mod:`selfplay_cli.algos.base`), so the one trainer loop drives it.

Actions. SAC plays Box actions only (any other action space is refused in one line: use PPO or DQN). The actor
(``learner.net``, the network saved as snapshots) is an :class:`~selfplay_cli.policies.network.MLPNet` with a
squashed arch: from an observation s it gives the mean and the log-std of a Gaussian over u, and the action is
``y = tanh(u)`` in [-1, 1]^d, mapped affinely onto the Box bounds for the game (:mod:`selfplay_cli.policies.heads`).
Everything the learner keeps and learns from is in the squashed space ``y``: the critics read ``(s, y)``, log-
probabilities are those of ``y``, so the default entropy target ``-d`` (d = the action's numbers) means the same for
every Box. A snapshot plays ``tanh(mean)`` greedily and ``tanh(mean + std * eps)`` sampling, on the bounds.

Per gradient step, on a batch of ``batch_size`` transitions (s, y, r, s', done) drawn uniformly from the buffer,
with y' ~ pi(.|s') and its log-probability log pi(y'|s'), alpha = exp(log_alpha):
    target  = r + gamma * (1 - done) * (min(Q1_targ(s', y'), Q2_targ(s', y')) - alpha * log pi(y'|s'))
              (with ``n_step`` = n > 1: r the discounted rewards of n decisions, s' the state n decisions later and
              gamma^n the discount, the return cut at a game's end: see :mod:`selfplay_cli.algos.replay`)
    critics:  (Q1(s, y) - target)^2 + (Q2(s, y) - target)^2, averaged over the batch
    actor:    alpha * log pi(y~|s) - min(Q1(s, y~), Q2(s, y~)),  y~ ~ pi(.|s) reparameterised
    alpha:    -log_alpha * (log pi(y~|s) + target_entropy)        (autotune; else alpha stays fixed)
    targets:  Q_targ <- tau * Q + (1 - tau) * Q_targ                (Polyak, every gradient step)
With a teacher (kickstarting, :mod:`selfplay_cli.algos.kickstart`) the actor's loss also has ``teacher_weight``
times the squared distance of tanh(mean(s)) to the teacher's action, on a batch of states the teacher labelled.
The two critics are one module whose layers hold both critics' weights side by side (one batched matmul a layer).

Units. A *transition* is one decision of one slot (one game seat). Everything that counts experience counts
transitions (``buffer_size``, ``learning_starts``, ``replay_ratio``), so a config means the same with 1 game or
256. Per transition collected, ``replay_ratio`` gradient steps are due (fractions carry over): the trainer plays
256 games at once, so the default 1/64 is 4 gradient steps of 256 transitions per step of the games (each
transition is then drawn ~4 times on average over its life in the buffer, whatever the number of games).

Exploration. Until the learner has collected ``learning_starts`` transitions, actions are uniform in the Box
(CleanRL's random warm-up) and no gradient step is made; then the actor samples.

Ends of games. A game that ends (won or lost) is a done: the target does not bootstrap past it. A game cut short by
a time limit (``truncated``) bootstraps from its final observation: s' is that observation and done 0
(``bootstrap_truncated``; off, a truncation counts as an end).

Turns. In a turn-based game (``acting``) a transition runs from one of the seat's decisions to its next (or to the
end of the game), its reward the sum of the rewards in between; steps where the seat did not act carry no
decision. Games that all act every step are the same with every slot acting. A decision waits in the learner
until the seat's next one (which brings s') or the end of its game, so transitions enter the buffer one step late.

Resume. :meth:`SACLearner.state_dict` holds the actor, the critics and their targets, the three optimisers, the
temperature, the random generators and the counters, but not the replay buffer (as DQN's): after a resume the
buffer refills, gradient steps waiting until it holds ``learning_starts`` transitions again; the actor keeps
acting (it does not go back to random actions).
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import torch
from torch import nn

from ..envs import SeatSpace
from ..envs.obs_spaces import image_layout
from ..errors import MarlError
from ..policies.heads import HeadMath, squashed_sample, to_numpy_actions
from ..policies.network import ACTIVATION_FNS, Arch, MLPNet, NetworkPolicy, build_network
from ..policies.spaces import ActionHead, describe_space
from ..signals import past_deadline, stop_requested
from .base import Share, action_head, as_bool, check_steps, learner_args, padded, share_draw, unpadded
from .kickstart import Imitation
from .optim import FlatAdam, flatten
from .replay import NStepChains, ReplayBuffer, store_decisions

# a gradient step's figures, in order (checked to be finite every update; the first five are its statistics)
STEP_FIGURES = ("the critic loss", "the actor loss", "the mean Q-value", "the entropy", "the imitation loss",
                "the critics' gradient norm", "the actor's gradient norm", "the log-temperature")


@dataclass
class SACConfig:
    """SAC's hyperparameters. The defaults are CleanRL's (lr 3e-4, 2 hidden layers, tau 0.005, gamma 0.99,
    batch 256) sized for a 2-core CPU: layers of 128 (wider layers make fewer gradient steps a second and learned
    later; narrower ones leave less room for a harder game), and a replay ratio of 1/64, 4 gradient steps per step
    of 256 games (more gradient steps on fewer transitions, while the games are cheap beside the updates). The
    measurements behind these choices: docs/history/learners.md."""

    buffer_size: int = 300_000  # replay capacity in transitions; the oldest are overwritten
    batch_size: int = 256  # transitions per gradient step (CleanRL's)
    lr: float = 3e-4  # Adam learning rate of the actor, the critics and the temperature (the SAC paper's)
    gamma: float = 0.99  # discount
    n_step: int = 1  # n-step returns: bootstrap from the decision n later (1: SAC's own one-step target)
    tau: float = 0.005  # Polyak step of the target critics, every gradient step
    replay_ratio: float = 1 / 64  # gradient steps per transition (4 a step of 256 games; see the module docstring)
    learning_starts: int = 5_000  # uniform random actions, and no gradient step, for this many transitions
    alpha: float = 0.2  # the entropy temperature: its start with autotune, else fixed
    autotune: bool = True  # tune alpha so the policy's entropy stays near target_entropy
    target_entropy: float | None = None  # the entropy autotune aims at; None: -(the action's numbers) (CleanRL)
    critic_hidden: tuple[int, ...] = (128, 128)  # each critic's hidden layers (its activation: the actor's)
    bootstrap_truncated: bool = True  # a game cut short bootstraps from its final observation (False: an end)
    # The actor: the network saved as snapshots (always a squashed Gaussian without a value head)
    arch: Arch = field(default_factory=lambda: Arch(hidden=(128, 128), activation="relu", value_head=False,
                                                    squash=True))

    def __post_init__(self) -> None:
        if isinstance(self.arch, dict):
            self.arch = Arch.from_dict(self.arch)
        if self.arch.dueling:
            raise ValueError("SAC's actor has no dueling head (arch dueling must be false)")
        # [sac.arch] hidden = [...] in a config file need not repeat what every SAC actor is:
        self.arch = replace(self.arch, squash=True, value_head=False)
        self.critic_hidden = tuple(int(h) for h in self.critic_hidden)
        if not all(h > 0 for h in self.critic_hidden):
            raise ValueError("critic_hidden must be positive layer widths")
        for name in ("buffer_size", "batch_size", "n_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")
        if self.learning_starts < 0:
            raise ValueError("learning_starts must not be negative")
        if not (0 < self.gamma <= 1 and self.lr > 0 and 0 < self.tau <= 1 and self.replay_ratio > 0
                and self.alpha > 0):
            raise ValueError("gamma, lr, tau, replay_ratio or alpha out of range")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["arch"] = self.arch.to_dict()
        d["critic_hidden"] = list(self.critic_hidden)
        return d


class TwinQ(nn.Module):
    """Two critics Q1(s, y), Q2(s, y) as one module: layer k holds both critics' weights as ``w{k}`` ``(2, in,
    out)`` and ``b{k}`` ``(2, 1, out)``, so each layer is one batched matmul for both. PyTorch's default Linear init
    (uniform in +-1/sqrt(fan_in)), as CleanRL's critics. ``forward`` returns ``(2, batch)``."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...], activation: str,
                 generator: torch.Generator) -> None:
        super().__init__()
        dims = [obs_dim + act_dim, *hidden, 1]
        self.n_layers = len(dims) - 1
        self._activation = ACTIVATION_FNS[activation]
        for k, (d_in, d_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
            bound = 1.0 / math.sqrt(d_in)
            w = (torch.rand((2, d_in, d_out), generator=generator) * 2 - 1) * bound
            b = (torch.rand((2, 1, d_out), generator=generator) * 2 - 1) * bound
            self.register_parameter(f"w{k}", nn.Parameter(w))
            self.register_parameter(f"b{k}", nn.Parameter(b))

    def forward(self, obs: torch.Tensor, actions: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """Q1 and Q2 of ``(obs, actions)``: ``(2, batch)``. ``frozen``: the weights as constants (the actor's loss
        differentiates through the critics to the actions, not into their weights)."""
        z = torch.cat((obs, actions), dim=1)
        for k in range(self.n_layers):
            w, b = getattr(self, f"w{k}"), getattr(self, f"b{k}")
            if frozen:
                w, b = w.detach(), b.detach()
            z = torch.matmul(z, w) + b if k == 0 else torch.baddbmm(b, z, w)
            if k < self.n_layers - 1:
                z = self._activation(z)
        return z.squeeze(-1)


def soft_target(rewards: torch.Tensor, dones: torch.Tensor, q_next: torch.Tensor, next_logp: torch.Tensor,
                alpha: float | torch.Tensor, discount: float | torch.Tensor) -> torch.Tensor:
    """The soft TD target ``r + discount * (1 - done) * (min(Q1', Q2') - alpha * log pi(y'|s'))``; ``q_next`` is
    the target critics' ``(2, batch)``, ``discount`` gamma (one step) or each transition's gamma^k (n steps)."""
    return rewards + discount * (1.0 - dones) * (q_next.min(dim=0).values - alpha * next_logp)


class SACLearner:
    """The actor, twin critics and their targets, the temperature, the optimisers and the replay buffer over
    ``n_slots`` slots: ``SACLearner(seat, n_slots, config, seed=0, device="cpu")`` (Box actions only)."""

    name = "sac"
    config_class = SACConfig
    synchronous = False  # rollout actors feed the replay with weights up to one fragment old

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        """The head for the seat's actions, or one clear :class:`MarlError` (SAC plays Box actions only, and reads
        flat observations: its critics are MLPs, so an image seat is refused rather than fed raw pixels)."""
        if image_layout(seat.observation) is not None:
            raise MarlError(f"SAC's critics read flat observations, not images ({describe_space(seat.observation)}): "
                            "use --algo ppo or dqn, whose networks read images with a convolutional encoder")
        return action_head("SAC", seat.action, ("box", "Box (continuous)"), "use --algo ppo or dqn")

    def __init__(self, seat: SeatSpace, n_slots: int, config: SACConfig | None = None, *, seed: int = 0,
                 device: str | torch.device = "cpu") -> None:
        self.seat, n_slots, cfg = learner_args(seat, n_slots, config, SACConfig)
        self.cfg = cfg
        self.head = self.check_seat(self.seat)
        self.device = torch.device(device)
        self.obs_shape = tuple(self.seat.observation.shape)
        self.obs_dim = int(np.prod(self.obs_shape))
        self.act_dim = self.n_actions = self.head.outputs
        self.n_slots = n_slots
        self.net: MLPNet = build_network(self.seat.observation, self.seat.action, cfg.arch, seed=seed).to(self.device)
        self.actor_opt = FlatAdam(self.net.parameters(), cfg.lr)
        critic_gen = torch.Generator().manual_seed(int(seed) + 0x5AC)
        self.critic = TwinQ(self.obs_dim, self.act_dim, cfg.critic_hidden, cfg.arch.activation,
                            critic_gen).to(self.device)
        self.target = copy.deepcopy(self.critic).requires_grad_(False)
        self.critic_opt = FlatAdam(self.critic.parameters(), cfg.lr)
        self.target_flat = flatten(self.target.parameters())  # the Polyak update is one operation on it
        self.log_alpha = nn.Parameter(torch.tensor([math.log(cfg.alpha)], device=self.device))
        self.alpha_opt = FlatAdam([self.log_alpha], cfg.lr)
        self.target_entropy = float(-self.act_dim if cfg.target_entropy is None else cfg.target_entropy)
        self.math = HeadMath(self.head, self.device)
        self.gen = torch.Generator(device=self.device).manual_seed(seed)  # the actor's samples
        self.rng = np.random.default_rng(seed)  # random warm-up actions and replay sampling
        self.share: Share | None = None  # in a rollout actor: its rows of the slots (draws stay the whole batch's)
        self.buffer = ReplayBuffer(cfg.buffer_size, self.obs_dim, (self.act_dim,), np.float32)
        self.chains = NStepChains(cfg.n_step, cfg.gamma, n_slots, self.obs_dim, (self.act_dim,))
        self.transitions = 0  # decisions collected so far (drives the random warm-up)
        self.grad_steps = 0
        self.updates = 0  # update() calls that made at least one gradient step
        self.cut: tuple[int, int] | None = None  # the last update, when a --minutes budget cut it: (gradient steps
        # done, due)
        self.credit = 0.0  # gradient steps due but not yet made (replay_ratio per transition)
        # The step in flight (act -> record) and each slot's decision waiting for its s' (see _step).
        self._obs: np.ndarray | None = None
        self._actions: np.ndarray | None = None
        b = n_slots
        self._pend = {"obs": np.zeros((b, self.obs_dim), np.float32), "act": np.zeros((b, self.act_dim), np.float32),
                      "rew": np.zeros(b, np.float32), "valid": np.zeros(b, bool)}
        self._held: dict[str, np.ndarray] | None = None  # decisions of truncated games awaiting final_obs
        # Kickstarting (algos/kickstart.py): the teacher's labelled states and the imitation term's weight
        self.imitation: Imitation | None = None
        self.imitation_capacity = 300_000
        self.teacher_weight = 0.0

    @property
    def alpha(self) -> float:
        return float(self.log_alpha.detach().exp())

    # -- acting ---------------------------------------------------------------------------------------------
    def _flat(self, obs: np.ndarray) -> np.ndarray:
        return np.array(obs, dtype=np.float32, order="C").reshape(len(obs), self.obs_dim)

    def _check_final_given(self) -> None:
        if self._held is not None:
            raise ValueError("games were truncated on the last recorded step: pass their final observations "
                             "(final_obs) to record() or update()")

    @torch.no_grad()
    def decide(self, obs: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Actions for this step's observations, within the Box bounds: uniform while the learner warms up
        (``learning_starts``), then sampled from the actor (``tanh(mean + std * eps)`` on the bounds); and, for
        :meth:`take`, the squashed actions the buffer keeps. With a :attr:`share` (a rollout actor's rows) the draws
        are the whole batch's (:func:`~.base.padded`)."""
        self._check_final_given()
        x = np.asarray(obs, dtype=np.float32).reshape(len(obs), self.obs_dim)
        self.head.check_mask(mask, len(x))  # Box actions take no mask: one clear error if one is given
        share = self.share
        if self.transitions < self.cfg.learning_starts:
            y = share_draw(lambda n: self.rng.uniform(-1.0, 1.0, (n, self.act_dim)), len(x), share)
            y = y.astype(np.float32)
            played = self.math.to_bounds(torch.from_numpy(y).to(self.device))
        else:
            mean, log_std = self.net.gaussian(torch.from_numpy(x).to(self.device))
            y_t, _ = squashed_sample(padded(mean, share), padded(log_std, share), self.gen)
            y_t = unpadded(y_t, share)
            played = self.math.to_bounds(y_t)
            y = y_t.cpu().numpy()
        return to_numpy_actions(self.head, played), {"actions": y}

    def take(self, obs: np.ndarray, taken: dict[str, Any]) -> None:
        """Keep this step's observations and the squashed actions :meth:`decide` chose (here or in a rollout actor)
        until :meth:`record` brings their outcome."""
        self._check_final_given()
        self._obs, self._actions = self._flat(obs), np.asarray(taken["actions"], dtype=np.float32)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Actions for this step's observations (:meth:`decide`, then :meth:`take`)."""
        played, taken = self.decide(obs, mask)
        self.take(obs, taken)
        return played

    def acting_state(self) -> dict[str, Any]:
        """What a rollout actor's copy needs to act as this learner does now: the actor's weights (on the CPU) and the
        transitions collected (the random warm-up ends at ``learning_starts``)."""
        return {"net": {k: v.detach().cpu() for k, v in self.net.state_dict().items()},
                "transitions": self.transitions}

    def load_acting_state(self, state: dict[str, Any]) -> None:
        """:meth:`acting_state` into a rollout actor's copy; ``noise_seed`` seeds its draws afresh (an actor's draws
        are its own stream, not the trainer's, which its updates use)."""
        self.net.load_state_dict(state["net"])
        self.transitions = int(state["transitions"])
        if "noise_seed" in state:
            self.gen.manual_seed(int(state["noise_seed"]))
            self.rng = np.random.default_rng(int(state["noise_seed"]))

    def record(self, rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray | None = None,
               acting: np.ndarray | None = None, final_obs: np.ndarray | None = None,
               final_mask: np.ndarray | None = None) -> bool:
        """Store this step's outcome; True when gradient steps are due (call :meth:`update`).

        ``truncated`` (a subset of ``dones``): games cut short, bootstrapped from their ``final_obs`` rows (given
        here or to the :meth:`update` that follows); ``acting``: the slots whose seat acted on this step (None:
        all). ``final_mask`` is accepted for the interface's sake (Box actions take no mask)."""
        if self._obs is None or self._actions is None:
            raise RuntimeError("record() without act()")
        self._check_final_given()
        n = self.n_slots
        rewards = np.asarray(rewards, dtype=np.float32).reshape(-1)
        dones = np.asarray(dones).reshape(-1) > 0
        if rewards.shape != (n,) or dones.shape != (n,):
            raise ValueError(f"rewards and dones need one entry for each of the {n} slots")
        cut = None
        if truncated is not None and self.cfg.bootstrap_truncated:
            cut = as_bool(truncated, n, "truncated")
            if not (dones[cut]).all():
                raise ValueError("a truncated game must also be done (dones marks every game that ended)")
        acts = np.ones(n, dtype=bool) if acting is None else as_bool(acting, n, "acting")
        taken = self._step(rewards, dones, cut, acts, final_obs)
        self._obs = self._actions = None
        self.transitions += taken
        if len(self.buffer) + taken >= max(1, self.cfg.learning_starts):
            self.credit += self.cfg.replay_ratio * taken
        return self.credit >= 1.0

    def _step(self, rewards: np.ndarray, dones: np.ndarray, cut: np.ndarray | None, acts: np.ndarray,
              final_obs: np.ndarray | None) -> int:
        """Decisions completed by this step's (s' is this step's observation), this step's decisions, rewards
        credited to each slot's decision in flight, and decisions ended with their game. Returns the decisions."""
        p = self._pend
        obs, actions = self._obs, self._actions
        assert obs is not None and actions is not None
        every = bool(acts.all())
        close = p["valid"] & acts
        if close.any():  # the seat decides again: its previous decision's s' is this observation
            if every and close.all():
                self._store(np.arange(self.n_slots), p["obs"], p["act"], p["rew"], obs, np.zeros(self.n_slots))
            else:
                rows = np.flatnonzero(close)
                self._store(rows, p["obs"][rows], p["act"][rows], p["rew"][rows], obs[rows], np.zeros(rows.size))
        if every:
            p["obs"][:], p["act"][:], p["rew"][:] = obs, actions, rewards
            p["valid"][:] = True
        else:
            p["obs"][acts], p["act"][acts], p["rew"][acts] = obs[acts], actions[acts], 0.0
            p["valid"] |= acts
            p["rew"] += np.where(p["valid"], rewards, 0.0).astype(np.float32)
        end = np.flatnonzero(dones & p["valid"])
        p["valid"][dones] = False
        if end.size:
            boot = np.zeros(end.size, bool) if cut is None else cut[end]
            self._held = {"rows": end, "obs": p["obs"][end].copy(), "act": p["act"][end].copy(),
                          "rew": p["rew"][end].copy(), "boot": boot}
            if not boot.any():
                self._release(None)
            elif final_obs is not None:
                self._release(final_obs)
        return int(acts.sum())

    def _release(self, final_obs: np.ndarray | None) -> None:
        """Store the decisions that ended with their game: done, or, cut short, bootstrapped from the final obs."""
        h = self._held
        assert h is not None
        rows, boot = h["rows"], h["boot"]
        next_obs = h["obs"].copy()  # never read where the game ended for good (done = 1)
        if final_obs is not None and boot.any():
            final = self._flat(final_obs)
            if len(final) != self.n_slots:
                raise ValueError(f"final_obs has {len(final)} rows for {self.n_slots} slots")
            next_obs[boot] = final[rows[boot]]
        self._held = None
        self._store(rows, h["obs"], h["act"], h["rew"], next_obs, (~boot).astype(np.float32), ended=True)

    def _store(self, rows: np.ndarray, obs: np.ndarray, act: np.ndarray, rew: np.ndarray, next_obs: np.ndarray,
               dones: np.ndarray, ended: bool = False) -> None:
        """The one-step decisions of slots ``rows`` whose s' is ``next_obs`` (``ended``: their games ended there)
        into the buffer, as the n-step transitions they complete (:mod:`selfplay_cli.algos.replay`)."""
        store_decisions(self.buffer, self.chains, rows, obs, act, rew, next_obs, dones, ended)

    def teach(self, obs: np.ndarray, actions: np.ndarray, mask: np.ndarray | None = None) -> None:
        """A teacher's actions (on the Box bounds) for observations this learner met: kept for the imitation term
        of the actor's loss while ``teacher_weight`` > 0 (:mod:`selfplay_cli.algos.kickstart`)."""
        if self.imitation is None:
            self.imitation = Imitation(self.head, self.obs_dim, self.imitation_capacity, self.device, squashed=True)
        self.imitation.add(obs, actions, mask)

    # -- learning -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def td_target(self, rewards: torch.Tensor, dones: torch.Tensor, next_obs: torch.Tensor,
                  next_actions: torch.Tensor | None = None, next_logp: torch.Tensor | None = None,
                  discounts: torch.Tensor | None = None) -> torch.Tensor:
        """The soft TD target (:func:`soft_target`) with the target critics, y' and log pi(y'|s') drawn from the
        actor unless given; ``discounts``: each transition's gamma^k (default gamma)."""
        if next_actions is None or next_logp is None:
            mean, log_std = self.net.gaussian(next_obs)
            next_actions, next_logp = squashed_sample(mean, log_std, self.gen)
        q_next = self.target(next_obs, next_actions)
        discount = self.cfg.gamma if discounts is None else discounts
        return soft_target(rewards, dones, q_next, next_logp, self.log_alpha.exp(), discount)

    def update(self, next_obs: np.ndarray | None = None, progress: float = 0.0,
               final_obs: np.ndarray | None = None) -> dict[str, float]:
        """Make the gradient steps due (none before the buffer holds ``learning_starts`` transitions).

        ``final_obs``: the final observations of games truncated on the last recorded step, if not given to
        :meth:`record`; ``next_obs`` and ``progress`` are accepted for the interface's sake (a decision's s' comes
        with the seat's next decision)."""
        cfg = self.cfg
        if self._held is not None:
            if final_obs is None:
                self._check_final_given()
            self._release(final_obs)
        k = int(self.credit) if len(self.buffer) >= max(1, cfg.learning_starts) else 0
        self.credit -= k
        if k:
            batches = self.buffer.sample(self.rng, (k, cfg.batch_size))  # all k batches in one draw
            obs, actions, rewards, next_o, dones, discounts = (
                torch.from_numpy(batches[key]).to(self.device)
                for key in ("obs", "actions", "rewards", "next_obs", "dones", "discounts"))
            steps = []
            for i in range(k):
                # the process is stopping (SIGTERM, Ctrl-C): this update is thrown away; the run's time is up (a
                # --minutes budget): the gradient steps done so far, at least one, are the update
                if stop_requested() or (steps and past_deadline()):
                    break
                steps.append(self._gradient_step(obs[i], actions[i], rewards[i], next_o[i], dones[i], discounts[i]))
            self.cut = (len(steps), k) if len(steps) < k and not stop_requested() else None
            self.credit += k - len(steps)  # (the steps a budget cut stay due: a resumed run makes them)
            k = len(steps)  # fewer when stopped
            if k:
                figures = torch.stack(steps)
                first = self.grad_steps - k + 1
                check_steps(figures, STEP_FIGURES, lambda r: f"gradient step {first + r:,}")
                sums = figures[:, :5].sum(0)  # critic loss, actor loss, Q, entropy, imitation loss
            self.updates += 1
        out = {"alpha": self.alpha, "buffer_size": float(len(self.buffer)), "grad_steps": float(self.grad_steps),
               "lr": self.actor_opt.lr}
        if k:  # the losses of this update's gradient steps (none yet while the buffer fills: no NaN in the metrics)
            mean = (sums / k).tolist()
            out.update({"critic_loss": mean[0], "actor_loss": mean[1], "q_mean": mean[2], "entropy": mean[3]})
            if self._teaching:
                out.update({"teacher_weight": self.teacher_weight, "imitation_loss": mean[4]})
        return out

    def _gradient_step(self, obs: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor,
                       next_obs: torch.Tensor, dones: torch.Tensor, discounts: torch.Tensor) -> torch.Tensor:
        """One step of the critics, the actor, the temperature and the targets; returns its figures
        (:data:`STEP_FIGURES`)."""
        cfg = self.cfg
        y = self.td_target(rewards, dones, next_obs, discounts=discounts)
        q = self.critic(obs, actions)
        critic_loss = (q - y).square().mean(dim=1).sum()  # MSE of Q1 plus MSE of Q2
        self.critic_opt.zero_grad()
        critic_loss.backward()
        critic_norm = self.critic_opt.step()

        alpha = self.log_alpha.detach().exp()
        mean, log_std = self.net.gaussian(obs)
        new_actions, logp = squashed_sample(mean, log_std, self.gen)
        q_new = self.critic(obs, new_actions, frozen=True).min(dim=0).values
        actor_loss = (alpha * logp - q_new).mean()
        imitation = torch.zeros((), device=self.device)
        if self._teaching:
            assert self.imitation is not None
            imitation = self.imitation.loss(self.net, cfg.batch_size, self.rng)
        self.actor_opt.zero_grad()
        (actor_loss + self.teacher_weight * imitation if self._teaching else actor_loss).backward()
        actor_norm = self.actor_opt.step()

        if cfg.autotune:
            alpha_loss = -(self.log_alpha * (logp.detach() + self.target_entropy)).mean()
            self.alpha_opt.zero_grad()
            alpha_loss.backward()
            self.alpha_opt.step()
        self.target_flat.lerp_(self.critic_opt.flat, cfg.tau)
        self.grad_steps += 1
        return torch.stack((critic_loss.detach(), actor_loss.detach(), q.detach().mean(), -logp.detach().mean(),
                            imitation.detach(), critic_norm, actor_norm, self.log_alpha.detach()[0]))

    @property
    def _teaching(self) -> bool:
        return self.teacher_weight > 0 and self.imitation is not None and len(self.imitation) > 0

    # -- playing and saving ---------------------------------------------------------------------------------
    def policy(self, id: str, env: str, greedy: bool = False) -> NetworkPolicy:
        """The live actor as a policy (no copy): ``tanh(mean)`` greedily, else sampled, on the Box bounds."""
        return NetworkPolicy(self.net, id, env, device=self.device, greedy=greedy)

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume except the replay buffer (see the module docstring)."""
        return {"net": self.net.state_dict(), "critic": self.critic.state_dict(), "target": self.target.state_dict(),
                "actor_opt": self.actor_opt.state_dict(), "critic_opt": self.critic_opt.state_dict(),
                "alpha_opt": self.alpha_opt.state_dict(), "log_alpha": self.log_alpha.detach().clone(),
                "gen": self.gen.get_state(), "rng": self.rng.bit_generator.state, "transitions": self.transitions,
                "grad_steps": self.grad_steps, "updates": self.updates, "credit": self.credit}

    def start_from(self, weights: dict[str, torch.Tensor]) -> None:
        """Start from a snapshot's weights (``marl train --init-from``): the actor takes them; a snapshot holds no
        critics, so the critics (and their target) stay as built, and every optimiser stays fresh."""
        self.net.load_state_dict(weights)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.critic.load_state_dict(state["critic"])
        self.target.load_state_dict(state["target"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.alpha_opt.load_state_dict(state["alpha_opt"])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        self.gen.set_state(state["gen"].cpu())
        self.rng.bit_generator.state = state["rng"]
        self.transitions = int(state["transitions"])
        self.grad_steps = int(state["grad_steps"])
        self.updates = int(state["updates"])
        self.credit = float(state["credit"])
        self._obs = self._actions = None
        self._pend["valid"][:] = False
        self.chains.clear()
        self._held = None
