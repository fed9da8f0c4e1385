"""FlatAdam: the same update as torch.optim.Adam (with clip_grad_norm_), on one flat buffer."""

from __future__ import annotations

import pytest
import torch

from selfplay_cli.algos import FlatAdam, flatten
from selfplay_cli.policies.network import Arch, build_network


def _loss(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    logits, value = net(x)
    return ((logits - y) ** 2).mean() + value.square().mean()


@pytest.mark.slow
@pytest.mark.parametrize("max_norm", [0.0, 0.05])
def test_flat_adam_matches_torch_adam(max_norm: float) -> None:
    arch = Arch(hidden=(16, 8), activation="tanh", value_head=True)
    ours, ref = build_network((4,), 3, arch, seed=1), build_network((4,), 3, arch, seed=1)
    opt = FlatAdam(ours.parameters(), lr=3e-3, eps=1e-5, max_grad_norm=max_norm)
    ref_opt = torch.optim.Adam(ref.parameters(), lr=3e-3, eps=1e-5)
    gen = torch.Generator().manual_seed(0)
    clipped = 0
    for _ in range(25):
        x, y = torch.randn(32, 4, generator=gen), torch.randn(32, 3, generator=gen) * 5
        opt.zero_grad()
        _loss(ours, x, y).backward()
        norm = float(opt.step())
        ref_opt.zero_grad()
        _loss(ref, x, y).backward()
        if max_norm:
            ref_norm = float(torch.nn.utils.clip_grad_norm_(ref.parameters(), max_norm))
            assert norm == pytest.approx(ref_norm, rel=1e-4)
            clipped += norm > max_norm
        ref_opt.step()
    for (name, p), q in zip(ours.named_parameters(), ref.parameters(), strict=True):
        assert torch.allclose(p, q, atol=1e-6), name
    assert clipped > 0 or not max_norm  # the clipping path was exercised
    # The parameters are views of the flat buffer, the grads views of the flat gradient.
    assert all(p.data_ptr() >= opt.flat.data_ptr() for p in ours.parameters())
    assert sum(p.numel() for p in ours.parameters()) == opt.flat.numel()


def test_flat_adam_resumes_exactly_and_refuses_foreign_state() -> None:
    arch = Arch(hidden=(8,), activation="relu", value_head=True)
    a, b = build_network((4,), 2, arch, seed=2), build_network((4,), 2, arch, seed=3)
    opt_a = FlatAdam(a.parameters(), lr=1e-2)
    x, y = torch.randn(16, 4), torch.randn(16, 2)
    for _ in range(3):
        opt_a.zero_grad()
        _loss(a, x, y).backward()
        opt_a.step()
    opt_b = FlatAdam(b.parameters(), lr=1e-2)
    b.load_state_dict(a.state_dict())  # copies into the flat views
    opt_b.load_state_dict(opt_a.state_dict())
    for net, opt in ((a, opt_a), (b, opt_b)):
        opt.zero_grad()
        _loss(net, x, y).backward()
        opt.step()
    assert torch.equal(opt_a.flat, opt_b.flat)
    with pytest.raises(ValueError, match="another optimiser"):
        opt_b.load_state_dict(torch.optim.Adam(a.parameters()).state_dict())


def test_flatten_keeps_values_and_shares_storage() -> None:
    ps = [torch.nn.Parameter(torch.randn(3, 2)), torch.nn.Parameter(torch.randn(5))]
    before = [p.detach().clone() for p in ps]
    flat = flatten(ps)
    assert all(torch.equal(p, q) for p, q in zip(ps, before, strict=True))
    flat.zero_()
    assert all(not p.any() for p in ps)
