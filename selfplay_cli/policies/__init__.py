"""Players: the one ``Policy`` interface, scripted bots as policies, network policies and snapshot files."""

from .base import Policy
from .bots import ScriptedPolicy

__all__ = ["Policy", "ScriptedPolicy"]

# Network policies and snapshot files need torch, which is slow to import: load them on first use.
_LAZY = {
    "Arch": "network",
    "MLPNet": "network",
    "NetworkPolicy": "network",
    "build_network": "network",
    "resolve_device": "network",
    "FORMAT": "snapshot",
    "FORMAT_VERSION": "snapshot",
    "LIMITS": "snapshot",
    "Snapshot": "snapshot",
    "SnapshotError": "snapshot",
    "SnapshotMeta": "snapshot",
    "expected_tensors": "snapshot",
    "export_snapshot": "snapshot",
    "file_sha256": "snapshot",
    "import_check": "snapshot",
    "load_policy": "snapshot",
    "load_snapshot": "snapshot",
    "policy_of": "snapshot",
    "read_meta": "snapshot",
    "read_snapshot": "snapshot",
    "save_snapshot": "snapshot",
    "weights_sha256": "snapshot",
}
__all__ += list(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
