"""The distributions behind the action heads, shared by network policies and the learners (torch).

* Discrete: a categorical over ``n`` logits; disallowed actions get ``fill`` (-inf for playing; the learners use the
  finite :data:`MASKED`, so entropies and their gradients never meet ``0 * -inf``).
* MultiDiscrete: one categorical per dimension. The ``sum(nvec)`` logits are laid out as a padded ``(B, k, W)``
  tensor (``W = max(nvec)``, padding masked), so every dimension is handled by the same batched operations; the
  log-probability and entropy of an action are the sums over its dimensions.
* Box: a diagonal Gaussian with the head's outputs as means and a learned, state-independent ``log_std`` per
  dimension. Log-probabilities and entropies are summed over dimensions; the sample ``mean + std * eps`` is what the
  learner stores (its log-probability is that of the unclipped sample), the game gets it clipped to the bounds.
* Box, squashed (an arch with ``squash``, SAC's actor): a diagonal Gaussian whose mean and log-std both come from the
  network (state-dependent std), squashed by tanh into [-1, 1] and mapped affinely onto the bounds. The log-std is
  ``tanh`` of its head's output mapped onto [:data:`LOG_STD_MIN`, :data:`LOG_STD_MAX`] (CleanRL's SAC). Greedy is
  ``tanh(mean)`` on the bounds; a sample is ``tanh(mean + std * eps)`` on the bounds. Log-probabilities (for
  learning) are those of the squashed action ``y = tanh(u)`` in [-1, 1], whatever the bounds, so an entropy target
  means the same for every Box.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .spaces import ActionHead, pad_index

MASKED = -1e9  # a disallowed action's logit in learning (exp underflows to exactly 0 in float32)
LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)
LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0  # a squashed Gaussian's log-std range (CleanRL's SAC)
LOG_2 = math.log(2.0)


class HeadMath:
    """An :class:`ActionHead`'s tensors on one device: padding indices (MultiDiscrete), bounds (Box)."""

    def __init__(self, head: ActionHead, device: torch.device | str = "cpu") -> None:
        self.head = head
        self.kind = head.kind
        self.device = torch.device(device)
        if head.kind == "multidiscrete":
            index, valid = pad_index(head.nvec)
            self.index = torch.from_numpy(index).to(self.device)
            self.valid = torch.from_numpy(valid).to(self.device)
            self.last = torch.tensor(head.nvec, device=self.device) - 1  # (k,)
        if head.kind == "box":
            self.low = torch.tensor(head.low, dtype=torch.float32, device=self.device)
            self.high = torch.tensor(head.high, dtype=torch.float32, device=self.device)

    # -- categorical heads ----------------------------------------------------------------------------------
    def padded(self, logits: torch.Tensor, mask: torch.Tensor | None, fill: float) -> torch.Tensor:
        """MultiDiscrete logits ``(B, sum(nvec))`` as ``(B, k, W)``, padding and disallowed entries at ``fill``."""
        out = logits[:, self.index]
        allowed = self.valid if mask is None else (mask[:, self.index] & self.valid)
        return out.masked_fill(~allowed, fill)

    def masked(self, logits: torch.Tensor, mask: torch.Tensor | None, fill: float) -> torch.Tensor:
        """Logits ready for a softmax over the last axis: Discrete ``(B, n)``, MultiDiscrete ``(B, k, W)``."""
        if self.kind == "multidiscrete":
            return self.padded(logits, mask, fill)
        return logits if mask is None else logits.masked_fill(~mask, fill)

    def log_prob_entropy(self, out: torch.Tensor, actions: torch.Tensor, mask: torch.Tensor | None,
                         log_std: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-row log-probability of ``actions`` and entropy of the policy (both ``(B,)``), for learning."""
        if self.kind == "box":
            assert log_std is not None
            return gaussian_log_prob(out, log_std, actions), gaussian_entropy(log_std).expand(out.shape[0])
        logp_all = torch.log_softmax(self.masked(out, mask, MASKED), dim=-1)
        if self.kind == "discrete":
            logp = logp_all.gather(1, actions[:, None]).squeeze(1)
            entropy = -(logp_all.exp() * logp_all).sum(-1)
        else:
            logp = logp_all.gather(2, actions[:, :, None]).squeeze(2).sum(1)
            entropy = -(logp_all.exp() * logp_all).sum(-1).sum(-1)
        return logp, entropy

    def sample(self, out: torch.Tensor, mask: torch.Tensor | None, generator: torch.Generator, greedy: bool,
               log_std: torch.Tensor | None = None, fill: float = float("-inf")) -> tuple[torch.Tensor, torch.Tensor]:
        """Actions for the outputs ``out``: ``(stored, played)``. They differ only for a Box head (the stored sample
        is unclipped, the played one clipped to the bounds); greedy is the argmax or the clipped mean."""
        if self.kind == "box":
            if greedy:
                a = out
            else:
                assert log_std is not None
                eps = torch.randn(out.shape, generator=generator, device=out.device)
                a = out + log_std.exp() * eps
            return a, self.clip(a)
        logits = self.masked(out, mask, fill)
        if greedy:
            a = logits.argmax(dim=-1)
        else:  # inverse CDF with one uniform per row and dimension
            probs = torch.softmax(logits, dim=-1)
            cdf = probs.cumsum_(dim=-1)
            u = torch.rand((*cdf.shape[:-1], 1), generator=generator, device=out.device)
            a = torch.searchsorted(cdf, u, right=True).squeeze(-1)
            a = torch.minimum(a, self.last) if self.kind == "multidiscrete" else a.clamp_(max=cdf.shape[-1] - 1)
            # A row whose cdf ends a rounding error below u would land past its last allowed action: take the argmax
            chosen = logits.gather(-1, a[..., None]).squeeze(-1)
            a = torch.where(chosen == fill, logits.argmax(dim=-1), a)
        return a, a

    def clip(self, a: torch.Tensor) -> torch.Tensor:
        flat = a.reshape(a.shape[0], -1)
        return torch.maximum(torch.minimum(flat, self.high), self.low).reshape(a.shape)

    def to_bounds(self, y: torch.Tensor) -> torch.Tensor:
        """Squashed actions ``y`` in [-1, 1] ``(B, d)`` mapped affinely onto the Box bounds (clipped against float
        rounding, so an action is always within them)."""
        return self.clip(self.low + (y + 1.0) * (0.5 * (self.high - self.low)))

    def sample_squashed(self, mean: torch.Tensor, log_std: torch.Tensor, generator: torch.Generator,
                        greedy: bool) -> torch.Tensor:
        """A squashed Gaussian's played actions on the bounds: ``tanh(mean)`` (greedy) or ``tanh(mean + std * eps)``.
        """
        u = mean
        if not greedy:
            u = mean + log_std.exp() * torch.randn(mean.shape, generator=generator, device=mean.device)
        return self.to_bounds(torch.tanh(u))


def squashed_log_std(raw: torch.Tensor) -> torch.Tensor:
    """A squashed Gaussian's log-std from its head's output: ``tanh`` mapped onto [LOG_STD_MIN, LOG_STD_MAX]."""
    return LOG_STD_MIN + (0.5 * (LOG_STD_MAX - LOG_STD_MIN)) * (torch.tanh(raw) + 1.0)


def squashed_sample(mean: torch.Tensor, log_std: torch.Tensor,
                    generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """A reparameterised sample ``y = tanh(mean + std * eps)`` in [-1, 1] ``(B, d)`` and its log-probability
    ``(B,)``: ``log N(u; mean, std) - sum log(1 - tanh(u)^2)``, the Jacobian term written stably as
    ``2 (log 2 - u - softplus(-2u))``. Gradients flow to ``mean`` and ``log_std``."""
    eps = torch.randn(mean.shape, generator=generator, device=mean.device)
    u = mean + log_std.exp() * eps
    log_gauss = (-0.5 * eps.square() - log_std - LOG_SQRT_2PI).sum(-1)
    log_jacobian = (2.0 * (LOG_2 - u - torch.nn.functional.softplus(-2.0 * u))).sum(-1)
    return torch.tanh(u), log_gauss - log_jacobian


def gaussian_log_prob(mean: torch.Tensor, log_std: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """log N(actions; mean, exp(log_std)^2), summed over the action dimensions: ``(B,)``."""
    mean, actions = mean.reshape(mean.shape[0], -1), actions.reshape(actions.shape[0], -1)
    z = (actions - mean) * torch.exp(-log_std)
    return (-0.5 * z.square() - log_std - LOG_SQRT_2PI).sum(-1)


def gaussian_entropy(log_std: torch.Tensor) -> torch.Tensor:
    """The entropy of a diagonal Gaussian: sum over dimensions of ``1/2 + log(sqrt(2 pi)) + log_std`` (a scalar)."""
    return (0.5 + LOG_SQRT_2PI + log_std).sum()


def to_numpy_actions(head: ActionHead, actions: torch.Tensor) -> np.ndarray:
    """Played actions as the game wants them: int64 ``(B,)`` / ``(B, k)``, or float32 ``(B, *shape)``."""
    a = actions.detach().to("cpu")
    if head.kind == "box":
        return a.reshape(a.shape[0], *head.shape).numpy().astype(np.float32, copy=False)
    return a.numpy().astype(np.int64, copy=False)
