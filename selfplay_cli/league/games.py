"""What the league asks of the games it stores, without importing any game.

The ledger stores games by name, of any kind. Three readings depend on what a game declares: the rules its results
follow (:func:`.derivation.rules_for_env`), which of its options make a variant (:func:`.variants.variant_key`) and
the player its ratings are anchored at (:func:`selfplay_cli.ratings.ladder.declared_anchor`). The league finds a
game's declaration through :func:`declaration`, in the catalog the package gives it when it is imported
(:func:`use_catalog`, called by ``selfplay_cli/__init__.py`` with the game registry), so the league imports no game
itself. A game the catalog does not know (a user's game not installed here) reads as undeclared: default rules, every
option given a variant, the ``random`` anchor.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["canonical_option", "declaration", "use_catalog"]

_lookup: Callable[[str], Any] | None = None
_canonical: Callable[[Any], Any] = lambda value: value  # noqa: E731  (no catalog: options as given)


def use_catalog(lookup: Callable[[str], Any], canonical: Callable[[Any], Any]) -> None:
    """Where declarations come from: ``lookup(name)`` a game's declaration (an object with ``for_options``,
    ``variant_options`` and ``anchor``, as :class:`selfplay_cli.envs.contract.EnvSpec` has) or None for a game it does
    not know; ``canonical(value)`` an option's value in the one form a variant records."""
    global _lookup, _canonical
    _lookup, _canonical = lookup, canonical


def declaration(env: str) -> Any | None:
    """The declaration of game ``env``, None for a game the catalog does not know (or with no catalog)."""
    return None if _lookup is None else _lookup(env)


def canonical_option(value: Any) -> Any:
    """An option's value in the one form a variant records (see :func:`use_catalog`)."""
    return _canonical(value)
