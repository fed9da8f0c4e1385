"""`marl envs`: the registered games, their seats, spaces and scripted players."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from gymnasium import spaces
from rich.table import Table

from ..envs import env_names, get_env
from ._output import console, print_json


def describe_space(space: spaces.Space) -> str:
    if isinstance(space, spaces.Discrete):
        return f"Discrete({space.n})"
    if isinstance(space, spaces.Box):
        lo, hi = space.low.min(), space.high.max()
        return f"Box({lo:g}, {hi:g}, {space.shape}, {space.dtype})"
    return str(space)


def env_rows() -> list[dict[str, Any]]:
    rows = []
    for name in env_names():
        spec = get_env(name)
        cfg = spec.config()
        rows.append({
            "name": name,
            "description": spec.description,
            "agents": list(spec.agents),
            "observation_space": describe_space(spec.observation_space(cfg)),
            "action_space": describe_space(spec.action_space(cfg)),
            "bots": {b.name: b.description for b in spec.bots.values()},
            "renderer": spec.make_renderer is not None,
        })
    return rows


def envs(
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON alone on stdout.")] = False,
) -> None:
    """List the registered games with their agents, spaces and scripted players."""
    rows = env_rows()
    if json_out:
        print_json(rows)
        return
    table = Table(title="registered games")
    for col in ("env", "agents", "observation (one seat)", "action", "scripted players"):
        table.add_column(col)
    for r in rows:
        table.add_row(r["name"], ", ".join(r["agents"]), r["observation_space"], r["action_space"],
                      ", ".join(r["bots"]))
    console.print(table)
