"""Running `marl` in the test process, as a user would from a shell: exit code, stdout, stderr."""

from __future__ import annotations

import json
import signal
from typing import Any

from selfplay_cli.cli import main


def run(capsys: Any, *args: str) -> tuple[int, str, str]:
    """``marl ARGS``: its exit code and what it printed on stdout and stderr."""
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def run_json(capsys: Any, *args: str) -> Any:
    """``marl ARGS --json``, which must succeed: the JSON it printed."""
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    return json.loads(out)


def ctrl_c_enabled() -> None:
    """In a child before it runs (``preexec_fn``): SIGINT back to its default. A suite started in the background by
    a shell without job control, or in a pytest-xdist worker, inherits SIGINT ignored, and so would the child:
    Python then never raises KeyboardInterrupt (a test of Ctrl-C timed out that way, taken for a hang)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def docs_text() -> str:
    """README and every page of the docs site (``docs/``), as one text: what a user can read."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    pages = sorted((root / "docs").rglob("*.md"))
    return "\n".join(p.read_text() for p in [root / "README.md", *pages])
