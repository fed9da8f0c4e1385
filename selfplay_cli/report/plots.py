"""A run's fitted ratings against training steps: one curve per learner, the scripted players as levels.

:func:`run_curves` collects them from the ladder (:func:`~selfplay_cli.league.ladder.ladder` with its defaults,
so the ratings are the ones ``marl league ladder`` shows); :func:`save_run_png` draws them with matplotlib (Agg,
headless); :func:`write_run_plot` does both and is what the training loop calls when a run ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..league.ladder import LadderRow, ladder
from ..league.store import League, LeagueError
from .png import check_png_path, new_figure, save_png

__all__ = ["BotLevel", "CurvePoint", "LearnerCurve", "RunCurves", "format_steps", "run_curves", "save_run_png",
           "write_run_plot", "y_limits"]


@dataclass(frozen=True)
class CurvePoint:
    """One rated snapshot: its name, training step, fitted Elo and interval, and the fit's flag (or None)."""

    policy: str
    step: int
    elo: float
    ci_low: float
    ci_high: float
    flag: str | None


@dataclass(frozen=True)
class LearnerCurve:
    """The rated snapshots of one learner of a run, in step order."""

    learner: str
    points: tuple[CurvePoint, ...]


@dataclass(frozen=True)
class BotLevel:
    """A scripted player's fitted Elo and interval."""

    name: str
    elo: float
    ci_low: float
    ci_high: float


