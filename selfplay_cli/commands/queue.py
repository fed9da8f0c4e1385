"""`marl queue`: the league's work queue: batches, jobs, workers; cancel a job or a batch."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

import typer

from ..errors import MarlError
from ..league.job_rows import JOB_STATES, JobRow, WorkerRow
from ..league.models import utcnow
from ._common import DbOpt, HomeOpt, JsonOpt, open_league
from ._output import console, print_json

app = typer.Typer(help="The league's work queue: queued, leased, done and dead jobs, the workers, cancelling.",
                  no_args_is_help=False, invoke_without_command=True, rich_markup_mode=None)

BatchOpt = Annotated[str | None, typer.Option("--batch", help="Only this batch (a tournament, a match, a run's "
                                              "gauntlets: the first column of marl queue).")]


@app.callback(invoke_without_command=True)
def show(
    ctx: typer.Context,
    home: HomeOpt = None,
    db: DbOpt = None,
    batch: BatchOpt = None,
    state: Annotated[list[str] | None, typer.Option("--state", help="Only jobs in this state (repeatable): queued, "
                                                    "leased, done, dead, cancelled.")] = None,
    last: Annotated[int, typer.Option("--last", min=0, help="Jobs listed (the newest).")] = 20,
    json_out: JsonOpt = False,
) -> None:
    """Show the queue: every batch with its jobs by state; the workers (alive, silent or stopped; the jobs each
    holds; jobs done, games and games/s); the newest jobs (--batch, --state, --last), with the error of each dead
    one. A worker is silent when its heart has not beaten for 360 s; its job then goes to the next worker."""
    if ctx.invoked_subcommand is not None:
        return
    for s in state or []:
        if s not in JOB_STATES:
            raise MarlError(f"--state {s!r}: a job's state is one of {', '.join(JOB_STATES)}")
    league = open_league(home, db, readonly=True)
    try:
        batches = league.queue.batches()
        workers = league.queue.workers()
        jobs = league.queue.jobs(batch=batch, states=state, limit=last)
    finally:
        league.close()
    if batch is not None and batch not in dict(batches):
        raise MarlError(f"no batch {batch!r} in the queue (marl queue lists them)")
    now = utcnow()
    if json_out:
        print_json({"batches": [{"batch": b, **counts} for b, counts in batches],
                    "workers": [{**w.to_json(), "status": _status(w, now)} for w in workers],
                    "jobs": [j.to_json() for j in jobs]})
        return
    _print_batches(batches)
    _print_workers(workers, now)
    _print_jobs(jobs, now)


@app.command("cancel")
def cancel(
    job_ids: Annotated[list[int] | None, typer.Argument(help="Jobs to cancel (their ids in marl queue).")] = None,
    batch: BatchOpt = None,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Cancel queued and leased jobs: by id, or a whole batch (--batch: a tournament, a match, a run's gauntlets). A
    worker playing one stops at its next heartbeat and stores nothing of it; games already stored stay."""
    if not job_ids and batch is None:
        raise MarlError("say what to cancel: job ids, or --batch NAME (marl queue lists them)")
    league = open_league(home, db)
    try:
        if batch is not None and batch not in dict(league.queue.batches()):
            raise MarlError(f"no batch {batch!r} in the queue (marl queue lists them)")
        known = {j.id for j in league.queue.jobs(ids=job_ids)} if job_ids else set()
        missing = sorted(set(job_ids or []) - known)
        if missing:
            raise MarlError(f"no job {missing[0]} in the queue (marl queue lists them)")
        n = league.queue.cancel_jobs(batch=batch, ids=job_ids)
    finally:
        league.close()
    if json_out:
        print_json({"cancelled": n})
    else:
        console.print(f"cancelled {n} job{'s' if n != 1 else ''}", markup=False)


def _ago(t: datetime | None, now: datetime) -> str:
    if t is None:
        return ""
    s = max((now - t).total_seconds(), 0.0)
    return f"{s:.0f} s ago" if s < 120 else f"{s / 60:.0f} min ago" if s < 7200 else f"{s / 3600:.1f} h ago"


def _status(w: WorkerRow, now: datetime) -> str:
    return w.status(now)


def _table(title: str, header: list[str], rows: list[list[Any]]) -> None:
    from rich.table import Table

    t = Table(title=title, title_justify="left")
    for h in header:
        t.add_column(h, overflow="fold")
    for r in rows:
        t.add_row(*[str(x) for x in r])
    console.print(t)


def _print_batches(batches: list[tuple[str, dict[str, int]]]) -> None:
    if not batches:
        console.print("the queue is empty: nothing was ever queued in this league", markup=False)
        return
    _table("batches", ["batch", *JOB_STATES], [[b, *(c[s] for s in JOB_STATES)] for b, c in batches])


def _print_workers(workers: list[WorkerRow], now: datetime) -> None:
    if not workers:
        return
    rows = []
    for w in workers:
        gps = w.games_per_second
        rows.append([w.name, _status(w, now), _ago(w.beat_at, now), "all" if w.serves is None else
                     ", ".join(w.serves), ", ".join(map(str, w.holding)) or "-", w.jobs_done, w.games,
                     f"{gps:.1f}" if gps is not None else "-"])
    _table("workers", ["worker", "status", "last beat", "batches", "holding", "jobs", "games", "games/s"], rows)


def _print_jobs(jobs: list[JobRow], now: datetime) -> None:
    if not jobs:
        return
    rows = []
    for j in jobs:
        res = j.result or {}
        note = j.error or (f"{res.get('games_stored', res.get('games', ''))} games" if j.state == "done" else "")
        rows.append([j.id, j.batch, j.kind, j.state, j.worker or "-", j.tries,
                     _ago(j.beat_at if j.state == "leased" else j.finished_at or j.created_at, now), note])
    _table("jobs", ["job", "batch", "kind", "state", "worker", "tries", "when", "games / error"], rows)
