"""Variants: a game played under options that change it is another game for the ratings.

A result means something only in the game it was played in: a win at pong to 3 points is not a win to 21, and a
crew of four landers is not one of two. So the ledger's games are rated per *variant*: the options of the game that
change it, those the game does not declare neutral (:attr:`~selfplay_cli.envs.contract.EnvSpec.neutral_options`)
and that differ from its defaults (:meth:`~selfplay_cli.envs.contract.EnvSpec.variant_options`). Every ladder, fit,
matrix, plot, gate, tournament and ``best`` reads the games of one variant, the default one (the game as declared)
unless another is asked for.

:func:`variant_key` is the one canonical name of a variant: the sorted, compact JSON of those options
(``{"points_to_win":3}``), ``""`` for the default. It is derived, not stored: each match row records the options its
games were played under (``params["env_options"]``: matches, gauntlets, tournaments, gates and training all have,
since before variants existed), and every reader derives the key from them. A league of any age therefore reads the
same way with no upgrade, a match without options (made without any, or by a marl that did not record them) belongs
to the default variant, and a game that later declares an option neutral joins the ladders it used to split on the
next read.
"""

from __future__ import annotations

import functools
import json
import shlex
from collections.abc import Mapping
from typing import Any

from selfplay_cli.league.games import canonical_option, declaration

__all__ = ["describe_variant", "other_variants_note", "value_text", "variant_flags", "variant_key", "variant_options"]


def variant_key(env: str, options: Mapping[str, Any] | None) -> str:
    """The variant of ``env`` that games played under ``options`` belong to: ``""`` for the game as declared, else
    the sorted compact JSON of the options that change it (see the module docstring). For a game this process
    cannot load, which options are neutral or at their default is unknown: every option given counts."""
    if not options or not isinstance(options, Mapping):
        return ""
    return _key(str(env), json.dumps(canonical_option(options), sort_keys=True))


@functools.lru_cache(maxsize=4096)
def _key(env: str, options_json: str) -> str:
    options = json.loads(options_json)
    spec = declaration(env)
    variant = options if spec is None else spec.variant_options(options)
    return json.dumps(variant, sort_keys=True, separators=(",", ":"), ensure_ascii=False) if variant else ""


def variant_options(key: str) -> dict[str, Any]:
    """The options a variant key stands for (``{}`` for the default variant)."""
    return dict(json.loads(key)) if key else {}


def value_text(value: Any) -> str:
    """An option's value as ``--env-option`` reads it: true/false, a number, a word; a list as JSON."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value if isinstance(value, str) else json.dumps(value)


def describe_variant(key: str) -> str:
    """``points_to_win=3, rules=seed``, or ``the default options``."""
    if not key:
        return "the default options"
    return ", ".join(f"{k}={value_text(v)}" for k, v in variant_options(key).items())


def variant_flags(key: str) -> str:
    """The ``--env-option`` flags that ask for a variant (empty for the default), quoted for a shell."""
    return " ".join(f"--env-option {shlex.quote(f'{k}={value_text(v)}')}" for k, v in variant_options(key).items())


def other_variants_note(env: str, counts: Mapping[str, int], shown: str, command: str) -> str | None:
    """One line for a ladder of variant ``shown`` of ``env``: the other variants with rated games (``counts``: games
    per variant key), how many each, and the command that shows each; None when there are none."""
    others = sorted((key, n) for key, n in counts.items() if key != shown and n)
    if not others:
        return None
    parts = [f"{n:,} game{'s' * (n != 1)} with {describe_variant(key)} ({command} --env {shlex.quote(env)}"
             f"{' ' + variant_flags(key) if key else ''})" for key, n in others]
    return f"{env} also has rated games under other options, in ladders of their own: " + "; ".join(parts)
