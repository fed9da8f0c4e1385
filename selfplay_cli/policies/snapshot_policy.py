"""Policy building: a playable network policy from a snapshot file the reader has checked in full
(:func:`~selfplay_cli.policies.snapshot_reader.read_snapshot`): the network its metadata describes, the weights
loaded strictly, and for a joint (SA) agent the policy that flies its whole team.
"""

from __future__ import annotations

import os

import torch

from ..envs import get_env
from .joint import JointPolicy
from .network import NetworkPolicy, SnapshotError, build_network
from .snapshot_format import joint_of
from .snapshot_reader import Snapshot, read_snapshot


def policy_of(
    snap: Snapshot,
    path: str | os.PathLike[str],
    id: str | None = None,
    device: str | torch.device = "cpu",
    greedy: bool = True,
    seed: int = 0,
) -> NetworkPolicy:
    """A playable policy from a snapshot :func:`~selfplay_cli.policies.snapshot_reader.read_snapshot` read from
    ``path`` (weights loaded strictly)."""
    meta = snap.meta
    obs_space, act_space = meta.spaces()
    net = build_network(obs_space, act_space, meta.arch, seed=0)  # the shapes were checked to fit
    try:
        net.load_state_dict(snap.tensors, strict=True)
    except RuntimeError as e:
        raise SnapshotError(f"{path}: weights do not fit the network ({str(e).splitlines()[0]})") from None
    policy = NetworkPolicy(net, id if id is not None else meta.id, meta.env, device=device, greedy=greedy,
                           seed=seed, meta=meta)
    policy.frame_stack = meta.frame_stack  # the game loop gives it the observations it learned on
    joint = joint_of(path, meta)
    if joint is None:
        return policy
    spec = get_env(meta.env)
    seat = spec.seat_spaces(spec.config(**meta.env_options))[0]
    return JointPolicy(policy, joint[0], joint[1], seat.observation, seat.action)  # type: ignore[return-value]


def load_policy(
    path: str | os.PathLike[str],
    id: str | None = None,
    device: str | torch.device = "cpu",
    greedy: bool = True,
    expect_env: str | None = None,
    seed: int = 0,
) -> NetworkPolicy:
    """A playable policy from a snapshot file (validated like
    :func:`~selfplay_cli.policies.snapshot_reader.read_snapshot`, weights loaded strictly).

    ``id`` defaults to ``run/name`` (``name`` for a run-less snapshot). The policy's ``meta`` is the file's.
    """
    return policy_of(read_snapshot(path, expect_env=expect_env), path, id=id, device=device, greedy=greedy,
                     seed=seed)
