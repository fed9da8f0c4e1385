"""Where this machine reads snapshot blobs from and writes them to: its own setting, never a row's.

In a shared league every row was written by someone else: a blob's row may name a location for its bytes
(``blobs.url``), and the league's ``meta`` may name a folder for new blobs (``blob_url``). marl reads or writes such a
location only when this machine allows it, in ``MARL_BLOB_LOCATIONS``: URL prefixes separated by spaces,

    export MARL_BLOB_LOCATIONS="file:///mnt/shared/marl-blobs https://blobs.example.org/marl/"

* a ``file://`` prefix is a folder: the regular files inside it may be read (symbolic links are followed, and the
  real file must still lie inside the real folder), and new blobs may be written into it or a folder below it;
* an ``http://`` or ``https://`` prefix allows reading (a GET) from URLs of the same scheme, host and port whose path
  lies under the prefix's path (``/marl/``: ``/marl/<sha256>``, not ``/marl-old/``; no ``..``). No redirect is
  followed (a redirect is an error that says so); connecting and each read time out (:data:`CONNECT_TIMEOUT`,
  :data:`READ_TIMEOUT`) and the whole fetch has a deadline (:data:`FETCH_DEADLINE`, or ``MARL_BLOB_DEADLINE``
  seconds), so a server that sends a byte now and then holds a worker no longer than that.

Unset or empty (the default), blobs are read only from the database rows' own bytes, and a league whose ``meta``
names a folder gets its new blobs in the database instead (one warning line per command: a training run never loses
a snapshot over it).

A location that is not allowed is never touched: not opened, not requested, not looked at; absent, unreadable or
there, it gets the same message. An allowed one is read as a stream and hashed as it is read, at most the size its
row says (itself at most the limit the caller gives: the largest snapshot file marl reads) plus one byte. Errors name
the blob, the location and what failed, never what was read there (no size, no hash of its bytes): they end up in
rows that every member reads, such as a failed job's error.
"""

from __future__ import annotations

import contextlib
import hashlib
import http.client
import math
import os
import posixpath
import socket
import ssl
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import SplitResult, unquote, urlsplit

from selfplay_cli.files import is_inside, opened_path
from selfplay_cli.league.failures import LeagueError, LeagueIOError, shown

__all__ = ["CONNECT_TIMEOUT", "DEADLINE_VARIABLE", "FETCH_DEADLINE", "LOCATIONS_VARIABLE", "READ_TIMEOUT", "Allowed",
           "allowed_locations", "altered", "fetch_deadline", "read_location", "writable_folder"]

LOCATIONS_VARIABLE = "MARL_BLOB_LOCATIONS"
"""The environment variable that lists the locations this machine reads blobs from and writes them to."""

DEADLINE_VARIABLE = "MARL_BLOB_DEADLINE"
"""The environment variable that sets :data:`FETCH_DEADLINE` (seconds) on this machine."""

CONNECT_TIMEOUT = 10.0
"""Seconds an ``http(s)://`` server may take to accept the connection."""

READ_TIMEOUT = 30.0
"""Seconds an ``http(s)://`` server may stay silent while a blob is read."""

FETCH_DEADLINE = 120.0
"""Seconds a whole ``http(s)://`` fetch may take, from connecting to the last byte (a 400 MB snapshot at 3.5 MB/s)."""

_MAX_DEADLINE = 86_400.0
_CHUNK = 1 << 20
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)


@dataclass(frozen=True)
class Allowed:
    """One entry of ``MARL_BLOB_LOCATIONS``: a folder (``file``: ``folder`` as written, ``real`` resolved) or an
    ``http``/``https`` prefix (``host``, ``port``, ``path`` ending in ``/``)."""

    scheme: str
    folder: str = ""
    real: str = ""
    host: str = ""
    port: int = 0
    path: str = "/"


def _bad(entry: str) -> LeagueError:
    return LeagueError(f"{LOCATIONS_VARIABLE}: {shown(entry, 200)} is not a file:///folder, http://host/path/ or "
                       "https://host/path/ prefix (several are separated by spaces)")


