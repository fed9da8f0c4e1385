"""A run's state and its snapshot moments: what a moment saves, how it is written as one unit, and the resume.

A snapshot moment saves every learner as a snapshot file, registers them in the league, and writes the run state
(``runs/<run>/state.pt``: the learners' and optimisers' state, the counters, the games' next seed, the opponents'
generator and win rates, the gauntlets asked for) that continues the run exactly from that moment.
"""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from .. import files
from ..envs import EnvSpec
from ..envs.obs_spaces import stacked_space
from ..errors import MarlError
from ..league.store import League
from ..players.files import snapshot_relpath
from ..policies.snapshot_format import SnapshotMeta, save_snapshot
from .config import TrainConfig
from .league_roles import LeagueRoles
from .opponents import Opponents
from .rollouts import Rollouts
from .state_file import STATE_VERSION

Job = tuple[tuple[str, ...], int, bool]
"""A gauntlet asked for, not known to be done: the moment's snapshot names, its first seed, and whether it is the
final one (played in full)."""


@dataclass
class RunState:
    """Where a run stands: the counters and names a snapshot moment saves and a resume restores."""

    steps: int = 0  # game steps played, every session's
    episodes: int = 0  # training games finished
    elapsed: float = 0.0  # seconds trained: before this process (a resumed run), then as training goes
    resumes: int = 0  # sessions before this one
    snapshots: list[str] = field(default_factory=list)  # full names of the run's snapshots, oldest first
    latest: list[int] = field(default_factory=list)  # player id of each learner's latest snapshot (0: none yet)
    jobs: list[Job] = field(default_factory=list)  # gauntlets asked for, not known to be done
    snapshot_step: int = -1  # the steps and episodes at the last snapshot moment
    snapshot_episode: int = -1


def step_label(steps: int) -> str:
    """A step count as a short name, to three significant figures: ``0``, ``500``, ``250k``, ``1M``, ``1.5M``,
    ``4.92M``."""
    rounded = float(f"{int(steps):.3g}")
    for scale, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if rounded >= scale:
            return f"{rounded / scale:g}{unit}"
    return f"{rounded:g}"


@dataclass(frozen=True)
class SavedAs:
    """What every learner's snapshot says of it, beside its weights and its network's arch (the learner's own, as
    its observations made it: an image seat's cnn): the spaces it reads and plays, the role it learns (None: the
    game has one), and a joint learner's seats and base (None: not one)."""

    spaces: list[Any]
    roles: list[str | None]
    joint: dict[str, Any] | None


