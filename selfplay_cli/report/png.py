"""Writing a matplotlib figure to a PNG file atomically (temporary name, then rename), with one-line errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..files import atomic_write
from ..league.store import LeagueError

__all__ = ["check_png_path", "new_figure", "save_png"]


def check_png_path(path: str | Path) -> Path:
    """``path`` as a Path, if it can name a PNG to write: it ends in ``.png``, is not a directory and its folder
    exists. Raises LeagueError (one line) otherwise."""
    p = Path(path).expanduser()
    if p.suffix.lower() != ".png":
        raise LeagueError(f"cannot write {p}: the file name must end in .png")
    if p.is_dir():
        raise LeagueError(f"cannot write {p}: it is a directory")
    if not p.parent.is_dir():
        raise LeagueError(f"cannot write {p}: no folder {p.parent}")
    return p


def save_png(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Draw ``fig`` (a :class:`matplotlib.figure.Figure` on an Agg canvas) into ``path`` as a PNG: written to a
    temporary name in the same folder, then renamed over ``path``. Returns ``path``.

    Raises:
        LeagueError: the path is not a writable ``.png`` file name.
    """
    p = check_png_path(path)
    try:
        with atomic_write(p) as fh:
            fig.savefig(fh, format="png", dpi=dpi)
    except OSError as exc:
        raise LeagueError(f"cannot write {p}: {exc.strerror or exc}") from exc
    return p


def new_figure(width: float, height: float) -> Any:
    """A matplotlib Figure on the Agg canvas: no pyplot, no GUI backend, no display touched."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig
