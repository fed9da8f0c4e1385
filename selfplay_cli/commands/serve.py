"""`marl serve`: the league's read-only web pages (:mod:`selfplay_cli.serve`), on this machine only unless told."""

from __future__ import annotations

import errno
import ipaddress
import socket
from typing import Annotated

import typer

from ..errors import MarlError
from ._common import DbOpt, HomeOpt
from ._output import console, err_console

EXTRA = 'pip install -e ".[serve]"'


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _bind(host: str, port: int) -> socket.socket:
    """A listening socket on ``host:port`` (port 0: a free one), or one line saying why not."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as e:
        raise MarlError(f"--host {host}: not an address of this machine ({e.strerror})") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
        sock.listen(128)
    except OSError as e:
        sock.close()
        if e.errno == errno.EADDRINUSE:
            raise MarlError(f"port {port} on {host} is in use: pick another with --port (or --port 0 for a free one)")\
                from None
        if e.errno in (errno.EACCES, errno.EPERM):
            raise MarlError(f"port {port} on {host} needs privileges this user lacks: use a port above 1023") \
                from None
        raise MarlError(f"cannot listen on {host}:{port}: {e.strerror or e}") from None
    return sock


def serve(
    host: Annotated[str, typer.Option("--host", help="Address to listen on. The default, 127.0.0.1, is this machine "
                                      "only; 0.0.0.0 lets anyone who can reach the machine read the league.")]
    = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", min=0, max=65_535, help="Port to listen on (0: a free one, "
                                      "printed).")] = 8000,
    home: HomeOpt = None,
    db: DbOpt = None,
) -> None:
    """Serve read-only web pages of the league: the ladder (sortable, filterable by game, variant and run), the score
    matrix with its Nash mixture, rating and exploitability curves per run, each player's page (lineage, games by
    opponent, predicted score against any other, replays), matches and gates with their SPRT, the work queue and
    the recorded replays.

    The league is opened read-only (SQLite with mode=ro, PostgreSQL with default_transaction_read_only): the server
    never writes. The ratings are fitted in one background thread when the server starts and whenever the league
    changes: a page shows the latest finished fit and says when it was made (before the first, a notice that reloads
    itself), so no page waits for a fit. It listens on 127.0.0.1 (this machine) unless --host says otherwise. Ctrl-C
    stops it. Needs the serve extra: pip install -e ".[serve]"."""
    try:
        import jinja2  # noqa: F401
        import starlette  # noqa: F401
        import uvicorn
    except ImportError as e:
        raise MarlError(f"marl serve needs its extra ({e.name} is missing): {EXTRA}") from None
    import os
    from pathlib import Path

    from ..league.home import DB_FILENAME, DEFAULT_HOME
    from ..serve.app import create_app
    from ..serve.queries import Reader

    if db is None:
        where_home = Path(home if home is not None else os.environ.get("MARL_HOME") or DEFAULT_HOME).expanduser()
        if not (where_home / DB_FILENAME).is_file():
            raise MarlError(f"no league at {where_home.resolve()} (no {DB_FILENAME} there): pass --home or --db")
    sock = _bind(host, port)
    try:
        reader = Reader(home, db)
    except BaseException:
        sock.close()
        raise
    where = reader.league.db_path or reader.league.url.render_as_string(hide_password=True)
    try:
        bound = sock.getsockname()[1]
        shown = f"[{host}]" if ":" in host else host
        console.print(f"marl serve: http://{shown}:{bound}/ (the league at {where}, read-only)", markup=False,
                      highlight=False)
        if _loopback(host):
            err_console.print(f"listening on {host} only: this machine alone can see the pages (use --host 0.0.0.0 "
                              "to expose them to other machines)", markup=False, highlight=False)
        else:
            err_console.print(f"warning: listening on {host}: anyone who can reach this machine on port {bound} can "
                              "read the whole league (names, ratings, games, replays)", markup=False,
                              highlight=False)
        app = create_app(reader, str(where))
        config = uvicorn.Config(app, log_level="warning", access_log=False, lifespan="on")
        uvicorn.Server(config).run(sockets=[sock])
    finally:
        sock.close()
        reader.close()