class SnapshotMoments:
    """Takes one run's snapshot moments and resumes it from the last (see :meth:`write`). In a league
    (``--league``), ``roles`` and each learner's ``first`` state (its ``state_dict`` as it was built), which a
    restart at a snapshot returns it to; both are part of the run state."""

    def __init__(self, league: League, cfg: TrainConfig, spec: EnvSpec, run_dir: Path, *, learners: list[Any],
                 names: list[str], saved: SavedAs, state: RunState, games: Rollouts, opponents: Opponents,
                 device: Any, roles: LeagueRoles | None = None, first: list[dict[str, Any]] | None = None) -> None:
        self.league, self.cfg, self.spec, self.run_dir = league, cfg, spec, run_dir
        self.learners, self.names, self.saved, self.state = learners, names, saved, state
        self.games, self.opponents, self.device = games, opponents, device
        self.roles, self.first = roles, first
        self.parents: list[int] | None = None  # --init-from: the snapshot each learner started from (player id),
        # its first snapshot's parent

    @property
    def state_path(self) -> Path:
        return self.run_dir / "state.pt"

    @property
    def pending_path(self) -> Path:
        return self.run_dir / "state.pt.pending"

    def base_name(self, trigger: str, which: list[int] | None = None) -> str:
        """The name of this snapshot moment (``-<learner>`` is added per learner): by the training step it stands
        for (``s0``, ``s1M``, ``s2M``, ... ``s6M``: every ``--snapshot-steps``, named by the schedule, and the final
        one by the budget; a league role's, ``roles``, by the step it was taken at), or, taken every
        ``--snapshot-every`` episodes, by the episodes finished (``ep90``). ``which``: the learners it saves (None:
        every one)."""
        cfg, steps = self.cfg, self.state.steps
        if trigger == "episodes":
            base = f"ep{self.state.episodes}"
        elif trigger == "steps":
            base = "s" + step_label(steps // cfg.snapshot_steps * cfg.snapshot_steps)
        elif trigger == "final" and cfg.minutes is None:
            base = "s" + step_label(cfg.steps)
        else:  # the start, or the end of a budget in minutes
            base = "s" + step_label(steps)
        taken = {f"{cfg.run}/{n}" for n in self.moment_names(base, which)}
        if taken & set(self.state.snapshots):  # two moments that round to one label: the exact count
            base = f"s{steps}" if not base.startswith("ep") else f"{base}.{steps}"  # decides
        return base

    def moment_names(self, base: str, which: list[int] | None = None) -> list[str]:
        """The snapshot names of a moment called ``base`` of the learners ``which`` (None: every one)."""
        which = list(range(len(self.names))) if which is None else which
        return [base if len(self.names) == 1 else f"{base}-{self.names[i]}" for i in which]

    def write(self, trigger: str, which: list[int] | None = None) -> None:
        """Save and register the snapshot of every learner (``which``: only these), named for ``trigger``
        (:meth:`base_name`), and ask for its gauntlet (with rating games on). A league's role moment (``roles``)
        then restarts the learners its rule restarts (:meth:`LeagueRoles.taken`), before the run state is written.

        One moment is one unit, whatever instant a kill comes at: the files are written first (each to a temporary
        name, then renamed), then the run state as it will be once they are registered (``state.pt.pending``),
        then all the rows in one transaction, which is the moment the snapshots exist; then the pending state
        becomes ``state.pt``. Killed before the transaction, the moment never happened (:meth:`restore` removes its
        files and pending state); killed after it, the pending state is the moment's, complete. A moment that fails
        before its rows are committed (a full disk: a file, the pending state or the rows cannot be written) removes
        what it wrote before the error goes on (:meth:`_undo`), so a failed run leaves no file that no row names.
        """
        cfg = self.cfg
        which = list(range(len(self.learners))) if which is None else list(which)
        names = self.moment_names(self.base_name(trigger, which), which)
        full = [f"{cfg.run}/{n}" for n in names]
        try:
            self._write(trigger, which, names, full)
        except BaseException:
            self._undo(names, full)
            raise

    def _undo(self, names: list[str], full: list[str]) -> None:
        """After a moment failed: unless its rows were committed (then the moment happened and its pending state is
        the run's, as :meth:`restore` finds it), remove its snapshot files and its pending state. Where the league
        cannot tell (its database gone), nothing is touched: the resume asks the league again."""
        try:
            for n in full:
                run, _, name = n.partition("/")
                if any(p.run == run and p.name == name
                       for p in self.league.roster.find_players(n, env=self.spec.name, include_removed=True)):
                    return
        except Exception:  # (the league cannot be asked now)
            return
        for name in names:
            with contextlib.suppress(OSError):
                (self.league.home / snapshot_relpath(self.cfg.run, name)).unlink(missing_ok=True)  # type: ignore[operator]
        with contextlib.suppress(OSError):
            self.pending_path.unlink(missing_ok=True)

    def _write(self, trigger: str, which: list[int], names: list[str], full: list[str]) -> None:
        """:meth:`write`'s work: files, pending state, rows, state."""
        cfg, state = self.cfg, self.state
        rows = [self._save(i, self.learners[i], name) for i, name in zip(which, names, strict=True)]
        latest = [self.league.roster.get_player(p).full_name if p else "" for p in state.latest]
        for i, name in zip(which, full, strict=True):
            latest[i] = name
        jobs = list(state.jobs)
        if cfg.eval_games:
            jobs.append((tuple(full), 10_000_000 + 10_000 * len(state.snapshots), trigger == "final"))
        if self.roles is not None and trigger == "roles":
            for i in self.roles.taken(which, state.steps):  # the snapshot is saved: now the restart
                self.learners[i].load_state_dict(self.first[i])  # type: ignore[index]
        elif cfg.restart_at_snapshot and trigger in ("steps", "episodes"):  # PSRO's oracle: a new best response
            for i in which:
                self.learners[i].load_state_dict(self.first[i])  # type: ignore[index]
        self.write_state(self.pending_path, latest=latest, snapshots=state.snapshots + full, jobs=jobs,
                         snapshot_step=state.steps, snapshot_episode=state.episodes)
        registered = self.league.roster.add_snapshots(rows)  # the moment exists from here on
        files.publish(self.pending_path, self.state_path)
        state.snapshot_episode, state.snapshot_step = state.episodes, state.steps
        for i, row in zip(which, registered, strict=True):
            state.latest[i] = row.id
        state.snapshots += full
        state.jobs = jobs
        self.opponents.set_pool(self.spec.name, steps=state.steps)

    def _save(self, i: int, learner: Any, name: str) -> dict[str, Any]:
        """Learner ``i``'s snapshot file, written as ``name``; the league row that will register it."""
        cfg, state, saved = self.cfg, self.state, self.saved
        rel = snapshot_relpath(cfg.run, name)
        latest = state.latest[i]
        if not latest and self.parents is not None:  # its first snapshot: the one it started from (--init-from)
            latest = self.parents[i]
        parent = self.league.roster.get_player(latest).full_name if latest else None
        meta = SnapshotMeta(env=self.spec.name, env_options=cfg.env_options,
                            obs_space=stacked_space(saved.spaces[i].observation, cfg.frame_stack),
                            act_space=saved.spaces[i].action, arch=learner.net.arch, algo=cfg.algo, step=state.steps,
                            frame_stack=cfg.frame_stack,
                            episode=state.episodes, run=cfg.run, name=name, parent=parent,
                            seat=self.names[i] if len(self.names) > 1 else None, role=saved.roles[i],
                            extra={"learner": self.names[i], **({"joint": saved.joint} if saved.joint else {})})
        meta = save_snapshot(self.league.home / rel, learner.net, meta)  # type: ignore[operator]
        row_meta = {**cfg.snapshot_meta, "weights_sha256": meta.weights_sha256, "learner": self.names[i]}
        if saved.roles[i] is not None:  # the seats it plays (a game whose seats hold several roles)
            row_meta["role"] = saved.roles[i]
        if self.roles is not None:  # its league role (--league)
            row_meta["league_role"] = self.roles.roles[i]
        return dict(env=self.spec.name, run=cfg.run, name=name, path=rel,  # the store hashes the file
                    step=state.steps, episode=state.episodes, algo=cfg.algo, parent_id=latest or None, meta=row_meta)

    def write_state(self, path: Path, *, latest: list[str], snapshots: list[str], jobs: list[Job],
                    snapshot_step: int, snapshot_episode: int) -> None:
        """Everything to continue exactly from a snapshot moment, written to a temporary name, flushed to disk and
        renamed to ``path``. Snapshots are named, not numbered: the state of a moment is written before its rows
        (and their ids) exist."""
        state = self.state
        opponents = self.opponents.state_dict()
        saved = {
            "version": STATE_VERSION,
            "learners": [learner.state_dict() for learner in self.learners],
            "latest": latest, "snapshots": snapshots, "steps": state.steps, "episodes": state.episodes,
            "snapshot_episode": snapshot_episode, "snapshot_step": snapshot_step,
            "next_seed": self.games.next_seed, "elapsed": state.elapsed, "resumes": state.resumes,
            "matchmaker": opponents["matchmaker"], "rates": opponents["rates"],
            "jobs": [[list(names), seed, full] for names, seed, full in jobs],
        }
        if self.roles is not None:
            saved.update(roles=json.dumps(self.roles.state_dict()))
        if self.first is not None:
            saved.update(first=self.first)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        with files.atomic_write(path) as f:
            torch.save(saved, f)

    def read_state(self, path: Path) -> dict[str, Any]:
        try:
            state = torch.load(path, map_location=self.device, weights_only=True)
        except Exception as e:  # a torn or foreign file: say which, never a traceback
            raise MarlError(f"{path}: cannot read the resume state ({e})") from None
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            raise MarlError(f"{path}: resume state written by another marl version; start a new run")
        return state

    def restore(self) -> str:
        """Continue a stopped or killed run from its latest snapshot moment (its lock held); returns a line saying
        from where.

        The league is the authority (see :meth:`write`): a pending state whose snapshots are registered is the
        newest moment's (the run was killed between the rows and the rename); one whose snapshots are not is a
        moment that never happened, and goes, with the files written for it. Files under the run's snapshot folder
        that no row names (a moment cut short, a temporary file of a killed process) go too.
        """
        notes = []
        for torn in self.run_dir.glob("*.tmp-*"):  # half-written by a killed process (the lock is ours now)
            torn.unlink()
        if self.pending_path.exists():
            pending = self.read_state(self.pending_path)
            if all(self._registered(n) for n in pending["latest"]):
                files.publish(self.pending_path, self.state_path)
                notes.append(f"the snapshots {', '.join(pending['latest'])} were registered as it was killed")
            else:
                self.pending_path.unlink()
        if not self.state_path.exists():
            if any(p.run == self.cfg.run for p in self.league.roster.players(env=self.spec.name, kind="snapshot")):
                raise MarlError(f"run '{self.cfg.run}' has snapshots but no resume state ({self.state_path})")
            self._remove_strays()  # killed before its first snapshot: nothing to continue, start it again
            return f"restarted {self.cfg.run} from the beginning (it was stopped before its first snapshot)"
        self._load(self.read_state(self.state_path))
        removed = self._remove_strays()
        if removed:
            notes.append(f"removed {removed} file(s) of a snapshot moment that never completed")
        self.games.restart_all()
        return f"resumed {self.cfg.run} at step {self.state.steps:,} (snapshot {self.state.snapshots[-1]})" + "".join(
            f"; {n}" for n in notes)

    def _load(self, saved: dict[str, Any]) -> None:
        """The learners, counters, opponents and games' next seed as a run state file has them (this session
        counted as one more resume)."""
        try:
            for learner, ls in zip(self.learners, saved["learners"], strict=True):
                learner.load_state_dict(ls)
        except (KeyError, ValueError, RuntimeError) as e:
            raise MarlError(f"{self.state_path}: cannot resume from this state ({e})") from None
        state = self.state
        state.snapshots = list(saved["snapshots"])
        state.latest = [self.player_id(n) for n in saved["latest"]]
        state.steps, state.episodes = int(saved["steps"]), int(saved["episodes"])
        state.snapshot_episode, state.snapshot_step = int(saved["snapshot_episode"]), int(saved["snapshot_step"])
        state.elapsed = float(saved["elapsed"])
        self.opponents.load_state_dict(saved, self.spec.name)
        if self.roles is not None:
            if "roles" not in saved or "first" not in saved:
                raise MarlError(f"{self.state_path}: the run state has no league roles to resume")
            self.roles.load_state_dict(json.loads(saved["roles"]))
        if self.first is not None:
            if "first" not in saved:
                raise MarlError(f"{self.state_path}: the run state has no first weights to restart from")
            self.first = list(saved["first"])
        state.jobs = [(tuple(names), int(seed), bool(full)) for names, seed, full in saved["jobs"]]
        state.resumes = int(saved["resumes"]) + 1
        self.games.next_seed = int(saved["next_seed"]) + (state.resumes << 40)  # a seed range of its own

    def player_id(self, full_name: str) -> int:
        """The league player of one of the run's snapshots, by its full name (``run/name``)."""
        run, _, name = full_name.partition("/")
        found = [p for p in self.league.roster.find_players(full_name,
                                                            env=self.spec.name) if p.run == run and p.name == name]
        if not found:
            raise MarlError(f"run '{self.cfg.run}': snapshot {full_name} of its resume state is not in the league")
        return found[0].id

    def _registered(self, full_name: str) -> bool:
        try:
            self.player_id(full_name)
        except MarlError:
            return False
        return True

    def _remove_strays(self) -> int:
        """Remove the files under ``snapshots/<run>/`` that no row of the league names."""
        folder = self.league.home / snapshot_relpath(self.cfg.run, "x").rsplit("/", 1)[0]  # type: ignore[operator]
        if not folder.is_dir():
            return 0
        known = set()
        for p in self.league.roster.players(env=self.spec.name, kind="snapshot", include_removed=True):
            if p.run == self.cfg.run:
                with contextlib.suppress(MarlError):  # a row whose path leaves the league names no file here
                    known.add(self.league.snapshot_file(p))
        removed = 0
        for f in folder.iterdir():
            if f.is_file() and f not in known:
                f.unlink()
                removed += 1
        return removed

