"""Terminal renderings of the reports, as rich renderables (the caller prints them).

* :func:`curves_chart`: a run's rating curves as a character chart. ``unicode=True`` (a terminal) draws with
  braille dots (2 x 4 per character) in colour; ``unicode=False`` (a pipe, a log file) draws plain ASCII, one
  point per character, with no colour, readable at 80 columns.
* :func:`curves_summary`: the numbers behind the chart: the run's best snapshot as the ladder marks it, then per
  learner.
* :func:`matrix_table` / :func:`matrix_summary`: the score matrix as a heat table, then its Nash mixture, cycles and
  the command that plays the missing games.

Everything is built from :class:`rich.text.Text`, never markup, so names with square brackets print as they are.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rich import box
from rich.console import Group, RenderableType
from rich.style import Style
from rich.table import Table
from rich.text import Text

from ..stats.bradley_terry import FLAG_PERFECT
from .matrix import CYCLE_TEST, MatrixReport
from .plots import BOUND_FLAGS, CurvePoint, ExploitPoint, RunCurves, format_steps, x_limits, y_limits

__all__ = ["curves_chart", "curves_summary", "matrix_summary", "matrix_table", "nice_ticks"]

_COLORS = ("cyan", "magenta", "green", "yellow", "blue", "red")
_MARKERS = "ox+#@%&~"  # a learner's points in ASCII; "*" (best), "=" (shared), "^ v ?" are marks (see _marks)
_BOT_STYLE = "grey62"
# braille dot bits by [row][column] inside one character cell (2 columns x 4 rows)
_BRAILLE = ((0x01, 0x08), (0x02, 0x10), (0x04, 0x20), (0x40, 0x80))


def nice_ticks(lo: float, hi: float, target: int = 5) -> list[float]:
    """Round tick values (1, 2, 2.5 or 5 times a power of ten apart) inside ``[lo, hi]``, about ``target`` of them."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(target, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw)
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(int((hi - first) / step + 1e-9) + 1)]


class _Canvas:
    """A pixel grid drawn into character cells: braille (2 x 4 pixels a cell) or ASCII (1 x 1)."""

    def __init__(self, cols: int, rows: int, unicode: bool) -> None:
        self.cols, self.rows, self.unicode = cols, rows, unicode
        self.sx, self.sy = (2, 4) if unicode else (1, 1)
        self.w, self.h = cols * self.sx, rows * self.sy
        self.layer = np.full((self.h, self.w), -1, dtype=np.int64)
        self.prio = np.full((self.h, self.w), -1, dtype=np.int64)

    def set(self, x: int, y: int, layer: int, prio: int) -> None:
        if 0 <= x < self.w and 0 <= y < self.h and prio >= self.prio[y, x]:
            self.layer[y, x], self.prio[y, x] = layer, prio

    def line(self, x0: int, y0: int, x1: int, y1: int, layer: int, prio: int) -> None:
        dx, dy = abs(x1 - x0), -abs(y1 - y0)
        sx, sy = (1 if x0 < x1 else -1), (1 if y0 < y1 else -1)
        err = dx + dy
        while True:
            self.set(x0, y0, layer, prio)
            if x0 == x1 and y0 == y1:
                return
            e2 = 2 * err
            if e2 >= dy:
                err += dy
                x0 += sx
            if e2 <= dx:
                err += dx
                y0 += sy

    def cells(self, glyphs: list[str]) -> list[list[tuple[str, int]]]:
        """Per cell: its character and the layer that owns it (-1: empty)."""
        out = []
        for r in range(self.rows):
            row = []
            for c in range(self.cols):
                lay = self.layer[r * self.sy:(r + 1) * self.sy, c * self.sx:(c + 1) * self.sx]
                pri = self.prio[r * self.sy:(r + 1) * self.sy, c * self.sx:(c + 1) * self.sx]
                if pri.max() < 0:
                    row.append((" ", -1))
                    continue
                owner = int(lay.flat[int(np.argmax(pri))])
                if self.unicode:
                    bits = 0
                    for yy, xx in zip(*np.nonzero(pri >= 0), strict=True):
                        bits |= _BRAILLE[yy][xx]
                    row.append((chr(0x2800 + bits), owner))
                else:
                    row.append((glyphs[owner], owner))
            out.append(row)
        return out


