"""A run's fitted ratings against training steps: one curve per learner, the scripted players as levels.

:func:`run_curves` collects them from the ladder (:func:`~selfplay_cli.ratings.ladder.ladder` with its defaults,
so the ratings are the ones ``marl league ladder`` shows), with the snapshot the ladder marks as the run's best;
:func:`save_run_png` draws them with matplotlib (Agg, headless); :func:`write_run_plot` does both and is what the
training loop calls when a run ends.

What a figure says it shows, it shows, and what it shows it says: the best snapshot, ratings that are bounds
(``perfect`` / ``zero``, only under ``--prior 0``) and ratings with no link to the anchor each get a marker and a
legend entry only when there are some. Learners whose curves fall on each other (the members of a team rated by the
same team games have equal ratings) are told apart by :func:`coinciding`: each gets its own marker and dash pattern
and is drawn a little to the side, which its legend entry states.

A league run (``--league alphastar``) has a line per league role (``meta["league_role"]``: main, main exploiter,
league exploiter), labelled with it. With exact exploitabilities (:func:`~selfplay_cli.exploit.exact.
run_exploitability`, a game with a known tree) the figure has a second panel: each snapshot's exact exploitability
against training steps, a line per learner in its Elo line's colour, on a log scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from ..league.store import League, LeagueError
from ..ratings.ladder import ladder
from ..ratings.ladder_rows import LadderRow
from ..stats.bradley_terry import DEFAULT_PRIOR, FLAG_PERFECT, FLAG_ZERO
from .png import check_png_path, new_figure, save_png

__all__ = ["BOUND_FLAGS", "BotLevel", "CurvePoint", "ExploitPoint", "LearnerCurve", "RunCurves", "coinciding",
           "dodge_steps", "format_steps", "run_curves", "run_figure", "save_run_png", "write_run_plot", "x_limits",
           "y_limits"]

BOUND_FLAGS = (FLAG_PERFECT, FLAG_ZERO)
"""Flags whose rating is a bound: ``perfect`` (the true rating is higher) and ``zero`` (lower); ``--prior 0`` only."""

COINCIDE = 0.01
"""Two learners' points closer than this share of the chart's Elo range (and at the same step) fall on each other."""



class ExploitPoint(Protocol):
    """What the chart and the table read of one moment's exact exploitability (the exact exploitability's ``RunPoint``
    is one): the report draws the figures; it does not compute them."""

    @property
    def policy(self) -> str: ...
    @property
    def step(self) -> int: ...
    @property
    def learner(self) -> str: ...
    @property
    def league_role(self) -> str | None: ...
    @property
    def exploitability(self) -> float: ...
    @property
    def nash_conv(self) -> float | None: ...
    @property
    def computed(self) -> bool: ...
    @property
    def filed(self) -> bool: ...
    @property
    def team(self) -> bool: ...


@dataclass(frozen=True)
class CurvePoint:
    """One rated snapshot: its name, training step, fitted Elo and interval, the fit's flag (or None) and whether
    the ladder marks it as its run's best snapshot."""

    policy: str
    step: int
    elo: float
    ci_low: float
    ci_high: float
    flag: str | None
    best: bool = False

    @property
    def bound(self) -> bool:
        """The rating is a bound, not an estimate (a ``perfect`` or ``zero`` flag)."""
        return self.flag in BOUND_FLAGS

    @property
    def unanchored(self) -> bool:
        """A flag other than a bound: no chain of games links this rating to the anchor."""
        return self.flag is not None and not self.bound


