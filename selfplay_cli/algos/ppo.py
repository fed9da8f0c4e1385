"""PPO (clipped objective, GAE) for a learner that drives some slots of the batched self-play games.

Reads top to bottom as CleanRL's ppo.py does: the hyperparameters with their meaning, the rollout buffer, the
advantage estimate, the update. The learner does not own the games: the trainer steps the shared
:class:`~selfplay_cli.play.training_games.SelfPlayGames` and hands each learner its slots' observations (and action
masks), rewards and dones (see :mod:`selfplay_cli.algos.base`), so two learners (one network per paddle) and one
shared network use the same code.

Per update: ``rollout_steps`` steps of every slot are collected with the current policy (sampling), advantages
come from GAE(lambda) over the rollout, and ``update_epochs`` passes of ``minibatches`` minibatches optimise
    L = -min(r A, clip(r, 1 - eps, 1 + eps) A) + vf_coef * (V - R)^2 / 2 - ent_coef * H
with r the probability ratio of the new to the old policy; with a teacher (kickstarting,
:mod:`selfplay_cli.algos.kickstart`) each minibatch's loss also has ``teacher_weight`` times the imitation loss on
as many states the teacher labelled.
An update under way when a run's time is up (:func:`~selfplay_cli.signals.past_deadline`: a ``--minutes`` budget)
ends after the minibatch it is in, keeping the minibatches it did: a run of updates that take minutes ends within
one minibatch of its budget.

Action spaces (the policy's distribution; :mod:`selfplay_cli.policies.heads`):
* Discrete: a categorical over the logits; masked actions get a logit of -1e9 (probability exactly 0), when acting
  and in the update (the rollout keeps each step's mask), so a masked action is never sampled nor learned towards.
* MultiDiscrete: a categorical per dimension; log-probabilities and entropies are summed over the dimensions.
* Box: a Gaussian, the network's outputs as means and a learned state-independent log-std; log-probabilities and
  the entropy summed over dimensions. The rollout keeps the sampled action, the game gets it clipped to the bounds.

Ends of games. A game that ends (won or lost) is a done: the value after it is not bootstrapped. A game cut short
by a time limit (``truncated``) is a done too, but its last step bootstraps from the value of its final
observation: delta = r + gamma * V(final obs) - V(s) (``bootstrap_truncated``); the advantage recursion stops there
all the same.

Turns. In a turn-based game a seat acts only on some steps (``acting``). Steps where it did not act are no
decisions: GAE runs over the seat's own decisions, each one's reward being the rewards from its step up to the
seat's next decision (or the game's end), and only decisions enter the loss. A decision whose continuation is not
known when the rollout ends (the seat's last, with its game still running) is not learned from yet: it bootstraps
the decisions before it, then is carried over to the next update as its first row, where the rest of its rewards
arrive (its recorded log-probability is the behaviour policy's; its value is recomputed by the updated network).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch

from ..envs import SeatSpace
from ..errors import NonFiniteError
from ..policies.heads import MASKED, HeadMath, to_numpy_actions
from ..policies.network import Arch, MLPNet, NetworkPolicy, build_network
from ..policies.spaces import ActionHead
from ..signals import past_deadline, stop_requested
from .base import Share, action_head, as_bool, check_steps, fix_mask, learner_args, padded, unpadded, values_of
from .kickstart import Imitation
from .optim import FlatAdam

# a minibatch's figures, in order (checked to be finite every update; the first six are its statistics)
STEP_FIGURES = ("the policy loss", "the value loss", "the entropy", "the approximate KL", "the clip fraction",
                "the imitation loss", "the gradient norm")


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
    bootstrap_truncated: bool = True  # a game cut short bootstraps from V(final obs) (False: counts as its end)
    reward_scale: float = 1.0  # rewards are multiplied by this before learning (keeps returns of order 1, so the
    # value loss does not swamp the policy's gradient in the shared trunk: the lander's +-100 terms want 0.01)
    arch: Arch = field(default_factory=lambda: Arch(hidden=(64, 64), activation="relu", value_head=True))

    def __post_init__(self) -> None:
        if isinstance(self.arch, dict):
            self.arch = Arch.from_dict(self.arch)
        for name in ("rollout_steps", "minibatches", "update_epochs"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")
        if not (0 < self.gamma <= 1 and 0 <= self.gae_lambda <= 1 and self.lr > 0 and self.clip_coef > 0):
            raise ValueError("gamma, gae_lambda, lr or clip_coef out of range")
        if not self.reward_scale > 0:  # (NaN fails too; the CLI bounds it further, train/bounds.py's RANGES)
            raise ValueError(f"reward_scale must be a positive number, not {self.reward_scale}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["arch"] = self.arch.to_dict()
        return d


class PPOLearner:
    """One network, its optimiser and its rollout buffer over ``n_slots`` slots of the games.

    Built as ``PPOLearner(seat, n_slots, config, seed=0, device="cpu")`` from the seat's
    :class:`~selfplay_cli.envs.SeatSpace`.
    """

    name = "ppo"
    config_class = PPOConfig
    synchronous = True  # rollout actors collect each rollout with the weights it updates (the same run as local)

    @staticmethod
    def check_seat(seat: SeatSpace) -> ActionHead:
        """The head for the seat's actions, or one clear :class:`MarlError` (an action space PPO cannot learn)."""
        return action_head("PPO", seat.action)

    def __init__(self, seat: SeatSpace, n_slots: int, config: PPOConfig | None = None, *, seed: int = 0,
                 device: str | torch.device = "cpu") -> None:
        self.seat, n_slots, cfg = learner_args(seat, n_slots, config, type(self).config_class)
        self.cfg = cfg
        self.device = torch.device(device)
        self.head = self.check_seat(self.seat)
        self.obs_shape = tuple(self.seat.observation.shape)
        self.n_actions = self.head.outputs
        self.n_slots = n_slots
        self.net: MLPNet = build_network(self.seat.observation, self.seat.action, cfg.arch, seed=seed).to(self.device)
        self.opt = FlatAdam(self.net.parameters(), lr=cfg.lr, eps=1e-5, max_grad_norm=cfg.max_grad_norm)
        self.gen = torch.Generator(device=self.device).manual_seed(seed)
        self.math = HeadMath(self.head, self.device)
        t, b, d = cfg.rollout_steps, n_slots, int(np.prod(self.obs_shape))
        # The observations in their own dtype: an image's uint8 frames take a quarter of float32's memory (the
        # network scales them), other observations float32.
        self.obs_dtype = np.dtype(self.seat.observation.dtype)
        self.obs = torch.zeros((t, b, d), dtype=torch.from_numpy(np.zeros(0, self.obs_dtype)).dtype, device=self.device)
        if self.head.kind == "box":  # the sampled (unclipped) actions, flat
            self.actions = torch.zeros((t, b, self.head.outputs), device=self.device)
        else:
            self.actions = torch.zeros((t, b, *self.head.action_shape), dtype=torch.long, device=self.device)
        self.logprobs = torch.zeros((t, b), device=self.device)
        self.values = torch.zeros((t, b), device=self.device)
        self.rewards = torch.zeros((t, b), device=self.device)
        self.dones = torch.zeros((t, b), device=self.device)  # the game ended after this step
        # Made when first needed, so a game without masks, time limits or turns pays nothing for them:
        self.masks: torch.Tensor | None = None  # (t, b, width) bool: the allowed actions at each step
        self.trunc_values: torch.Tensor | None = None  # (t, b): V(final obs) where a game was truncated, else 0
        self.acting: torch.Tensor | None = None  # (t, b) bool: the seat acted (turn-based games)
        self.carry: dict[str, torch.Tensor] | None = None  # turn-based: each slot's decision carried over
        self._final_due: tuple[int, np.ndarray] | None = None  # truncated rows of the last step awaiting final_obs
        # On the CPU, numpy views of the buffers: a step's arrays go in with one numpy copy, no tensor made.
        self._np = ({"obs": self.obs.numpy(), "rewards": self.rewards.numpy(), "dones": self.dones.numpy()}
                    if self.device.type == "cpu" else None)
        self.t = 0
        self.updates = 0
        self.cut: tuple[int, int] | None = None  # the last update, when a --minutes budget cut it: (minibatches done,
        # planned)
        # Kickstarting (algos/kickstart.py): the teacher's labelled states and the imitation term's weight
        self.imitation: Imitation | None = None
        self.imitation_capacity = 300_000
        self.teacher_weight = 0.0
        self.rng = np.random.default_rng(seed)  # draws the imitation term's batches
        self.share: Share | None = None  # in a rollout actor: its rows of the slots (draws stay the whole batch's)
        # Rollout buffers of a subclass beyond PPO's own ((t, b, ...) tensors: a centralised critic's inputs), kept,
        # flattened and carried over with the observations (:mod:`.mappo`); PPO has none.
        self.extra: dict[str, torch.Tensor] = {}

    # -- acting ---------------------------------------------------------------------------------------------
    def _tensor(self, obs: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.asarray(obs, dtype=self.obs_dtype), device=self.device).reshape(len(obs), -1)

    @torch.inference_mode()
    def decide(self, obs: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Sample actions for this step's observations (never an action ``mask`` forbids): the actions the game
        gets, and what the rollout keeps of this step besides the observations (the sampled actions, their
        log-probabilities, the values, the mask), for :meth:`take`. :meth:`act` is the two in one; a rollout actor
        decides (for its :attr:`share` of the slots) and the trainer's learner takes.

        Discrete sampling is the inverse-CDF draw ``a = #{k : cdf_k <= u}`` with one uniform ``u`` per slot from the
        learner's generator (multinomial does the same draw several times slower on small batches). With a share,
        the network is evaluated and sampled on the whole batch's rows, the others zeros (:func:`~.base.padded`):
        a matrix product's rows can round differently with the batch's size, and PPO's promise is the local run's
        numbers, bit for bit, for the cost of a forward pass (microseconds beside a step of the games)."""
        self._check_final_given()
        share = self.share
        m = fix_mask(mask, self.head, len(obs))
        m_t = None if m is None else torch.as_tensor(m, device=self.device)
        x = padded(self._tensor(obs), share)
        full_m = None if m_t is None else padded(m_t, share, True)
        logits, value = self.net(x)
        if self.head.kind == "discrete" and full_m is None:
            logp_all = torch.log_softmax(logits, dim=-1)
            u = torch.rand((x.shape[0], 1), generator=self.gen, device=self.device)
            cdf = logp_all.exp().cumsum_(dim=1)
            action = torch.searchsorted(cdf, u, right=True).clamp_(max=self.n_actions - 1)
            logp = logp_all.gather(1, action).squeeze(1)
            stored = played = action.squeeze(1)
        else:
            stored, played = self.math.sample(logits, full_m, self.gen, greedy=False, log_std=self.net.log_std,
                                              fill=MASKED)
            logp, _ = self.math.log_prob_entropy(logits, stored, full_m, self.net.log_std)
        return to_numpy_actions(self.head, unpadded(played, share)), {
            "actions": unpadded(stored, share), "logprobs": unpadded(logp, share), "values": unpadded(value, share),
            "mask": m_t}

    def take(self, obs: np.ndarray, taken: dict[str, Any]) -> None:
        """Keep one step of the rollout: its observations and what :meth:`decide` chose for them (here or in a
        rollout actor; tensors or numpy arrays)."""
        self._check_final_given()
        t = self.t
        if self._np is not None:
            self._np["obs"][t] = np.asarray(obs).reshape(len(obs), -1)
        else:
            self.obs[t].copy_(self._tensor(obs))
        self.actions[t] = torch.as_tensor(taken["actions"], device=self.device).reshape(self.actions[t].shape)
        self.logprobs[t] = torch.as_tensor(taken["logprobs"], device=self.device)
        if taken["values"] is not None:  # (an actor without a value head: its critic values the rollout later)
            self.values[t] = torch.as_tensor(taken["values"], device=self.device)
        m = taken.get("mask")
        if m is not None or self.masks is not None:
            if self.masks is None:
                self.masks = torch.ones((self.cfg.rollout_steps, self.n_slots, self.head.mask_width),
                                        dtype=torch.bool, device=self.device)
            self.masks[t] = True if m is None else torch.as_tensor(m, device=self.device)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Sample actions for this step's observations and remember what the update needs (:meth:`decide`, then
        :meth:`take`)."""
        played, taken = self.decide(obs, mask)
        self.take(obs, taken)
        return played

    def acting_state(self) -> dict[str, Any]:
        """What a rollout actor's copy needs to act as this learner does now: the network's weights (on the CPU) and
        the sampling generator's state."""
        return {"net": {k: v.detach().cpu() for k, v in self.net.state_dict().items()},
                "gen": self.gen.get_state().cpu()}

    def load_acting_state(self, state: dict[str, Any]) -> None:
        """:meth:`acting_state` (or a part of it: the trainer takes back the generator state its actors ended with)."""
        if "net" in state:
            self.net.load_state_dict(state["net"])
        if "gen" in state:
            self.gen.set_state(state["gen"])
        if "noise_seed" in state:  # an actor of a trainer on another device: draws of its own
            self.gen.manual_seed(int(state["noise_seed"]))

    def record(self, rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray | None = None,
               acting: np.ndarray | None = None, final_obs: np.ndarray | None = None,
               final_mask: np.ndarray | None = None) -> bool:
        """Store this step's outcome; True when the rollout is full and :meth:`update` is due.

        ``truncated`` (a subset of ``dones``): games cut short, whose ``final_obs`` rows (given here or to the
        :meth:`update` that follows this step) bootstrap the return; ``acting``: the slots whose seat acted on
        this step (None: all). ``final_mask`` is accepted for the interface's sake (values need no mask)."""
        self._check_final_given()
        if self.cfg.reward_scale != 1.0:
            raw = np.asarray(rewards, dtype=np.float32)
            with np.errstate(over="ignore"):
                rewards = raw * np.float32(self.cfg.reward_scale)
            if not np.isfinite(rewards).all():  # the games gave finite rewards: the scale overflowed them
                r = float(raw[~np.isfinite(rewards)][0])
                raise NonFiniteError(f"a reward of {r:g} times reward_scale {self.cfg.reward_scale:g} is beyond "
                                     "float32 (inf): lower reward_scale")
        if self._np is not None:
            self._np["rewards"][self.t] = rewards
            self._np["dones"][self.t] = dones
        else:
            self.rewards[self.t] = torch.as_tensor(rewards, dtype=torch.float32, device=self.device)
            self.dones[self.t] = torch.as_tensor(dones, dtype=torch.float32, device=self.device)
        if truncated is not None and self.cfg.bootstrap_truncated:
            cut = as_bool(truncated, self.n_slots, "truncated")
            if cut.any():
                if not np.asarray(dones, dtype=bool).reshape(-1)[cut].all():
                    raise ValueError("a truncated game must also be done (dones marks every game that ended)")
                if self.trunc_values is None:
                    self.trunc_values = torch.zeros_like(self.values)
                self._final_due = (self.t, np.flatnonzero(cut))
                if final_obs is not None:
                    self._bootstrap(final_obs)
        if acting is not None:
            acts = as_bool(acting, self.n_slots, "acting")
            if self.acting is None and not acts.all():
                self.acting = torch.ones((self.cfg.rollout_steps, self.n_slots), dtype=torch.bool, device=self.device)
            if self.acting is not None:
                self.acting[self.t] = torch.as_tensor(acts, device=self.device)
        self.t += 1
        return self.t == self.cfg.rollout_steps

    def _bootstrap(self, final_obs: np.ndarray) -> None:
        """V(final obs) of the games truncated on the last recorded step, into ``trunc_values``."""
        assert self._final_due is not None and self.trunc_values is not None
        t, rows = self._final_due
        final = np.asarray(final_obs, dtype=self.obs_dtype)
        if len(final) != self.n_slots:
            raise ValueError(f"final_obs has {len(final)} rows for {self.n_slots} slots")
        self.trunc_values[t, torch.as_tensor(rows, device=self.device)] = self._final_values(final[rows], rows)
        self._final_due = None

    # -- the values the returns rest on (a centralised critic's subclass values other inputs: :mod:`.mappo`) -------
    def _values(self, obs: torch.Tensor, extra: dict[str, torch.Tensor]) -> torch.Tensor:
        """V of rows of the rollout (their flat observations, and the same rows of :attr:`extra`), no gradients."""
        return values_of(self.net, obs, self.device)

    def _final_values(self, final: np.ndarray, rows: np.ndarray) -> torch.Tensor:
        """V of the final observations ``final`` of the slots ``rows``, cut short on the last recorded step."""
        return values_of(self.net, final, self.device)

    def _next_values(self, next_obs: np.ndarray) -> torch.Tensor:
        """V of the observations after the rollout's last step (what its last steps bootstrap from)."""
        return values_of(self.net, self._tensor(next_obs), self.device)

    def _forward(self, batch: dict[str, Any], idx: torch.Tensor) -> tuple[torch.Tensor, Any]:
        """The policy's outputs and the values (with gradients) of the minibatch ``idx`` of ``batch``."""
        return self.net(batch["obs"].index_select(0, idx))

    def _value_loss(self, value: Any, batch: dict[str, Any], idx: torch.Tensor) -> torch.Tensor:
        """The value loss of the minibatch: (V - R)^2 / 2."""
        return 0.5 * (value - batch["returns"].index_select(0, idx)).square().mean()

    def _check_final_given(self) -> None:
        if self._final_due is not None:
            raise ValueError("games were truncated on the last recorded step: pass their final observations "
                             "(final_obs) to record() or update()")

    def teach(self, obs: np.ndarray, actions: np.ndarray, mask: np.ndarray | None = None) -> None:
        """A teacher's actions for observations this learner met (and their masks): kept for the imitation term of
        the loss while ``teacher_weight`` > 0 (:mod:`selfplay_cli.algos.kickstart`)."""
        if self.imitation is None:
            self.imitation = Imitation(self.head, int(np.prod(self.obs_shape)), self.imitation_capacity, self.device,
                                       obs_dtype=self.obs_dtype)
        self.imitation.add(obs, actions, mask)

    # -- learning -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def _advantages(self, next_obs: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """GAE(lambda): A_t = delta_t + gamma * lambda * (1 - done_t) * A_{t+1},
        delta_t = r_t + gamma * (1 - done_t) * V(s_{t+1}) + gamma * trunc_t * V(final_t) - V(s_t)."""
        cfg = self.cfg
        next_value = self._next_values(next_obs)
        next_values = torch.cat((self.values[1:], next_value[None]))  # V(s_{t+1}) for every t
        live = 1.0 - self.dones
        deltas = self.rewards + cfg.gamma * next_values * live - self.values  # all steps at once; only A is a recursion
        if self.trunc_values is not None:  # games cut short: bootstrap from their final observation's value
            deltas += cfg.gamma * self.trunc_values
        carry = cfg.gamma * cfg.gae_lambda * live
        adv = torch.zeros_like(self.rewards)
        last = torch.zeros(self.n_slots, device=self.device)
        for t in reversed(range(cfg.rollout_steps)):
            last = deltas[t] + carry[t] * last
            adv[t] = last
        return adv, adv + self.values

    def _turn_advantages(self, rewards: np.ndarray, dones: np.ndarray, boot: np.ndarray, acting: np.ndarray,
                         values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """GAE over each slot's own decisions (turn-based games; rows ``(K, slots)``, row 0 the carried decision).

        Scanning backwards, the rewards of steps where the seat did not act are summed into its previous
        decision's reward, up to the seat's next decision or the end of the game (a done at a step where it did
        not act ends the decision before it; the steps after belong to the next game). ``boot`` is V(final obs)
        where a game was truncated (0 otherwise). A decision with a next decision bootstraps from its value and
        chains its advantage; one whose game ended stops there; one with neither (the seat's last, its game still
        running) is carried over. Returns the advantages, the rows to learn from, the row carried (one per slot
        at most) and each carried decision's reward so far."""
        g, lam = self.cfg.gamma, self.cfg.gae_lambda
        k_rows, b = rewards.shape
        adv = np.zeros((k_rows, b), dtype=np.float32)
        learn = np.zeros((k_rows, b), dtype=bool)
        carried = np.zeros((k_rows, b), dtype=bool)
        carry_reward = np.zeros(b, dtype=np.float32)
        follow_r = np.zeros(b, dtype=np.float32)  # rewards after the current row, up to the next decision
        follow = np.full(b, 2)  # what follows: 0 a decision, 1 the end of the game, 2 nothing known yet
        follow_boot = np.zeros(b, dtype=np.float32)
        next_v = np.zeros(b, dtype=np.float32)
        next_a = np.zeros(b, dtype=np.float32)
        for k in reversed(range(k_rows)):
            a, d, r = acting[k], dones[k], rewards[k]
            idle_end = ~a & d
            follow_r = np.where(idle_end, r, np.where(~a, follow_r + r, follow_r))
            follow = np.where(idle_end, 1, follow)
            follow_boot = np.where(idle_end, boot[k], follow_boot)
            reward = np.where(d, r, r + follow_r)
            kind = np.where(d, 1, follow)
            bootstrap = np.where(d, boot[k], follow_boot)
            delta = reward + g * np.where(kind == 0, next_v, bootstrap) - values[k]
            a_k = delta + np.where(kind == 0, g * lam * next_a, 0.0)
            is_learn, is_carry = a & (kind != 2), a & (kind == 2)
            adv[k] = np.where(is_learn, a_k, 0.0)
            learn[k], carried[k] = is_learn, is_carry
            carry_reward = np.where(is_carry, reward, carry_reward)
            next_v = np.where(a, values[k], next_v)
            next_a = np.where(is_learn, a_k, np.where(is_carry, 0.0, next_a))
            follow_r = np.where(a, 0.0, follow_r)
            follow = np.where(a, 0, follow)
            follow_boot = np.where(a, 0.0, follow_boot)
        return adv, learn, carried, carry_reward

    def _turn_batch(self) -> dict[str, Any]:
        """The rollout with the carried decisions as row 0, reduced to the decisions to learn from (turns)."""
        t, b = self.cfg.rollout_steps, self.n_slots
        c = self.carry
        if c is None:
            zeros = torch.zeros((1, b), device=self.device)
            c = {"obs": self.obs[:1] * 0, "actions": self.actions[:1] * 0, "logprobs": zeros, "values": zeros,
                 "reward": zeros[0], "valid": torch.zeros(b, dtype=torch.bool, device=self.device),
                 "masks": None if self.masks is None else torch.ones_like(self.masks[:1]),
                 **{k: v[:1] * 0 for k, v in self.extra.items()}}
        ext = {"obs": torch.cat((c["obs"], self.obs)), "actions": torch.cat((c["actions"], self.actions)),
               "logprobs": torch.cat((c["logprobs"], self.logprobs)), "values": torch.cat((c["values"], self.values)),
               **{k: torch.cat((c[k], v)) for k, v in self.extra.items()}}
        if self.masks is not None:
            cm = c["masks"] if c["masks"] is not None else torch.ones_like(self.masks[:1])
            ext["masks"] = torch.cat((cm, self.masks))
        rewards = torch.cat((c["reward"][None], self.rewards)).cpu().numpy()
        dones = torch.cat((torch.zeros((1, b), device=self.device), self.dones)).cpu().numpy() > 0
        boot = np.zeros((t + 1, b), dtype=np.float32)
        if self.trunc_values is not None:
            boot[1:] = self.trunc_values.cpu().numpy()
        acting = np.concatenate((c["valid"].cpu().numpy()[None], self.acting.cpu().numpy()))  # type: ignore[union-attr]
        values = ext["values"].cpu().numpy()
        adv, learn, carried, carry_reward = self._turn_advantages(rewards, dones, boot, acting, values)
        idx = torch.as_tensor(np.flatnonzero(learn.reshape(-1)), device=self.device)
        flat = {k: v.reshape(-1, *v.shape[2:]).index_select(0, idx) for k, v in ext.items()}
        adv_t = torch.as_tensor(adv.reshape(-1), device=self.device).index_select(0, idx)
        flat["adv"], flat["returns"] = adv_t, adv_t + flat["values"]
        flat["next_carry"] = (ext, carried, carry_reward)
        return flat

    def _set_carry(self, ext: dict[str, torch.Tensor], carried: np.ndarray, carry_reward: np.ndarray) -> None:
        """Keep each slot's carried decision (after the update: its value from the updated network)."""
        rows = torch.as_tensor(carried.argmax(axis=0), device=self.device)
        cols = torch.arange(self.n_slots, device=self.device)
        c = {k: v[rows, cols][None].clone() for k, v in ext.items()}
        c["reward"] = torch.as_tensor(carry_reward, device=self.device)
        c["valid"] = torch.as_tensor(carried.any(axis=0), device=self.device)
        c["values"] = self._values(c["obs"][0], {k: c[k][0] for k in self.extra})[None]
        c.setdefault("masks", None)  # type: ignore[arg-type]
        self.carry = c

    def _batch(self, next_obs: np.ndarray) -> dict[str, Any]:
        """The rollout flat, one row a step of a slot (a decision, in turn-based games: with ``next_carry``, what
        carries over): observations, actions, log-probabilities, values, advantages, returns and masks (or None)."""
        if self.acting is not None:
            return self._turn_batch()
        adv, returns = self._advantages(next_obs)
        return {"obs": self.obs.reshape(-1, self.obs.shape[-1]),
                "actions": self.actions.reshape(-1, *self.actions.shape[2:]), "logprobs": self.logprobs.reshape(-1),
                "values": self.values.reshape(-1), "adv": adv.reshape(-1), "returns": returns.reshape(-1),
                "masks": None if self.masks is None else self.masks.reshape(-1, self.masks.shape[-1]),
                **{k: v.reshape(-1, *v.shape[2:]) for k, v in self.extra.items()}}

    def _minibatch_step(self, batch: dict[str, Any], idx: torch.Tensor, teaching: bool) -> torch.Tensor:
        """One gradient step on the minibatch ``idx`` of ``batch``; returns its figures (:data:`STEP_FIGURES`)."""
        cfg = self.cfg
        out, value = self._forward(batch, idx)
        m = None if batch.get("masks") is None else batch["masks"].index_select(0, idx)
        logp, ent = self.math.log_prob_entropy(out, batch["actions"].index_select(0, idx), m, self.net.log_std)
        entropy = ent.mean()
        log_ratio = logp - batch["logprobs"].index_select(0, idx)
        ratio = log_ratio.exp()
        a = batch["adv"].index_select(0, idx)
        if cfg.norm_adv and a.numel() > 1:
            a = (a - a.mean()) / (a.std() + 1e-8)
        pg_loss = torch.max(-a * ratio, -a * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)).mean()
        v_loss = self._value_loss(value, batch, idx)
        loss = pg_loss + cfg.vf_coef * v_loss - cfg.ent_coef * entropy
        imitation = torch.zeros((), device=self.device)
        if teaching:
            imitation = self.imitation.loss(self.net, idx.numel(), self.rng)  # type: ignore[union-attr]
            loss = loss + self.teacher_weight * imitation
        self.opt.zero_grad()
        loss.backward()
        grad_norm = self.opt.step()  # clips the gradient norm to max_grad_norm first
        with torch.no_grad():
            return torch.stack((pg_loss, v_loss, entropy, (ratio - 1 - log_ratio).mean(),
                                ((ratio - 1).abs() > cfg.clip_coef).float().mean(), imitation, grad_norm))

    def update(self, next_obs: np.ndarray, progress: float = 0.0,
               final_obs: np.ndarray | None = None) -> dict[str, float]:
        """One PPO update on the full rollout; ``progress`` in [0, 1] anneals the learning rate. ``final_obs``: the
        final observations of games truncated on the last recorded step, if not given to :meth:`record`."""
        cfg = self.cfg
        if self._final_due is not None and final_obs is not None:
            self._bootstrap(final_obs)
        self._check_final_given()
        if self.t != cfg.rollout_steps:
            raise RuntimeError("update() before the rollout is full")
        if cfg.anneal_lr:
            self.opt.lr = cfg.lr * max(0.0, 1.0 - progress)
        batch = self._batch(next_obs)
        turns = batch.get("next_carry")
        n = batch["obs"].shape[0]
        mb = max(1, n // cfg.minibatches)
        rows: list[torch.Tensor] = []  # per minibatch: its figures (STEP_FIGURES)
        teaching = self.teacher_weight > 0 and self.imitation is not None and len(self.imitation) > 0
        for _ in range(cfg.update_epochs if n else 0):
            # the process is stopping (SIGTERM, Ctrl-C): this update is thrown away; the run's time is up (a
            # --minutes budget): the minibatches done so far, at least one, are the update
            if stop_requested() or (rows and past_deadline()):
                break
            order = torch.randperm(n, generator=self.gen, device=self.device)
            for start in range(0, n, mb):
                if stop_requested() or (rows and past_deadline()):
                    break
                rows.append(self._minibatch_step(batch, order[start:start + mb], teaching))
        count, per_epoch = len(rows), -(-n // mb)
        planned = (cfg.update_epochs if n else 0) * per_epoch
        self.cut = (count, planned) if 0 < count < planned and not stop_requested() else None
        figures = torch.stack(rows) if rows else torch.zeros((0, len(STEP_FIGURES)), device=self.device)
        check_steps(figures, STEP_FIGURES, lambda r: f"update {self.updates + 1:,} (epoch {r // per_epoch + 1}, "
                                                     f"minibatch {r % per_epoch + 1})")
        stats = figures[:, :6].sum(0)
        if turns is not None:
            self._set_carry(*turns)
        if self.trunc_values is not None:
            self.trunc_values.zero_()
        self.t = 0
        self.updates += 1
        names = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac", "imitation_loss")
        out = {k: float(v) / max(count, 1) for k, v in zip(names, stats.tolist(), strict=True)}
        if teaching:
            out["teacher_weight"] = self.teacher_weight
        else:
            del out["imitation_loss"]
        b_ret, b_val = batch["returns"], batch["values"]
        out["explained_variance"] = float(1 - torch.var(b_ret - b_val) / (torch.var(b_ret) + 1e-8)) if n > 1 else 0.0
        out["lr"] = self.opt.lr
        if turns is not None:
            out["decisions"] = float(n)  # the decisions learned from (turn-based games)
        if self.head.kind == "box":
            out["std"] = float(self.net.log_std.detach().exp().mean())  # type: ignore[union-attr]
        return out

    # -- playing and saving ---------------------------------------------------------------------------------
    def policy(self, id: str, env: str, greedy: bool = False) -> NetworkPolicy:
        """The live network as a policy (no copy): e.g. the 'self' opponent, or for evaluation games."""
        return NetworkPolicy(self.net, id, env, device=self.device, greedy=greedy)

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume: weights, optimiser, sampling generator, update count. (Not a turn-based
        game's carried decisions: a resumed run starts its games afresh.)"""
        return {"net": self.net.state_dict(), "opt": self.opt.state_dict(), "gen": self.gen.get_state(),
                "updates": self.updates}

    def start_from(self, weights: dict[str, torch.Tensor]) -> None:
        """Start from a snapshot's weights (``marl train --init-from``): the network takes them (its value head
        too: a snapshot holds the whole network); the optimiser stays as it is, fresh in a new learner."""
        self.net.load_state_dict(weights)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        self.gen.set_state(state["gen"])
        self.updates = int(state["updates"])
        self.carry = None
        self._final_due = None
