"""`marl envs`: the registered games, their seats, kind, turns, spaces and scripted players."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from rich.table import Table

from ..envs import describe_space, env_names, get_env
from ..envs.loading import plugin_errors
from ..policies.bots import league_bots
from ..results import Rules
from ._output import console, print_json

__all__ = ["describe_space", "env_row", "env_rows", "envs"]


def env_row(name: str) -> dict[str, Any]:
    """What `marl envs` shows of one game (an EnvError if it cannot be loaded)."""
    spec = get_env(name)
    cfg = spec.config()
    seats = spec.seat_spaces(cfg)
    return {
        "name": name,
        "description": spec.description,
        "agents": list(spec.agents),
        "kind": spec.kind,
        "turns": spec.turns,
        "sides": [list(side) for side in spec.side_seats()] if spec.kind == "two-sides" else None,
        "tie_tolerance": spec.tie_tolerance if spec.kind == "cooperative" else None,
        "max_steps": spec.max_steps(cfg),
        "seats": [{"agent": agent, "role": role, **seat.to_json()}
                  for agent, role, seat in zip(spec.agents, spec.seat_roles(cfg), seats, strict=True)],
        # one seat's spaces (the first), as before per-seat spaces existed
        "observation_space": describe_space(seats[0].observation),
        "action_space": describe_space(seats[0].action),
        # every game has a random player: its own, or marl's (uniform over the seat's legal actions)
        "bots": {name: spec.bots[name].description if name in spec.bots else "uniformly random legal actions "
                 "(marl's own)" for name in league_bots(spec)},
        "anchor": spec.anchor,
        "renderer": spec.make_renderer is not None,
        "live_options": list(spec.live_options),
        "train_defaults": spec.train_defaults,
    }


def env_rows(names: list[str] | None = None) -> list[dict[str, Any]]:
    """The registered games, then ``names`` (games of your own, ``module:factory``) not among them; an installed
    package's game that fails to load is a row with its ``error``."""
    rows, failed = [], plugin_errors()
    registered = env_names()
    for name in sorted(set(registered) | set(failed)):
        if name in failed:
            rows.append({"name": name, "error": str(failed[name])})
        else:
            rows.append(env_row(name))
    for name in names or []:
        if name not in registered and name not in failed and all(r["name"] != name for r in rows):
            rows.append(env_row(name))
    return rows


def _per_seat(row: dict[str, Any], key: str) -> str:
    texts = [s[key] + (" masked" if key == "action" and s["mask"] else "") for s in row["seats"]]
    if len(set(texts)) == 1:
        return texts[0]
    return "\n".join(f"{s['agent']}: {t}" for s, t in zip(row["seats"], texts, strict=True))


def envs(
    games: Annotated[list[str] | None, typer.Argument(
        help="Also show these games of your own: module:factory (e.g. mypkg.mygame:env) or a module with a function "
             "env or parallel_env.", show_default=False)] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON alone on stdout.")] = False,
) -> None:
    """List the registered games (and any GAMES named) with their agents, kind, turns, per-seat spaces and
    scripted players.

    Games come from marl itself, from installed packages (entry-point group selfplay_cli.envs) and, named on the
    command line, from your own PettingZoo environments: `marl envs mypkg.mygame:env`.
    """
    rows = env_rows(games)
    if json_out:
        print_json(rows)
        return
    table = Table(title="registered games")
    for col in ("env", "agents", "kind", "turns", "observation (per seat)", "action (per seat)", "scripted players"):
        table.add_column(col)
    for r in rows:
        if "error" in r:
            table.add_row(r["name"], "", "", "", f"cannot be loaded: {r['error']}", "", "")
            continue
        table.add_row(r["name"], ", ".join(r["agents"]), r["kind"], r["turns"], _per_seat(r, "observation"),
                      _per_seat(r, "action"), ", ".join(r["bots"]))
    console.print(table)
    for r in rows:
        roles = dict.fromkeys(seat["role"] for seat in r.get("seats", ()))
        if len(roles) > 1:  # seats that differ: a snapshot plays only its own role
            rules = Rules.of(get_env(r["name"]))
            per_side = "; rated per side" if rules.sides_differ else ""
            console.print(f"{r['name']}: seats of {len(roles)} roles ("
                          + ", ".join(f"{s['agent']}: {s['role']}" for s in r["seats"])
                          + f"): a snapshot plays only seats of the role it learned{per_side}", markup=False,
                          highlight=False)
        if r.get("train_defaults"):
            console.print(f"{r['name']} trains with its own defaults (a --config file or flags override them): "
                          f"{_settings(r['train_defaults'])}", markup=False, highlight=False)
        if r.get("live_options"):
            console.print(f"{r['name']}: a [curriculum] may drive {', '.join(r['live_options'])}", markup=False,
                          highlight=False)


def _settings(d: dict[str, Any], prefix: str = "") -> str:
    """``{"ppo": {"gamma": 0.999}, "games": 64}`` as ``games=64, [ppo] gamma=0.999``."""
    plain = [f"{k}={v}" for k, v in d.items() if not isinstance(v, dict)]
    tables = [f"[{k}] " + ", ".join(f"{kk}={vv}" for kk, vv in v.items()) for k, v in d.items() if isinstance(v, dict)]
    return "; ".join(([", ".join(plain)] if plain else []) + tables)