@dataclass(frozen=True)
class LearnerCurve:
    """The rated snapshots of one learner of a run, in step order; ``learner`` is its label (its league role where
    it has one)."""

    learner: str
    points: tuple[CurvePoint, ...]
    league_role: str | None = None


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
        prior: the fit's prior in virtual draws (0: maximum likelihood, where bounds appear).
        exploitability: the exact exploitability of the run's snapshots, in step order, where it was asked for
            (:func:`~selfplay_cli.exploit.exact.run_exploitability`); None otherwise.
    """

    env: str
    run: str
    curves: tuple[LearnerCurve, ...]
    bots: tuple[BotLevel, ...]
    anchor: tuple[str, float] | None
    confidence: float = 0.95
    prior: float = DEFAULT_PRIOR
    exploitability: tuple[ExploitPoint, ...] | None = None

    @property
    def best(self) -> CurvePoint | None:
        """The snapshot the ladder marks as the run's best, if it marks one."""
        return next((p for c in self.curves for p in c.points if p.best), None)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (finite numbers only, Elo rounded to 0.1)."""
        return {
            "env": self.env,
            "run": self.run,
            "anchor": None if self.anchor is None else {"policy": self.anchor[0], "elo": round(self.anchor[1], 1)},
            "confidence": self.confidence,
            "prior": self.prior,
            "best": None if self.best is None else self.best.policy,
            "learners": [
                {"learner": c.learner, "league_role": c.league_role,
                 "points": [{"policy": p.policy, "step": p.step, "elo": round(p.elo, 1), "ci_low": round(p.ci_low, 1),
                             "ci_high": round(p.ci_high, 1), "flag": p.flag, "best": p.best} for p in c.points]}
                for c in self.curves
            ],
            "bots": [{"policy": b.name, "elo": round(b.elo, 1), "ci_low": round(b.ci_low, 1),
                      "ci_high": round(b.ci_high, 1)} for b in self.bots],
            "exploitability": None if self.exploitability is None else [p.to_json() for p in self.exploitability],
        }


def line_label(league_role: str | None, learner: str, shared: bool) -> str:
    """The label of a learner's line: its league role where it has one (``role: learner`` when the role has several
    learners, ``shared``), else the learner."""
    if not league_role:
        return learner
    return f"{league_role}: {learner}" if shared else league_role


def run_curves(league: League, run: str, rows: list[LadderRow] | None = None, *,
               prior: float = DEFAULT_PRIOR, variant: str | None = None) -> RunCurves:
    """The curves of ``run``: its rated snapshots per learner (each with the ladder's ``best`` mark) and the env's
    rated bots.

    ``rows``: a ladder of the run's env already fitted (default: ``ladder(league, env, prior=prior)``, in
    ``variant``: by default the run's own, the options its snapshots were made for).
    Snapshots are grouped by ``meta["learner"]`` (a run with one network has one group, named after the run) and
    ``meta["league_role"]`` (a league run's line per role, labelled with it: :func:`line_label`); removed snapshots
    and snapshots without rated games are left out.

    Raises:
        LeagueError: unknown run, or a run without rated snapshots.
    """
    info = league.roster.get_run(run)
    if info is None:
        runs = [r.name for r in league.roster.list_runs()]
        shown = ", ".join(runs[-10:]) if runs else "none yet"
        raise LeagueError(f"no run named '{run}' (runs: {shown})")
    env = info.env
    if rows is None:
        if variant is None:
            from ..league.variants import variant_key
            from ..players.snapshots import run_options

            variant = variant_key(env, run_options(league, run))
        rows = ladder(league, env, prior=prior, variant=variant)
    by_id = {r.player_id: r for r in rows if r.player_id is not None}
    groups: dict[tuple[str | None, str], list[CurvePoint]] = {}
    for p in league.roster.players(env=env, kind="snapshot"):
        if p.run != run or p.id not in by_id:
            continue
        r = by_id[p.id]
        key = (str(p.meta.get("league_role") or "") or None, str(p.meta.get("learner") or "") or run)
        groups.setdefault(key, []).append(CurvePoint(r.policy, int(p.step), r.elo, r.ci_low, r.ci_high, r.flag,
                                                     best=bool(getattr(r, "best", False))))
    if not groups:
        raise LeagueError(f"run '{run}' has no rated snapshots yet (each snapshot is rated against the scripted "
                          "players after it is taken; or play some: marl league tournament --run ...)")
    roles = [role for role, _ in groups]
    curves = tuple(
        LearnerCurve(learner=line_label(role, learner, roles.count(role) > 1),
                     points=tuple(sorted(points, key=lambda q: (q.step, q.policy))), league_role=role)
        for (role, learner), points in groups.items()
    )
    bots = tuple(BotLevel(r.policy, r.elo, r.ci_low, r.ci_high)
                 for r in sorted((r for r in rows if r.kind == "bot"), key=lambda r: -r.elo))
    anchor = next(((r.policy, r.elo) for r in rows if r.anchor), None)
    return RunCurves(env=env, run=run, curves=curves, bots=bots, anchor=anchor, prior=prior)


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


def _shared(a: LearnerCurve, b: LearnerCurve, tol: float) -> int:
    """How many of ``a``'s points have a point of ``b`` at the same step within ``tol`` Elo."""
    at = {p.step: p.elo for p in b.points}
    return sum(1 for p in a.points if p.step in at and abs(at[p.step] - p.elo) <= tol)


def _nearness(a: LearnerCurve, b: LearnerCurve, tol: float) -> str | None:
    """How ``a`` falls on ``b``, for ``a``'s legend: ``same Elo as b at 3 of 3 snapshots`` where every rating of
    ``a`` within ``tol`` of ``b``'s at the same step prints (to the unit, as the figure prints them) as ``b``'s,
    ``within 9 Elo of b at 1 of 3 snapshots`` (the widest gap, rounded up) otherwise; None where none is."""
    at = {p.step: p.elo for p in b.points}
    pairs = [(p.elo, at[p.step]) for p in a.points if p.step in at and abs(at[p.step] - p.elo) <= tol]
    if not pairs:
        return None
    where = f"at {len(pairs)} of {len(a.points)} snapshot{'s' if len(a.points) != 1 else ''}"
    if all(f"{x:.0f}" == f"{y:.0f}" for x, y in pairs):
        return f"same Elo as {b.learner} {where}"
    gap = max(1, math.ceil(max(abs(x - y) for x, y in pairs)))
    return f"within {gap} Elo of {b.learner} {where}"


def coinciding(curves: RunCurves) -> list[tuple[int, ...]]:
    """Groups (two or more, by index into ``curves.curves``) of learners whose curves fall on each other: linked by
    at least one point at the same step within :data:`COINCIDE` of the chart's Elo range. Drawn as they are, the
    last of a group would hide the others (a team's members rated by the same games have equal ratings)."""
    lo, hi = y_limits(curves)
    tol = COINCIDE * (hi - lo)
    n = len(curves.curves)
    group = list(range(n))

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            if _shared(curves.curves[i], curves.curves[j], tol):
                group[root(j)] = root(i)
    members: dict[int, list[int]] = {}
    for i in range(n):
        members.setdefault(root(i), []).append(i)
    return [tuple(m) for m in members.values() if len(m) > 1]


def x_limits(curves: RunCurves) -> tuple[float, float]:
    """The training steps to show: the first to the last snapshot; around a single step, 5% of it either side."""
    steps = [p.step for c in curves.curves for p in c.points]
    lo, hi = float(min(steps)), float(max(steps))
    if hi > lo:
        return lo, hi
    pad = max(1.0, 0.05 * abs(lo))
    return lo - pad, hi + pad


def dodge_steps(curves: RunCurves) -> dict[int, float]:
    """How far (in steps) each learner of a :func:`coinciding` group is drawn aside so that every member shows:
    members spread symmetrically, 1.5% of the step range shown apart. Learners not in a group are not moved."""
    lo, hi = x_limits(curves)
    gap = 0.015 * (hi - lo)
    out = {}
    for members in coinciding(curves):
        for k, i in enumerate(members):
            out[i] = (k - (len(members) - 1) / 2) * gap
    return out


_PNG_MARKERS = ("o", "s", "D", "P", "X", "h", "p", "8")
_DASHES = ("-", "--", ":", "-.")


def run_figure(curves: RunCurves) -> Any:
    """``curves`` drawn on a matplotlib Figure (Agg canvas; :func:`save_run_png` writes it).

    Each learner: its snapshots' ratings joined by a line, each point in the learner's own marker, the interval as
    a shaded band (error bars where a learner has a single snapshot). Learners that fall on each other
    (:func:`coinciding`) take different dash patterns and are drawn a little aside (:func:`dodge_steps`), which
    their legend entries say. The ladder's best snapshot of the run: a gold star. Only when there are some: open
    markers for ratings that are bounds (``perfect`` / ``zero``, under ``--prior 0``), crosses for ratings with no
    chain of games to the anchor. Each scripted player: a dashed grey level labelled with its name. The legend
    names every learner and every kind of mark drawn, and nothing else. The marks carry gids (``line:<learner>``,
    ``points:<learner>``, ``bound:<learner>``, ``unanchored:<learner>``, ``best``) by which they can be found.
    With ``curves.exploitability``: a second panel below, sharing the steps (:func:`_draw_exploitability`).
    """
    panels = bool(curves.exploitability)
    fig = new_figure(9.0, 8.0 if panels else 5.0)
    ax = fig.add_subplot(2, 1, 1) if panels else fig.add_subplot()
    ylo, yhi = y_limits(curves)
    dodge = dodge_steps(curves)
    groups = {i: g for g in coinciding(curves) for i in g}
    for k in range(len(curves.curves)):
        _draw_learner(ax, curves, k, dodge.get(k, 0.0), groups.get(k), COINCIDE * (yhi - ylo))
    points = [(k, p) for k, c in enumerate(curves.curves) for p in c.points]
    _draw_best_and_legend_marks(ax, points, dodge)
    for bot in curves.bots:
        ax.axhline(bot.elo, color="0.45", linestyle="--", linewidth=1.0)
        near_top = bot.elo > ylo + 0.92 * (yhi - ylo)
        ax.text(0.995, bot.elo, f" {bot.name} ", transform=ax.get_yaxis_transform(), ha="right",
                va="top" if near_top else "bottom", fontsize=9, color="0.3")
    _label_axes(ax, curves, points, ylo, yhi)
    if not all(math.isfinite(v) for v in (ylo, yhi)):  # pragma: no cover - ladder rows are always finite
        raise AssertionError("non-finite plot range")
    if panels:
        _draw_exploitability(fig.add_subplot(2, 1, 2, sharex=ax), curves)
    return fig


EXPLOIT_FLOOR = 1e-4
"""Where an exploitability below it (an equilibrium's 0, or rounding below it) is drawn on the log scale."""


def _draw_exploitability(ax: Any, curves: RunCurves) -> None:
    """The exact exploitability of each snapshot against training steps on ``ax``, log scale: a line per learner
    (labelled as its Elo line, in its colour; a team run's teams on a line of their own), figures below
    :data:`EXPLOIT_FLOOR` drawn at it and said so in the legend. Gids: ``exploitability:<label>``."""
    from matplotlib.ticker import FuncFormatter

    points = curves.exploitability or ()
    colors = {c.learner: f"C{k % 10}" for k, c in enumerate(curves.curves)}
    roles = [role for role, _ in dict.fromkeys((p.league_role, p.learner) for p in points)]
    lines: dict[str, list[ExploitPoint]] = {}
    for p in points:
        label = line_label(p.league_role, p.learner, roles.count(p.league_role) > 1)
        lines.setdefault(label + (" (teams)" if p.team else ""), []).append(p)
    for k, (label, group) in enumerate(lines.items()):
        color = colors.get(label, f"C{(len(colors) + k) % 10}")
        marker = _PNG_MARKERS[list(colors).index(label) % len(_PNG_MARKERS)] if label in colors else "o"
        line, = ax.plot([p.step for p in group], [max(p.exploitability, EXPLOIT_FLOOR) for p in group], color=color,
                        marker=marker, markersize=4.5, linewidth=1.6, label=label)
        line.set_gid(f"exploitability:{label}")
    if any(p.exploitability < EXPLOIT_FLOOR for p in points):
        ax.plot([], [], linestyle="none", label=f"below {EXPLOIT_FLOOR:g} (0: an equilibrium): drawn at it")
    ax.set_yscale("log")
    plain = FuncFormatter(lambda y, _pos: f"{y:.3g}")  # 0.3, not 3 x 10^-1
    ax.yaxis.set_major_formatter(plain)
    ax.yaxis.set_minor_formatter(plain)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: format_steps(x)))
    ax.set_xlabel("training step (game steps)")
    ax.set_ylabel("exact exploitability (game's returns, log)")
    ax.set_title(f"{curves.run}: exact exploitability by training step (OpenSpiel's best response over the game tree)")
    ax.grid(True, which="both", color="0.9", linewidth=0.6)
    ax.legend(loc="best", fontsize=8)


