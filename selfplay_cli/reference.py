"""The command reference of the docs site (``docs/reference/cli.md``), generated from the CLI's own metadata: every
command and group with its help, every argument and option with its flags, value, default, environment variable
and help, as ``marl COMMAND --help`` has them. Nothing is typed by hand, so it cannot drift: ``tests/test_docs.py``
renders it again and fails where the file and the CLI differ.

The site's home page (``docs/index.md``) is README's text (:func:`home_page`), checked the same way.
``python -m selfplay_cli.reference --write`` (in the repository) writes both.
"""

from __future__ import annotations

import inspect
import re
from typing import Any

__all__ = ["home_page", "render"]

_HEAD = """# Command reference

Every command of `marl`, with its arguments and options, generated from the CLI itself
(`python -m selfplay_cli.reference --write`; a test fails when this page and the CLI differ).
`marl COMMAND --help` prints the same. The pages under *Commands* explain each with examples.
"""


def render() -> str:
    """The whole reference, as Markdown."""
    from typer._click import Context

    from .cli import build_command

    root = build_command()
    out = [_HEAD]
    top = Context(root, info_name="marl")
    for name, command in sorted(_children(root).items()):
        _command(command, Context(command, info_name=name, parent=top), ["marl", name], out)
    return "\n".join(out).rstrip() + "\n"


def _children(command: Any) -> dict[str, Any]:
    return {n: c for n, c in (getattr(command, "commands", None) or {}).items() if not getattr(c, "hidden", False)}


def _command(command: Any, ctx: Any, path: list[str], out: list[str]) -> None:
    """One command's section (a group's, then its commands'): its help, then a table of what it takes, each row as
    ``--help`` prints it (the names with the value they take; the help with its default, range and variable)."""
    from typer._click import Context

    out.append(f"{'#' * min(len(path), 4)} `{' '.join(path)}`\n")
    text = inspect.cleandoc(command.help or "").replace("\b\n", "")
    if text:
        out.append(_escape_text(text) + "\n")
    records = [p.get_help_record(ctx) for p in command.params]
    rows = [f"| `{names}` | {_cell(help_)} |" for names, help_ in (r for r in records if r is not None)]
    if rows:
        out += ["| argument / option | what it is |", "|---|---|", *rows, ""]
    for name, sub in sorted(_children(command).items()):
        _command(sub, Context(sub, info_name=name, parent=ctx), [*path, name], out)


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|").replace("<", "&lt;")


def _escape_text(text: str) -> str:
    """Help text as Markdown: paragraphs kept, nothing read as a heading or HTML."""
    return "\n".join(("\\" + line if line.startswith("#") else line).replace("<", "&lt;") for line in text.splitlines())


def home_page(readme: str) -> str:
    """The site's home page: README, its links into ``docs/`` made the site's own, without CI's markers."""
    text = re.sub(r"<!-- ci:[\w-]+ -->\n", "", readme)
    return re.sub(r"\]\(docs/([^)]*)\)", r"](\1)", text)


if __name__ == "__main__":
    import sys
    from pathlib import Path

    if sys.argv[1:] == ["--write"]:
        Path("docs/reference/cli.md").write_text(render())
        Path("docs/index.md").write_text(home_page(Path("README.md").read_text()))
    else:
        sys.stdout.write(render())
