"""A game's options as a user can set them (``--env-option NAME=VALUE``, ``[env_options]``): name, type, default,
and whether a training curriculum may drive it, read from what the game declares.

* A game whose config is a dataclass (the built-in games): its fields, their declared types and defaults.
* A user's PettingZoo game: its factory's keyword arguments (``spec.option_source``), with the defaults and the
  types of the signature (an annotation, else the default's type). A factory that takes only ``**kwargs`` says
  nothing of its options; it is followed to where it passes them on, by PettingZoo's conventions (:func:`_passed_on`:
  ``parallel_env``, a closure of ``parallel_wrapper_fn``, to the ``env`` it wraps; ``env`` to its module's
  ``raw_env``; SISL's ``raw_env(*args, **kwargs)`` to the class it builds), and the first signature that names
  options is read instead, and the listing says whose it is. So ``marl envs pettingzoo.sisl.pursuit_v5`` (whose
  ``parallel_env`` marl flies) lists the options ``pursuit_v5:env`` does. ``render_mode`` is marl's to set, not an
  option.
"""

from __future__ import annotations

import dataclasses
import dis
import inspect
import sys
import types
import typing
from dataclasses import dataclass
from typing import Any, Literal, Union

from .contract import KINDS, EnvSpec

__all__ = ["GameOption", "GameOptions", "game_options"]

NOT_OPTIONS = frozenset({"render_mode"})  # keyword arguments of a factory that marl sets itself


@dataclass(frozen=True)
class GameOption:
    """One option of a game."""

    name: str
    type: str  # int, float, bool, str, a type's name, or "any" where the game does not say
    default: Any = None  # None also where there is none (``required``)
    choices: tuple[Any, ...] = ()  # the only values it takes (a Literal), else empty
    required: bool = False  # the factory has no default for it
    live: bool = False  # a [curriculum] may drive it while games run (the game's live_options)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "type": self.type, "default": self.default, "choices": list(self.choices),
                "required": self.required, "live": self.live}


@dataclass(frozen=True)
class GameOptions:
    """What a game says of its options: ``options`` as declared, ``source`` where they were read (``config``, a
    dataclass; ``factory``: its keyword arguments; ``raw_env``: the module's raw_env, PettingZoo's convention;
    else the module and name of the callable the factory passes them on to, :func:`_named`), and
    ``open``: it also takes keyword options it does not name (``**kwargs``), so the list may be incomplete."""

    options: tuple[GameOption, ...]
    source: str
    open: bool = False


def _describe(tp: Any) -> tuple[str, tuple[Any, ...]]:
    """A type as a word and, for a Literal, its values: ``int``, ``float | None``, ``str`` with ``('a', 'b')``."""
    if tp is inspect.Parameter.empty or tp is Any:
        return "any", ()
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is Literal:
        kinds = {type(a).__name__ for a in args}
        return (kinds.pop() if len(kinds) == 1 else "any"), tuple(args)
    if origin in (Union, types.UnionType):
        parts = [_describe(a) for a in args if a is not type(None)]
        words = " | ".join(p[0] for p in parts) + (" | None" if type(None) in args else "")
        return words, tuple(c for p in parts for c in p[1])
    if isinstance(tp, str):  # an annotation that could not be resolved: as written
        return tp, ()
    return getattr(tp, "__name__", str(tp)), ()


def _from_dataclass(cfg: Any, live: set[str]) -> GameOptions:
    try:
        hints = typing.get_type_hints(type(cfg))
    except Exception:  # an annotation that cannot be resolved: as written
        hints = {}
    out = []
    for f in dataclasses.fields(cfg):
        if not f.init:
            continue
        word, choices = _describe(hints.get(f.name, f.type))
        out.append(GameOption(f.name, word, getattr(cfg, f.name), choices, live=f.name in live))
    return GameOptions(tuple(out), "config")


def _signature(fn: Any) -> inspect.Signature | None:
    try:
        return inspect.signature(fn, eval_str=True)
    except Exception:  # an annotation that does not evaluate: read them as written
        try:
            return inspect.signature(fn)
        except (TypeError, ValueError):
            return None


def _from_signature(sig: inspect.Signature, source: str, live: set[str]) -> GameOptions:
    out, open_ = [], False
    for p in sig.parameters.values():
        if p.kind is p.VAR_KEYWORD:
            open_ = True
            continue
        if p.kind in (p.VAR_POSITIONAL, p.POSITIONAL_ONLY) or p.name in NOT_OPTIONS:
            continue
        required = p.default is p.empty
        default = None if required else p.default
        word, choices = _describe(p.annotation)
        if word == "any" and default is not None:
            word = type(default).__name__
        out.append(GameOption(p.name, word, default, choices, required=required, live=p.name in live))
    return GameOptions(tuple(out), source, open_)


