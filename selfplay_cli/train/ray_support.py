"""Ray for a run (``--executor ray``, ``--eval ray``): the optional import and joining a cluster, each failure one line.

Ray is an optional extra (``pip install "selfplay-cli[ray]"``). :func:`ray_module` imports it or refuses in one line
(exit 2) before anything is written; :func:`connect` starts Ray on this machine's cores or joins a running cluster
(``--ray-address``, e.g. ``ray start --head`` on one machine and ``ray start --address HEAD:6379`` on the others),
and says in one line (exit 4) when the cluster cannot be reached. :class:`RayConnection` is the context a run holds:
Ray is shut down at its end only if this process started it (a test, or a script, may have started it already).
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import sys
import tempfile
from collections.abc import Iterator
from types import ModuleType
from typing import Any

from ..errors import MarlError, MarlIOError

INSTALL_HINT = 'pip install "selfplay-cli[ray]"'


def ray_module() -> ModuleType:
    """The ``ray`` module, or one :class:`MarlError` (exit 2) saying how to install it."""
    try:
        import ray
    except ImportError:
        raise MarlError(f"--executor ray and --eval ray need Ray, which is not installed ({INSTALL_HINT})") from None
    return ray


def connect(address: str = "", *, num_cpus: int | None = None) -> bool:
    """Join the Ray cluster at ``address`` ("": start Ray on this machine; ``RAY_ADDRESS`` in the environment is
    honoured as Ray honours it); returns whether this call started (or joined) Ray, False when it was running
    already. A cluster that cannot be reached is one :class:`MarlIOError` (exit 4)."""
    ray = ray_module()
    where = address or os.environ.get("RAY_ADDRESS", "")
    if where:
        _reachable(where)
    if ray.is_initialized():
        _errors_to_stderr()
        return False
    kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": logging.ERROR, "log_to_driver": False,
                              "configure_logging": True}
    if where:
        kwargs["address"] = where
    else:
        kwargs["num_cpus"] = num_cpus or os.cpu_count() or 1
        # the workers find the package as this process does (an editable install, or the current folder)
        kwargs["runtime_env"] = {"env_vars": {"SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}}
    kept = _Kept()
    try:  # joining, Ray's core says each failed try on stderr, for 20 s: one line says it all
        with _stderr_kept() if where else contextlib.nullcontext(kept) as kept:
            ray.init(**kwargs)
    except (ConnectionError, TimeoutError, RuntimeError, ValueError) as e:
        said = kept.text
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if "InvalidAuthToken" in said or "Unauthenticated" in said:
            first = ("it asks for a token this process does not have (Ray 2.59 and later): set RAY_AUTH_MODE=token "
                     "here, with the head's token in ~/.ray/auth_token or RAY_AUTH_TOKEN (ray get-auth-token prints "
                     "it)")
        raise MarlIOError(f"cannot reach the Ray cluster at {where}: {first}") from None
    _errors_to_stderr()
    return True


class _Kept:
    """What this process wrote on its stderr while it was held (:func:`_stderr_kept`), once the block has ended."""

    text = ""


@contextlib.contextmanager
def _stderr_kept() -> Iterator[_Kept]:
    """Hold what this process writes on its stderr (file descriptor 2: Ray's C++ core writes there directly) in a
    temporary file for the length of the block; :attr:`_Kept.text` has it afterwards."""
    kept = _Kept()
    with tempfile.TemporaryFile() as held:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(held.fileno(), 2)
        try:
            yield kept
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            kept.text = held.read().decode(errors="replace")


def _errors_to_stderr() -> None:
    """Ray's news of its workers' deaths ("(raylet) A worker died or was killed ...") on stderr, not stdout: the
    driver prints them from a thread of its own (``log_to_driver`` or not) on stdout, which under ``--json`` is
    the JSON's alone. Ray calls its module's ``print_to_stdstream`` for each; it is given the line marked as an
    error. (Nothing is changed where a Ray without that function is installed.)"""
    try:
        from ray._private import worker
    except ImportError:
        return
    show = getattr(worker, "print_to_stdstream", None)
    if show is None or getattr(show, "marl_stderr", False):
        return

    def to_stderr(data: dict[str, Any], *args: Any, **kwargs: Any) -> None:
        show({**data, "is_err": True}, *args, **kwargs)

    to_stderr.marl_stderr = True  # type: ignore[attr-defined]
    worker.print_to_stdstream = to_stderr


def _reachable(address: str) -> None:
    """A ``host:port`` cluster address checked with one TCP connection (5 s at most) before Ray tries it, so a wrong
    address is one line at once rather than Ray's retries and their log lines; other forms (``auto``,
    ``ray://...``) are left to Ray."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or "/" in address:
        return
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=5).close()
    except OSError as e:
        raise MarlIOError(f"cannot reach the Ray cluster at {address}: {e.strerror or e}") from None


class RayConnection:
    """Ray for the length of a ``with`` block: :func:`connect` on entry, ``ray.shutdown()`` on exit when this block
    started it."""

    def __init__(self, address: str = "", num_cpus: int | None = None) -> None:
        self.address, self.num_cpus = address, num_cpus
        self.started = False

    def __enter__(self) -> RayConnection:
        self.started = connect(self.address, num_cpus=self.num_cpus)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.started:
            ray_module().shutdown()
            self.started = False


def ray_for(settings: dict[str, Any]) -> contextlib.AbstractContextManager[Any]:
    """Ray for a run whose settings (``TrainConfig.to_dict()``'s layout) put its games or its rating games on Ray
    (``executor`` or ``eval`` ``ray``), nothing otherwise. Started here, Ray counts at least one CPU per rollout actor
    and one for the trainer, whatever the machine has: an actor waits for a CPU of Ray's count, not for a core (rating
    actors ask for none)."""
    if "ray" not in (settings.get("executor"), settings.get("eval")):
        return contextlib.nullcontext()
    want = (int(settings.get("actors", 2)) if settings.get("executor") == "ray" else 0) + 1
    return RayConnection(str(settings.get("ray_address") or ""), num_cpus=max(os.cpu_count() or 1, want))
