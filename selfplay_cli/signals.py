"""Ctrl-C and a polite kill held off a block that must finish whole (a database transaction, a snapshot moment),
and long work told to stop when they come, or to end early when a deadline passes.

A signal's handler runs in the main thread, between two of its bytecodes. Work that other threads do (a run's
learners update side by side in threads) does not see it, and the main thread, unwinding, waits for them: with
``update_epochs = 1e9`` that was an hour. So whoever stops on a signal calls :func:`request_stop`, and long loops
in any thread ask :func:`stop_requested` between their steps (a learner's minibatches and gradient steps) and end
early; the work they leave is thrown away with the process (a run resumes from its last snapshot moment).

A deadline (:func:`deadline`: a run's ``--minutes`` budget) is asked the same way, :func:`past_deadline`, by the
same loops; there the work done so far is kept (a learner's update that has done some of its minibatches when the
budget runs out ends there, an update of fewer minibatches), so a run ends within one minibatch of its budget,
however long its updates are.

A process that starts a long-lived child of its own (a study's ``marl train``) makes the child die with it
(:func:`dies_with_parent`: the kernel sends the child SIGTERM when the parent dies, SIGKILL included) and hands the
signals it is stopped by to the child, waiting for it (:func:`stop_child`).

Nothing here imports from the rest of marl, so every room can use it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["Terminated", "clear_stop", "deadline", "dies_with_parent", "past_deadline", "request_stop", "signals_held",
           "stop_child", "stop_on_sigterm", "stop_requested", "stoppable"]

_stop = threading.Event()
_deadline: tuple[Callable[[], float], float] | None = None  # (clock, the time on it that work ends at)


def request_stop() -> None:
    """Tell every long loop of the process (in any thread) to end at its next step: the process is stopping."""
    _stop.set()


def stop_requested() -> bool:
    """Whether the process is stopping (:func:`request_stop`): a long loop ends at once when it is."""
    return _stop.is_set()


@contextmanager
def stoppable() -> Iterator[None]:
    """A block of long work (a training run) that stops on any exception leaving it (Ctrl-C, SIGTERM's, an
    error): :func:`request_stop` is called before the exception goes on, so threads still at work end at their next
    step instead of keeping the clean-up of the blocks around it waiting (so it goes innermost). The request stands
    until whoever waits for those threads has seen them end and calls :func:`clear_stop` (a process may go on
    learning after a stopped run, as a test does: a request left standing would end every later update at once)."""
    _stop.clear()
    try:
        yield
    except BaseException:
        request_stop()
        raise


def clear_stop() -> None:
    """The threads a stop was for have ended: long loops run to their end again."""
    _stop.clear()


@contextmanager
def deadline(at: float | None, clock: Callable[[], float]) -> Iterator[None]:
    """While the block runs, :func:`past_deadline` is True once ``clock()`` reaches ``at`` (None: no deadline); long
    loops in any thread that ask it end early, keeping what they did."""
    global _deadline
    before, _deadline = _deadline, (None if at is None else (clock, at))
    try:
        yield
    finally:
        _deadline = before


def past_deadline() -> bool:
    """Whether the deadline of the :func:`deadline` block under way has passed (False outside one)."""
    set_at = _deadline
    return set_at is not None and set_at[0]() >= set_at[1]


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


class Terminated(Exception):  # noqa: N818 (it is how a run learns of SIGTERM, not an error)
    """SIGTERM arrived (under :func:`stop_on_sigterm`): the work stops as it does on Ctrl-C."""


@contextmanager
def stop_on_sigterm() -> Iterator[None]:
    """While a block runs, SIGTERM (a CI job cancelled, ``kill``, a container stopped) raises :class:`Terminated` in
    the main thread, so the work ends cleanly: a training run stops its rating worker, sets its status and says how
    to resume it."""
    def handler(signum: int, frame: Any) -> None:
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. called from a test harness thread): leave SIGTERM alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def dies_with_parent(sig: int = signal.SIGTERM) -> Callable[[], None] | None:
    """A ``preexec_fn`` for :class:`subprocess.Popen` under which the child is sent ``sig`` when this process dies,
    however it dies (SIGKILL too): Linux's ``prctl(PR_SET_PDEATHSIG)``, set in the child between fork and exec. A
    parent that died before that (the child would never be told) ends the child there. None where there is no such
    call (not Linux): the child then outlives a parent killed with SIGKILL.

    The kernel sends the signal when the *thread* that started the child ends: start it from the main thread."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up now: between fork and exec, only the call
    except (OSError, AttributeError):
        return None
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
    parent = os.getpid()

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, sig, 0, 0, 0)
        if os.getppid() != parent:  # the parent died before the call: nobody is left to send it
            os._exit(128 + sig)

    return preexec


def stop_child(proc: subprocess.Popen, sig: int, patience: float) -> None:
    """Hand ``sig`` (SIGINT or SIGTERM: what this process was stopped by) to child ``proc`` and wait for it to end,
    up to ``patience`` seconds; a child still running then, or another signal while waiting (the user insists), is
    killed (SIGKILL) and waited for. Used by a process whose stop must not leave its child running on."""
    with contextlib.suppress(OSError):
        proc.send_signal(sig)
    try:
        proc.wait(timeout=patience)
        return
    except BaseException:  # noqa: BLE001 (patience ran out, or a second Ctrl-C / SIGTERM: either way, end it now)
        pass
    while proc.returncode is None:
        with contextlib.suppress(OSError):
            proc.kill()
        with contextlib.suppress(BaseException):  # a killed child is collected at once; a third signal changes nothing
            proc.wait()
