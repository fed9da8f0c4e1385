"""`marl checkpoint list|show|tag|rm|export|import|push`: the snapshots of the league."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ..errors import MarlError, MarlIOError
from ._common import (
    DbOpt,
    EnvOpt,
    HomeOpt,
    JsonOpt,
    QuietOpt,
    check_env,
    open_league,
    progress_bar,
    progress_enabled,
    typed_game,
)
from ._output import console, err_console, print_json

app = typer.Typer(help="List, inspect, tag, remove, export, import and push snapshots.", no_args_is_help=True,
                  rich_markup_mode=None)
NameArg = Annotated[str, typer.Argument(metavar="NAME", help="A snapshot: s6M-left, pong-1/s6M-left, a tag, latest, "
                                        "best or an id.")]


def _row_json(p) -> dict:
    from ..envs.loading import not_named_here

    return {"id": p.id, "policy": p.full_name, "kind": p.kind, "env": p.env, "run": p.run, "name": p.name,
            "step": p.step, "episode": p.episode, "algo": p.algo, "tags": list(p.tags), "elo_online": round(p.elo, 1),
            "games": p.games, "path": p.path, "sha256": p.sha256, "parent_id": p.parent_id, "removed": p.removed,
            "created": p.created_at.isoformat(),
            "playable_here": not not_named_here(p.env)}  # False: a game of someone's own nobody here named


@app.command("list")
def list_cmd(
    env: Annotated[str | None, typer.Option("--env", callback=typed_game, help="Only this game's snapshots "
                                            "(default: every game's).")] = None,
    run: Annotated[str | None, typer.Option("--run", help="Only this run's snapshots.")] = None,
    bots: Annotated[bool, typer.Option("--bots", help="Also list the scripted players.")] = False,
    include_removed: Annotated[bool, typer.Option("--all", help="Also list removed snapshots.")] = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """The snapshots in the league, oldest first."""
    league = open_league(home, db, readonly=True)
    try:
        rows = league.roster.players(env=check_env(env), kind=None if bots else "snapshot",
                                     include_removed=include_removed)
    finally:
        league.close()
    if run is not None:
        rows = [p for p in rows if p.run == run]
    from ..envs.loading import not_named_here, not_named_note

    note = not_named_note([p.env for p in rows])
    if note:
        err_console.print(note, markup=False, highlight=False)
    if json_out:
        print_json([_row_json(p) for p in rows])
        return
    table = Table(title="snapshots" if not bots else "players")
    for col in ("id", "policy", "env", "kind", "step", "episode", "algo", "tags", "online Elo", "games", "created"):
        table.add_column(col)
    for p in rows:
        env_cell = p.env + (" (not imported)" if not_named_here(p.env) else "")
        table.add_row(str(p.id), p.full_name + (" (removed)" if p.removed else ""), env_cell, p.kind, f"{p.step:,}",
                      str(p.episode), p.algo or "", ", ".join(p.tags), f"{p.elo:.0f}", str(p.games),
                      p.created_at.strftime("%Y-%m-%d %H:%M"))
    console.print(table)


def _details(league, p) -> dict:
    """A player's league record, its lineage (parent, grandparent, ...) and its file's metadata."""
    from ..players.files import snapshot_path
    from ..policies.snapshot_reader import read_meta

    data = _row_json(p)
    lineage, parent = [], p.parent_id
    while parent is not None and len(lineage) < 50:
        q = league.roster.get_player(parent)
        lineage.append(q.full_name)
        parent = q.parent_id
    data["lineage"] = lineage
    if not p.is_bot and not p.removed:
        data["file"] = read_meta(snapshot_path(league, p)).to_dict()
    return data


def _print_details(data: dict) -> None:
    for key, value in data.items():
        if key == "file":
            for k, v in value.items():
                console.print(f"  file.{k}: {v}", markup=False)
        else:
            console.print(f"{key}: {value}", markup=False)


@app.command("show")
def show(
    name: Annotated[str, typer.Argument(metavar="NAME", help="A snapshot (s6M-left, pong-1/s6M-left, a tag, latest, "
                                        "best, an id) or a team of per-seat snapshots (s6M: each member).")],
    env: EnvOpt = None, home: HomeOpt = None, db: DbOpt = None, json_out: JsonOpt = False,
) -> None:
    """Everything about one snapshot: league record, lineage and the file's metadata. A team name (s6M) shows each
    of its members (s6M-left, s6M-right)."""
    from ..ratings.names import Team, resolve_or_team

    league = open_league(home, db, readonly=True)
    try:
        found = resolve_or_team(league, name, check_env(env), include_removed=True)
        members = found.members if isinstance(found, Team) else (found,)
        details = [_details(league, p) for p in members]
    finally:
        league.close()
    if json_out:
        print_json(details[0] if not isinstance(found, Team) else {"team": found.full_name, "members": details})
        return
    if isinstance(found, Team):
        console.print(f"team {found.full_name}: {len(members)} snapshots, one per seat ({found.describe()})",
                      markup=False)
    for i, data in enumerate(details):
        if i or isinstance(found, Team):
            console.print()
        _print_details(data)


@app.command("tag")
def tag(name: NameArg, tag_name: Annotated[str, typer.Argument(metavar="TAG", help="The tag to give it.")],
        env: EnvOpt = None, home: HomeOpt = None, db: DbOpt = None) -> None:
    """Give a snapshot a name of your own (moves the tag if another snapshot had it)."""
    from ..ratings.names import resolve

    league = open_league(home, db)
    try:
        p = resolve(league, name, check_env(env))
        league.roster.tag(p.id, tag_name)
    finally:
        league.close()
    console.print(f"tagged {p.full_name} as {tag_name}", markup=False)


@app.command("rm")
def rm(name: NameArg, env: EnvOpt = None,
       keep_file: Annotated[bool, typer.Option("--keep-file", help="Keep the snapshot file on disk (and touch no "
                                               "file: this also removes a row whose path leaves the league).")]
       = False,
       force: Annotated[bool, typer.Option("--force", help="Remove it even though a stopped run needs it to resume "
                                           "(its last snapshot, a gauntlet it owes, its teacher): that run is ended "
                                           "for good (status ended). A run being trained is never ended from here.")]
       = False,
       home: HomeOpt = None, db: DbOpt = None) -> None:
    """Remove a snapshot from the pool; its games stay in the ledger and keep counting in the ratings. A snapshot a
    run still needs is refused (which run, and why), unless --force."""
    from ..ratings.names import resolve
    from ..train.needs import needs_of

    league = open_league(home, db)
    try:
        p = resolve(league, name, check_env(env))
        if p.is_bot:
            raise MarlError(f"{p.full_name} is a scripted player; only snapshots can be removed")
        path = None
        if not keep_file:
            try:
                path = league.snapshot_file(p)  # before anything changes: a row whose path leaves the league
            except MarlError as e:
                raise MarlError(f"{e}; marl checkpoint rm --keep-file {name} removes the row alone") from None
        needs = needs_of(league, p)
        live = [n for n in needs if n.pid is not None]
        if live:
            raise MarlError(f"{p.full_name} is needed by {live[0].describe()}: stop that training first (Ctrl-C, "
                            f"or kill {live[0].pid}), then remove it")
        if needs and not force:
            raise MarlError(f"{p.full_name} is needed by {'; by '.join(n.describe() for n in needs)}; marl "
                            f"checkpoint rm --force {name} removes it and ends {_runs(needs)} for good")
        league.roster.remove_snapshot(p.id, end_runs=[n.run for n in needs])
    finally:
        league.close()
    if path is not None and path.is_file():
        try:
            path.unlink()
        except OSError as e:
            raise MarlIOError(f"removed {p.full_name} from the league, but cannot delete {path}: "
                              f"{e.strerror or e}") from None
    ended = f"; ended {_runs(needs)}, which needed it" if needs else ""
    console.print(f"removed {p.full_name} ({p.games} games stay in the ledger){ended}", markup=False)


def _runs(needs) -> str:
    names = list(dict.fromkeys(n.run for n in needs))
    return ("run " if len(names) == 1 else "runs ") + ", ".join(f"'{r}'" for r in names)


@app.command("export")
def export(name: NameArg, out: Annotated[Path, typer.Argument(help="Destination file (.safetensors).")],
           env: EnvOpt = None, home: HomeOpt = None, db: DbOpt = None) -> None:
    """Write a snapshot as one portable file (weights and metadata) that `marl checkpoint import` registers."""
    from ..players.files import registered, snapshot_path
    from ..policies.snapshot_reader import export_snapshot
    from ..ratings.names import resolve

    league = open_league(home, db, readonly=True)
    try:
        p = resolve(league, name, check_env(env))
        if p.is_bot:
            raise MarlError(f"{p.full_name} is a scripted player: there is no file to export")
        # the home's file, or the league's copy where this machine has none; never a file that is not the row's
        export_snapshot(snapshot_path(league, p), out, expect_env=p.env, registered=registered(p))
    finally:
        league.close()
    console.print(f"exported {p.full_name} to {out}", markup=False)


@app.command("import")
def import_cmd(
    file: Annotated[Path, typer.Argument(help="A snapshot file written by `marl train` or `marl checkpoint export`.")],
    run: Annotated[str | None, typer.Option("--run", help="Run to file it under (default: its own run, or "
                                            "'imported').")] = None,
    name: Annotated[str | None, typer.Option("--name", help="Name in the run (default: its own name).")] = None,
    env: EnvOpt = None,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Register a snapshot file in the league, checking its game, its spaces and its weights' checksum."""
    from ..players.snapshots import import_snapshot

    league = open_league(home, db)
    try:
        p = import_snapshot(league, file, run=run, name=name, env=check_env(env))
    finally:
        league.close()
    if json_out:
        print_json(_row_json(p))
    else:
        console.print(f"imported {file} as {p.full_name} (id {p.id}, {p.env})", markup=False)