def _draw_learner(ax: Any, curves: RunCurves, k: int, shift: float, group: tuple[int, ...] | None,
                  tol: float) -> None:
    """Learner ``k`` of ``curves`` on ``ax`` (see :func:`run_figure`): its line and band (or error bar), its exact
    points, its legend entry (naming the learners of its coinciding ``group``, within ``tol`` Elo, and the
    ``shift`` it is drawn aside by), its bounds and its unanchored points."""
    curve = curves.curves[k]
    color, marker = f"C{k % 10}", _PNG_MARKERS[k % len(_PNG_MARKERS)]
    dash = _DASHES[group.index(k) % len(_DASHES)] if group else "-"
    steps = [p.step + shift for p in curve.points]
    elo = [p.elo for p in curve.points]
    low = [p.ci_low for p in curve.points]
    high = [p.ci_high for p in curve.points]
    if len(steps) > 1:
        ax.fill_between(steps, low, high, color=color, alpha=0.18, linewidth=0)
        line, = ax.plot(steps, elo, color=color, linewidth=1.6, linestyle=dash)
        line.set_gid(f"line:{curve.learner}")
    else:
        ax.errorbar(steps, elo, yerr=[[elo[0] - low[0]], [high[0] - elo[0]]], color=color, capsize=3,
                    fmt="none")
    exact = [(x, p) for x, p in zip(steps, curve.points, strict=True) if p.flag is None]
    dots, = ax.plot([x for x, _ in exact], [p.elo for _, p in exact], linestyle="none", marker=marker,
                    color=color, markersize=4.5)
    dots.set_gid(f"points:{curve.learner}")
    label = curve.learner
    if group:  # each learner of its group it falls on, and how close (a group links through its members)
        near = [n for i in group if i != k and (n := _nearness(curve, curves.curves[i], tol)) is not None]
        label += (f" ({'; '.join(near)}; drawn {'+' if shift >= 0 else '-'}{format_steps(abs(shift))} steps "
                  "aside)")
    ax.plot([], [], color=color, linestyle=dash, linewidth=1.6, marker=marker, markersize=4.5, label=label)
    bound = [(x, p) for x, p in zip(steps, curve.points, strict=True) if p.bound]
    if bound:
        line, = ax.plot([x for x, _ in bound], [p.elo for _, p in bound], linestyle="none", marker=marker,
                        markerfacecolor="white", color=color, markersize=6)
        line.set_gid(f"bound:{curve.learner}")
    loose = [(x, p) for x, p in zip(steps, curve.points, strict=True) if p.unanchored]
    if loose:
        line, = ax.plot([x for x, _ in loose], [p.elo for _, p in loose], linestyle="none", marker="x",
                        color=color, markersize=6)
        line.set_gid(f"unanchored:{curve.learner}")


