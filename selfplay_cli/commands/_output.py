"""One console for the whole CLI: rich for people, plain JSON under --json, plain text when not a TTY."""

from __future__ import annotations

import json
import sys
from typing import Any

from rich.console import Console

console = Console(highlight=False, soft_wrap=True)
if not console.is_terminal:  # piped output: plain, and wide enough that tables are never cut to "…"
    console = Console(highlight=False, soft_wrap=True, width=max(console.width, 200))
err_console = Console(stderr=True, highlight=False, soft_wrap=True)


def print_json(data: Any) -> None:
    """Print JSON alone on stdout (no rich markup, no colour)."""
    sys.stdout.write(json.dumps(data, indent=2, default=str) + "\n")
    sys.stdout.flush()
