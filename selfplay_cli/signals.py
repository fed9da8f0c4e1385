"""Ctrl-C and a polite kill held off a block that must finish whole (a database transaction, a snapshot moment).

Nothing here imports from the rest of marl, so every room can use it.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["signals_held"]


@contextmanager
def signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block is done, then act as they would have (``KeyboardInterrupt`` for
    Ctrl-C). Blocks nest: an inner block hands what it caught to the outer one. (A signal mask would not do: the
    process may have other threads, and a signal delivered to one of them still runs Python's handler in the main
    thread.) SIGKILL cannot wait. Outside the main thread signals cannot be handled, and the block runs as it is."""
    caught: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        caught.append(signum)

    try:
        previous = {sig: signal.signal(sig, hold) for sig in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for sig in dict.fromkeys(caught):
        handler = previous[sig]
        if callable(handler):
            handler(sig, None)
        elif sig == signal.SIGINT and handler != signal.SIG_IGN:
            raise KeyboardInterrupt
        elif handler == signal.SIG_DFL:
            signal.raise_signal(sig)