def _draw_best_and_legend_marks(ax: Any, points: list[tuple[int, CurvePoint]], dodge: dict[int, float]) -> None:
    """The ladder's best snapshot as a gold star, and a legend entry for each kind of mark drawn (bounds,
    unanchored ratings) that is not under the star."""
    best = next(((k, p) for k, p in points if p.best), None)
    if best is not None:
        k, p = best
        note = {FLAG_PERFECT: " (at least: a bound)", FLAG_ZERO: " (at most: a bound)"}.get(p.flag or "", "")
        star, = ax.plot([p.step + dodge.get(k, 0.0)], [p.elo], linestyle="none", marker="*", markersize=15,
                        markerfacecolor="gold", markeredgecolor="black", markeredgewidth=0.8, zorder=5,
                        label=f"best snapshot of the run (ladder): {p.policy}, {p.elo:.0f}{note}")
        star.set_gid("best")
    if any(p.bound and not p.best for _, p in points):  # a bound under the star shows no open marker
        ax.plot([], [], linestyle="none", marker="o", markerfacecolor="white", color="0.3", markersize=6,
                label="open: a bound (perfect score: at least; zero: at most)")
    if any(p.unanchored and not p.best for _, p in points):
        ax.plot([], [], linestyle="none", marker="x", color="0.3", markersize=6,
                label="x: no games linking it to the anchor (offset unknown)")


