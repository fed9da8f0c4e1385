"""A benchmark's figures as a file the docs quote: what the script printed, with when, where and on what code it ran.

Each script in ``benchmarks/`` runs its ``main()`` inside :func:`recorded`; when it ends well, what it printed goes to
``benchmarks/results/NAME.json`` (written to a temporary name, then renamed) with the date, the machine (cores, CPU,
memory, system), the load average at its start and end, the command and the commit measured. The docs quote a
benchmark's figures between ``<!-- figures:NAME -->`` and ``<!-- /figures -->``: ``python -m selfplay_cli.reference
--write`` renders them from this file, and the docs test fails where a page and its file differ. A run that fails
or is stopped writes nothing (the last good run's file stays).
"""

from __future__ import annotations

import contextlib
import datetime
import io
import json
import os
import platform
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


class _Tee(io.TextIOBase):
    """Text written to the terminal as before, and kept."""

    def __init__(self, out):
        self.out, self.kept = out, io.StringIO()

    def write(self, s: str) -> int:
        self.kept.write(s)
        return self.out.write(s)

    def flush(self) -> None:
        self.out.flush()

    def isatty(self) -> bool:
        return self.out.isatty()

    def reconfigure(self, **options) -> None:
        """As the stream's own (a benchmark asking for line buffering gets it on the terminal or file it writes)."""
        self.out.reconfigure(**options)


def machine() -> str:
    """This machine in a line: cores, CPU model, memory, system (no host name: the file is committed)."""
    model = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = " ".join(line.split(":", 1)[1].split())
                break
    memory = ""
    with contextlib.suppress(ValueError, OSError, AttributeError):
        memory = f", {os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2 ** 30:.0f} GB"
    return f"{os.cpu_count()} cores{f' ({model})' if model else ''}{memory}, {platform.system()} {platform.machine()}"


def commit() -> str:
    """The commit measured (short), ``+changes`` when the code in the work tree differs from it (the package's or the
    benchmarks'; not the results files, which a run rewrites); "" outside a git checkout."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "selfplay_cli",
                                "benchmarks", ":!benchmarks/results"], cwd=ROOT, capture_output=True, text=True,
                               timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""
    return f"{head}+changes" if head and dirty else head


def _load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


@contextlib.contextmanager
def recorded(name: str | None = None) -> Iterator[dict]:
    """Run a benchmark's body, its printing kept; on a good end, write ``benchmarks/results/NAME.json`` (NAME: the
    script's own name unless given). The body gets a dict: what it puts there is written too (a benchmark's figures
    as data, for a page that renders them as a table)."""
    name = name or Path(sys.argv[0]).stem
    started, load_start = datetime.datetime.now().astimezone(), _load()
    tee = _Tee(sys.stdout)
    sys.stdout = tee
    data: dict = {}
    try:
        yield data
    except SystemExit as e:
        if e.code not in (None, 0):
            raise
    finally:
        sys.stdout = tee.out
    write(name, {
        "benchmark": name,
        "command": " ".join(["python", f"benchmarks/{Path(sys.argv[0]).name}", *sys.argv[1:]]),
        "date": started.date().isoformat(),
        "started": started.isoformat(timespec="seconds"),
        "seconds": round((datetime.datetime.now().astimezone() - started).total_seconds(), 1),
        "machine": machine(),
        "load_start": load_start,
        "load_end": _load(),
        "commit": commit(),
        "printed": tee.kept.getvalue().splitlines(),
        **data,
    })


def write(name: str, data: dict) -> Path:
    """``data`` as ``benchmarks/results/NAME.json``, whole or not at all (a temporary name, then renamed)."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")
    os.replace(tmp, path)
    print(f"(figures written to {os.path.relpath(path, ROOT)})", file=sys.stderr)
    return path
