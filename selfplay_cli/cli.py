"""The `marl` command line: one module per verb under ``commands/``; this file only wires them."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from . import __version__
from .commands import envs as envs_cmd
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


def main(argv: list[str] | None = None) -> int:
    """Console entry point: user mistakes become one line on stderr and a non-zero exit, never a traceback."""
    try:
        app(args=argv, standalone_mode=True)
    except MarlError as e:
        sys.stderr.write(f"marl: error: {e}\n")
        return e.exit_code
    except SystemExit as e:
        return int(e.code or 0) if not isinstance(e.code, str) else 1
    return 0
