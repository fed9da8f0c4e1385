"""Ray for a run (``--executor ray``, ``--eval ray``): the optional import and joining a cluster, each failure one line.

Ray is an optional extra (``pip install "selfplay-cli[ray]"``). :func:`ray_module` imports it or refuses in one line
(exit 2) before anything is written; :func:`connect` starts Ray on this machine's cores or joins a running cluster
(``--ray-address``, e.g. ``ray start --head`` on one machine and ``ray start --address HEAD:6379`` on the others),
and says in one line (exit 4) when the cluster cannot be reached. :class:`RayConnection` is the context a run holds:
Ray is shut down at its end only if this process started it (a test, or a script, may have started it already).

Started on this machine, Ray is given no more actors than it has cores (:func:`check_local_actors`: one line, exit
2): each actor is a process of its own with its own copy of torch and the game, and 200 of them on 2 cores took 5 GB
in 25 s before any game was played. A cluster (``--ray-address``, or ``RAY_ADDRESS``) is the place for more.
What Ray starts here ends with the run on every way out: :func:`shutdown` at the end of the block (a return, an
error, Ctrl-C, SIGTERM, a start cut short). A run killed outright (SIGKILL) cannot shut it down: Ray's fate sharing
ends its core and its workers within seconds, but its two node agents (``ray::DashboardAgent``,
``ray::RuntimeEnvAgent``) waited a minute for a dead GCS before they left; so Ray started here has a keeper
(:data:`KEEPER`), a small process that notes Ray's processes under this one while they live and kills what is left
of them when this process is gone (its pipe closes) or has shut Ray down.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from types import ModuleType
from typing import Any

from .errors import MarlError, MarlIOError

INSTALL_HINT = 'pip install "selfplay-cli[ray]"'


def ray_module() -> ModuleType:
    """The ``ray`` module, or one :class:`MarlError` (exit 2) saying how to install it."""
    try:
        import ray
    except ImportError:
        raise MarlError(f"--executor ray and --eval ray need Ray, which is not installed ({INSTALL_HINT})") from None
    return ray


KEEPER = r"""
import os, re, select, signal, sys
run, package, me = int(sys.argv[1]), os.fsencode(sys.argv[2]), os.getpid()
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)

def read(path):
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError:
        return b""

def start(pid):
    stat = read(f"/proc/{pid}/stat")
    return stat[stat.rfind(b")") + 2:].split()[19:20] or None

def children(pid):
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []
    return [int(c) for t in tasks for c in read(f"/proc/{pid}/task/{t}/children").split()]

def in_session(pid, session):
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}").encode().startswith(session):
                return True
        except OSError:
            pass
    return False

seen, session = {}, None
while not select.select([0], [], [], 0.25)[0]:  # until this process's pipe has news, or closes (it is gone)
    todo = children(run)
    while todo:
        pid = todo.pop()
        if pid == me or pid in seen:
            continue
        todo += children(pid)
        line = read(f"/proc/{pid}/cmdline")
        if line.startswith(b"ray::") or package in line:  # Ray's: its core, agents, workers (not a rating worker)
            seen[pid] = start(pid)
            if session is None:  # its core's command lines name it: --log_dir=/tmp/ray/session_.../logs
                found = re.search(rb"(/[^\x00\s=]*/session_[^/\x00\s]+/)", line)
                session = found.group(1) if found else None
# what Ray started is this process's: those noted, and those that hold files of its session (Ray's node agents,
# started a moment before the run stopped Ray, and left by it)
if session is not None:
    for name in os.listdir("/proc"):
        if name.isdigit() and int(name) not in (run, me) and int(name) not in seen and in_session(name, session):
            seen[int(name)] = start(name)
for pid, when in seen.items():
    if when is not None and start(pid) == when:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