def _label_axes(ax: Any, curves: RunCurves, points: list[tuple[int, CurvePoint]], ylo: float, yhi: float) -> None:
    """Limits, tick format, axis labels (the fit and its anchor), title, grid and legend of the run's figure."""
    from matplotlib.ticker import FuncFormatter

    ax.set_ylim(ylo, yhi)
    if len({p.step for _, p in points}) == 1:  # one step: 5% of it either side (matplotlib's margins: a step)
        ax.set_xlim(*x_limits(curves))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: format_steps(x)))
    ax.set_xlabel("training step (game steps)")
    anchor = f"; {curves.anchor[0]} = {curves.anchor[1]:.0f}" if curves.anchor else ""
    fit = "maximum likelihood" if curves.prior == 0 else f"prior {curves.prior:g} draws"
    ax.set_ylabel(f"Elo (Bradley-Terry, {fit}{anchor})")
    pct = f"{100 * curves.confidence:g}%"
    ax.set_title(f"{curves.run} ({curves.env}): fitted Elo by training step, {pct} intervals")
    ax.grid(True, color="0.9", linewidth=0.6)
    ax.legend(loc="best", fontsize=8)


def save_run_png(curves: RunCurves, path: str | Path) -> Path:
    """Draw ``curves`` (:func:`run_figure`) into the PNG ``path`` (written to a temporary name, then renamed);
    returns the path.

    Raises:
        LeagueError: the path is not a writable ``.png`` file.
    """
    return save_png(run_figure(curves), path)


def write_run_plot(league: League, run: str, path: str | Path) -> Path:
    """Fit the ladder of ``run``'s env (ladder defaults) and write the run's rating curves as a PNG to ``path``
    (temporary name, then renamed). Returns the path written.

    Raises:
        LeagueError: unknown run, no rated snapshot in the run, or a path that is not a writable ``.png``.
    """
    check_png_path(path)  # before the fit: a bad path fails at once
    return save_run_png(run_curves(league, run), path)
