"""Checking a queued job's spec before it is played: the keys its kind needs, each of its type and within bounds.

In a shared league a job's spec was written by someone else (or by a newer marl), so it is input: a spec missing a key
or holding ``rounds=1e8`` must not end a worker, nor hold it for days. Each kind of job checks its spec with these
helpers (:func:`~selfplay_cli.evaluation.games_jobs.check_spec`,
:func:`~selfplay_cli.evaluation.gauntlet_jobs.check_spec`) when it is made (a bug of marl's then says so at once) and
before a worker plays it: a spec refused is a :class:`BadSpec`, and the job is marked dead with it at once (no worker
could play it, so trying again is pointless).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..errors import MarlError
from ..league.job_rows import TRIES_LIMIT

__all__ = ["MAX_NAME", "MAX_PLAYER_ID", "MAX_SEED", "BadSpec", "flag", "ids", "names", "number", "table", "text",
           "tries", "whole"]

MAX_PLAYER_ID = 2**63 - 1
"""A player id as the database holds it."""
MAX_SEED = 2**62
"""A job's first seed at most: its rounds' seeds and a playoff's (a few thousand above) stay within 64 bits."""
MAX_NAME = 401
"""A player's full name, ``run/name``: two names of at most 200 characters (:func:`~selfplay_cli.league.roster.
check_name`)."""
_MAX_TABLE = 256  # keys of a table in a spec (a game's options, a match's parameters)
_MAX_SHOWN = 40  # characters of a refused value in the error line


class BadSpec(MarlError):
    """A job's spec that its kind refuses: the message says which key and why."""


def _shown(value: Any) -> str:
    text_ = repr(value)
    return text_ if len(text_) <= _MAX_SHOWN else text_[:_MAX_SHOWN] + "..."


def _get(spec: Mapping[str, Any], key: str, required: bool) -> Any:
    if key not in spec:
        if required:
            raise BadSpec(f"{key} is missing")
        return None
    return spec[key]


def whole(spec: Mapping[str, Any], key: str, low: int, high: int, *, required: bool = True) -> None:
    """``spec[key]`` is a whole number from ``low`` to ``high`` (absent is fine when not ``required``)."""
    v = _get(spec, key, required)
    if v is None and not required:
        return
    if not isinstance(v, int) or isinstance(v, bool):
        raise BadSpec(f"{key} must be a whole number, not {_shown(v)}")
    if not low <= v <= high:
        raise BadSpec(f"{key} must be from {low:,} to {high:,}, not {_shown(v)}")


def number(spec: Mapping[str, Any], key: str, low: float, high: float, *, required: bool = True) -> None:
    """``spec[key]`` is a finite number in ``[low, high)``."""
    v = _get(spec, key, required)
    if v is None and not required:
        return
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v) or not low <= v < high:
        raise BadSpec(f"{key} must be a number from {low:g} up to {high:g}, not {_shown(v)}")


def flag(spec: Mapping[str, Any], key: str, *, required: bool = False) -> None:
    """``spec[key]`` is true or false."""
    v = _get(spec, key, required)
    if v is not None and not isinstance(v, bool):
        raise BadSpec(f"{key} must be true or false, not {_shown(v)}")


def text(spec: Mapping[str, Any], key: str, *, required: bool = True, none: bool = False,
         choices: tuple[str, ...] | None = None, longest: int = MAX_NAME) -> None:
    """``spec[key]`` is text of 1 to ``longest`` characters (one of ``choices`` when given; None too when
    ``none``)."""
    v = _get(spec, key, required)
    if v is None and (none or not required):
        return
    if not isinstance(v, str) or not 1 <= len(v) <= longest:
        raise BadSpec(f"{key} must be text of 1 to {longest} characters, not {_shown(v)}")
    if choices is not None and v not in choices:
        raise BadSpec(f"{key} must be one of {', '.join(choices)}, not {_shown(v)}")


def ids(spec: Mapping[str, Any], key: str, most: int) -> None:
    """``spec[key]`` is a list of 1 to ``most`` player ids."""
    v = _get(spec, key, True)
    if not isinstance(v, list) or not 1 <= len(v) <= most:
        raise BadSpec(f"{key} must be a list of 1 to {most} player ids, not {_shown(v)}")
    for i in v:
        if not isinstance(i, int) or isinstance(i, bool) or not 1 <= i <= MAX_PLAYER_ID:
            raise BadSpec(f"{key} must hold player ids, not {_shown(i)}")


def names(spec: Mapping[str, Any], key: str, most: int, *, required: bool = True) -> None:
    """``spec[key]`` is a list of at most ``most`` names (text of 1 to :data:`MAX_NAME` characters)."""
    v = _get(spec, key, required)
    if v is None and not required:
        return
    if not isinstance(v, list) or len(v) > most:
        raise BadSpec(f"{key} must be a list of at most {most} names, not {_shown(v)}")
    for name in v:
        if not isinstance(name, str) or not 1 <= len(name) <= MAX_NAME:
            raise BadSpec(f"{key} must hold names of 1 to {MAX_NAME} characters, not {_shown(name)}")


def table(spec: Mapping[str, Any], key: str, *, required: bool = False) -> None:
    """``spec[key]`` is a table (a JSON object) of at most a few hundred entries, keyed by text; None is fine when not
    ``required``."""
    v = _get(spec, key, required)
    if v is None and not required:
        return
    if not isinstance(v, dict) or len(v) > _MAX_TABLE or not all(isinstance(k, str) and len(k) <= 200 for k in v):
        raise BadSpec(f"{key} must be a table of at most {_MAX_TABLE} named entries, not {_shown(v)}")


def tries(spec: Mapping[str, Any]) -> None:
    """``max_tries``, where the spec gives it, is from 1 to :data:`~selfplay_cli.league.job_rows.TRIES_LIMIT`."""
    whole(spec, "max_tries", 1, TRIES_LIMIT, required=False)
