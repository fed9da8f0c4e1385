"""One console for the whole CLI: rich for people, plain JSON under --json, plain text when not a TTY."""

from __future__ import annotations

import json
import math
import sys
from typing import Any

from rich.console import Console

console = Console(highlight=False, soft_wrap=True)
if not console.is_terminal:  # piped output: plain, and wide enough that tables are never cut to "…"
    console = Console(highlight=False, soft_wrap=True, width=max(console.width, 200))
err_console = Console(stderr=True, highlight=False, soft_wrap=True)


def finite(data: Any) -> Any:
    """``data`` with every NaN or infinity replaced by None: JSON has no such numbers (``NaN`` is not JSON)."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: finite(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [finite(v) for v in data]
    return data


def print_json(data: Any) -> None:
    """Print JSON alone on stdout (no rich markup, no colour); a NaN or infinity anywhere becomes null."""
    sys.stdout.write(json.dumps(finite(data), indent=2, default=str, allow_nan=False) + "\n")
    sys.stdout.flush()
