"""JSON from the league's rows, parsed with bounds: the one parser of every JSON column.

In a shared league every row was written by someone else, so a JSON value is input: a 5,000-deep array would make
Python's ``json`` raise ``RecursionError`` (and the command exit 5), a 100 MB value would be read whole. Every JSON
column (:class:`~selfplay_cli.league.models.BoundedJSON`) is read through :func:`loads`, which refuses a value over its
column's size in bytes, nested deeper than :data:`MAX_DEPTH`, or not JSON, before ``json.loads`` sees it: the depth is
found by one linear scan of the brackets outside strings. A value refused reads as an :class:`Unreadable` (an empty
dict, or :class:`UnreadableList`, holding the reason), so the query that read it goes on and the row's reader makes that
one row unusable, saying so in one line (:func:`say_unusable`, once per row per command), never failing the command.

Nothing here imports SQLAlchemy or anything of the project: the column type lives with the models.
"""

from __future__ import annotations

import json
import re
import sys
from typing import Any

__all__ = ["MAX_DEPTH", "JSONBoundsError", "Unreadable", "UnreadableList", "check_value", "depth_of", "forget_said",
           "loads", "raw", "read_column", "say_once", "say_unusable", "unreadable"]

MAX_DEPTH = 32
"""Arrays and objects nested in one value, at most (marl's own values nest four or five deep)."""

