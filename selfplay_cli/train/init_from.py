"""``marl train GAME --init-from SNAPSHOT_OR_TEAM``: a run whose learners start from a snapshot's weights.

What the name means (:func:`plan_init`, when the run is created, so a refusal leaves no run behind):

* one snapshot of the game (``l2/s4k``, a tag, an id, ``latest``...): every learner starts from it, whatever the
  run's team size or sharing (a shared network, FuPS, starts from it directly; with one network per learner, NoPS,
  each starts from a copy);
* a team, the per-learner snapshots of one moment of a run (``l4/s4k`` for ``l4/s4k-lander_0`` ...
  ``l4/s4k-lander_3``; its members in the seat order of the run that trained them): learner ``i`` starts from
  member ``resize_members(members, learners, seed)[i]`` (:func:`~selfplay_cli.policies.resize.resize_members`, seed
  001's rule, drawn from the run's ``--seed``): the first members keep their places, extra learners copy members
  from the third on (a team of 1 or 2: any member), fewer learners drop members from the third on. A shared network
  (FuPS, one learner) starts from the team's first member.

The snapshot may be of another variant of the game (the lander's ``landers=2`` team into a ``landers=3`` run: that
is the point); its networks must fit the learners' exactly (the observations, the actions, the layers: refused in
one line naming the difference otherwise), and it must have been trained by the run's algorithm (a DQN snapshot
cannot start a PPO learner: their networks' heads mean different things).

The network takes the snapshot's weights; everything else starts fresh: the optimiser (its moments and step count),
PPO's and DQN's generators, SAC's critics (a snapshot holds the actor only), the replay buffers. DQN's target network
is synced to the weights. The plan is saved in the run's configuration (``init_plan``: the member each learner
starts from), said in the first metrics line and in ``--json``; the first snapshot of each learner names its
member as its parent (``marl checkpoint NAME`` shows the lineage). The weights are loaded when the run takes its
first snapshot moment: a resumed run continues from its own state, never from its parent's again.
"""

from __future__ import annotations

from typing import Any

import torch

from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..league.variants import variant_key
from ..policies.resize import describe_resize, resize_members
from ..policies.snapshot_format import expected_tensors, fit_problems
from ..policies.spaces import describe_space
from .config import TrainConfig, learner_setup
from .learners import run_learners

__all__ = ["load_init", "plan_init"]


def _team(league: League, text: str, env: str) -> list[PlayerRow] | None:
    """The team ``text`` names (``run/base`` or ``base``): the live snapshots ``<base>-<learner>`` of one run, each
    the snapshot of the learner its name ends in, in the seat order of the run that trained them (its own variant's
    seats); None if there are none. Several runs with such a team: one line asking for ``run/name``."""
    run, _, base = text.rpartition("/")
    by_run: dict[str, list[PlayerRow]] = {}
    for p in league.roster.players(env=env, kind="snapshot"):
        learner = p.meta.get("learner")
        if (p.run is None or (run and p.run != run) or not isinstance(learner, str)
                or p.name != f"{base}-{learner}"):
            continue
        by_run.setdefault(p.run, []).append(p)
    teams = {r: ms for r, ms in by_run.items() if len(ms) > 1}
    if len(teams) > 1:
        raise MarlError(f"--init-from: '{text}' is a team in several runs ({', '.join(sorted(teams))}): use run/name")
    if not teams:
        return None
    (run_name, members), = teams.items()
    return sorted(members, key=lambda p: _seat_order(league, run_name, env, p))


def _seat_order(league: League, run: str, env: str, p: PlayerRow) -> tuple[int, str]:
    """Where a team member sits in the run that trained it: its learner's seat in that run's variant of the game
    (a league's roles, which hold no seat of their own, after the seats in name order)."""
    from ..envs import get_env
    from ..players.snapshots import run_options

    try:
        agents = get_env(env).for_options(**run_options(league, run)).agents
    except (MarlError, TypeError, ValueError):
        agents = get_env(env).agents
    learner = p.meta.get("learner")
    return (agents.index(learner), "") if learner in agents else (len(agents), p.name)


def _source(league: League, cfg: TrainConfig) -> tuple[str, list[PlayerRow]]:
    """What ``cfg.init_from`` names in the run's game: (its full name, its members in seat order): one snapshot (a
    list of one), or a team. One line for an unknown name, a scripted player, a removed snapshot."""
    from ..ratings.names import resolve

    name = cfg.init_from
    try:
        row = resolve(league, name, cfg.env, variant=variant_key(cfg.env, cfg.env_options))
    except MarlError as e:
        members = _team(league, name, cfg.env)
        if members is None:
            raise MarlError(f"--init-from: {e}") from None
        return f"{members[0].run}/{name.rpartition('/')[2]}", members
    if row.kind != "snapshot":
        raise MarlError(f"--init-from: {row.full_name} is a scripted player, not a snapshot: it has no weights to "
                        "start from (a scripted player can be a --teacher)")
    return row.full_name, [row]