_HOPS = 4
"""How many times a factory is followed to where it passes its options on (parallel_env, env, raw_env, a class)."""


def _passed_on(fn: Any) -> list[Any]:
    """Where ``fn``, which names no option of its own (``**kwargs``), may pass its keyword arguments on, in the order
    tried: the function it wraps (``__wrapped__``), the callables its closure holds (PettingZoo's
    ``parallel_wrapper_fn(env)``: ``env``), its module's ``raw_env`` (PettingZoo's ``env(**kwargs)``), and, for a
    class, the one class or function of its own package that its ``__init__`` calls by a global name (SISL's
    ``raw_env(*args, **kwargs)``: ``Pursuit``)."""
    out: list[Any] = []
    wrapped = getattr(fn, "__wrapped__", None)
    if callable(wrapped):
        out.append(wrapped)
    for cell in getattr(fn, "__closure__", None) or ():
        try:
            held = cell.cell_contents
        except ValueError:  # an empty cell
            continue
        if inspect.isfunction(held) or inspect.isclass(held):
            out.append(held)
    module = getattr(fn, "__module__", None) or ""
    raw = getattr(sys.modules.get(module), "raw_env", None)
    if callable(raw):
        out.append(raw)
    init = getattr(fn, "__init__", None) if inspect.isclass(fn) else None
    code, names = getattr(init, "__code__", None), getattr(init, "__globals__", None)
    package = module.rpartition(".")[0]
    if code is not None and isinstance(names, dict) and package:
        called = {i.argval for i in dis.get_instructions(code) if i.opname == "LOAD_GLOBAL"}
        own = [names[n] for n in sorted(called) if n in names and (inspect.isclass(names[n])
                                                                  or inspect.isfunction(names[n]))
               and (getattr(names[n], "__module__", "") or "").startswith(package + ".")]
        if len(own) == 1:
            out.append(own[0])
    return [f for f in out if f is not fn]


def _named(fn: Any, live: set[str]) -> tuple[Any, GameOptions] | None:
    """The first callable from ``fn`` on (``fn``, then where it passes its options on, :func:`_passed_on`, up to
    :data:`_HOPS` times) whose signature names options or takes no others, and what it says; None where none
    does."""
    seen: set[int] = set()
    todo = [(fn, 0)]
    while todo:  # depth first, in the order _passed_on tries them
        f, hops = todo.pop()
        if id(f) in seen:
            continue
        seen.add(id(f))
        sig = _signature(f)
        if sig is None:
            continue
        found = _from_signature(sig, "factory", live)
        if found.options or not found.open:
            return f, found
        if hops < _HOPS:
            todo += [(g, hops + 1) for g in reversed(_passed_on(f))]
    return None


def _source_name(fn: Any) -> str:
    """How a listing names where its options were read: ``raw_env`` (PettingZoo's convention), else the callable's
    module and name."""
    name = getattr(fn, "__qualname__", None) or getattr(fn, "__name__", None) or repr(fn)
    return "raw_env" if name == "raw_env" else f"{getattr(fn, '__module__', '?')}.{name}"


def game_options(spec: EnvSpec) -> GameOptions:
    """The options of ``spec`` (see the module docstring); ``GameOptions((), "none", open=True)`` where nothing
    can be read."""
    live = set(spec.live_options)
    cfg = spec.config()
    if dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        return _from_dataclass(cfg, live)
    source = spec.option_source if spec.option_source is not None else spec.make_config
    sig = _signature(source)
    if sig is None:
        return _with_kind(spec, GameOptions((), "none", open=True))
    found = _from_signature(sig, "factory", live)
    if found.open and not found.options:  # env(**kwargs): followed to where it passes them on
        named = _named(source, live)
        if named is not None and named[0] is not source:
            found = dataclasses.replace(named[1], source=_source_name(named[0]))
    return _with_kind(spec, found)


def _with_kind(spec: EnvSpec, found: GameOptions) -> GameOptions:
    """``found`` and, for a game that takes marl's ``kind`` option (a PettingZoo game that does not declare its
    kind), that option: its default is the kind the game has without it."""
    if spec.make_kind is None or spec.kind_from == "metadata" or any(o.name == "kind" for o in found.options):
        return found
    kind = GameOption("kind", "str", spec.kind, KINDS)
    return GameOptions((*found.options, kind), found.source, found.open)