def _plain_path(path: str) -> str:
    """An absolute path, normalised as text (``..`` and ``.`` resolved, one leading ``/``): nothing is touched."""
    return posixpath.normpath("/" + path.lstrip("/"))


def _file_path(parts: SplitResult) -> str | None:
    """The absolute path of a ``file://`` URL of this machine, or None (another host, a relative path, a NUL)."""
    path = unquote(parts.path)
    if parts.netloc not in ("", "localhost") or not path.startswith("/") or "\0" in path:
        return None
    return _plain_path(path)


def _parse(entry: str) -> Allowed:
    try:
        parts = urlsplit(entry)
        if parts.scheme == "file":
            path = _file_path(parts)
            if path is None or parts.query or parts.fragment:
                raise _bad(entry)
            return Allowed("file", folder=path, real=os.path.realpath(path))
        if parts.scheme in ("http", "https"):
            path = unquote(parts.path) or "/"
            if (not parts.hostname or parts.username is not None or parts.password is not None or parts.query
                    or parts.fragment or not path.startswith("/") or {".", ".."} & set(path.split("/"))):
                raise _bad(entry)
            return Allowed(parts.scheme, host=parts.hostname, port=parts.port or _default_port(parts.scheme),
                           path=path if path.endswith("/") else path + "/")
    except ValueError:  # (a port that is not a number)
        raise _bad(entry) from None
    raise _bad(entry)


def _default_port(scheme: str) -> int:
    return 443 if scheme == "https" else 80


def allowed_locations() -> tuple[Allowed, ...]:
    """The locations ``MARL_BLOB_LOCATIONS`` allows now (read at every call; an entry that is not a location is a
    :class:`LeagueError` naming it)."""
    return tuple(_parse(entry) for entry in os.environ.get(LOCATIONS_VARIABLE, "").split())


def fetch_deadline() -> float:
    """Seconds a whole fetch may take here: ``MARL_BLOB_DEADLINE``, else :data:`FETCH_DEADLINE`."""
    raw = os.environ.get(DEADLINE_VARIABLE, "").strip()
    if not raw:
        return FETCH_DEADLINE
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not 0 < value <= _MAX_DEADLINE:
        raise LeagueError(f"{DEADLINE_VARIABLE}: {shown(raw)} is not a number of seconds above 0 and at most "
                          f"{_MAX_DEADLINE:,.0f}")
    return value


def _real_file(path: str, allowed: tuple[Allowed, ...]) -> str | None:
    """The real path of the file ``path`` (absolute, normalised) names when it lies in an allowed folder, else None.
    A path that does not lie in one as written is not touched at all; one that does is resolved (symbolic links
    followed) and must still lie in one."""
    if not _in_folders(path, allowed):
        return None
    real = os.path.realpath(path)
    return real if any(a.scheme == "file" and is_inside(real, a.real) for a in allowed) else None


def _in_folders(path: str, allowed: tuple[Allowed, ...]) -> bool:
    """Whether ``path`` (absolute, normalised) lies in an allowed folder as written (nothing is touched)."""
    return any(a.scheme == "file" and (is_inside(path, a.folder) or is_inside(path, a.real)) for a in allowed)


