"""The optimiser the learners share: Adam over one flat buffer of a network's parameters."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import torch


def flatten(params: Iterable[torch.Tensor]) -> torch.Tensor:
    """Move ``params`` into one new contiguous tensor (same device and dtype) and make each a view of it; returns it.

    Whole-network operations (an optimiser step, a target-network copy) then become one operation on it."""
    params = list(params)
    first = params[0]
    flat = torch.empty(sum(p.numel() for p in params), device=first.device, dtype=first.dtype)
    offset = 0
    with torch.no_grad():
        for p in params:
            n = p.numel()
            flat[offset:offset + n].copy_(p.reshape(-1))
            p.data = flat[offset:offset + n].view_as(p)
            offset += n
    return flat


class FlatAdam:
    """Adam (Kingma & Ba; PyTorch's exact update) over one flat buffer holding all of a network's parameters.

    The parameters become views into one contiguous tensor, and their ``.grad`` views into a second one, which
    autograd accumulates into in place. A step is then a handful of whole-buffer operations (the gradient norm for
    clipping, the two moment updates, the parameter update) instead of per-parameter bookkeeping: on this
    project's small networks ``torch.optim.Adam``'s Python overhead (grouping, zeroing, a norm per tensor for
    clipping) was a third of a DQN gradient step. The network must be on its final device before the optimiser is
    made; ``load_state_dict`` on the network copies into the views, so loading weights keeps them flat.

    Per step t with gradient g (after clipping its global norm to ``max_grad_norm`` when that is > 0):
        m = b1 m + (1 - b1) g,   v = b2 v + (1 - b2) g^2,
        p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)
    """

    def __init__(self, params: Iterable[torch.nn.Parameter], lr: float, betas: tuple[float, float] = (0.9, 0.999),
                 eps: float = 1e-8, max_grad_norm: float = 0.0) -> None:
        self.params = [p for p in params if p.requires_grad]
        if not self.params:
            raise ValueError("FlatAdam needs at least one parameter")
        self.flat = flatten(self.params)
        self.grad = torch.zeros_like(self.flat)
        offset = 0
        for p in self.params:
            p.grad = self.grad[offset:offset + p.numel()].view_as(p)
            offset += p.numel()
        self.m = torch.zeros_like(self.flat)
        self.v = torch.zeros_like(self.flat)
        self.lr, self.betas, self.eps, self.max_grad_norm = float(lr), betas, float(eps), float(max_grad_norm)
        self.steps = 0

    def zero_grad(self) -> None:
        self.grad.zero_()

    def step(self) -> torch.Tensor:
        """One Adam step from the accumulated gradients; returns the gradient norm before clipping."""
        g = self.grad
        norm = torch.linalg.vector_norm(g)
        if self.max_grad_norm > 0:
            g.mul_((self.max_grad_norm / (norm + 1e-6)).clamp_(max=1.0))  # as nn.utils.clip_grad_norm_
        b1, b2 = self.betas
        self.steps += 1
        self.m.lerp_(g, 1 - b1)
        self.v.mul_(b2).addcmul_(g, g, value=1 - b2)
        denom = (self.v.sqrt() / math.sqrt(1 - b2 ** self.steps)).add_(self.eps)
        with torch.no_grad():
            self.flat.addcdiv_(self.m, denom, value=-self.lr / (1 - b1 ** self.steps))
        return norm

    def state_dict(self) -> dict[str, Any]:
        return {"m": self.m, "v": self.v, "steps": self.steps, "lr": self.lr}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Moments and step count from :meth:`state_dict` (a resume); refuses another optimiser's state."""
        if not isinstance(state, dict) or not {"m", "v", "steps", "lr"} <= set(state):
            raise ValueError("optimiser state from another optimiser (saved by an older marl?)")
        if state["m"].shape != self.m.shape:
            raise ValueError(f"optimiser state for {state['m'].numel()} parameters; this network has {self.m.numel()}")
        self.m.copy_(state["m"])
        self.v.copy_(state["v"])
        self.steps = int(state["steps"])
        self.lr = float(state["lr"])
