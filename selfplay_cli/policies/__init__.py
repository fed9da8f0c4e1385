"""Players: the one ``Policy`` interface (:mod:`.base`), scripted players as policies (:mod:`.bots`), network
policies (:mod:`.network`: the MLP, with a convolutional encoder for images; :mod:`.arch`: its shape; :mod:`.heads`:
the action heads' maths; :mod:`.bank`: many networks stacked to act at once), one agent for a whole team
(:mod:`.joint`), the spaces a seat reads and acts in (:mod:`.spaces`), and snapshot files in three parts: the file
format (:mod:`.snapshot_format`: metadata, checksums, limits, saving), the hostile-input reader
(:mod:`.snapshot_reader`: every check before anything is built) and policy building from a checked file
(:mod:`.snapshot_policy`)."""

from .base import Policy
from .bots import ScriptedPolicy

__all__ = ["Policy", "ScriptedPolicy"]

# Network policies and snapshot files need torch, which is slow to import: load them on first use.
_LAZY = {
    "Arch": "arch",
    "MLPNet": "network",
    "NetworkPolicy": "network",
    "build_network": "network",
    "resolve_device": "network",
    "FORMAT": "snapshot_format",
    "FORMAT_VERSION": "snapshot_format",
    "LIMITS": "snapshot_format",
    "Snapshot": "snapshot_reader",
    "SnapshotError": "arch",
    "SnapshotMeta": "snapshot_format",
    "expected_tensors": "snapshot_format",
    "export_snapshot": "snapshot_reader",
    "file_sha256": "snapshot_format",
    "import_check": "snapshot_reader",
    "load_policy": "snapshot_policy",
    "load_snapshot": "snapshot_reader",
    "policy_of": "snapshot_policy",
    "read_meta": "snapshot_reader",
    "read_snapshot": "snapshot_reader",
    "save_snapshot": "snapshot_format",
    "weights_sha256": "snapshot_format",
}
__all__ += list(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
