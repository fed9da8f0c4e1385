"""`marl envs`: the registered games, their seats, kind, turns, spaces and scripted players; `marl envs NAME`: a
game's options too."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from rich.table import Table

from ..envs import describe_space, env_names, game_options, get_env
from ..envs.loading import plugin_errors
from ..policies.bots import league_bots
from ..results import Rules
from ._common import typed_game
from ._output import console, print_json

__all__ = ["describe_space", "env_row", "env_rows", "envs"]


def env_row(name: str) -> dict[str, Any]:
    """What `marl envs` shows of one game (an EnvError if it cannot be loaded)."""
    spec = get_env(name)
    cfg = spec.config()
    seats = spec.seat_spaces(cfg)
    options = game_options(spec)
    trained = spec.train_defaults.get("env_options", {})
    return {
        "name": name,
        "description": spec.description,
        "agents": list(spec.agents),
        "kind": spec.kind,
        # where the kind came from: declared (marl's own game), metadata (a PettingZoo game's marl_kind), agents (not
        # declared: by the number of agents; marl train --kind, or the option kind=..., sets it)
        "kind_from": spec.kind_from,
        "turns": spec.turns,
        "sides": [list(side) for side in spec.side_seats()] if spec.kind == "two-sides" else None,
        "tie_tolerance": spec.tie_tolerance if spec.kind == "cooperative" else None,
        "max_steps": spec.max_steps(cfg),
        # the game's global state (PettingZoo's state()), for learners that read it; None where it has none
        "state_space": None if (state := spec.state_space(cfg)) is None else describe_space(state),
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
        # --env-option NAME=VALUE: type, default, whether a curriculum may drive it, and what `marl train` sets
        "options": [{**o.to_json(), **({"train_default": trained[o.name]} if o.name in trained else {})}
                    for o in options.options],
        "options_from": options.source,  # config, factory, raw_env (PettingZoo's), or what the factory passes on to
        "options_open": options.open,  # it also takes keyword options it does not name (**kwargs)
    }


def env_rows(names: list[str] | None = None) -> list[dict[str, Any]]:
    """The games ``names`` (registered ones, or games of your own, ``module:factory``), each once, in the order
    given; without names, every registered game, an installed package's game that fails to load as a row with its
    ``error``."""
    if names:
        return [env_row(name) for name in dict.fromkeys(names)]
    rows, failed = [], plugin_errors()
    for name in sorted(set(env_names()) | set(failed)):
        rows.append({"name": name, "error": str(failed[name])} if name in failed else env_row(name))
    return rows


def _per_seat(row: dict[str, Any], key: str) -> str:
    texts = [s[key] + (" masked" if key == "action" and s["mask"] else "") for s in row["seats"]]
    if len(set(texts)) == 1:
        return texts[0]
    return "\n".join(f"{s['agent']}: {t}" for s, t in zip(row["seats"], texts, strict=True))


def envs(
    games: Annotated[list[str] | None, typer.Argument(
        callback=typed_game,
        help="Show only these games, with their options: registered ones (pong) or games of your own, "
             "module:factory (e.g. mypkg.mygame:env) or a module with a function env or parallel_env.",
        show_default=False)] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON alone on stdout (every game's options "
                                           "included).")] = False,
) -> None:
    """List the registered games with their agents, kind, turns, per-seat spaces and scripted players; name GAMES
    to see those alone, with their options (what marl train's and marl match's --env-option NAME=VALUE set): type,
    default, and which a training curriculum may drive.

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
        _print_reading(r)
        if r.get("kind_from") == "agents":
            console.print(f"{r['name']}: {r['kind']} by default ({len(r['agents'])} agents; the game does not "
                          "declare its kind): marl train --kind cooperative trains its agents as one team, "
                          "--env-option kind=... plays it so", markup=False, highlight=False)
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
                          f"{_settings(r['train_defaults'])}"
                          + ("; its [ppo] is also where [mappo] and [poca] start" if "ppo" in r["train_defaults"]
                             else ""), markup=False, highlight=False)
        if r.get("live_options"):
            console.print(f"{r['name']}: a [curriculum] may drive {', '.join(r['live_options'])}", markup=False,
                          highlight=False)
    if games:
        for r in rows:
            _print_options(r)
    else:
        console.print("marl envs NAME shows a game's options (--env-option NAME=VALUE) with their types and defaults",
                      markup=False, highlight=False)


def _print_reading(row: dict[str, Any]) -> None:
    """How the seats' observations are read where the game gives them otherwise (flattened, a mask taken out), and
    the game's global state where it has one."""
    given: dict[str, list[str]] = {}
    for seat in row.get("seats", ()):
        if "given" in seat:
            given.setdefault(f"{seat['given']}, read as {seat['observation']}", []).append(seat["agent"])
    for text, agents in given.items():
        console.print(f"{row['name']}: {', '.join(agents)} observe {text} (selfplay_cli/envs/obs_spaces.py: "
                      "one-hots, the Dict's key order; an action_mask entry is the seat's mask)", markup=False,
                      highlight=False)
    if row.get("state_space"):
        console.print(f"{row['name']}: global state {row['state_space']} (for learners that read it)", markup=False,
                      highlight=False)


def _print_options(row: dict[str, Any]) -> None:
    """A game's options as a table: name, type (or the values it takes), default, and, where the game has them,
    whether a curriculum may drive it and what `marl train` sets it to."""
    name, options = row["name"], row["options"]
    more = " it also takes keyword options it does not name (**kwargs): see its documentation."
    if not options:
        console.print(f"{name}: no options {'named' if row['options_open'] else ''}".rstrip()
                      + (f";{more}" if row["options_open"] else ""), markup=False, highlight=False)
        return
    live = any(o["live"] for o in options)
    trained = any("train_default" in o for o in options)
    where = {"config": "", "factory": " (its factory's keyword arguments)",
             "raw_env": " (raw_env's keyword arguments: PettingZoo's env and parallel_env pass theirs on to it)"}
    source = where.get(row["options_from"], f" (the keyword arguments of {row['options_from']}, to which its factory "
                                            "passes its own)")
    table = Table(title=f"{name}: options, --env-option NAME=VALUE{source}")
    for col in ("option", "type", "default") + (("live",) if live else ()) + (("marl train sets",) if trained else ()):
        table.add_column(col)
    for o in options:
        kind = "one of " + ", ".join(map(str, o["choices"])) if o["choices"] else o["type"]
        cells = [o["name"], kind, "(required)" if o["required"] else str(o["default"])]
        if live:
            cells.append("curriculum" if o["live"] else "")
        if trained:
            cells.append(str(o["train_default"]) if "train_default" in o else "")
        table.add_row(*cells)
    console.print(table)
    if row["options_open"]:
        console.print(f"{name}:{more}", markup=False, highlight=False)


def _settings(d: dict[str, Any], prefix: str = "") -> str:
    """``{"ppo": {"gamma": 0.999}, "games": 64}`` as ``games=64, [ppo] gamma=0.999``."""
    plain = [f"{k}={v}" for k, v in d.items() if not isinstance(v, dict)]
    tables = [f"[{k}] " + ", ".join(f"{kk}={vv}" for kk, vv in v.items()) for k, v in d.items() if isinstance(v, dict)]
    return "; ".join(([", ".join(plain)] if plain else []) + tables)
