"""A team-size study's PNGs: mean team return against the team size flown (a line per trained size), and the
curves of the adapted runs against the runs trained from scratch at the same size."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..files import atomic_write

__all__ = ["plot_curves", "plot_returns"]


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=100)
    return path


def plot_returns(report: dict[str, Any], path: Path) -> Path:
    """Mean team return (95% interval) against the team size flown, one line per size trained at; the x axis is
    ticked at the sizes studied only."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for n in report["train"]:
        cells = sorted((c for c in report["returns"] if c["trained"] == n), key=lambda c: c["evaluated"])
        xs = [c["evaluated"] for c in cells]
        ys = [c["mean"] for c in cells]
        lo = [c["mean"] - c["low"] if c["low"] is not None else 0 for c in cells]
        hi = [c["high"] - c["mean"] if c["high"] is not None else 0 for c in cells]
        ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=f"trained with {n}")
    vs = [c for c in report["returns"] if c["trained"] == report["train"][0]]
    if vs:
        vs = sorted(vs, key=lambda c: c["evaluated"])
        ax.plot([c["evaluated"] for c in vs], [c["vs"]["mean"] for c in vs], color="grey", linestyle=":",
                label=f"{report['vs']}")
    sizes = sorted({int(c["evaluated"]) for c in report["returns"]} | {int(m) for m in report.get("eval", ())})
    ax.set_xticks(sizes, [str(m) for m in sizes])  # whole seats: the sizes studied, nothing between them
    ax.set_xticks([], minor=True)
    ax.set_xlabel(f"team size flown ({report['size_option']})")
    ax.set_ylabel("mean team return per game")
    ax.set_title(f"{report['env']}: team size (study {report['study']})")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out = _save(fig, path)
    plt.close(fig)
    return out


def plot_curves(report: dict[str, Any], path: Path) -> Path:
    """Each adapted run's snapshots' mean team return (their rating games) against training steps, beside the fresh
    run of its size, and a line where it reached the fresh run's final return on the study's seeds."""
    plt = _pyplot()
    pairs = report["adaptive"]
    cols = max(1, min(3, len(pairs)))
    rows = max(1, -(-len(pairs) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.5 * cols, 3.4 * rows), squeeze=False)
    for ax, a in zip(axes.flat, pairs, strict=False):
        for key, label, style in (("fresh_curve", f"fresh at {a['to']}", "--"),
                                  ("curve", f"adapted {a['from']} -> {a['to']}", "-")):
            pts = a[key]
            ax.plot([p[0] for p in pts], [p[2] for p in pts], style, marker="o", markersize=3, label=label)
        if a.get("steps_to_reach") is not None:  # the moment it reached the fresh run's final (the study's seeds)
            ax.axvline(a["steps_to_reach"], color="grey", linestyle=":", label="reached fresh's final")
        ax.set_title(f"{a['from']} -> {a['to']}")
        ax.set_xlabel("game steps")
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    for ax in list(axes.flat)[len(pairs):]:
        ax.axis("off")
    axes.flat[0].set_ylabel("mean team return (rating games)")
    fig.suptitle(f"{report['env']}: adapted from another size vs trained afresh")
    fig.tight_layout()
    out = _save(fig, path)
    plt.close(fig)
    return out
