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
from .load import check_fits, env_options_of, load_player, mix_seed, plays_greedy

__all__ = ["blob_cache_file", "cached_blob", "check_fits", "check_legacy_file", "env_options_of", "load_player",
           "mix_seed", "plays_greedy", "read_row_snapshot", "registered", "snapshot_path", "snapshot_relpath"]
