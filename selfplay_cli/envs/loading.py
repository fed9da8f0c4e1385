"""Finding a game by name: the registered games, installed packages' entry points, OpenSpiel games, and the games
of your own you name (``module:factory`` / ``module``), tried in that order.

- The registered games are those :func:`register` was given: the built-in games, registered when
  :mod:`selfplay_cli.envs` is imported, and any a program using marl as a library registers.

- An installed package registers games under the entry-point group ``selfplay_cli.envs``; the entry point's name
  is the game's name and it loads an :class:`EnvSpec` or a factory of PettingZoo envs, e.g. in pyproject.toml::

      [project.entry-points."selfplay_cli.envs"]
      mygame = "mypkg.mygame:env"

- ``openspiel:GAME`` or ``openspiel:GAME(param=value,...)`` is an OpenSpiel game (OpenSpiel's own game string),
  played through marl's adapter (:mod:`selfplay_cli.envs.adapters.openspiel`; needs the extra ``[openspiel]``).
- ``module:factory`` names a callable (keyword arguments are the game's options, ``--env-option k=v``) that
  returns a PettingZoo AECEnv or ParallelEnv (or an EnvSpec object); a dotted ``module`` alone is a module that
  has ``parallel_env()`` (preferred) or ``env()``. The module is imported as Python would, with the current
  folder tried last, so ``marl train mygame:env`` works from the folder that holds ``mygame.py``.

Who chooses the code that runs: the user of this machine, never the league. In a shared league every row (a run's
game, a player, a job's spec), a run's stored config and a snapshot file was written by someone else, and importing
the module one names runs that module's code (``os:abort``, an ``evilmod.py`` in the current folder). So a game of
your own is imported only once it is *admitted*: named in this command (the CLI calls :func:`admit` for the game
argument and every ``--env``), or listed in this machine's ``MARL_GAMES`` (comma-separated ``module:factory`` or
``module`` names, read at every lookup). :func:`get_env` and :func:`find` resolve registered games, entry points,
``openspiel:`` names (which run no one's code but OpenSpiel's) and admitted names; any other module name is
refused with :class:`GameNotAdmittedError` (one line, an :class:`EnvError`) and nothing is imported. A program
using marl as a library admits the games it means with :func:`admit`. A process passes its admitted names on to
the processes it starts for the same work (:func:`admitted`).

A name read from a snapshot file is resolved with :func:`known_env`, which never imports at all: a file that says
it plays ``evilmod:env`` is refused even where ``evilmod:env`` is admitted but not loaded yet.

Games loaded by name are kept for the life of the process; entry points are read once.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import re
import sys
from typing import Any

from .adapters.openspiel import PREFIX as OPENSPIEL_PREFIX
from .adapters.openspiel import openspiel_game
from .adapters.pettingzoo import adapt
from .contract import EnvError, EnvSpec, UnknownEnvError

ENTRY_POINT_GROUP = "selfplay_cli.envs"

GAMES_VARIABLE = "MARL_GAMES"
"""The environment variable that admits games of your own on this machine: ``MARL_GAMES=mygame:env,other:env``."""

_LOADED: dict[str, EnvSpec] = {}
_ADMITTED: set[str] = set()
_VARIABLE: tuple[str, frozenset[str]] = ("", frozenset())  # MARL_GAMES as last read, and the names it holds
_PLUGINS: dict[str, EnvSpec] | None = None
_PLUGIN_ERRORS: dict[str, EnvError] = {}
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
_REGISTRY: dict[str, EnvSpec] = {}


def register(spec: EnvSpec) -> EnvSpec:
    """Add ``spec`` to the registered games under its name (a ValueError if a game of that name is registered)."""
    if spec.name in _REGISTRY:
        raise ValueError(f"env {spec.name!r} is already registered")
    _REGISTRY[spec.name] = spec
    return spec


def _as_spec(name: str, obj: Any, where: str) -> EnvSpec:
    """An EnvSpec from what a name points at: an EnvSpec (renamed to ``name``), or a factory of PettingZoo envs."""
    if isinstance(obj, EnvSpec):
        if obj.name != name:
            from dataclasses import replace

            obj = replace(obj, name=name)
        return obj
    if not callable(obj):
        raise EnvError(name, f"game {name!r}: {where} is a {type(obj).__name__}, not a function that returns a "
                             "PettingZoo env")
    return adapt(name, obj)


def _entry_points() -> list[Any]:
    try:
        return list(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))
    except Exception:  # a broken installation's metadata: no plugins rather than no marl
        return []


def load_plugins(reload: bool = False) -> dict[str, EnvSpec]:
    """The games of installed packages, loaded once (``reload`` reads the entry points again). A game that fails
    to load is left out, its error kept for :func:`plugin_errors` and for whoever asks for it by name."""
    global _PLUGINS
    if _PLUGINS is not None and not reload:
        return _PLUGINS
    plugins: dict[str, EnvSpec] = {}
    errors: dict[str, EnvError] = {}
    for ep in _entry_points():
        name = ep.name
        if name in _REGISTRY or name in plugins:
            errors[name] = EnvError(name, f"game {name!r} from entry point {ep.value!r}: the name is taken by another "
                                          "game")
            continue
        try:
            obj = ep.load()
        except Exception as e:
            errors[name] = EnvError(name, f"game {name!r}: loading entry point {ep.value!r} failed: "
                                          f"{type(e).__name__}: {e}")
            continue
        try:
            plugins[name] = _as_spec(name, obj, f"entry point {ep.value!r}")
        except (EnvError, ValueError) as e:
            errors[name] = e if isinstance(e, EnvError) else EnvError(name, f"game {name!r}: {e}")
    _PLUGINS = plugins
    _PLUGIN_ERRORS.clear()
    _PLUGIN_ERRORS.update(errors)
    return plugins


def plugin_names() -> list[str]:
    return sorted(load_plugins())


def plugin_errors() -> dict[str, EnvError]:
    """Entry-point games that failed to load, by name, with why."""
    load_plugins()
    return dict(_PLUGIN_ERRORS)


class GameNotAdmittedError(EnvError):
    """A game of someone else's naming (a league's row, a job, a stored config): its module is not imported, since
    a game of your own runs only when you name it (see the module's docstring). One line saying how to name it."""

    def __init__(self, name: str) -> None:
        shown = name if len(name) <= 120 else name[:117] + "..."
        super().__init__(name, f"game {shown!r} is not imported: it is no registered game, and a module is imported "
                               f"only when you name it (--env {shown}, marl train {shown}, or "
                               f"{GAMES_VARIABLE}={shown}), never because the league, a job or a stored config "
                               "names it")


def _user_name(name: str) -> bool:
    """Whether ``name`` is a game of your own's name (``module:factory`` or a dotted ``module``), not a registered
    game's, an entry point's or an OpenSpiel game's."""
    return not name.startswith(OPENSPIEL_PREFIX) and (":" in name or "." in name)


def _from_variable() -> frozenset[str]:
    """The names ``MARL_GAMES`` lists now (read at every lookup; split again only when it changed)."""
    global _VARIABLE
    raw = os.environ.get(GAMES_VARIABLE, "")
    if raw != _VARIABLE[0]:
        _VARIABLE = (raw, frozenset(n.strip() for n in raw.split(",") if n.strip()))
    return _VARIABLE[1]


def admit(name: str) -> None:
    """Let this process import the game ``name`` when it is asked for: a name the user of this machine gave (a
    command's game argument or ``--env``, a program's own call). Nothing is imported now; a registered game's,
    an entry point's or an OpenSpiel game's name needs no admitting and is left as it is."""
    name = str(name).strip()
    if _user_name(name):
        _ADMITTED.add(name)


def admitted() -> tuple[str, ...]:
    """The games of your own this process may import (by :func:`admit`, and ``MARL_GAMES`` now), to pass on to a
    process it starts for the same work (a rating worker, a Ray actor, perhaps on another machine of a cluster),
    which admits them again."""
    return tuple(sorted(_ADMITTED | _from_variable()))


def is_admitted(name: str) -> bool:
    """Whether the game of your own ``name`` may be imported here: admitted, or listed in ``MARL_GAMES``."""
    return name in _ADMITTED or name in _from_variable()


def not_named_here(name: str) -> bool:
    """Whether :func:`get_env` would refuse ``name`` as a module nobody of this machine named (nothing is imported to
    say so): how a command that only lists the league's rows (the ladder, ``marl checkpoint list``) marks the rows
    that cannot be played here."""
    name = str(name)
    if not _user_name(name) or name in _REGISTRY or is_admitted(name):
        return False
    return name not in load_plugins() and name not in _PLUGIN_ERRORS


def not_named_note(names: list[str]) -> str | None:
    """One line for the rows of games :func:`not_named_here`: they are listed, and cannot be played until named."""
    games = [n for n in dict.fromkeys(names) if not_named_here(n)]
    if not games:
        return None
    shown = ", ".join(n if len(n) <= 60 else n[:57] + "..." for n in games[:5]) + (", ..." if len(games) > 5 else "")
    return (f"not imported here: {shown} (a module is imported only when you name the game, with --env or in "
            f"{GAMES_VARIABLE}, never because a league row names it): its players are listed, and cannot play until "
            "you do")


def find(name: str) -> EnvSpec | None:
    """The game of an entry point, an OpenSpiel name or an admitted module name; None for a plain unknown name (the
    caller says so); :class:`GameNotAdmittedError` for a module name nobody of this machine named."""
    plugins = load_plugins()
    if name in plugins:
        return plugins[name]
    if name in _PLUGIN_ERRORS:
        raise _PLUGIN_ERRORS[name]
    if name.startswith(OPENSPIEL_PREFIX):
        if name not in _LOADED:
            _LOADED[name] = openspiel_game(name)
        return _LOADED[name]
    if not _user_name(name):
        return None
    if not is_admitted(name):
        _check_syntax(name)  # a name that is no module at all says so, as before
        raise GameNotAdmittedError(name)
    if name not in _LOADED:
        _LOADED[name] = load_user_game(name)
    return _LOADED[name]


def _import(name: str, module: str) -> Any:
    def missing(e: ModuleNotFoundError) -> bool:  # the module itself (or a package above it) is not there
        return bool(e.name) and (module == e.name or module.startswith(e.name + "."))

    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if not missing(e):
            raise EnvError(name, f"game {name!r}: importing {module} failed: {e}") from None
        cwd = os.getcwd()
        if cwd in sys.path or "" in sys.path:
            first = e
        else:  # as `python -m` would: the current folder, tried after everything else
            sys.path.append(cwd)
            try:
                return importlib.import_module(module)
            except ModuleNotFoundError as e2:
                if not missing(e2):
                    raise EnvError(name, f"game {name!r}: importing {module} failed: {e2}") from None
                first = e2
            except Exception as e2:
                raise EnvError(name, f"game {name!r}: importing {module} failed: {type(e2).__name__}: {e2}") from None
        known = ", ".join(sorted(_REGISTRY) + plugin_names())
        raise EnvError(name, f"unknown env {name!r}: there is no module named {first.name!r} (registered games: "
                             f"{known}; a game of your own is module:factory, e.g. mypkg.mygame:env, with the module "
                             "importable)") from None
    except Exception as e:
        raise EnvError(name, f"game {name!r}: importing {module} failed: {type(e).__name__}: {e}") from None


def _check_syntax(name: str) -> tuple[str, str, str]:
    module, sep, attr = name.partition(":")
    if not _MODULE.match(module) or (sep and not re.match(r"^[A-Za-z_][A-Za-z0-9_.]*$", attr)):
        shown = name if len(name) <= 120 else name[:117] + "..."
        raise EnvError(name, f"unknown env {shown!r}: a game of your own is named module:factory (e.g. "
                             f"mypkg.mygame:env) or module; registered: {', '.join(sorted(_REGISTRY))}")
    return module, sep, attr


def load_user_game(name: str) -> EnvSpec:
    """The game ``module:factory`` or ``module`` (see the module's docstring), imported now, or an EnvError saying
    why not. It imports whatever it is given: callers go through :func:`get_env`, which imports admitted names
    only."""
    module, sep, attr = _check_syntax(name)
    mod = _import(name, module)
    if sep:
        obj: Any = mod
        for part in attr.split("."):
            if not hasattr(obj, part):
                public = sorted(k for k in vars(mod) if not k.startswith("_") and callable(getattr(mod, k)))
                hint = f" (it has: {', '.join(public[:12])})" if public else ""
                raise EnvError(name, f"game {name!r}: module {module} has no {attr!r}{hint}")
            obj = getattr(obj, part)
        return _as_spec(name, obj, f"{module}:{attr}")
    for attr in ("parallel_env", "env"):
        obj = getattr(mod, attr, None)
        if callable(obj):
            return _as_spec(name, obj, f"{module}.{attr}")
    raise EnvError(name, f"game {name!r}: module {module} has neither parallel_env() nor env(); name its factory "
                         f"as {module}:FACTORY")


def known_env(name: str) -> EnvSpec | None:
    """The game called ``name`` if it is already known: built in, an installed package's entry point, or a game of
    your own this process has loaded because a user named it (admitted, and loaded). Nothing is imported: this is
    how a name read from a file (a snapshot's metadata) is resolved, since importing a module a file names runs that
    module's code."""
    spec = _REGISTRY.get(name)
    if spec is not None:
        return spec
    plugins = load_plugins()
    if name in plugins:
        return plugins[name]
    if name in _PLUGIN_ERRORS:
        raise _PLUGIN_ERRORS[name]
    if name.startswith(OPENSPIEL_PREFIX):  # OpenSpiel's own games: nothing of the file's choosing is imported
        return find(name)
    return _LOADED.get(name) if is_admitted(name) else None


def get_env(name: str) -> EnvSpec:
    """The game called ``name``: a registered one (built in, or from an installed package's entry point), an
    OpenSpiel game ``openspiel:GAME(params)``, or a user's PettingZoo game ``module:factory`` / ``module`` that was
    admitted (:func:`admit`, ``MARL_GAMES``; loaded once, then kept). Any other module name raises
    :class:`GameNotAdmittedError` without importing it; a plain unknown name :class:`UnknownEnvError`."""
    spec = _REGISTRY.get(name)
    if spec is not None:
        return spec
    found = find(name)
    if found is not None:
        return found
    raise UnknownEnvError(name, env_names())


def env_names() -> list[str]:
    """The registered games: built in, and those of installed packages (entry-point group ``selfplay_cli.envs``)
    that load."""
    return sorted(set(_REGISTRY) | set(plugin_names()))
