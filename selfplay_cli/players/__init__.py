"""A league row as a playing policy: loading a player (:mod:`.load`) from its snapshot file, found on this machine
or fetched from the league and checked against its row (:mod:`.files`). Below both rated play and training, which
load their players here."""

from .files import (
    blob_cache_file,
    cached_blob,
    check_legacy_file,
    read_row_snapshot,
    registered,
    snapshot_path,
    snapshot_relpath,
)

_LOAD = ("check_fits", "env_options_of", "load_player", "mix_seed", "plays_greedy")


def __getattr__(name: str) -> object:
    """:mod:`.load`'s names, imported when first asked for: it brings the play loop and torch, which a command that
    only reads snapshot rows (``marl league ladder``, ``marl checkpoint show``) never needs."""
    if name in _LOAD:
        from . import load

        return getattr(load, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["blob_cache_file", "cached_blob", "check_fits", "check_legacy_file", "env_options_of", "load_player",
           "mix_seed", "plays_greedy", "read_row_snapshot", "registered", "snapshot_path", "snapshot_relpath"]
