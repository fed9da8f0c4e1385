"""Running `marl` in the test process, as a user would from a shell: exit code, stdout, stderr."""

from __future__ import annotations

import json
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
