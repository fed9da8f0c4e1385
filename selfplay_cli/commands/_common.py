"""Options and helpers shared by the commands: the league home, name resolution, progress bars."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

from ..envs import env_names, get_env
from ..errors import MarlError
from ..league.store import League, PlayerRow
from ._output import err_console

HomeOpt = Annotated[
    Path | None,
    typer.Option("--home", envvar="MARL_HOME", help="League home (database, snapshots, videos). Default ./league."),
]
DbOpt = Annotated[
    str | None,
    typer.Option("--db", envvar="MARL_DB", help="Any SQLAlchemy URL for the league (default <home>/league.db)."),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON alone on stdout.")]
EnvOpt = Annotated[str | None, typer.Option("--env", help="Game, where the policies do not imply it.")]
DeviceOpt = Annotated[str, typer.Option("--device", help="Where networks run: auto, cpu or cuda.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")]


def open_league(home: Path | None, db: str | None) -> League:
    return League.open(home=home, url=db)


def check_env(env: str | None) -> str | None:
    if env is not None:
        get_env(env)  # unknown env -> a clear error
    return env


def parse_env_options(env: str, items: list[str] | None) -> dict:
    """``KEY=VALUE`` game options (ints, floats, true/false or text), checked by the game's own config."""
    options: dict = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise MarlError(f"--env-option must look like KEY=VALUE, not {item!r}")
        value: object = raw.strip()
        for cast in (int, float):
            try:
                value = cast(raw)
                break
            except ValueError:
                continue
        if raw.strip().lower() in ("true", "false"):
            value = raw.strip().lower() == "true"
        options[key.strip()] = value
    try:
        get_env(env).config(**options)
    except (TypeError, ValueError) as e:
        raise MarlError(f"{env}: {e}") from None
    return options


def resolve_players(league: League, names: list[str], env: str | None) -> list[PlayerRow]:
    """Resolve names to players. Snapshots imply their game; bot names need the game from them or --env."""
    from ..league.names import resolve

    env = check_env(env)
    rows: dict[int, PlayerRow] = {}
    pending = []
    for i, name in enumerate(names):
        try:
            rows[i] = resolve(league, name, env)
        except MarlError:
            pending.append(i)
    if pending:
        found = {r.env for r in rows.values()}
        if env is None and len(found) == 1:
            env = found.pop()
        elif env is None and not found and len(env_names()) == 1:
            env = env_names()[0]
        if env is not None:
            league.ensure_bots(env, get_env(env).bots)
        for i in pending:
            rows[i] = resolve(league, names[i], env)  # raises the precise error (unknown, ambiguous, ...)
    return [rows[i] for i in range(len(names))]


class RateColumn(ProgressColumn):
    """Items per second, e.g. ``57 games/s``."""

    def __init__(self, unit: str) -> None:
        super().__init__()
        self.unit = unit

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        return Text(f"{speed:,.0f} {self.unit}/s" if speed else f"- {self.unit}/s")


def progress_enabled(quiet: bool = False) -> bool:
    return not quiet and err_console.is_terminal


@contextmanager
def progress_bar(description: str, total: int | None, unit: str, enabled: bool) -> Iterator[Callable[..., None]]:
    """A rich progress bar on stderr (rate and ETA) when it is a terminal; a no-op otherwise.

    ``total`` None (work of unknown size, e.g. a game to 21) shows a pulsing bar with the count and the rate."""
    if not enabled:
        yield lambda n=1: None
        return
    columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), RateColumn(unit),
               TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn()]
    with Progress(*columns, console=err_console, transient=True) as prog:
        task = prog.add_task(description, total=total)
        yield lambda n=1: prog.advance(task, n)
