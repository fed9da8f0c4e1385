"""Values from outside (a ``--config`` TOML file, ``--env-option KEY=VALUE``) checked against the types a
dataclass declares, so a wrong type is one clear line naming the setting and the type it wants, instead of a
comparison failing deep inside (``'<' not supported between 'str' and 'int'``) or a float silently taken for a
count.

Only the declared types are checked here (whole numbers, finite numbers, true/false, text, one of a few words,
lists, tables); ranges stay with the dataclass that knows them (its ``__post_init__``).
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from typing import Any, Literal, Union

from .errors import MarlError

__all__ = ["check_fields", "describe", "field_types", "from_text"]

MAX_INT = 2**63 - 1  # what a database column or a seed generator takes


class _Mismatch(Exception):
    """``value`` is not of the wanted type (caught where the setting's name is known)."""


def field_types(cls: type) -> dict[str, Any]:
    """Declared field types of a dataclass (string annotations resolved); {} for anything else."""
    if not dataclasses.is_dataclass(cls):
        return {}
    try:
        return typing.get_type_hints(cls)
    except Exception:  # an annotation that cannot be resolved: check nothing rather than guess
        return {}


def _is_union(tp: Any) -> bool:
    return typing.get_origin(tp) in (Union, types.UnionType)


def describe(tp: Any) -> str:
    """What a type wants, in words: ``a whole number``, ``a number``, ``true or false``, ``one of 'a', 'b'``."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if _is_union(tp):
        return " or ".join(describe(a) for a in args if a is not type(None))
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if tp is bool:
        return "true or false"
    if tp is int:
        return "a whole number"
    if tp is float:
        return "a number"
    if tp is str:
        return "text"
    if origin in (tuple, list):
        return f"a list of {_plural(describe(args[0]))}" if args else "a list"
    if origin is dict:
        return f"a table of {_plural(describe(args[1]))}" if len(args) == 2 else "a table"
    if dataclasses.is_dataclass(tp):
        return "a table of settings"
    return getattr(tp, "__name__", str(tp))


def _plural(words: str) -> str:
    return {"a whole number": "whole numbers", "a number": "numbers", "text": "texts"}.get(words, words)


def _coerce(value: Any, tp: Any) -> Any:
    """``value`` as ``tp`` (an int for a float, a tuple for a list, an integral float for an int), or _Mismatch."""
    if tp is Any or tp is object:
        return value
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if _is_union(tp):
        if value is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a)
            except _Mismatch:
                continue
        raise _Mismatch
    if origin is Literal:
        if value in args and type(value) in {type(a) for a in args}:
            return value
        raise _Mismatch
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _Mismatch
    if tp is int:
        if isinstance(value, bool):
            raise _Mismatch
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        if isinstance(value, int) and abs(value) <= MAX_INT:
            return value
        raise _Mismatch
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return float(value)
        raise _Mismatch
    if tp is str:
        if isinstance(value, str):
            return value
        raise _Mismatch
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise _Mismatch
        if origin is tuple and args and (len(args) != 2 or args[1] is not Ellipsis):
            if len(value) != len(args):
                raise _Mismatch
            return tuple(_coerce(v, a) for v, a in zip(value, args, strict=True))
        items = [_coerce(v, args[0]) for v in value] if args else list(value)
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise _Mismatch
        if len(args) == 2:
            return {_coerce(k, args[0]): _coerce(v, args[1]) for k, v in value.items()}
        return dict(value)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if isinstance(value, tp):
            return value
        if isinstance(value, dict):
            return check_fields(tp, value)
        raise _Mismatch
    return value


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def check_fields(cls: type, values: dict[str, Any], where: str = "") -> dict[str, Any]:
    """``values`` with each known field checked against (and converted to) its declared type: ints for floats,
    whole floats (``5e6``) for ints, tuples for lists. Unknown keys pass through untouched (the caller names
    them). Raises MarlError ``<where><field> wants <type>, not <value> (default: <default>)``."""
    hints = field_types(cls)
    defaults = {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING} \
        if hints else {}
    out = dict(values)
    for key, value in values.items():
        if key not in hints:
            continue
        try:
            out[key] = _coerce(value, hints[key])
        except _Mismatch:
            default = f" (default: {defaults[key]!r})" if defaults.get(key) is not None else ""
            wanted = describe(hints[key])
            if isinstance(value, float) and not math.isfinite(value):
                wanted = wanted.replace("a number", "a finite number")
            raise MarlError(f"{where}{key} wants {wanted}, not {_shown(value)}{default}") from None
        except MarlError as e:  # a nested table: name the whole path
            raise MarlError(f"{where}{key}.{e}") from None
    return out


def from_text(text: str, tp: Any) -> Any:
    """A value typed on the command line (``KEY=VALUE``) read as the declared type ``tp``; raises ValueError with
    what was wanted when it cannot be."""
    raw = text.strip()
    if _is_union(tp):
        if raw.lower() in ("none", "null") and type(None) in typing.get_args(tp):
            return None
        for a in typing.get_args(tp):
            if a is type(None):
                continue
            try:
                return from_text(raw, a)
            except ValueError:
                continue
        raise ValueError(describe(tp))
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is Literal:
        for a in args:
            if str(a) == raw:
                return a
        raise ValueError(describe(tp))
    if tp is bool:
        if raw.lower() in ("true", "1", "yes", "on"):
            return True
        if raw.lower() in ("false", "0", "no", "off"):
            return False
        raise ValueError(describe(tp))
    if tp is int:
        try:
            value = int(raw.replace("_", ""))
        except ValueError:
            raise ValueError(describe(tp)) from None
        if abs(value) > MAX_INT:
            raise ValueError(describe(tp) + f" (at most {MAX_INT})")
        return value
    if tp is float:
        try:
            value = float(raw.replace("_", ""))
        except ValueError:
            raise ValueError(describe(tp)) from None
        if not math.isfinite(value):
            raise ValueError("a finite number")
        return value
    if tp is str:
        return raw
    raise ValueError(f"{describe(tp)} (not settable as KEY=VALUE)")
