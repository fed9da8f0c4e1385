"""`marl worker`: lease rating jobs from a league's queue and play them, on any machine."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import EXIT_INTERRUPTED, EXIT_TERMINATED, MarlError
from ..league.job_rows import BEAT_SECONDS, REACH_SECONDS, SCAVENGE_SECONDS
from ..signals import Terminated, stop_on_sigterm
from ._common import MAX_PARALLEL, DbOpt, DeviceOpt, HomeOpt, JsonOpt, QuietOpt, open_league
from ._output import console, err_console, print_json

WORKER_HELP = "\n\n".join((
    "Play the league's queued rating games: lease a job (a few minutes of games of a tournament, an SPRT, a gate, a "
    "training run's gauntlets), play it while beating a heart on it, store its games with the job's end in one "
    "transaction, and take the next. Start any number, on any machine that reaches the database: marl worker --db "
    "postgresql+psycopg://USER@HOST/DB. Snapshots are fetched from the league by their sha256 (checked, cached).",
    "A job whose worker goes silent for --scavenge seconds is taken by another; a job that fails is tried again after "
    "a wait, and marked dead after its tries (marl queue shows them). Ctrl-C or SIGTERM gives the job in play back "
    "at once (and says which). A database that goes away is waited for (said once), and the worker goes on when it "
    "is back; one that cannot be reached when the worker starts is waited for the same way, up to --wait-db seconds.",
    "Without --until-empty or --jobs the worker runs until stopped. Exit codes: 0 done, 2 a bad option or a league it "
    "cannot use, 4 the database cannot be reached within --wait-db seconds of the start, 130 Ctrl-C, 143 SIGTERM.",
))


def worker(
    home: HomeOpt = None,
    db: DbOpt = None,
    batch: Annotated[list[str] | None, typer.Option("--batch", help="Only jobs of this batch (repeatable; marl queue "
                                                    "lists them). Default: every batch.")] = None,
    jobs: Annotated[int | None, typer.Option("--jobs", min=1, help="Leave after this many jobs.")] = None,
    until_empty: Annotated[bool, typer.Option("--until-empty", help="Leave when no job is queued or in play.")] = False,
    beat: Annotated[float, typer.Option("--beat", min=0.05, help="Seconds between heartbeats on the job in play.")
                    ] = BEAT_SECONDS,
    scavenge: Annotated[float, typer.Option("--scavenge", min=0.1, help="A job whose heart has not beaten for this "
                                            "many seconds is taken over from its silent worker.")] = SCAVENGE_SECONDS,
    name: Annotated[str | None, typer.Option("--name", help="How marl queue lists this worker (default "
                                             "worker@HOST:PID).")] = None,
    wait_db: Annotated[float, typer.Option("--wait-db", min=0.0, max=86_400.0, help="Seconds a worker that starts "
                                           "while its database server cannot be reached waits for it (trying again "
                                           "with a growing wait) before it leaves (exit 4); 0: not at all.")
                       ] = REACH_SECONDS,
    device: DeviceOpt = "cpu",
    parallel: Annotated[int, typer.Option("--parallel", min=1, max=MAX_PARALLEL, help="Games played at once.")
                        ] = 1024,
    json_out: JsonOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Lease and play the league's queued rating games (see marl worker --help)."""
    from ..evaluation.jobs import Outcome
    from ..evaluation.worker import Leaving, WorkerOptions, reach_league, run_worker

    if beat >= scavenge:
        raise MarlError(f"--beat ({beat:g} s) must be shorter than --scavenge ({scavenge:g} s), or a working worker's "
                        "jobs would be taken from it")
    _check_blob_settings()
    _check_league_here(home, db)

    def said(line: str) -> None:
        err_console.print(f"marl worker: {line}", markup=False)

    league = reach_league(lambda: open_league(home, db), said, wait_db)
    options = WorkerOptions(batches=tuple(batch) if batch else None, max_jobs=jobs, until_empty=until_empty,
                            beat=beat, scavenge=scavenge, device=device, parallel=parallel, name=name)

    def on_job(out: Outcome) -> None:
        if quiet or json_out:
            return
        j = out.job
        what = f"job {j.id} ({j.batch}, {j.kind}, try {j.tries})"
        if out.state == "done":
            rate = f", {out.games / out.seconds:.1f} games/s" if out.seconds > 0 else ""
            console.print(f"{what}: {out.games} games in {out.seconds:.1f} s{rate}", markup=False)
        elif out.state == "counted":
            console.print(f"{what}: finished by another worker first; counted once", markup=False)
        elif out.state == "lost":
            console.print(f"{what}: cancelled or taken over while in play; dropped", markup=False)
        else:
            console.print(f"{what}: failed ({out.error}); {out.extra.get('state', 'queued')}", markup=False)

    if not (quiet or json_out):
        said(f"leasing jobs from {league!r}" + (f", batches {', '.join(batch)}" if batch else ""))
    left: list[Leaving] = []
    try:
        with stop_on_sigterm():
            report = run_worker(league, options, say=said, on_job=on_job, on_leave=left.append)
    except Terminated:
        said("stopped by SIGTERM; " + (left[0].describe() if left else "no job was in play"))
        raise typer.Exit(EXIT_TERMINATED) from None
    except KeyboardInterrupt:
        said("interrupted; " + (left[0].describe() if left else "no job was in play"))
        raise typer.Exit(EXIT_INTERRUPTED) from None
    finally:
        league.close()
    if json_out:
        print_json(report.to_json())
    elif not quiet:
        gps = f", {report.games / report.seconds:.1f} games/s" if report.seconds > 0 else ""
        console.print(f"{report.name}: {report.done} jobs done, {report.games} games{gps}; {report.counted} finished "
                      f"by another first, {report.failed} failed, {report.lost} dropped", markup=False)


worker.__doc__ = WORKER_HELP


def _check_blob_settings() -> None:
    """This machine's blob settings (MARL_BLOB_LOCATIONS, MARL_BLOB_DEADLINE) read once before any job: one that is
    wrong is one line now, not every job's error."""
    from ..league.locations import allowed_locations, fetch_deadline

    allowed_locations()
    fetch_deadline()


def _check_league_here(home: Path | None, db: str | None) -> None:
    """A worker joins a league that exists: a SQLite league (the home's, or one named by URL) must be a file on this
    machine, since a worker elsewhere cannot share it; nothing is created for a worker."""
    from ..league.store import DB_FILENAME, DEFAULT_HOME

    if not db:
        where = Path(home or DEFAULT_HOME).expanduser() / DB_FILENAME
        if not where.is_file():
            raise MarlError(f"no league at {where.parent}: give the league's database with --db (a league shared by "
                            "machines lives on PostgreSQL: --db postgresql+psycopg://USER@HOST/DB) or its --home")
        return
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        url = make_url(db)
    except ArgumentError:
        return  # (open_league says what is wrong with it)
    if url.get_backend_name() != "sqlite" or url.database in (None, "", ":memory:"):
        return
    path = Path(url.database).expanduser()
    if not path.is_file():
        raise MarlError(f"no league database at {path} on this machine: SQLite leagues live in one file on one "
                        "machine; for workers on other machines put the league on PostgreSQL (--db "
                        "postgresql+psycopg://USER@HOST/DB, docs: Many machines)")