_SPECIAL = re.compile(r'[\[\]{}"]')
_STRING_REST = re.compile(r'[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)  # a string's characters after its opening quote


class JSONBoundsError(ValueError):
    """A JSON value over its size or depth, or not JSON: the message says which, in a few words."""


class Unreadable(dict):  # type: ignore[type-arg]
    """A JSON column's value that could not be read within bounds: empty, with the ``reason``. Code that only
    ``.get()``\\ s from it sees nothing; readers that build a row check :func:`unreadable` and make the row unusable."""

    def __init__(self, reason: str) -> None:
        super().__init__()
        self.reason = reason

    def __repr__(self) -> str:
        return f"Unreadable({self.reason!r})"


class UnreadableList(list):  # type: ignore[type-arg]
    """:class:`Unreadable` for a column that holds a list."""

    def __init__(self, reason: str) -> None:
        super().__init__()
        self.reason = reason

    def __repr__(self) -> str:
        return f"UnreadableList({self.reason!r})"


def unreadable(value: object) -> str | None:
    """Why a column's value could not be read (None when it was read)."""
    return value.reason if isinstance(value, Unreadable | UnreadableList) else None


def _size(n: int) -> str:
    return f"{n:,} bytes"


def depth_of(text: str, max_depth: int = MAX_DEPTH) -> int:
    """The nesting depth of the arrays and objects in ``text`` (brackets inside strings do not count), found in one
    linear pass (at most ``max_depth`` when there are no more opening brackets than that: a bound, then, not the
    depth); a :class:`JSONBoundsError` as soon as it passes ``max_depth``. Malformed text is left to the parser."""
    opening = text.count("[") + text.count("{")
    if opening <= max_depth:  # (the common case: no deeper than the brackets it has, whatever their order)
        return opening
    depth = deepest = 0
    pos, n = 0, len(text)
    while pos < n:
        m = _SPECIAL.search(text, pos)
        if m is None:
            break
        c = m.group()
        if c == '"':
            end = _STRING_REST.match(text, m.end())
            if end is None:  # an unterminated string: not JSON, which the parser says
                break
            pos = end.end()
            continue
        pos = m.end()
        if c in "[{":
            depth += 1
            if depth > max_depth:
                raise JSONBoundsError(f"nested deeper than {max_depth} levels")
            deepest = max(deepest, depth)
        else:
            depth -= 1
    return deepest


def loads(data: str | bytes | bytearray | memoryview, *, max_bytes: int, max_depth: int = MAX_DEPTH) -> Any:
    """``data`` parsed as JSON, refused (:class:`JSONBoundsError`) when it is over ``max_bytes`` bytes, nested deeper
    than ``max_depth``, or not JSON. The size and the depth are checked before the parser runs, each in linear
    time."""
    if isinstance(data, bytearray | memoryview):
        data = bytes(data)
    if len(data) > max_bytes:  # (a str's characters are at most its bytes: over in characters is over in bytes)
        raise JSONBoundsError(f"{_size(len(data))}, over the {max_bytes:,} this column holds")
    if isinstance(data, bytes):
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise JSONBoundsError("not UTF-8 text") from None
    else:
        text = data
        size = len(text.encode("utf-8", "surrogatepass"))
        if size > max_bytes:
            raise JSONBoundsError(f"{_size(size)}, over the {max_bytes:,} this column holds")
    depth_of(text, max_depth)
    try:
        return json.loads(text)
    except RecursionError:  # (cannot happen within MAX_DEPTH; kept so no parse ever escapes as one)
        raise JSONBoundsError(f"nested deeper than {max_depth} levels") from None
    except ValueError as exc:
        raise JSONBoundsError(f"not JSON ({str(exc)[:80]})") from None


def read_column(value: Any, *, max_bytes: int, kind: type, max_depth: int = MAX_DEPTH) -> Any:
    """A JSON column's stored ``value`` as a reader gets it: the raw text (or bytes) parsed by :func:`loads`, or a value
    a driver already parsed, either way of the column's ``kind`` (dict or list) or null; an :class:`Unreadable` (or
    :class:`UnreadableList`) saying why otherwise. Never raises."""
    if value is None:
        return None
    bad = UnreadableList if kind is list else Unreadable
    try:
        if isinstance(value, str | bytes | bytearray | memoryview):
            value = loads(value, max_bytes=max_bytes, max_depth=max_depth)
        if value is None:  # (JSON null: how SQLAlchemy stores a None)
            return None
        if not isinstance(value, kind):
            return bad(f"a JSON {type(value).__name__}, not the {kind.__name__} this column holds")
        return value
    except JSONBoundsError as exc:
        return bad(str(exc))
    except Exception as exc:  # MemoryError, anything: a value, never the command
        return bad(f"unreadable ({type(exc).__name__})")


def check_value(value: Any, *, max_bytes: int, max_depth: int = MAX_DEPTH, what: str = "value") -> str:
    """``value`` as the JSON text a column would store, refused (:class:`JSONBoundsError`, naming ``what``) when a
    reader would refuse it: over ``max_bytes``, deeper than ``max_depth``, or not JSON (NaN, a set...)."""
    try:
        text = json.dumps(value, allow_nan=False)
    except RecursionError:
        raise JSONBoundsError(f"{what}: nested deeper than {max_depth} levels") from None
    except (TypeError, ValueError) as exc:
        raise JSONBoundsError(f"{what}: not JSON ({str(exc)[:80]})") from None
    try:
        loads(text, max_bytes=max_bytes, max_depth=max_depth)
    except JSONBoundsError as exc:
        raise JSONBoundsError(f"{what}: {exc}") from None
    return text


def raw(value: Any) -> Any:
    """The engine's JSON deserializer: the stored text itself, left for the column's type to parse with its bounds
    (psycopg would otherwise parse every JSON value with plain ``json.loads`` as it fetches a row)."""
    return value


_said: set[str] = set()


def say_unusable(row: str, column: str, reason: str, consequence: str = "the row is left unusable") -> None:
    """One line on stderr: ``row``'s ``column`` could not be read (``reason``), and what follows; said once per row and
    column in a command."""
    say_once(f"{row}\0{column}", f"{row}: its {column} cannot be read ({reason}); {consequence}")


def say_once(key: str, line: str) -> None:
    """``marl: warning: <line>`` on stderr, once per ``key`` in a command (a warning about a row, or about a
    setting, that many calls meet)."""
    if key in _said:
        return
    _said.add(key)
    sys.stderr.write(f"marl: warning: {line}\n")
    sys.stderr.flush()


def forget_said() -> None:
    """A new command: every unusable row is said again (``marl`` run twice in one process, as tests do)."""
    _said.clear()
