"""Which runs still need a snapshot, so that removing it (``marl checkpoint rm``) never kills a run for good.

A run that is not over can be resumed (``marl train --resume``), and resuming reads, by name: the snapshots of its
last snapshot moment (the run state's ``latest``, ``runs/<run>/state.pt``, or a pending state whose moment was
registered as the run was killed), the snapshots whose rating gauntlet it still owes (the state's ``jobs``) and
its teacher (``[teacher] player``, unless it is ``best`` or ``latest``, which name whatever is best or newest
then). A run whose trainer is at work (a live process holds ``runs/<run>/lock``) also plays its run's snapshots
as opponents and rates its new snapshots against them at any moment. Removing any of these stops the run, and its
``--resume`` would be refused for ever; :func:`needs_of` says which runs need a snapshot and why.

A removal forced anyway ends each run that needed it (status :data:`ENDED`, written in the same transaction as
the removal), and ``--resume`` of such a run is one line saying what it lacks (:func:`check_resumable`).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import MarlError
from ..league.store import League, LeagueError, PlayerRow, RunRow, RunStatus
from .lock import live_trainer
from .state_file import STATE_VERSION, plain_state

ENDED = RunStatus.ENDED
"""The status of a run ended because a snapshot it needed was removed (``marl checkpoint rm --force``): final,
like ``finished``; ``--resume`` refuses it in one line."""
OVER = (RunStatus.FINISHED, ENDED)
"""Statuses of runs that will not be resumed, and so need no snapshot."""
DYNAMIC_NAMES = ("best", "latest")  # a teacher named so is whatever is best or newest when the run resumes


@dataclass(frozen=True)
class Need:
    """A run that needs a snapshot, and why (``why`` reads in brackets after "needed by run 'NAME'")."""

    run: str
    why: str
    pid: int | None = None  # the live process training the run, if one is

    def describe(self) -> str:
        return f"run '{self.run}' ({self.why})"


def trainer_pid(league: League, run: str) -> int | None:
    """The live process training ``run`` (:func:`~selfplay_cli.train.lock.live_trainer`), or None: no lock, a
    stale lock of a killed process, or a league without a home."""
    folder = _run_folder(league, run)
    return None if folder is None else live_trainer(folder / "lock")


def needs_of(league: League, row: PlayerRow) -> list[Need]:
    """The runs (not over) that need snapshot ``row``: its own run while a live trainer plays its snapshots, or
    whose resume state names it; any run of its game whose teacher it is."""
    needs = []
    for run in league.roster.list_runs(env=row.env):
        if run.status in OVER:
            continue
        pid = trainer_pid(league, run.name)
        if run.name == row.run:
            if pid is not None:
                needs.append(Need(run.name, f"its trainer, process {pid}, is at work and plays the run's snapshots",
                                  pid))
                continue
            why = _state_need(league, run, row.full_name)
            if why is not None:
                needs.append(Need(run.name, why))
                continue
        if _starts_from(league, run, row):
            needs.append(Need(run.name, "--init-from: its learners start from it when it takes its first snapshot",
                              pid))
            continue
        teacher = _teacher(run)
        if teacher is not None and teacher not in DYNAMIC_NAMES:
            with contextlib.suppress(MarlError):
                if _resolve_teacher(league, run, teacher).id == row.id:
                    needs.append(Need(run.name, f"its teacher: [teacher] player = {teacher!r}",
                                      pid))
    return needs


def resumable(league: League, name: str, env: str | None = None) -> RunRow:
    """The run ``name`` that ``marl train --resume`` may continue (of game ``env`` where given), or one line saying
    why not: no such run, a configuration that cannot be read, another game, or ended (:func:`check_resumable`).
    Torch-free, so a refused resume is said before the trainer's imports."""
    run = league.roster.get_run(name)
    if run is None:
        raise MarlError(f"no run named '{name}' to resume")
    if run.unusable is not None:  # (said once above it on stderr too)
        raise MarlError(f"run '{name}': its configuration in the league cannot be read ({run.unusable}): start a "
                        "new run")
    if env is not None and env != run.env:
        raise MarlError(f"run '{name}' trains {run.env}, not {env}")
    check_resumable(league, run)  # a run a removed snapshot has ended: one line saying which
    return run


def check_resumable(league: League, run: RunRow) -> None:
    """Refuse, in one line, the resume of a run that a removed snapshot has ended: one marked :data:`ENDED`, or one
    whose resume state names a snapshot removed since (by an older marl, which did not ask): that run is marked
    ended now, unless a live process still trains it."""
    missing = _missing(league, run)
    if run.status != ENDED and not missing:
        return
    if run.status != ENDED and not league.readonly and trainer_pid(league, run.name) is None:
        league.roster.set_run_status(run.name, ENDED)
    what = (f"{', '.join(missing)}, which it needed, " if missing else "a snapshot it needed ") + "was removed"
    raise MarlError(f"run '{run.name}' was ended: {what} (marl checkpoint rm --force), so it cannot be resumed; its "
                    f"snapshots and games stay in the league: train a new run (marl train {run.env})")