@app.command("push")
def push(
    names: Annotated[list[str] | None, typer.Argument(metavar="[NAME]...", help="Snapshots to store: s6M-left, "
                                                      "pong-1/s6M-left, a tag, an id; a team name stores each "
                                                      "member.")] = None,
    every: Annotated[bool, typer.Option("--all", help="Every snapshot of the league (of --env) but removed ones, "
                                        "which no machine plays.")] = False,
    to: Annotated[str | None, typer.Option("--to", metavar="URL", help="From now on keep the league's snapshot "
                                           "files in this folder instead of the database: a file:// URL of a disk "
                                           "every machine of the league mounts at the same path (file:///mnt/"
                                           "shared/marl-blobs); 'db': in the database again. Files stored before "
                                           "stay where they are.")] = None,
    env: EnvOpt = None,
    home: HomeOpt = None,
    db: DbOpt = None,
    quiet: QuietOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Store snapshot files in the league's database, so that any machine that has only the database (--db) can
    play them. Snapshots trained or imported by this marl are there already; this stores those of leagues made
    before, from this machine's files, each checked by hash first. Says how many were stored (and their bytes),
    how many were there already, whose file is not on this machine and whose file is not the one registered;
    exits 1 if any snapshot asked for is still not in the database. With --to alone, only sets where the league
    keeps them."""
    from ..players.files import check_legacy_file
    from ..ratings.names import Team, resolve_or_team

    if names and every:
        raise MarlError("name the snapshots to push, or pass --all for every snapshot of the league, not both")
    if not names and not every and to is None:
        raise MarlError("name the snapshots to push, or pass --all for every snapshot of the league")
    league = open_league(home, db)
    try:
        if to is not None:
            league.blobs.set_blob_location(None if to == "db" else to)
        location = league.blobs.blob_location()
        if to is not None and not json_out:
            console.print(f"the league keeps its snapshot files in {location or 'the database'} from now on",
                          markup=False)
        if not names and not every:
            if json_out:
                print_json({"blob_url": location})
            return
        if every:
            rows = league.roster.players(env=check_env(env), kind="snapshot")
        else:
            rows = []
            for name in names or []:
                found = resolve_or_team(league, name, check_env(env))
                rows += found.members if isinstance(found, Team) else [found]
            rows = list({p.id: p for p in rows if not p.is_bot}.values())
        with progress_bar("storing snapshot files", len(rows), "files", progress_enabled(quiet or json_out)) as bar:
            report = league.blobs.ensure_blobs(rows, check_legacy=check_legacy_file, advance=bar)
    finally:
        league.close()
    if json_out:
        print_json({**report.to_dict(), "blob_url": location})
    else:
        console.print(f"stored {len(report.stored)} snapshot file{'s' * (len(report.stored) != 1)} in the league "
                      f"({report.stored_bytes:,} bytes); {len(report.present)} there already", markup=False)
        for what, names_ in (("not on this machine, not in the league", report.missing),
                             ("refused", report.refused)):
            for name in names_:
                console.print(f"{what}: {name}: {report.reasons[name]}", markup=False)
    if report.missing or report.refused:
        raise typer.Exit(1)