def _read(league: League, row: PlayerRow) -> Any:
    """The snapshot file of ``row``, validated in full (the hostile-file reader) and checked to be the one its row
    registered."""
    from ..players.files import read_row_snapshot

    if row.removed:
        raise MarlError(f"--init-from: {row.full_name} was removed from the league")
    try:
        snap, _ = read_row_snapshot(league, row)
    except MarlError as e:
        raise MarlError(f"--init-from: {e}") from None
    return snap


def _check_fit(cfg: TrainConfig, name: str, space: Any, row: PlayerRow, snap: Any) -> None:
    """Refuse, in one line, a snapshot that cannot start learner ``name`` of seat ``space``: a joint snapshot,
    another algorithm's, other spaces, other layers."""
    meta = snap.meta
    if isinstance(meta.extra, dict) and meta.extra.get("joint"):
        raise MarlError(f"--init-from: {row.full_name} is one agent over a whole team (--sharing sa): it cannot "
                        f"start learner {name}, which plays one seat")
    if meta.algo and meta.algo != cfg.algo:
        raise MarlError(f"--init-from: {row.full_name} was trained by {meta.algo}; this run learns with {cfg.algo}: "
                        f"use --algo {meta.algo}")
    seat, section = learner_setup(cfg, space)
    obs, act = tuple(seat.observation.shape), describe_space(seat.action)
    snap_act = describe_space(meta.spaces()[1])
    if tuple(meta.obs_shape) != obs:
        raise MarlError(f"--init-from: {row.full_name} reads observations of shape {list(meta.obs_shape)}; learner "
                        f"{name} of this run reads {list(obs)}")
    if snap_act != act:
        raise MarlError(f"--init-from: {row.full_name} plays {snap_act}; learner {name} of this run plays {act}")
    expected = expected_tensors(obs, seat.action, section.arch)
    problems = fit_problems({k: tuple(v.shape) for k, v in snap.tensors.items()}, expected)
    if problems:
        raise MarlError(f"--init-from: {row.full_name}'s network ({meta.arch.describe()}) does not fit learner "
                        f"{name}'s ({section.arch.describe()}): {'; '.join(problems[:3])}; give the run the "
                        f"snapshot's network ([{cfg.algo}.arch])")


def plan_init(league: League, cfg: TrainConfig) -> dict[str, Any]:
    """What ``cfg.init_from`` starts each learner from, checked (the snapshots read and fitted to the learners):
    ``from`` (as typed), ``source`` (its full name), ``members`` (its snapshots, seat order), ``rule`` (how the
    members were given to the learners, in words) and ``learners``: per learner name, the ``member`` (its index)
    and ``snapshot`` (full name, and ``id``) it starts from. Empty without ``init_from``."""
    if not cfg.init_from:
        return {}
    source, members = _source(league, cfg)
    names, spaces = run_learners(cfg)
    if len(members) == 1:
        picks = [0] * len(names)
        rule = "one snapshot: every learner starts from it"
    else:
        picks = resize_members(len(members), len(names), cfg.seed)
        rule = (describe_resize(len(members), len(names)) if len(names) > 1
                else f"a team of {len(members)} into one shared network: it starts from the first member")
    snaps: dict[int, Any] = {}
    for name, space, k in zip(names, spaces, picks, strict=True):
        row = members[k]
        if row.id not in snaps:
            snaps[row.id] = _read(league, row)
        _check_fit(cfg, name, space, row, snaps[row.id])
    return {"from": cfg.init_from, "source": source, "members": [m.full_name for m in members], "rule": rule,
            "seed": cfg.seed,
            "learners": {name: {"member": k, "snapshot": members[k].full_name, "id": members[k].id}
                         for name, k in zip(names, picks, strict=True)}}


def load_init(league: League, cfg: TrainConfig, learners: list[Any], names: list[str]) -> list[int]:
    """Start each learner from its snapshot of ``cfg.init_plan`` (:func:`plan_init`): its network takes the weights
    (``learner.start_from``: the optimiser and the rest stay fresh). Returns the player id each learner started
    from, its first snapshot's parent. One line if a snapshot has gone or changed since the run was created."""
    plan = cfg.init_plan["learners"]
    read: dict[int, Any] = {}
    parents = []
    for learner, name in zip(learners, names, strict=True):
        entry = plan.get(name)
        if not isinstance(entry, dict):
            raise MarlError(f"run '{cfg.run}': its init_plan names no snapshot for learner {name}")
        try:
            row = league.roster.get_player(int(entry["id"]))
        except (MarlError, KeyError, TypeError, ValueError):
            raise MarlError(f"--init-from: snapshot {entry.get('snapshot')} is no longer in the league") from None
        if row.full_name != entry.get("snapshot"):
            raise MarlError(f"--init-from: player #{row.id} is {row.full_name}, not {entry.get('snapshot')}")
        if row.id not in read:
            read[row.id] = _read(league, row)
        try:
            learner.start_from({k: v.to(torch.float32) for k, v in read[row.id].tensors.items()})
        except RuntimeError as e:  # (checked when the run was created; a file changed since is caught above)
            raise MarlError(f"--init-from: {row.full_name} does not fit learner {name} ({e})") from None
        parents.append(row.id)
    return parents
