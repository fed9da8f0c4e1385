"""Finding a user's game by name: installed packages' entry points, and ``module:factory`` / ``module`` names.

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

Games loaded by name are kept for the life of the process; entry points are read once.

Only a name a user gave (a command's argument or ``--env``, a config file, a league's rows, which hold names users
gave) is imported. A name read from a snapshot file is resolved with :func:`known_env`, which never imports: a
file that says it plays ``evilmod:env`` must not run ``evilmod.py`` from the folder it was imported in. An
``openspiel:`` name runs no one's code but OpenSpiel's, so it is resolved wherever it is read.
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
from .registry import _REGISTRY, EnvError, EnvSpec, UnknownEnvError

ENTRY_POINT_GROUP = "selfplay_cli.envs"

_LOADED: dict[str, EnvSpec] = {}
_PLUGINS: dict[str, EnvSpec] | None = None
_PLUGIN_ERRORS: dict[str, EnvError] = {}
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


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


def find(name: str) -> EnvSpec | None:
    """The game of an entry point or a module name; None for a plain unknown name (the caller says so)."""
    plugins = load_plugins()
    if name in plugins:
        return plugins[name]
    if name in _PLUGIN_ERRORS:
        raise _PLUGIN_ERRORS[name]
    if name in _LOADED:
        return _LOADED[name]
    if name.startswith(OPENSPIEL_PREFIX):
        spec = openspiel_game(name)
    elif ":" not in name and "." not in name:
        return None
    else:
        spec = load_user_game(name)
    _LOADED[name] = spec
    return spec


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


def load_user_game(name: str) -> EnvSpec:
    """The game ``module:factory`` or ``module`` (see the module's docstring), or an EnvError saying why not."""
    module, sep, attr = name.partition(":")
    if not _MODULE.match(module) or (sep and not re.match(r"^[A-Za-z_][A-Za-z0-9_.]*$", attr)):
        raise EnvError(name, f"unknown env {name!r}: a game of your own is named module:factory (e.g. "
                             f"mypkg.mygame:env) or module; registered: {', '.join(sorted(_REGISTRY))}")
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
    your own this process has loaded because a user named it. Nothing is imported: this is how a name read from a
    file (a snapshot's metadata) is resolved, since importing a module a file names runs that module's code."""
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
    return _LOADED.get(name)


def get_env(name: str) -> EnvSpec:
    """The game called ``name``: a registered one (built in, or from an installed package's entry point), or a
    user's PettingZoo game ``module:factory`` / ``module`` or an OpenSpiel game ``openspiel:GAME(params)`` (loaded
    once, then kept)."""
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
