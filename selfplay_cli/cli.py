"""The `marl` command line: one module per verb under ``commands/``; this file only wires them."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from . import __version__
from .commands import checkpoint as checkpoint_cmd
from .commands import elo as elo_cmd
from .commands import envs as envs_cmd
from .commands import league as league_cmd
from .commands import match as match_cmd
from .commands import record as record_cmd
from .commands import train as train_cmd
from .envs import UnknownEnvError
from .errors import MarlError

app = typer.Typer(
    name="marl",
    help="Self-play league training and Elo evaluation of multi-agent RL policies.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"marl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """Self-play league training and Elo evaluation of multi-agent RL policies."""


app.command("envs", help="List the registered games: agents, spaces, scripted players.")(envs_cmd.envs)
app.command("train", help="Train agents by self-play (PPO or DQN); every snapshot joins the league, rated.")(
    train_cmd.train)
app.add_typer(checkpoint_cmd.app, name="checkpoint", help="List, inspect, tag, remove, export and import snapshots.")
app.command("match", help="Play rated games between two policies (Elo difference, CI, LOS, SPRT).")(match_cmd.match)
app.add_typer(elo_cmd.app, name="elo", help="Fit ratings with confidence intervals; gate a model on its strength.")
app.add_typer(league_cmd.app, name="league", help="The league ladder and tournaments.")
app.command("record", help="Record games as mp4/gif videos, or replay a stored game exactly.")(record_cmd.record)


def main(argv: list[str] | None = None) -> int:
    """Console entry point: user mistakes become one line on stderr and a non-zero exit, never a traceback."""
    try:
        app(args=argv, standalone_mode=True)
    except MarlError as e:
        sys.stderr.write(f"marl: error: {e}\n")
        return e.exit_code
    except UnknownEnvError as e:  # the envs room raises its own error (it imports nothing from the project)
        sys.stderr.write(f"marl: error: {e}\n")
        return MarlError.exit_code
    except SystemExit as e:
        return int(e.code or 0) if not isinstance(e.code, str) else 1
    return 0