@dataclass(frozen=True)
class RunCurves:
    """Everything a plot of a run shows.

    Attributes:
        env, run: the game and the run.
        curves: one per learner (snapshots grouped by ``meta["learner"]``), in order of their first snapshot.
        bots: the env's scripted players that have a rating, best first.
        anchor: the ladder's anchor (name and rating), the zero point of every rating.
        confidence: the level of the intervals.
    """

    env: str
    run: str
    curves: tuple[LearnerCurve, ...]
    bots: tuple[BotLevel, ...]
    anchor: tuple[str, float] | None
    confidence: float = 0.95

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (finite numbers only, Elo rounded to 0.1)."""
        return {
            "env": self.env,
            "run": self.run,
            "anchor": None if self.anchor is None else {"policy": self.anchor[0], "elo": round(self.anchor[1], 1)},
            "confidence": self.confidence,
            "learners": [
                {"learner": c.learner,
                 "points": [{"policy": p.policy, "step": p.step, "elo": round(p.elo, 1), "ci_low": round(p.ci_low, 1),
                             "ci_high": round(p.ci_high, 1), "flag": p.flag} for p in c.points]}
                for c in self.curves
            ],
            "bots": [{"policy": b.name, "elo": round(b.elo, 1), "ci_low": round(b.ci_low, 1),
                      "ci_high": round(b.ci_high, 1)} for b in self.bots],
        }


def run_curves(league: League, run: str, rows: list[LadderRow] | None = None, variant: str | None = None
               ) -> RunCurves:
    """The curves of ``run``: its rated snapshots per learner and the env's rated bots.

    ``rows``: a ladder of the run's env already fitted (default: ``ladder(league, env)`` with its defaults, in
    ``variant``: by default the run's own, the options its snapshots were made for).
    Snapshots are grouped by ``meta["learner"]`` (a run with one network has one group, named after the run);
    removed snapshots and snapshots without rated games are left out.

    Raises:
        LeagueError: unknown run, or a run without rated snapshots.
    """
    info = league.get_run(run)
    if info is None:
        runs = [r.name for r in league.list_runs()]
        shown = ", ".join(runs[-10:]) if runs else "none yet"
        raise LeagueError(f"no run named '{run}' (runs: {shown})")
    env = info.env
    if rows is None:
        if variant is None:
            from ..league.variants import variant_key
            from ..rated.snapshots import run_options

            variant = variant_key(env, run_options(league, run))
        rows = ladder(league, env, variant=variant)
    by_id = {r.player_id: r for r in rows if r.player_id is not None}
    groups: dict[str, list[CurvePoint]] = {}
    for p in league.players(env=env, kind="snapshot"):
        if p.run != run or p.id not in by_id:
            continue
        r = by_id[p.id]
        learner = str(p.meta.get("learner") or "")
        groups.setdefault(learner, []).append(CurvePoint(r.policy, int(p.step), r.elo, r.ci_low, r.ci_high, r.flag))
    if not groups:
        raise LeagueError(f"run '{run}' has no rated snapshots yet (each snapshot is rated against the scripted "
                          "players after it is taken; or play some: marl league tournament --run ...)")
    curves = tuple(
        LearnerCurve(learner=name or run, points=tuple(sorted(points, key=lambda q: (q.step, q.policy))))
        for name, points in groups.items()
    )
    bots = tuple(BotLevel(r.policy, r.elo, r.ci_low, r.ci_high)
                 for r in sorted((r for r in rows if r.kind == "bot"), key=lambda r: -r.elo))
    anchor = next(((r.policy, r.elo) for r in rows if r.anchor), None)
    return RunCurves(env=env, run=run, curves=curves, bots=bots, anchor=anchor)


def y_limits(curves: RunCurves) -> tuple[float, float]:
    """The Elo range to show: every rating (snapshots and bots), widened to take in the intervals but by at most
    a quarter of that span on each side (intervals of flagged players reach +-MAX_ELO and would flatten the rest)."""
    values = [p.elo for c in curves.curves for p in c.points] + [b.elo for b in curves.bots]
    lows = [p.ci_low for c in curves.curves for p in c.points]
    highs = [p.ci_high for c in curves.curves for p in c.points]
    lo, hi = min(values), max(values)
    span = max(hi - lo, 100.0)
    low = max(min(lows + [lo]), lo - 0.25 * span)
    high = min(max(highs + [hi]), hi + 0.25 * span)
    margin = 0.04 * span
    return min(low, lo - margin), max(high, hi + margin)


def format_steps(x: float) -> str:
    """``1,500,000 -> "1.5M"``, ``300,000 -> "300k"``, ``0 -> "0"``."""
    a = abs(x)
    for scale, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if a >= scale:
            text = f"{x / scale:.1f}".rstrip("0").rstrip(".")
            return f"{text}{unit}"
    return f"{x:.0f}"


def save_run_png(curves: RunCurves, path: str | Path) -> Path:
    """Draw ``curves`` into the PNG ``path`` (written to a temporary name, then renamed); returns the path.

    Each learner: its snapshots' ratings joined by a line, the interval as a shaded band (error bars where a
    learner has a single snapshot); open markers for ratings that are bounds (a perfect or zero score). Each
    scripted player: a dashed horizontal line labelled with its name.

    Raises:
        LeagueError: the path is not a writable ``.png`` file.
    """
    from matplotlib.ticker import FuncFormatter

    fig = new_figure(9.0, 5.0)
    ax = fig.add_subplot()
    colors = [f"C{i % 10}" for i in range(len(curves.curves))]
    for curve, color in zip(curves.curves, colors, strict=True):
        steps = [p.step for p in curve.points]
        elo = [p.elo for p in curve.points]
        low = [p.ci_low for p in curve.points]
        high = [p.ci_high for p in curve.points]
        if len(steps) > 1:
            ax.fill_between(steps, low, high, color=color, alpha=0.18, linewidth=0)
            ax.plot(steps, elo, color=color, linewidth=1.6, label=curve.learner)
        else:
            ax.errorbar(steps, elo, yerr=[[elo[0] - low[0]], [high[0] - elo[0]]], color=color, capsize=3,
                        fmt="none")
            ax.plot([], [], color=color, linewidth=1.6, label=curve.learner)
        exact = [p for p in curve.points if p.flag is None]
        bound = [p for p in curve.points if p.flag is not None]
        ax.plot([p.step for p in exact], [p.elo for p in exact], "o", color=color, markersize=3.5)
        if bound:
            ax.plot([p.step for p in bound], [p.elo for p in bound], "o", markerfacecolor="white", color=color,
                    markersize=4.5)
    ylo, yhi = y_limits(curves)
    for bot in curves.bots:
        ax.axhline(bot.elo, color="0.45", linestyle="--", linewidth=1.0)
        near_top = bot.elo > ylo + 0.92 * (yhi - ylo)
        ax.text(0.995, bot.elo, f" {bot.name} ", transform=ax.get_yaxis_transform(), ha="right",
                va="top" if near_top else "bottom", fontsize=9, color="0.3")
    ax.set_ylim(ylo, yhi)
    steps_all = [p.step for c in curves.curves for p in c.points]
    if min(steps_all) == max(steps_all):
        ax.set_xlim(min(steps_all) - 1, max(steps_all) + 1)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: format_steps(x)))
    ax.set_xlabel("training step (game steps)")
    anchor = f", {curves.anchor[0]} = {curves.anchor[1]:.0f}" if curves.anchor else ""
    ax.set_ylabel(f"Elo (Bradley-Terry fit{anchor})")
    pct = f"{100 * curves.confidence:g}%"
    ax.set_title(f"{curves.run} ({curves.env}): fitted Elo by training step, {pct} intervals; open = bound")
    ax.grid(True, color="0.9", linewidth=0.6)
    ax.legend(loc="best", fontsize=9, title="learner", title_fontsize=9)
    if not all(math.isfinite(v) for v in (ylo, yhi)):  # pragma: no cover - ladder rows are always finite
        raise AssertionError("non-finite plot range")
    return save_png(fig, path)


def write_run_plot(league: League, run: str, path: str | Path) -> Path:
    """Fit the ladder of ``run``'s env (ladder defaults) and write the run's rating curves as a PNG to ``path``
    (temporary name, then renamed). Returns the path written.

    Raises:
        LeagueError: unknown run, no rated snapshot in the run, or a path that is not a writable ``.png``.
    """
    check_png_path(path)  # before the fit: a bad path fails at once
    return save_run_png(run_curves(league, run), path)