# -- what a resume reads --------------------------------------------------------------------------------------------


def _run_folder(league: League, run: str) -> Path | None:
    """``runs/<run>`` under the home, None where there is none (no home, or a run name that is no folder name)."""
    try:
        return league.home_path("runs", run)
    except LeagueError:
        return None


def _state_names(path: Path) -> tuple[list[str], list[str]] | None:
    """A run state's ``latest`` snapshots and the snapshots of its owed gauntlets (full names), or None where there
    is no state a resume could use (no file, unreadable, another version's)."""
    if not path.is_file():
        return None

    def read(state: Any) -> tuple[list[str], list[str]] | None:
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            return None
        return [str(n) for n in state["latest"]], [str(n) for names, _, _ in state["jobs"] for n in names]

    def with_torch(path: Path) -> Any:
        import torch

        return torch.load(path, map_location="cpu", weights_only=True, mmap=True)

    # The plain reader first (no torch); a layout it does not know is read by torch, so a needed snapshot stays
    # needed. A file neither reads is torn or foreign: resuming refuses it by itself.
    for reader in (plain_state, with_torch):
        try:
            return read(reader(path))
        except Exception:
            continue
    return None


def _state_need(league: League, run: RunRow, full_name: str) -> str | None:
    """Why the resume of ``run`` reads snapshot ``full_name`` (its run state or a pending one), or None."""
    folder = _run_folder(league, run.name)
    if folder is None:
        return None
    for path in (folder / "state.pt", folder / "state.pt.pending"):
        names = _state_names(path)
        if names is None:
            continue
        latest, owed = names
        if full_name in latest:
            return "marl train --resume continues from it: the run's last snapshot"
        if full_name in owed:
            return "marl train --resume plays the rating gauntlet the run still owes it"
    return None


def _registered(league: League, full_name: str, env: str) -> bool:
    run, _, name = full_name.partition("/")
    return any(p.run == run and p.name == name for p in league.roster.find_players(full_name, env=env))


def _missing(league: League, run: RunRow) -> list[str]:
    """The snapshots a resume of ``run`` would read that are removed: those of the state it would resume from (a
    pending state whose moment is registered, as :meth:`Trainer.restore` takes it, else ``state.pt``), and its
    teacher."""
    missing = []
    folder = _run_folder(league, run.name)
    if folder is not None:
        pending, state = _state_names(folder / "state.pt.pending"), _state_names(folder / "state.pt")
        if pending is not None and all(_registered(league, n, run.env) for n in pending[0]):
            state = pending
        if state is not None:
            names = dict.fromkeys(state[0] + state[1])
            missing += [n for n in names if not _registered(league, n, run.env)]
    teacher = _teacher(run)
    if teacher is not None and teacher not in DYNAMIC_NAMES:
        with contextlib.suppress(MarlError):
            found = _resolve_teacher(league, run, teacher, include_removed=True)
            if found.removed:
                missing.append(f"its teacher {found.full_name}")
    return missing


def _starts_from(league: League, run: RunRow, row: PlayerRow) -> bool:
    """Whether ``run``'s learners are still to start from snapshot ``row`` (``--init-from``: its ``init_plan``
    names it, and the run has no state of its own yet, which it would resume from instead)."""
    plan = (run.config or {}).get("init_plan")
    learners = plan.get("learners") if isinstance(plan, dict) else None
    if not isinstance(learners, dict) or row.id not in {e.get("id") for e in learners.values() if isinstance(e, dict)}:
        return False
    folder = _run_folder(league, run.name)
    return folder is None or not any((folder / f).exists() for f in ("state.pt", "state.pt.pending"))


def _teacher(run: RunRow) -> str | None:
    teacher = (run.config or {}).get("teacher")
    player = teacher.get("player") if isinstance(teacher, dict) else None
    return player if isinstance(player, str) and player else None


def _resolve_teacher(league: League, run: RunRow, name: str, include_removed: bool = False) -> PlayerRow:
    """The player ``name`` means as the run's teacher, found as the trainer finds it."""
    from ..league.variants import variant_key
    from ..ratings.names import resolve

    options = (run.config or {}).get("env_options")
    return resolve(league, name, run.env, include_removed=include_removed,
                   variant=variant_key(run.env, options if isinstance(options, dict) else {}))
