"""Rendering of ladder rows (shared by `marl league ladder` and `marl elo fit`)."""

from __future__ import annotations

import csv
import sys

from rich.table import Table

from ._output import console, print_json


def _fmt_elo(x: float) -> str:
    return f"{x:.1f}"


def render_ladder(rows: list, title: str, json_out: bool = False, csv_out: bool = False,
                  online: dict[str, float] | None = None) -> None:
    if json_out:
        print_json([r.to_json() for r in rows])
        return
    if csv_out:
        w = csv.writer(sys.stdout)
        keys = list(rows[0].to_json()) if rows else ["policy", "kind", "elo", "ci_low", "ci_high", "games", "wins",
                                                      "draws", "losses", "rank"]
        w.writerow(keys)
        for r in rows:
            d = r.to_json()
            w.writerow([d[k] for k in keys])
        return
    table = Table(title=title)
    for col, just in (("rank", "right"), ("policy", "left"), ("kind", "left"), ("step", "right"),
                      ("Elo", "right"), ("95% interval", "center"), ("games", "right"), ("W-D-L", "center"),
                      ("score", "right")):
        table.add_column(col, justify=just)
    if online:
        table.add_column("online", justify="right")
    for r in rows:
        note = f" ({r.flag})" if r.flag else ""
        anchor = " (anchor)" if r.anchor else ""
        cells = [str(r.rank), r.policy + anchor, r.kind, "" if r.step is None else f"{r.step:,}",
                 _fmt_elo(r.elo) + note, f"{_fmt_elo(r.ci_low)} .. {_fmt_elo(r.ci_high)}", str(r.games),
                 f"{r.wins}-{r.draws}-{r.losses}", f"{100 * r.score:.1f}%"]
        if online:
            cells.append(f"{online.get(r.policy, float('nan')):.0f}")
        table.add_row(*cells)
    console.print(table)
