"""What a ladder's table is shown with: :func:`verdict_lines`, the plain lines under it that say who is best and by
how much (the top over the next player, each run's best over the run's next best, the circles of claims), and
:func:`select_rows`, the rows a user asked to see (one run's, the first ones), ranks unchanged."""

from __future__ import annotations

from selfplay_cli.league.store import LeagueError
from selfplay_cli.ratings.ladder_rows import LadderRow

__all__ = ["select_rows", "verdict_lines"]


def verdict_lines(rows: list[LadderRow]) -> list[str]:
    """Who is best, and by how much, in plain lines: the ladder's top over the next player, then each run's best
    over the run's next best (or the snapshots it cannot be told apart from); in a game rated per side, for each
    side (its lines led by ``<side> side:``), since ratings compare only within a side."""
    by_side: dict[str | None, list[LadderRow]] = {}
    for r in rows:
        by_side.setdefault(r.side, []).append(r)
    if list(by_side) != [None] and by_side:
        return [f"{side} side: {line}" for side, group in by_side.items() for line in _verdicts(group)]
    return _verdicts(rows)


def _verdicts(rows: list[LadderRow]) -> list[str]:
    """:func:`verdict_lines` of one table."""
    lines = []
    ranked = [r for r in rows if r.tier is not None and r.copy_of is None]
    if len(ranked) >= 2 and ranked[0].margin is not None:
        top, m = ranked[0], ranked[0].margin
        shared = sum(1 for r in ranked if r.tier == top.tier) - 1
        though = f", though {m.over} is above it beyond doubt" if m.high < 0.0 else ""  # (a circle of claims)
        lines.append(f"top: {top.policy}{though}, {m.text()}" + (
            "" if m.separated and not shared else
            f"; {shared} more player{'s' if shared != 1 else ''} in its tier") + _circle_text(top))
    for r in rows:
        if not r.best:
            continue
        m = r.best_margin
        if m is None:
            lines.append(f"best of {r.run}: {r.policy} (the run's only rated snapshot)")
        elif m.high < 0.0:  # the next is above it beyond doubt: only where the claims go round in a circle
            lines.append(f"best of {r.run}: {r.policy} by Elo, though {m.over} is above it beyond doubt: {m.text()}"
                         + _circle_text(r))
        elif not r.tied:
            lines.append(f"best of {r.run}: {r.policy}, {m.text()}" + _circle_text(r))
        else:
            names = ", ".join(r.tied[:3]) + (f" and {len(r.tied) - 3} more" if len(r.tied) > 3 else "")
            lines.append(f"best of {r.run}: {r.policy} by Elo, not separated from {names}: {m.text()}"
                         + _circle_text(r))
    said = {frozenset(r.circle) for r in ranked[:1] if r.circle} | {frozenset(r.circle) for r in rows if r.best}
    circles = {frozenset(r.circle): r.circle for r in ranked if r.circle and frozenset(r.circle) not in said}
    for c in list(circles.values())[:3]:
        lines.append("a circle beyond doubt: " + " above ".join((*c, c[0])))
    if len(circles) > 3:
        more = len(circles) - 3
        lines.append(f"and {more} more circle{'s' * (more > 1)} (each row's own in --json)")
    return lines


def _circle_text(row: LadderRow) -> str:
    """``; in a circle beyond doubt: A above B above C above A`` where the row is in one, else ''."""
    if not row.circle:
        return ""
    return "; in a circle beyond doubt: " + " above ".join((*row.circle, row.circle[0]))


def select_rows(rows: list[LadderRow], run: str | None = None, top: int | None = None) -> list[LadderRow]:
    """The rows to show: with ``run``, that run's snapshots plus the scripted players (for reference); with
    ``top``, the first ``top`` of those. Order and ranks are kept: a rank is always the one in the whole ladder.

    Raises:
        LeagueError: ``top < 1``.
    """
    if top is not None and top < 1:
        raise LeagueError(f"--top must be at least 1, not {top}")
    if run is not None:
        rows = [r for r in rows if r.run == run or r.kind == "bot"]
    return rows if top is None else rows[:top]
