"""Charts as data for inline SVG: the pages' templates draw them (every label through Jinja's escaping), so the
server ships no chart library and the browser fetches nothing. :func:`line_chart` places the points of a few series
(a run's Elo per learner with its intervals, or its exploitability) and the horizontal levels (the scripted players)
in a box; :func:`heat` gives a matrix cell its colour."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Chart", "heat", "line_chart"]

PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
WIDTH, HEIGHT, LEFT, RIGHT, TOP, BOTTOM = 760, 340, 64, 150, 16, 40


@dataclass
class Chart:
    """A chart's geometry: series of ``(x, y, low, high, label)`` points in pixels, levels, axis ticks."""

    width: int = WIDTH
    height: int = HEIGHT
    series: list[dict] = field(default_factory=list)
    levels: list[dict] = field(default_factory=list)
    xticks: list[tuple[float, str]] = field(default_factory=list)
    yticks: list[tuple[float, str]] = field(default_factory=list)
    box: tuple[int, int, int, int] = (LEFT, TOP, WIDTH - RIGHT, HEIGHT - BOTTOM)
    ylabel: str = ""
    xlabel: str = ""


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    if hi <= lo:
        return [lo]
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)
    start = math.ceil(lo / step) * step
    return [start + k * step for k in range(int((hi - start) / step) + 1)]


def _short(x: float) -> str:
    for unit, size in (("M", 1e6), ("k", 1e3)):
        if abs(x) >= size:
            return f"{x / size:g}{unit}"
    return f"{x:g}"


def line_chart(series: list[tuple[str, list[tuple[float, float, float | None, float | None, str]]]],
               levels: list[tuple[str, float]], xlabel: str, ylabel: str, log: bool = False) -> Chart:
    """A chart of ``series`` (name, points ``(x, y, low, high, label)``; low/high None: no interval) and
    horizontal ``levels`` (name, y); ``log``: a log scale for y (values at or below 0 left out)."""
    chart = Chart(xlabel=xlabel, ylabel=ylabel)
    f = (lambda v: math.log10(v)) if log else (lambda v: v)
    pts = [(x, y, lo, hi) for _, ps in series for x, y, lo, hi, _ in ps if not log or y > 0]
    xs = [p[0] for p in pts] or [0.0]
    ys = [f(v) for p in pts for v in (p[1], p[2], p[3]) if v is not None and (not log or v > 0)]
    ys += [f(y) for _, y in levels if not log or y > 0]
    ys = ys or [0.0]
    x0, x1 = min(xs), max(xs)
    y0, y1 = min(ys), max(ys)
    if x1 == x0:
        x0, x1 = x0 - 1, x1 + 1
    pad = (y1 - y0) * 0.06 or 1.0
    y0, y1 = y0 - pad, y1 + pad
    left, top, right, bottom = chart.box

    def px(x: float) -> float:
        return round(left + (x - x0) / (x1 - x0) * (right - left), 1)

    def py(y: float) -> float:
        return round(bottom - (f(y) - y0) / (y1 - y0) * (bottom - top), 1)

    for k, (name, ps) in enumerate(series):
        shown = [(px(x), py(y), None if lo is None else py(lo), None if hi is None else py(hi), label)
                 for x, y, lo, hi, label in ps if not log or y > 0]
        path = " ".join(f"{'M' if i == 0 else 'L'}{x},{y}" for i, (x, y, *_) in enumerate(shown))
        chart.series.append({"name": name, "colour": PALETTE[k % len(PALETTE)], "points": shown, "path": path})
    for name, y in levels:
        if not log or y > 0:
            chart.levels.append({"name": name, "y": py(y), "value": y})
    chart.xticks = [(px(t), _short(t)) for t in _ticks(x0, x1)]
    if log:
        chart.yticks = [(py(10 ** e), f"{10 ** e:g}") for e in range(math.floor(y0), math.ceil(y1) + 1)
                        if y0 <= e <= y1]
    else:
        chart.yticks = [(py(t), f"{t:g}") for t in _ticks(y0, y1)]
    return chart


def heat(place: float | None) -> str:
    """A cell's colour for a score from 0 (the row player loses: red) through 0.5 (yellow) to 1 (wins: green);
    grey without a measured score."""
    if place is None or not math.isfinite(place):
        return "#d9d9d9"
    p = min(max(place, 0.0), 1.0)
    stops = ((0.0, (215, 48, 39)), (0.5, (255, 255, 191)), (1.0, (26, 152, 80)))
    (a, ca), (b, cb) = (stops[0], stops[1]) if p <= 0.5 else (stops[1], stops[2])
    t = (p - a) / (b - a)
    r, g, bl = (round(x + (y - x) * t) for x, y in zip(ca, cb, strict=True))
    return f"#{r:02x}{g:02x}{bl:02x}"
