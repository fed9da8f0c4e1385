"""One training session of a run, from start (or resume) to its end, with the run's status kept true.

:func:`run_training` builds the :class:`~.loop.Trainer`, restores a resumed run (taking its lock), trains, and
writes what became of the run into the league: ``running`` once a resumed run is this process's, ``finished``,
``stopped`` on Ctrl-C or SIGTERM (raised as :class:`RunStopped`, which says at which step), ``failed`` on anything
else. A refused resume (another process trains the run) leaves the run's status as it was. The CLI only prints.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..errors import MarlError
from ..league.roster import RunStatus
from ..league.store import League
from ..signals import Terminated
from .config import TrainConfig
from .loop import Trainer
from .progress import TrainReport

__all__ = ["RunStopped", "run_training"]


class RunStopped(Exception):  # noqa: N818 (a run stopped on request, not an error)
    """The run was stopped by Ctrl-C (``why`` "Ctrl-C") or SIGTERM ("SIGTERM") at game step ``steps`` (None when it
    stopped before its trainer existed); its status is ``stopped`` and its last snapshot moment is kept."""

    def __init__(self, why: str, steps: int | None) -> None:
        super().__init__(f"stopped ({why})")
        self.why = why
        self.steps = steps


def run_training(league: League, cfg: TrainConfig, *, resumed: bool,
                 on_progress: Callable[[dict[str, Any]], None] | None = None,
                 on_note: Callable[[str], Any] | None = None) -> TrainReport:
    """Train run ``cfg.run`` (already created in ``league``, or being resumed) to its budget and return the
    trainer's report; ``on_note`` is told what a resume found (the moment it continues from)."""
    trainer = None
    claimed = not resumed  # a resumed run is this process's once restore has taken its lock
    try:
        trainer = Trainer(league, cfg, on_progress=on_progress)
        if resumed:
            note = trainer.restore()
            claimed = True
            league.roster.set_run_status(cfg.run, RunStatus.RUNNING)
            if on_note is not None:
                on_note(note)
        report = trainer.train()
    except (KeyboardInterrupt, Terminated) as stop:
        league.roster.set_run_status(cfg.run, RunStatus.STOPPED)
        raise RunStopped("SIGTERM" if isinstance(stop, Terminated) else "Ctrl-C",
                         trainer.state.steps if trainer is not None else None) from None
    except MarlError:
        if claimed:  # a refused resume (e.g. another process trains it) leaves the run as it is
            league.roster.set_run_status(cfg.run, RunStatus.FAILED)
        raise
    except BaseException:  # whatever else ends it, the run is not left 'running'
        league.roster.set_run_status(cfg.run, RunStatus.FAILED)
        raise
    league.roster.set_run_status(cfg.run, RunStatus.FINISHED)
    return report
