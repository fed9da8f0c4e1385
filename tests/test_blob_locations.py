"""Where blobs are read from and written to is this machine's setting (``MARL_BLOB_LOCATIONS``), never a row's: a
row naming a location elsewhere is refused without it being touched, an allowed one is read within a size, a deadline
and no redirect, errors never tell what a location holds, the league's blob folder is written only where allowed,
and the cache only inside itself. (Issue 49, section 2.)"""

from __future__ import annotations

import builtins
import contextlib
import hashlib
import http.server
import json
import os
import re
import socket
import threading
import time
import tracemalloc
from functools import partial
from pathlib import Path

import pytest
from cli_helpers import run
from sqlalchemy import select, text

from selfplay_cli.errors import MarlError
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.league.models import Blob
from selfplay_cli.league.store import League, LeagueError
from selfplay_cli.players.files import blob_cache_file, snapshot_relpath
from selfplay_cli.players.load import load_player
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import MAX_FILE_BYTES, SnapshotMeta, save_snapshot

SHORT = {"points_to_win": 1}


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch) -> Path:
    """This machine's cache, empty; no location allowed unless a test says so."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("MARL_CACHE", str(folder))
    monkeypatch.delenv("MARL_BLOB_LOCATIONS", raising=False)
    monkeypatch.delenv("MARL_BLOB_DEADLINE", raising=False)
    return folder


@pytest.fixture
def sqlite_url(tmp_path) -> str:
    return f"sqlite:///{tmp_path / 'league.db'}"


def save(home: Path, name: str, seed: int) -> str:
    rel = snapshot_relpath("r", name)
    arch = Arch(hidden=(16,))
    save_snapshot(home / rel, build_network((8, 6), 3, arch, seed=seed),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, algo="ppo", run="r", name=name,
                               step=1000 * seed))
    return rel


def trained(url: str, home: Path, names=("s1",)) -> League:
    league = League.open(home, url=url)
    league.roster.create_run("r", "pong", {})
    league.roster.add_snapshots([dict(env="pong", run="r", name=n, path=save(home, n, seed=i + 1), step=1000 * (i + 1),
                                      algo="ppo") for i, n in enumerate(names)])
    league.roster.ensure_bots("pong", ["cpu"])
    return league


def execute(league: League, sql: str, **params) -> None:
    with league.session() as s:
        s.execute(text(sql), params)


def kept_at(league: League, sha: str, url: str, size: int | None = None) -> None:
    """The blob ``sha`` now kept at ``url`` (its bytes out of the row), with ``size`` in its row if given."""
    execute(league, "update blobs set data = NULL, url = :url where sha256 = :sha", url=url, sha=sha)
    if size is not None:
        execute(league, "update blobs set size = :size where sha256 = :sha", size=size, sha=sha)


def allow(monkeypatch, *locations: str) -> None:
    monkeypatch.setenv("MARL_BLOB_LOCATIONS", " ".join(locations))


def one_line(exc: BaseException) -> str:
    message = str(exc)
    assert "\n" not in message
    return message


class Touched:
    """Records every path this process opens, stats or resolves while it is active (``os.open``, ``open``,
    ``os.stat``, ``os.lstat``: what ``realpath`` calls too): what a refused location must never be."""

    def __init__(self) -> None:
        self.paths: list[str] = []

    def __enter__(self) -> Touched:
        self._patch = pytest.MonkeyPatch()
        for module, name in ((os, "open"), (os, "stat"), (os, "lstat"), (builtins, "open")):
            real = getattr(module, name)

            def spy(path, *args, _real=real, **kwargs):
                if isinstance(path, (str, bytes, os.PathLike)):
                    self.paths.append(os.fsdecode(path))
                return _real(path, *args, **kwargs)

            self._patch.setattr(module, name, spy)
        return self

    def __exit__(self, *exc: object) -> None:
        self._patch.undo()

    def any_of(self, *paths: Path) -> list[str]:
        names = {str(p) for p in paths}
        return [p for p in self.paths if p in names or any(p.startswith(n + os.sep) for n in names)]


# ---------------------------------------------------------------------------------------------------------------
# Locations a row names that this machine does not allow


def test_a_location_outside_the_allow_list_is_never_touched_and_its_error_tells_nothing(sqlite_url, tmp_path,
                                                                                          monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    allowed = tmp_path / "allowed"
    allowed.mkdir()
    secret = tmp_path / "secret.txt"
    secret.write_bytes(b"root:x:0:0:the secret of this machine\n" * 17)
    digest = hashlib.sha256(secret.read_bytes()).hexdigest()
    folder = tmp_path / "a folder"
    folder.mkdir()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)  # (opening it to read would block: touching it would hang this test)
    allow(monkeypatch, allowed.as_uri())
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    messages = {}
    for target in (secret, tmp_path / "absent", folder, fifo, Path(f"{allowed}/../secret.txt")):
        url = "file://" + str(target)
        kept_at(a, s1.sha256, url)
        with Touched() as spy, pytest.raises(LeagueError) as e:
            load_player(elsewhere, s1)
        assert spy.paths  # (the spy saw this process at work)
        assert spy.any_of(secret, tmp_path / "absent", folder, fifo) == []
        message = one_line(e.value)
        assert "not a location this machine reads blobs from" in message and "MARL_BLOB_LOCATIONS" in message
        assert s1.sha256 in message
        messages[target] = message.replace(repr(url), "URL")
        assert message.endswith(repr(url))
    assert len(set(messages.values())) == 1  # present, absent, a folder, a FIFO, a climb out: one and the same
    said = messages[secret]
    size = len(secret.read_bytes())
    assert digest[:8] not in said and str(size) not in said and f"{size:,}" not in said
    assert not blob_cache_file(s1.sha256).exists()
    elsewhere.close()
    a.close()


def test_a_worker_fails_the_job_of_such_a_row_and_the_jobs_error_tells_nothing(sqlite_url, tmp_path, monkeypatch):
    from selfplay_cli.evaluation.games_jobs import games_jobs

    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1, cpu = a.roster.find_players("r/s1")[0], a.roster.find_players("cpu")[0]
    secret = tmp_path / "shadow"
    secret.write_bytes(b"x" * 670)
    kept_at(a, s1.sha256, secret.as_uri())
    (jid,) = a.queue.enqueue("b", games_jobs(a, [s1], cpu, games=2, first_seed=0, match_kind="match", env_options=SHORT,
                                             job_rounds=1))
    worker = League.open(tmp_path / "worker-home", url=sqlite_url)
    report = run_worker(worker, WorkerOptions(max_jobs=1, poll=0.01))
    (job,) = a.queue.jobs(ids=[jid])
    assert report.failed == 1 and job.error is not None
    assert "not a location this machine reads blobs from" in job.error
    # neither the file's size (a number of its own: a sha256 in the error may hold the digits) nor its hash
    assert not re.search(r"(?<![0-9a-f])670(?![0-9a-f])", job.error)
    assert hashlib.sha256(b"x" * 670).hexdigest()[:6] not in job.error
    worker.close()
    a.close()


def test_http_locations_not_allowed_are_never_requested(sqlite_url, tmp_path, monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    server = Server(lambda conn, request: conn.sendall(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n"))
    allow(monkeypatch, f"http://127.0.0.1:{server.port}/marl/")
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    try:
        for url in (f"http://127.0.0.1:{server.port}/", f"http://127.0.0.1:{server.port}/marl-old/{s1.sha256}",
                    f"http://127.0.0.1:{server.port}/marl/../{s1.sha256}",
                    f"http://127.0.0.1:{server.port}/marl/%2e%2e/{s1.sha256}",
                    f"http://localhost:{server.port}/marl/{s1.sha256}",
                    f"https://127.0.0.1:{server.port}/marl/{s1.sha256}",
                    f"http://me@127.0.0.1:{server.port}/marl/{s1.sha256}",
                    f"http://127.0.0.1:99999999/marl/{s1.sha256}", f"http://127.0.0.1:x/marl/{s1.sha256}",
                    f"http://[::1/marl/{s1.sha256}",
                    f"ftp://127.0.0.1:{server.port}/marl/{s1.sha256}",
                    f"http://169.254.169.254/marl/{s1.sha256}"):
            kept_at(a, s1.sha256, url)
            with pytest.raises(LeagueError, match="nothing was read"):
                load_player(elsewhere, s1)
        assert server.requests == []
        kept_at(a, s1.sha256, f"http://127.0.0.1:{server.port}/marl/{s1.sha256}")  # allowed: asked (and absent)
        with pytest.raises(LeagueError, match=r"cannot read it \(HTTP 404\)"):
            load_player(elsewhere, s1)
        assert server.requests == [f"GET /marl/{s1.sha256} HTTP/1.1"]
    finally:
        server.close()
    elsewhere.close()
    a.close()


def test_the_cli_refuses_such_a_row_in_one_line_and_plays_it_once_the_folder_is_allowed(sqlite_url, tmp_path,
                                                                                      capsys, monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    shared = tmp_path / "shared disk"
    shared.mkdir()
    (shared / s1.sha256).write_bytes((home / s1.path).read_bytes())
    kept_at(a, s1.sha256, (shared / s1.sha256).as_uri())
    a.close()
    where = ("--db", sqlite_url, "--home", str(tmp_path / "empty"))
    code, _, err = run(capsys, "match", "r/s1", "cpu", "--games", "2", "--env-option", "points_to_win=1", *where)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err and "MARL_BLOB_LOCATIONS" in err
    allow(monkeypatch, shared.as_uri())
    code, out, err = run(capsys, "match", "r/s1", "cpu", "--games", "2", "--env-option", "points_to_win=1", *where,
                         "--json")
    assert code == 0 and json.loads(out)["games"] == 2, err
    assert blob_cache_file(s1.sha256).read_bytes() == (home / s1.path).read_bytes()


def test_a_bad_setting_is_one_line_before_any_job(tmp_path, capsys, monkeypatch):
    for name, value, said in (("MARL_BLOB_LOCATIONS", "/mnt/plain/path", "not a file:///folder"),
                              ("MARL_BLOB_LOCATIONS", "ftp://host/x/", "not a file:///folder"),
                              ("MARL_BLOB_DEADLINE", "0", "above 0"), ("MARL_BLOB_DEADLINE", "nan", "above 0")):
        monkeypatch.setenv(name, value)
        code, _, err = run(capsys, "worker", "--home", str(tmp_path / "h"), "--until-empty")
        assert code == 2 and err.count("\n") == 1 and said in err and name in err, err
        monkeypatch.delenv(name)


# ---------------------------------------------------------------------------------------------------------------
# Allowed locations: bounded


def test_a_blob_is_never_read_past_the_limit_dev_zero_and_sparse_giants(sqlite_url, tmp_path, monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    shared = tmp_path / "shared"
    shared.mkdir()
    giant = shared / "giant"
    with open(giant, "wb") as f:
        f.truncate(3 * 10**9)  # (sparse: 3 GB that take no disk)
    os.mkfifo(shared / "fifo")
    allow(monkeypatch, shared.as_uri(), "file:///dev")
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    cases = (("file:///dev/zero", 10**14, "not a size of a snapshot"), ("file:///dev/zero", 2 * 10**9,
             "not a size of a snapshot"), ("file:///dev/zero", MAX_FILE_BYTES, "not a regular file"),
             (giant.as_uri(), 3 * 10**9, "not a size of a snapshot"), (giant.as_uri(), MAX_FILE_BYTES, "altered"),
             ((shared / "fifo").as_uri(), 1000, "not a regular file"), ("file:///dev/null", 0, "not a regular file"))
    tracemalloc.start()
    try:
        for url, size, said in cases:
            kept_at(a, s1.sha256, url, size)
            t = time.perf_counter()
            with pytest.raises(LeagueError) as e:
                elsewhere.blobs.blob_bytes(s1.sha256, "r/s1", limit=MAX_FILE_BYTES)
            assert said in one_line(e.value) and time.perf_counter() - t < 5
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 5 * 2**20, peak  # nothing of the giants was read
    elsewhere.close()
    a.close()


def test_bytes_in_the_row_past_the_limit_are_not_loaded(db_url, tmp_path):
    home = tmp_path / "home"
    a = trained(db_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    size = (home / s1.path).stat().st_size
    assert a.blobs.blob_bytes(s1.sha256, limit=size) == (home / s1.path).read_bytes()
    with pytest.raises(LeagueError) as e:
        a.blobs.blob_bytes(s1.sha256, "r/s1", limit=size - 1)
    assert f"{size:,} bytes, more than any snapshot file marl reads ({size - 1:,})" in one_line(e.value)
    a.close()


class Server:
    """A local HTTP server (127.0.0.1, an ephemeral port): each request's first line is kept in ``requests`` and
    answered by ``answer(connection, request_line)`` in a thread of its own; ``sent`` counts what answers sent
    through :meth:`send`."""

    def __init__(self, answer) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.requests: list[str] = []
        self.sent = 0
        self.answer = answer
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn:
            head = b""
            while b"\r\n\r\n" not in head:
                chunk = conn.recv(4096)
                if not chunk:
                    return
                head += chunk
            line = head.split(b"\r\n", 1)[0].decode()
            self.requests.append(line)
            with contextlib.suppress(OSError):  # (the client went away)
                self.answer(conn, line)

    def send(self, conn: socket.socket, data: bytes) -> None:
        conn.sendall(data)
        self.sent += len(data)

    def close(self) -> None:
        self.sock.close()


def test_redirects_are_refused_not_followed(sqlite_url, tmp_path, monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    data = (home / s1.path).read_bytes()

    def answer(conn, line):
        if line.startswith("GET /to-ftp"):
            conn.sendall(b"HTTP/1.1 302 Found\r\nLocation: ftp://127.0.0.1/x\r\nContent-Length: 0\r\n\r\n")
        elif line.startswith("GET /to-same-host"):
            conn.sendall(b"HTTP/1.1 301 Moved\r\nLocation: /blob\r\nContent-Length: 0\r\n\r\n")
        else:
            conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: %d\r\n\r\n" % len(data) + data)

    server = Server(answer)
    allow(monkeypatch, f"http://127.0.0.1:{server.port}/")
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    try:
        for path in ("to-ftp", "to-same-host"):
            kept_at(a, s1.sha256, f"http://127.0.0.1:{server.port}/{path}")
            with pytest.raises(LeagueError) as e:
                elsewhere.blobs.blob_bytes(s1.sha256, limit=MAX_FILE_BYTES)
            assert "redirect" in one_line(e.value) and "follows none" in str(e.value)
        assert server.requests == ["GET /to-ftp HTTP/1.1", "GET /to-same-host HTTP/1.1"]  # not one request more
        with pytest.raises(LeagueError, match="redirect"):  # asked again at once: the same answer, not asked again
            elsewhere.blobs.blob_bytes(s1.sha256, limit=MAX_FILE_BYTES)
        assert len(server.requests) == 2
        kept_at(a, s1.sha256, f"http://127.0.0.1:{server.port}/blob")
        assert elsewhere.blobs.blob_bytes(s1.sha256, limit=MAX_FILE_BYTES) == data
    finally:
        server.close()
    elsewhere.close()
    a.close()


@pytest.mark.parametrize("where", ["body", "headers"])
def test_a_server_that_drips_is_let_go_at_the_deadline(sqlite_url, tmp_path, monkeypatch, where):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    size = (home / s1.path).stat().st_size

    def drip(conn, line):
        head = b"HTTP/1.1 200 OK\r\n" + (b"Content-Length: %d\r\n\r\n" % size if where == "body" else b"X-Slow: ")
        server.send(conn, head)
        while True:
            server.send(conn, b"a")
            time.sleep(0.2)  # (the fault itself: one byte every 0.2 s, each within any read timeout)

    server = Server(drip)
    allow(monkeypatch, f"http://127.0.0.1:{server.port}/")
    kept_at(a, s1.sha256, f"http://127.0.0.1:{server.port}/{s1.sha256}")
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    try:
        with pytest.raises(LeagueError) as e:
            elsewhere.blobs.blob_bytes(s1.sha256, "r/s1", limit=MAX_FILE_BYTES, deadline=1.0)
    finally:
        server.close()
    assert "not read within 1 s" in one_line(e.value) and "MARL_BLOB_DEADLINE" in str(e.value)
    assert server.sent < 100  # a handful of drops, not the snapshot (without the deadline: drops until closed)
    elsewhere.close()
    a.close()


@pytest.mark.parametrize("announced", [False, True])
def test_a_server_that_streams_past_the_size_is_cut_after_it(sqlite_url, tmp_path, monkeypatch, announced):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]

    def endless(conn, line):
        server.send(conn, b"HTTP/1.1 200 OK\r\n" + (b"Content-Length: 1000000000\r\n" if announced else b"")
                    + b"\r\n")
        while True:
            server.send(conn, bytes(1 << 16))

    server = Server(endless)
    allow(monkeypatch, f"http://127.0.0.1:{server.port}/")
    kept_at(a, s1.sha256, f"http://127.0.0.1:{server.port}/{s1.sha256}")
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    tracemalloc.start()
    try:
        with pytest.raises(LeagueError) as e:
            elsewhere.blobs.blob_bytes(s1.sha256, "r/s1", limit=MAX_FILE_BYTES)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        server.close()
    assert "altered" in one_line(e.value) and "1,000,000,000" not in str(e.value)
    assert peak < 5 * 2**20 and server.sent < 64 * 2**20  # cut after the row's size (plus what the sockets buffer)
    elsewhere.close()
    a.close()


def test_allowed_http_and_file_locations_play_end_to_end(sqlite_url, tmp_path, monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home, names=("s1", "s2"))
    s1, s2 = a.roster.find_players("r/s1")[0], a.roster.find_players("r/s2")[0]
    shared = tmp_path / "shared"
    shared.mkdir()
    for row in (s1, s2):
        (shared / row.sha256).write_bytes((home / row.path).read_bytes())
    handler = partial(http.server.SimpleHTTPRequestHandler, directory=str(shared))
    handler.log_message = lambda *args: None  # type: ignore[attr-defined]
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        allow(monkeypatch, (tmp_path / "link").as_uri(), f"http://127.0.0.1:{server.server_address[1]}/blobs/")
        (tmp_path / "link").symlink_to(shared)  # the folder allowed by another name: a link to it
        kept_at(a, s1.sha256, (shared / s1.sha256).as_uri())
        kept_at(a, s2.sha256, f"http://127.0.0.1:{server.server_address[1]}/blobs/../{s2.sha256}")
        elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
        assert load_player(elsewhere, s1).id == "r/s1"
        with pytest.raises(LeagueError, match="not a location this machine"):
            load_player(elsewhere, s2)
        (shared / "blobs").mkdir()
        (shared / "blobs" / s2.sha256).write_bytes((home / s2.path).read_bytes())
        kept_at(a, s2.sha256, f"http://127.0.0.1:{server.server_address[1]}/blobs/{s2.sha256}")
        assert load_player(elsewhere, s2).id == "r/s2"
        assert blob_cache_file(s2.sha256).read_bytes() == (home / s2.path).read_bytes()
        elsewhere.close()
    finally:
        server.shutdown()
    a.close()


def test_a_link_inside_an_allowed_folder_that_leads_out_is_refused_untouched(sqlite_url, tmp_path, monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    shared, outside = tmp_path / "shared", tmp_path / "outside"
    shared.mkdir()
    outside.mkdir()
    (outside / s1.sha256).write_bytes((home / s1.path).read_bytes())  # even the right bytes, outside: refused
    (shared / s1.sha256).symlink_to(outside / s1.sha256)
    (shared / "sub").symlink_to(outside)
    allow(monkeypatch, shared.as_uri())
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    for url in ((shared / s1.sha256).as_uri(), (shared / "sub" / s1.sha256).as_uri()):
        kept_at(a, s1.sha256, url)
        with pytest.raises(LeagueError, match="not a location this machine reads blobs from"):
            load_player(elsewhere, s1)
    elsewhere.close()
    a.close()


# ---------------------------------------------------------------------------------------------------------------
# Writing: the league's blob folder, the cache


def stored(league: League, sha: str) -> tuple[str | None, bool]:
    with league.session(readonly=True) as s:
        url, data = s.execute(select(Blob.url, Blob.data).where(Blob.sha256 == sha)).one()
    return url, data is not None


def test_a_blob_folder_this_machine_does_not_allow_gets_nothing_the_database_gets_the_blob(tmp_path, capsys,
                                                                                           monkeypatch):
    home = tmp_path / "home"
    trained(f"sqlite:///{home / 'league.db'}", home).close()
    other = tmp_path / "someone else's folder"
    other.mkdir()
    with League.open(home) as league:
        execute(league, "insert into meta (key, value) values ('blob_url', :url)", url=other.as_uri())
    contributed = tmp_path / "c0.safetensors"
    arch = Arch(hidden=(16,))
    save_snapshot(contributed, build_network((8, 6), 3, arch, seed=10),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, algo="ppo", run="c", name="c0"))
    code, out, err = run(capsys, "checkpoint", "import", str(contributed), "--home", str(home))
    assert code == 0, err
    assert err.count("\n") == 1 and err.startswith("marl: warning: ") and "MARL_BLOB_LOCATIONS" in err
    assert "in the league's database instead" in err
    assert list(other.iterdir()) == []
    with League.open(home) as league:
        c0 = league.roster.find_players("c/c0")[0]
        assert stored(league, c0.sha256) == (None, True)
    for i, url in enumerate(("file:///proc/sys", "http://host/x", "file://relative", "nonsense")):  # none fails
        with League.open(home) as league:
            execute(league, "update meta set value = :url where key = 'blob_url'", url=url)
            row = league.roster.add_snapshot(env="pong", run="r", name=f"x{i}", path=save(home, f"x{i}", seed=20 + i))
            assert stored(league, row.sha256) == (None, True)
    allow(monkeypatch, other.as_uri())  # allowed now: written there
    with League.open(home) as league:
        execute(league, "update meta set value = :url where key = 'blob_url'", url=other.as_uri())
        row = league.roster.add_snapshot(env="pong", run="r", name="s9", path=save(home, "s9", seed=9))
        assert stored(league, row.sha256) == ((other / row.sha256).as_uri(), False)
        assert (other / row.sha256).read_bytes() == (home / row.path).read_bytes()


def test_an_allowed_blob_folder_that_cannot_be_written_gets_the_blob_into_the_database(tmp_path, capsys, monkeypatch):
    home, shared = tmp_path / "home", tmp_path / "shared"
    shared.mkdir()
    a = trained(f"sqlite:///{home / 'league.db'}", home)
    allow(monkeypatch, shared.as_uri())
    execute(a, "insert into meta (key, value) values ('blob_url', :url)", url=(shared / "not made").as_uri())
    (shared / "leads-out").symlink_to(tmp_path / "outside")
    (tmp_path / "outside").mkdir()
    for i, folder in enumerate(("not made", "leads-out")):
        execute(a, "update meta set value = :url where key = 'blob_url'", url=(shared / folder).as_uri())
        row = a.roster.add_snapshot(env="pong", run="r", name=f"w{i}", path=save(home, f"w{i}", seed=30 + i))
        assert stored(a, row.sha256) == (None, True)
    err = capsys.readouterr().err
    assert err.count("marl: warning: cannot write") == 2 and "new ones are stored in the league's database" in err
    assert list((tmp_path / "outside").iterdir()) == [] and not (shared / "not made").exists()
    a.close()


def test_push_to_a_folder_not_allowed_says_how_to_allow_it(tmp_path, capsys, monkeypatch):
    home, shared = tmp_path / "home", tmp_path / "shared"
    shared.mkdir()
    trained(f"sqlite:///{home / 'league.db'}", home).close()
    code, out, err = run(capsys, "checkpoint", "push", "--to", shared.as_uri(), "--home", str(home))
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert f"add it to MARL_BLOB_LOCATIONS first (export MARL_BLOB_LOCATIONS={shared.as_uri()})" in err
    allow(monkeypatch, shared.as_uri())
    code, out, err = run(capsys, "checkpoint", "push", "--to", shared.as_uri(), "--home", str(home))
    assert code == 0 and out == f"the league keeps its snapshot files in {shared.as_uri()} from now on\n", err


def test_a_link_planted_at_a_temporary_name_is_never_followed(tmp_path, capsys, monkeypatch):
    from selfplay_cli import files

    home, shared = tmp_path / "home", tmp_path / "shared"
    shared.mkdir()
    a = trained(f"sqlite:///{home / 'league.db'}", home)
    allow(monkeypatch, shared.as_uri())
    a.blobs.set_blob_location(shared.as_uri())
    victim = tmp_path / "victim"
    victim.write_bytes(b"mine")
    rel = save(home, "s5", seed=5)
    sha = hashlib.sha256((home / rel).read_bytes()).hexdigest()
    (shared / f"{sha}.tmp-{os.getpid()}").symlink_to(victim)  # the name a writer of this pid once used
    (shared / sha).symlink_to(victim)  # and the blob's own name
    row = a.roster.add_snapshot(env="pong", run="r", name="s5", path=rel)
    assert victim.read_bytes() == b"mine"
    assert not (shared / sha).is_symlink() and (shared / sha).read_bytes() == (home / rel).read_bytes()
    assert stored(a, row.sha256) == ((shared / sha).as_uri(), False)
    rel = save(home, "s6", seed=6)  # a link at the very temporary name the writer picks: refused, not followed
    sha = hashlib.sha256((home / rel).read_bytes()).hexdigest()
    monkeypatch.setattr(files.secrets, "token_hex", lambda n: "guessed")
    (shared / f"{sha}.guessed.tmp-{os.getpid()}").symlink_to(victim)
    row = a.roster.add_snapshot(env="pong", run="r", name="s6", path=rel)
    assert victim.read_bytes() == b"mine" and not (shared / sha).exists()
    assert stored(a, row.sha256) == (None, True) and "cannot write" in capsys.readouterr().err
    a.close()
    target = tmp_path / "state.json"  # a home's files (files.write_atomic): the same
    files.temp_path(target).symlink_to(victim)
    files.write_atomic(target, "{}")
    assert victim.read_bytes() == b"mine" and target.read_text() == "{}" and not files.temp_path(target).exists()


@pytest.mark.parametrize("link", ["blobs", "shard"])
def test_a_cache_folder_that_leads_out_of_the_cache_is_refused_nothing_written_outside(sqlite_url, tmp_path, cache,
                                                                                      capsys, link):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    a.close()
    outside = tmp_path / "elsewhere-disk"
    outside.mkdir()
    if link == "blobs":
        cache.mkdir()
        (cache / "blobs").symlink_to(outside)
    else:
        (cache / "blobs").mkdir(parents=True)
        (cache / "blobs" / s1.sha256[:2]).symlink_to(outside)
    with League.open(tmp_path / "empty", url=sqlite_url) as elsewhere, pytest.raises(MarlError) as e:
        load_player(elsewhere, s1)
    assert "outside" in one_line(e.value) and "nothing is written there" in str(e.value)
    assert list(outside.iterdir()) == []
    code, _, err = run(capsys, "match", "r/s1", "cpu", "--games", "2", "--db", sqlite_url, "--home",
                       str(tmp_path / "empty"))
    assert code == 2 and err.count("\n") == 1 and "outside" in err and "Traceback" not in err
    assert list(outside.iterdir()) == []


def test_a_link_inside_the_cache_to_the_cache_itself_is_fine_and_a_cached_link_is_replaced(sqlite_url, tmp_path,
                                                                                           cache):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    (cache / "store").mkdir(parents=True)
    (cache / "blobs").symlink_to(cache / "store")  # a link that stays inside the cache
    (cache / "store" / s1.sha256[:2]).mkdir()
    victim = tmp_path / "victim"
    victim.write_bytes(b"mine")
    (cache / "store" / s1.sha256[:2] / f"{s1.sha256}.safetensors").symlink_to(victim)
    with League.open(tmp_path / "empty", url=sqlite_url) as elsewhere:
        assert load_player(elsewhere, s1).id == "r/s1"
    cached = cache / "store" / s1.sha256[:2] / f"{s1.sha256}.safetensors"
    assert not cached.is_symlink() and cached.read_bytes() == (home / s1.path).read_bytes()
    assert victim.read_bytes() == b"mine"
    a.close()


def test_the_error_of_an_allowed_location_that_is_not_the_blob_tells_nothing_of_it(sqlite_url, tmp_path,
                                                                                  monkeypatch):
    home = tmp_path / "home"
    a = trained(sqlite_url, home)
    s1 = a.roster.find_players("r/s1")[0]
    shared = tmp_path / "shared"
    shared.mkdir()
    other = bytes(range(256)) * 40
    (shared / "other").write_bytes(other)
    allow(monkeypatch, shared.as_uri())
    elsewhere = League.open(tmp_path / "elsewhere", url=sqlite_url)
    for size in (len(other), len(other) + 1, 100):
        kept_at(a, s1.sha256, (shared / "other").as_uri(), size)
        with pytest.raises(LeagueError) as e:
            load_player(elsewhere, s1)
        message = one_line(e.value)
        assert "altered" in message and hashlib.sha256(other).hexdigest()[:8] not in message
        assert not re.search(r"\b10,?240\b", message.replace(s1.sha256, ""))
    elsewhere.close()
    a.close()