def writable_folder(url: str) -> tuple[Path, tuple[str, ...], Path] | None:
    """Where a league's blob folder ``url`` (its ``meta`` ``blob_url``) may be written on this machine: the real
    allowed folder it lies in, the folder names below it, and the folder as the URL names it (what rows name); None
    when ``url`` is not the ``file://`` URL of a folder that lies in an allowed folder (it is then not touched).
    Whether the levels below lead out by symbolic links is checked as they are opened
    (:func:`selfplay_cli.files.folder_inside`)."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return None
    path = _file_path(parts) if parts.scheme == "file" and not parts.query and not parts.fragment else None
    if path is None:
        return None
    for a in allowed_locations():
        if a.scheme != "file":
            continue
        for base in (a.folder, a.real):
            if is_inside(path, base):
                below = tuple(p for p in path[len(base.rstrip("/")):].split("/") if p)
                return Path(a.real), below, Path(path)
    return None


def _http_allowed(parts: SplitResult, allowed: tuple[Allowed, ...]) -> bool:
    path = unquote(parts.path)
    if (not parts.hostname or parts.username is not None or parts.password is not None or parts.fragment
            or not path.startswith("/") or {".", ".."} & set(path.split("/"))):
        return False
    try:
        port = parts.port or _default_port(parts.scheme)
    except ValueError:  # (a port that is not one)
        return False
    return any(a.scheme == parts.scheme and a.host == parts.hostname and a.port == port and path.startswith(a.path)
               for a in allowed)


def _at(where: str, what: str, url: str | None) -> str:
    """A message: the blob (``where``), what failed, then the location (last: a job's error is cut at its end)."""
    return f"{where}: {what}" + (f": {shown(url, 200)}" if url is not None else "")


def altered(where: str, url: str | None = None) -> LeagueError:
    """The refusal of bytes that are not the blob they are kept as (``where``: the blob; ``url``: where they were
    read, if not from its row): it never says what was read (its size or hash), which would tell anyone who reads
    the error what a location holds."""
    return LeagueError(_at(where, "its bytes are not the file it names (altered, or not the size its row says), "
                              "nothing was loaded from it", url))


def read_location(url: str, *, sha: str, size: int, limit: int, where: str, deadline: float | None = None) -> bytes:
    """The bytes of the blob ``sha`` kept at ``url``, checked: a ``file://`` or ``http(s)://`` location this machine
    allows (see the module docstring), read as a stream and hashed as it is read, at most ``size`` (its row's
    size, which must be at most ``limit``) plus one byte; refused (:func:`altered`) unless they are ``size`` bytes
    that hash to ``sha``. A location that is not allowed is refused without being touched. ``deadline``: seconds the
    whole fetch of an ``http(s)://`` location may take (default :func:`fetch_deadline`). Errors
    (:class:`LeagueError`, :class:`LeagueIOError` when reading failed) start with ``where`` (the blob), say what
    failed, and end with the URL."""
    try:
        parts = urlsplit(url)
        scheme = parts.scheme
    except ValueError:
        scheme = ""
    if scheme not in ("file", "http", "https"):
        raise LeagueError(_at(where, "not a file://, http:// or https:// URL, nothing was read", url))
    allowed = allowed_locations()
    denied = LeagueError(_at(where, f"not a location this machine reads blobs from ({LOCATIONS_VARIABLE} lists "
                                    "them), nothing was read", url))
    path = None
    if scheme == "file":
        path = _file_path(parts) if not parts.query and not parts.fragment else None
        if path is None or not _in_folders(path, allowed):
            raise denied
    elif not _http_allowed(parts, allowed):
        raise denied
    if not 0 <= size <= limit:
        raise LeagueError(_at(where, f"its row says {size:,} bytes, not a size of a snapshot marl reads (at most "
                                     f"{limit:,}), nothing was read", url))
    if path is not None:
        real = _real_file(path, allowed)
        if real is None:
            raise denied
        return _read_file(real, allowed, sha=sha, size=size, where=where, url=url, denied=denied)
    return _read_http(parts, sha=sha, size=size, where=where, url=url,
                      deadline=fetch_deadline() if deadline is None else deadline)


def _read_file(real: str, allowed: tuple[Allowed, ...], *, sha: str, size: int, where: str, url: str,
               denied: LeagueError) -> bytes:
    """The file at the real path ``real`` (checked to lie in an allowed folder): opened without following a link
    (one swapped in since is refused), without blocking (a FIFO), checked to be a regular file of ``size`` bytes
    whose real path still lies in an allowed folder, read in chunks."""
    try:
        fd = os.open(real, os.O_RDONLY | _NOFOLLOW | _NONBLOCK | _CLOEXEC)
    except OSError as exc:
        raise LeagueIOError(_at(where, f"cannot read it ({exc.strerror or exc})", url)) from None
    try:
        opened = opened_path(fd)
        if opened is not None and not any(a.scheme == "file" and is_inside(opened, a.real) for a in allowed):
            raise denied  # (a link swapped in since it was resolved)
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise LeagueError(_at(where, "not a regular file, nothing was read", url))
        if st.st_size != size:
            raise altered(where, url)
        h, chunks, total = hashlib.sha256(), [], 0
        while chunk := os.read(fd, min(_CHUNK, size + 1 - total)):
            total += len(chunk)
            if total > size:
                raise altered(where, url)
            h.update(chunk)
            chunks.append(chunk)
    except OSError as exc:
        raise LeagueIOError(_at(where, f"cannot read it ({exc.strerror or exc})", url)) from None
    finally:
        os.close(fd)
    if total != size or h.hexdigest() != sha:
        raise altered(where, url)
    return b"".join(chunks)


def _read_http(parts: SplitResult, *, sha: str, size: int, where: str, url: str, deadline: float) -> bytes:
    """GET an allowed ``http(s)://`` location: no redirect followed, connect and read timeouts, the whole fetch cut
    at ``deadline`` seconds (a watchdog shuts the socket, so even a server that drips its headers is let go)."""
    port = parts.port or _default_port(parts.scheme)
    timeout = min(CONNECT_TIMEOUT, deadline)
    conn: http.client.HTTPConnection
    if parts.scheme == "https":
        conn = http.client.HTTPSConnection(parts.hostname or "", port, timeout=timeout,
                                           context=ssl.create_default_context())
    else:
        conn = http.client.HTTPConnection(parts.hostname or "", port, timeout=timeout)
    expired = threading.Event()
    late = LeagueIOError(_at(where, f"not read within {deadline:g} s ({DEADLINE_VARIABLE} sets it), nothing was "
                                    "loaded from it", url))

    def expire() -> None:
        expired.set()
        sock = conn.sock
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)

    watchdog = threading.Timer(deadline, expire)
    watchdog.daemon = True
    end = time.monotonic() + deadline
    watchdog.start()
    try:
        conn.connect()
        if expired.is_set():
            raise late
        conn.sock.settimeout(READ_TIMEOUT)
        target = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        conn.request("GET", target, headers={"Accept-Encoding": "identity", "User-Agent": "marl"})
        response = conn.getresponse()
        if 300 <= response.status < 400:
            raise LeagueError(_at(where, f"the server answered with a redirect (HTTP {response.status}) and marl "
                                         "follows none (the row must name the blob's own location), nothing was "
                                         "read", url))
        if response.status != 200:
            raise LeagueIOError(_at(where, f"cannot read it (HTTP {response.status})", url))
        announced = response.getheader("Content-Length")
        if announced is not None and announced.strip().isdigit() and int(announced) != size:
            raise altered(where, url)
        h, chunks, total = hashlib.sha256(), [], 0
        while chunk := response.read1(min(_CHUNK, size + 1 - total)):
            if expired.is_set() or time.monotonic() > end:
                raise late
            total += len(chunk)
            if total > size:
                raise altered(where, url)
            h.update(chunk)
            chunks.append(chunk)
        if expired.is_set():
            raise late
    except (OSError, http.client.HTTPException, ValueError) as exc:
        if expired.is_set():
            raise late from None
        if isinstance(exc, http.client.IncompleteRead):  # (its message counts the bytes read: not said)
            raise LeagueIOError(_at(where, "cannot read it (the server ended its answer early)", url)) from None
        reason = getattr(exc, "strerror", None) or getattr(exc, "reason", None) or str(exc) or type(exc).__name__
        raise LeagueIOError(_at(where, f"cannot read it ({shown(str(reason), 120)[1:-1]})", url)) from None
    finally:
        watchdog.cancel()
        conn.close()
    if total != size or h.hexdigest() != sha:
        raise altered(where, url)
    return b"".join(chunks)
