"""The run state's file (``runs/<run>/state.pt``, :mod:`.state` writes it): its version, and its plain values read
without torch.

Which snapshots a run still needs (:mod:`.needs`: ``marl checkpoint rm`` asks) is written in its state, a
``torch.save`` file; reading those names with ``torch.load`` would cost a command that needs no tensor the import of
torch (about 1.3 s).
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path
from typing import Any

STATE_VERSION = 3  # 2: flat-buffer optimiser state (FlatAdam); 3: snapshots by name, pending gauntlets


class _Plain(dict):
    """A dict a pickle may set attributes on (a state dict's ``OrderedDict`` and its ``_metadata``)."""


def _stand_in(*args: Any, **kwargs: Any) -> None:
    return None


class _PlainValues(pickle.Unpickler):
    """Reads the plain values of a ``torch.save`` pickle (dicts, lists, strings, numbers) and nothing else: a class
    or function it names is never imported, only stood in for (a tensor comes out as None), and its storages are
    not read. The names a resume needs are plain values, so reading them costs no ``import torch`` (about 1.3 s)."""

    def find_class(self, module: str, name: str) -> Any:
        return _Plain if (module, name) == ("collections", "OrderedDict") else _stand_in

    def persistent_load(self, pid: Any) -> None:
        return None


def plain_state(path: Path) -> Any:
    """The plain values of the run state at ``path`` (a ``torch.save`` zip file): its ``data.pkl`` read by
    :class:`_PlainValues`."""
    with zipfile.ZipFile(path) as z:
        pickled = [n for n in z.namelist() if n.endswith("/data.pkl") and n.count("/") == 1]
        if len(pickled) != 1:
            raise ValueError("not a torch.save file")
        with z.open(pickled[0]) as f:
            return _PlainValues(f).load()