def _marks(curves: RunCurves, px: Callable[[float], int], py: Callable[[float], int], sx: int,
           sy: int) -> tuple[dict[tuple[int, int], tuple[str, str]], list[tuple[str, str]]]:
    """The character cells that carry a mark instead of a learner's own point, and the legend entries of the marks
    that show: points of several learners in one cell (``=``: a team whose members have equal ratings, where
    otherwise only the last learner drawn would show), bounds (``^`` at least, ``v`` at most), ratings with no
    link to the anchor (``?``), and the ladder's best snapshot (``*``, which wins its cell)."""
    cells: dict[tuple[int, int], tuple[str, str]] = {}
    owners: dict[tuple[int, int], list[int]] = {}
    where: dict[tuple[int, int], list[CurvePoint]] = {}
    for k, curve in enumerate(curves.curves):
        for p in curve.points:
            cell = (py(p.elo) // sy, px(p.step) // sx)
            where.setdefault(cell, []).append(p)
            if k not in owners.setdefault(cell, []):
                owners[cell].append(k)
    for cell, ks in owners.items():
        if len(ks) > 1:
            cells[cell] = ("=", "bold")
    for cell, points in where.items():
        for p in points:
            if p.bound:
                cells[cell] = ("^" if p.flag == FLAG_PERFECT else "v", "bold")
            elif p.unanchored:
                cells[cell] = ("?", "bold")
    best = curves.best
    if best is not None:
        cells[(py(best.elo) // sy, px(best.step) // sx)] = ("*", "bold yellow")  # "*": one cell wide anywhere
    shown = {glyph for glyph, _ in cells.values()}
    legend: list[tuple[str, str]] = []
    if "=" in shown:
        who = sorted({k for cell, ks in owners.items() if cells.get(cell, ("",))[0] == "=" for k in ks})
        legend.append(("=", " = ".join(curves.curves[k].learner for k in who) + " (same point)"))
    for glyph, what in (("^", "at least (a perfect score: a bound)"), ("v", "at most (a zero score: a bound)"),
                        ("?", "no games linking it to the anchor")):
        if glyph in shown:
            legend.append((glyph, what))
    if best is not None:
        cell = (py(best.elo) // sy, px(best.step) // sx)
        mine = next(k for k, c in enumerate(curves.curves) if best in c.points)
        also = [curves.curves[k].learner for k in owners[cell] if k != mine]
        notes = [f"with {', '.join(also)}"] if also else []
        if best.flag is not None:
            notes.append(_flag(best.flag).strip(" []"))  # "perfect: a bound"
        legend.append(("*", f"best (ladder): {best.policy}" + (f" ({'; '.join(notes)})" if notes else "")))
    return cells, legend


def curves_chart(curves: RunCurves, width: int = 80, unicode: bool = True, height: int | None = None) -> Text:
    """The rating curves of a run as text, ``width`` characters wide: the y axis in Elo, the x axis in training
    steps, a line per learner with its snapshots marked and their intervals as dotted bars, each scripted player
    as a dashed level labelled on the right, a title and a legend. The ladder's best snapshot, points of several
    learners in one character, bounds and unanchored ratings get marks of their own (:func:`_marks`), and the
    legend names each mark drawn and no other."""
    rows = height or (14 if unicode else 18)
    ylo, yhi = y_limits(curves)
    yticks = [t for t in nice_ticks(ylo, yhi, 5) if ylo <= t <= yhi]
    ylabels = [f"{t:.0f}" for t in yticks]
    left = max([len(s) for s in ylabels] + [4]) + 2
    x0, x1 = x_limits(curves)
    canvas = _Canvas(1, rows, unicode)  # the plot's height in pixels, before its width is known

    def py(y: float) -> int:
        y = min(max(y, ylo), yhi)
        return int(round((yhi - y) / (yhi - ylo) * (canvas.h - 1)))

    bot_rows = _bot_labels(curves, lambda y: py(y) // canvas.sy, unicode)
    right = (max(len(s) for s in bot_rows.values()) + 1) if bot_rows else 0
    cols = max(width - left - right, 20)
    canvas = _Canvas(cols, rows, unicode)

    def px(x: float) -> int:
        return int(round((x - x0) / (x1 - x0) * (canvas.w - 1)))

    glyphs, styles = _draw(canvas, curves, px, py)
    cells = canvas.cells(glyphs)
    marks, mark_legend = _marks(curves, px, py, canvas.sx, canvas.sy)
    tick_rows = {py(t) // canvas.sy: s for t, s in zip(yticks, ylabels, strict=True)}
    vbar, tick = ("│", "┤") if unicode else ("|", "+")

    text = Text()
    pct = f"{100 * curves.confidence:g}%"
    text.append(f"{curves.run} ({curves.env}): fitted Elo by training step, {pct} intervals\n", style="bold")
    for r in range(rows):
        label = tick_rows.get(r)
        text.append((label or "").rjust(left - 2) + " " + (tick if label else vbar))
        for c, (ch, owner) in enumerate(cells[r]):
            if (r, c) in marks:
                ch, style = marks[(r, c)]
                text.append(ch, style=style if unicode else "")
            else:
                text.append(ch, style=styles[owner] if unicode and owner >= 0 else "")
        if r in bot_rows:
            text.append(" " + bot_rows[r], style=_BOT_STYLE if unicode else "")
        text.append("\n")
    xticks = [t for t in nice_ticks(x0, x1, max(cols // 16, 2)) if x0 <= t <= x1]
    text.append(_x_axis(xticks, lambda t: px(t) // canvas.sx, left, cols, right, unicode))
    items: list[tuple[str, str]] = []
    for k, curve in enumerate(curves.curves):
        color = _COLORS[k % len(_COLORS)]
        items.append((("━━ " if unicode else _MARKERS[k % len(_MARKERS)] + " ") + curve.learner, color))
    if curves.bots:
        items.append((("╌╌ " if unicode else "- ") + "scripted", _BOT_STYLE))
    items.append((("⡇ " if unicode else ": ") + f"{pct} interval", ""))
    items += [(f"{glyph} {what}", "") for glyph, what in mark_legend]
    text.append_text(_wrapped(items, left, width, unicode))
    return text


def _bot_labels(curves: RunCurves, row_of: Callable[[float], int], unicode: bool) -> dict[int, str]:
    """The scripted players' labels by character row (``row_of`` an Elo), players on one row sharing its label,
    each label cut to 12 characters."""
    bot_rows: dict[int, str] = {}
    for bot in curves.bots:
        r = row_of(bot.elo)
        bot_rows[r] = f"{bot_rows[r]}, {bot.name}" if r in bot_rows else bot.name
    return {r: name if len(name) <= 12 else name[:11] + "…" if unicode else name[:12]
            for r, name in bot_rows.items()}


def _draw(canvas: _Canvas, curves: RunCurves, px: Callable[[float], int],
          py: Callable[[float], int]) -> tuple[list[str], list[str]]:
    """Draw the scripted players' dashed levels and each learner's intervals, line and points on ``canvas``
    (``px``, ``py``: a step and an Elo to pixels); returns the glyph and the style of each layer drawn."""
    unicode = canvas.unicode
    glyphs: list[str] = []
    styles: list[str] = []
    for b, bot in enumerate(curves.bots):
        glyphs.append("-")
        styles.append(_BOT_STYLE)
        y = py(bot.elo)
        for x in range(canvas.w):
            if unicode and x % 4 >= 2:
                continue  # dashed
            canvas.set(x, y, b, 1)
    for k, curve in enumerate(curves.curves):
        color = _COLORS[k % len(_COLORS)]
        marker = _MARKERS[k % len(_MARKERS)]
        base = len(glyphs)
        glyphs += [":", ".", marker]  # interval, line, point
        styles += [f"dim {color}", color, f"bold {color}"]
        pts = [(px(p.step), py(p.elo), py(p.ci_high), py(p.ci_low)) for p in curve.points]
        for x, _y, top, bottom in pts:
            for y in range(top, bottom + 1):
                if not unicode or y % 2 == 0:
                    canvas.set(x, y, base, 0)
        for (xa, ya, _, _), (xb, yb, _, _) in zip(pts, pts[1:], strict=False):
            canvas.line(xa, ya, xb, yb, base + 1, 2)
        for x, y, _, _ in pts:
            canvas.set(x, y, base + 2, 3)
            if unicode:
                for ddx, ddy in ((1, 0), (0, 1), (1, 1)):
                    canvas.set(x + ddx if x + ddx < canvas.w else x - ddx, y + ddy if y + ddy < canvas.h else y - ddy,
                               base + 2, 3)
    return glyphs, styles


def _x_axis(xticks: list[float], col_of: Callable[[float], int], left: int, cols: int, right: int,
            unicode: bool) -> str:
    """The chart's x axis: its line with a tick at each of ``xticks`` (``col_of``: a step to its column), and
    under it "steps" and the ticks' labels, a label left out where it would touch another."""
    corner, hbar, xtick = ("└", "─", "┬") if unicode else ("+", "-", "+")
    axis = [hbar] * cols
    under = [" "] * (cols + right)
    for t in xticks:
        c = col_of(t)
        axis[c] = xtick
        s = format_steps(t)
        start = min(max(c - len(s) // 2, 0), cols + right - len(s))
        if all(ch == " " for ch in under[max(start - 1, 0):start + len(s) + 1]):
            under[start:start + len(s)] = list(s)
    return " " * (left - 1) + corner + "".join(axis) + "\n" + "steps".ljust(left) + "".join(under).rstrip() + "\n"


def _wrapped(items: list[tuple[str, str]], indent: int, width: int, unicode: bool) -> Text:
    """Legend items (text, style) two spaces apart, on as many lines as ``width`` needs, each indented."""
    out = Text(" " * indent)
    used = indent
    for i, (item, style) in enumerate(items):
        if i and used + 2 + len(item) > width:
            out.append("\n" + " " * indent)
            used = indent
        elif i:
            out.append("  ")
            used += 2
        out.append(item, style=style if unicode else "")
        used += len(item)
    return out


def curves_summary(curves: RunCurves) -> Text:
    """Per learner: how many snapshots are rated, the latest and the highest rated with their intervals; the
    snapshot the ladder marks as the run's best (the ladder decides it, which need not be the highest point); the
    scripted players' ratings; the anchor. Short lines (names and numbers only), so it reads at 80 columns."""
    out = Text()
    best = curves.best
    if best is not None:
        out.append(f"best snapshot of the run (ladder): {best.policy} ({format_steps(best.step)} steps): "
                   f"{_elo(best.elo, best.ci_low, best.ci_high)}{_flag(best.flag)}\n", style="bold")
    for curve in curves.curves:
        last = curve.points[-1]
        top = max(curve.points, key=lambda p: (p.elo, p.step))
        count = len(curve.points)
        out.append(f"{curve.learner}: {count} rated snapshot{'s' if count != 1 else ''}\n", style="bold")
        out.append(f"  latest  {last.policy} ({format_steps(last.step)} steps): "
                   f"{_elo(last.elo, last.ci_low, last.ci_high)}{_flag(last.flag)}\n")
        if top is not last:
            out.append(f"  highest {top.policy} ({format_steps(top.step)} steps): "
                       f"{_elo(top.elo, top.ci_low, top.ci_high)}{_flag(top.flag)}\n")
    if curves.bots:
        out.append("scripted players\n", style="bold")
        for b in curves.bots:
            out.append(f"  {b.name}: {_elo(b.elo, b.ci_low, b.ci_high)}\n")
    if curves.anchor:
        out.append(f"(ratings relative to {curves.anchor[0]} = {curves.anchor[1]:.0f})", style="dim")
    return out


def _elo(elo: float, low: float, high: float) -> str:
    return f"{elo:.0f} ({low:.0f}..{high:.0f})" if high > low else f"{elo:.0f}"


def _flag(flag: str | None) -> str:
    if flag is None:
        return ""
    return f" [{flag}: a bound]" if flag in BOUND_FLAGS else f" [{flag}: no link to the anchor]"


def _heat(score: float) -> Style:
    """Background from red (score 0) through grey (0.5) to green (1), white text."""
    s = min(max(score, 0.0), 1.0)
    red, mid, green = (190, 40, 40), (88, 88, 88), (30, 150, 60)
    a, b, t = (red, mid, s / 0.5) if s < 0.5 else (mid, green, (s - 0.5) / 0.5)
    rgb = tuple(int(round(x + (y - x) * t)) for x, y in zip(a, b, strict=True))
    return Style(color="white", bgcolor=f"rgb({rgb[0]},{rgb[1]},{rgb[2]})")


def matrix_table(report: MatrixReport, unicode: bool = True) -> Table:
    """The score matrix as a heat table: a row per player (number, name, Elo), a column per player (by number);
    each cell the row player's score in percent (with ``--payoff score``: its mean payoff in the game's units) over
    the game count, coloured red (loses) to green (wins). A pair with fewer than ``min_games`` games shows ``?`` over
    its count."""
    n = report.n
    measured = report.measured
    what = "score %" if report.payoffs is None else "mean payoff (half the score margin)"
    table = Table(box=box.SIMPLE_HEAD if unicode else box.ASCII2, padding=(0, 0), pad_edge=False, show_edge=False,
                  collapse_padding=True, title=Text(f"{report.env}: row player's {what} against column player "
                                                     "(games below)"))
    table.add_column("#", justify="right", no_wrap=True)
    table.add_column(" player", justify="left", no_wrap=True, overflow="ellipsis", max_width=24)
    table.add_column("Elo ", justify="right", no_wrap=True)
    for k in range(n):
        table.add_column(str(k + 1), justify="right", no_wrap=True, min_width=4)
    for i, p in enumerate(report.players):
        cells: list[Text] = [Text(str(i + 1)), Text(" " + p.policy), Text(f"{p.elo:.0f} ")]
        for j in range(n):
            g = int(report.games[i, j])
            if i == j:
                cells.append(Text("·\n" if unicode else ".\n", style="dim"))
            elif measured[i, j]:
                shown, place = report.cell(i, j)
                cells.append(Text(f"{shown} \n{g} ", style=_heat(place) if unicode else ""))
            else:
                cells.append(Text(f"? \n{g} ", style="dim"))
        table.add_row(*cells)
    return table


def matrix_summary(report: MatrixReport, home: str | Path | None = None, unicode: bool = True) -> RenderableType:
    """What the matrix says: the legend, the Nash mixture, the significant 3-cycles and the command that plays the
    games the under-measured pairs lack."""
    names = [p.policy for p in report.players]
    out = Text()
    out.append(f"? : fewer than {report.min_games} games (--min-games): not measured; left out of the Nash mixture "
               "and the cycle tests.\n", style="dim")
    out.append("\nNash equilibrium of the meta-game ", style="bold")
    units = ("score - 0.5" if report.payoff == "points"
             else "half the row player's game score minus the column player's: its return in a zero-sum game")
    out.append(f"(payoff = {units}; a population mix no player beats on average)\n", style="dim")
    if report.nash is None:
        out.append(f"  needs two players with at least {report.min_games} games against each other.\n")
    else:
        sub = report.nash_players
        if len(sub) < report.n:
            left_out = [str(i + 1) for i in range(report.n) if i not in sub]
            out.append(f"  over the measured sub-game, the largest group whose pairs are all measured: players "
                       f"{', '.join(str(i + 1) for i in sub)} (left out: {', '.join(left_out)})\n", style="dim")
        width = 30
        for k in report.nash.support:
            w = float(report.nash.mixture[k])
            full = int(round(w * width))
            bar = ("█" if unicode else "#") * full
            out.append(f"  {100 * w:5.1f}% ")
            out.append(bar.ljust(width), style="cyan" if unicode else "")
            out.append(f" {sub[k] + 1}. {names[sub[k]]}\n")
    out.append("\nSignificant 3-cycles ", style="bold")
    pct = f"{100 * report.edges.alpha:g}%"
    out.append(f"({CYCLE_TEST}; {report.edges.tests} tests, family-wise {pct})\n", style="dim")
    if not report.cycles:
        out.append("  none\n")
    for c in report.cycles[:20]:
        a, b, d = (names[i] for i in c.players)
        ps = ", ".join(f"{p:.2g}" for p in c.p_values)
        out.append(f"  {a} > {b} > {d} > {a}   (p = {ps})\n")
    if len(report.cycles) > 20:
        out.append(f"  ... and {len(report.cycles) - 20} more (--json lists them all)\n")
    missing = report.under_measured()
    total = report.n * (report.n - 1) // 2
    if missing:
        out.append(f"\n{len(missing)} of {total} pairs have fewer than {report.min_games} games; play them with:\n",
                   style="bold")
        out.append("  " + (report.fill_command(home) or "") + "\n")
    else:
        out.append(f"\nEvery pair has at least {report.min_games} games.\n")
    return Group(out)


def exploitability_table(points: tuple[ExploitPoint, ...]) -> Table:
    """The exact exploitability of a run's snapshots (``marl league plot --exploitability``), one row each, in step
    order: its name, step, league role (a column only when some snapshot has one), exploitability and NashConv, and
    whether it was computed now or read from the figure filed earlier."""
    roles = any(p.league_role for p in points)
    table = Table(title="exact exploitability (OpenSpiel's best response over the game tree, in the game's returns)")
    for column in ("snapshot", "step", *(["league role"] if roles else []), "exploitability", "NashConv", "figure"):
        table.add_column(column, justify="left" if column in ("snapshot", "league role", "figure") else "right")
    for p in points:
        table.add_row(p.policy, f"{p.step:,}", *([p.league_role or ""] if roles else []), f"{p.exploitability:.4f}",
                      "" if p.nash_conv is None else f"{p.nash_conv:.4f}",
                      ("computed now" + (", filed" if p.filed else " (a team: not filed)")) if p.computed
                      else "filed earlier")
    return table