"""
"""The keeper of Ray started here (``python -c KEEPER PID RAY_PACKAGE_FOLDER``): every quarter second it notes the
Ray processes under process PID (named ``ray::...``, or run from Ray's package folder), by pid and start time (a pid
given to another process since is never taken for one of them), and Ray's session folder; when its stdin has news or
closes (PID shut Ray down, or is gone), it kills those still alive and any other process holding a file of that
session open (Ray's node agents, which Ray's core starts: a stop in the middle of ``ray.init`` left them for a
minute), and leaves."""

_keeper: subprocess.Popen | None = None


def _start_keeper() -> None:
    global _keeper
    if _keeper is not None or not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError):  # (no keeper: Ray's own fate sharing is what is left)
        package = os.path.dirname(ray_module().__file__ or "") + os.sep
        _keeper = subprocess.Popen([sys.executable, "-c", KEEPER, str(os.getpid()), package], stdin=subprocess.PIPE,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)


def _end_keeper() -> None:
    """Tell the keeper that Ray is shut down: it kills what Ray left (nothing, as a rule) and leaves."""
    global _keeper
    keeper, _keeper = _keeper, None
    if keeper is None:
        return
    with contextlib.suppress(OSError):
        keeper.stdin.write(b"x")  # type: ignore[union-attr]
        keeper.stdin.close()  # type: ignore[union-attr]
    with contextlib.suppress(subprocess.TimeoutExpired):
        keeper.wait(timeout=10)


def shutdown() -> None:
    """Shut down Ray started by :func:`connect` here, and what it left of its processes (its keeper's work)."""
    try:
        ray_module().shutdown()
    finally:
        _end_keeper()


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
        _start_keeper()  # Ray's processes on this machine are this run's: they end with it
    kept = _Kept()
    try:  # joining, Ray's core says each failed try on stderr, for 20 s: one line says it all
        with _stderr_kept() if where else contextlib.nullcontext(kept) as kept, _sigterm_kept():
            ray.init(**kwargs)
    except (ConnectionError, TimeoutError, RuntimeError, ValueError) as e:  # (what it started is shut down)
        said = kept.text
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if "InvalidAuthToken" in said or "Unauthenticated" in said:
            first = ("it asks for a token this process does not have (Ray 2.59 and later): set RAY_AUTH_MODE=token "
                     "here, with the head's token in ~/.ray/auth_token or RAY_AUTH_TOKEN (ray get-auth-token prints "
                     "it)")
        raise MarlIOError(f"cannot reach the Ray cluster at {where}: {first}") from None
    _errors_to_stderr()
    return True


@contextlib.contextmanager
def _sigterm_kept() -> Iterator[None]:
    """``ray.init`` with this process's own SIGTERM handling kept: Ray sets a handler of its own (``sys.exit(15)``:
    a run ended silently with exit 15, its stop unsaid), which is put back to what it was when ``ray.init`` returns.
    SIGTERM, Ctrl-C or anything else that stops ``ray.init`` halfway has what it started shut down at once (its
    processes lingered for seconds otherwise), and a SIGTERM that came meanwhile is then raised again for the
    handler that was in place before (``Terminated`` in a run, or the default: the process ends by it)."""
    import signal
    import threading

    before = signal.getsignal(signal.SIGTERM) if threading.current_thread() is threading.main_thread() else None
    main = before is not None  # (None: not the main thread, or a handler not set from Python: left to Ray)
    try:
        yield
    except BaseException as e:
        with contextlib.suppress(Exception):
            shutdown()
        if main:
            signal.signal(signal.SIGTERM, before)
            if isinstance(e, SystemExit) and e.code == signal.SIGTERM:  # Ray's handler: the SIGTERM, handed on
                signal.raise_signal(signal.SIGTERM)
        raise
    if main:
        signal.signal(signal.SIGTERM, before)


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
            shutdown()
            self.started = False


def machine_cores() -> int:
    """The cores this process may run on (its CPU affinity, where the system has one: a container's share)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def check_local_actors(actors: int, flag: str, address: str = "") -> None:
    """Refuse (one :class:`MarlError`, exit 2) more than one actor per core of this machine for Ray started here:
    no cluster ``address`` (nor ``RAY_ADDRESS``), and no Ray already running in this process (whoever started it
    chose its size)."""
    if address or os.environ.get("RAY_ADDRESS"):
        return
    ray = sys.modules.get("ray")
    if ray is not None and getattr(ray, "is_initialized", lambda: False)():
        return
    cores = machine_cores()
    if actors > cores:
        raise MarlError(f"{flag} {actors} is more Ray actors than this machine has cores ({cores}): give at most "
                        f"{cores}, or join a Ray cluster with more with --ray-address HOST:PORT")


def ray_for(settings: dict[str, Any]) -> contextlib.AbstractContextManager[Any]:
    """Ray for a run whose settings (``TrainConfig.to_dict()``'s layout) put its games or its rating games on Ray
    (``executor`` or ``eval`` ``ray``), nothing otherwise. Started here, Ray counts at least one CPU per rollout actor
    and one for the trainer, whatever the machine has: an actor waits for a CPU of Ray's count, not for a core (rating
    actors ask for none)."""
    if "ray" not in (settings.get("executor"), settings.get("eval")):
        return contextlib.nullcontext()
    address = str(settings.get("ray_address") or "")
    if settings.get("executor") == "ray":
        check_local_actors(int(settings.get("actors", 2)), "--actors", address)
    if settings.get("eval") == "ray":
        check_local_actors(int(settings.get("eval_actors", 1)), "--eval-actors", address)
    want = (int(settings.get("actors", 2)) if settings.get("executor") == "ray" else 0) + 1
    return RayConnection(address, num_cpus=max(machine_cores(), want))
