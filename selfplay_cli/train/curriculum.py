"""Curricula driven by training progress: game options that change as a run goes on.

A run's TOML takes a ``[curriculum]`` table, one entry per live option of the game (``EnvSpec.live_options``; the
game's core changes them between steps with ``set_options``). ``progress`` is the share of the budget spent (steps,
or minutes with ``--minutes``): lessons are measured by the ratio of the steps played to the steps of the budget::

    [curriculum]
    hit_reward = { start = 0.5, end = 0.0, until = 0.5 }      # linear from 0.5 to 0 over the first half of the run
    point_reward = { start = 0.2, end = 1.0, from = 0.1, until = 0.6 }
    bat_scale = { lessons = [[0.0, 2.0], [0.3, 1.5], [0.6, 1.0]] }   # ML-Agents-style lessons: value from a progress

A ramp holds ``start`` until ``from`` (default 0), moves linearly to ``end`` at ``until`` (default 1) and holds it.
Lessons are ``[progress, value]`` pairs in increasing progress; the first must start at 0. A plain number holds
that value for the whole run (``bat_scale = 1.0`` switches off a game's default bat curriculum). Only training games
follow the curriculum: rating games are played under the run's ``[env_options]``, the game as it is finally meant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import MarlError


@dataclass(frozen=True)
class Schedule:
    """One option's values against progress: a linear ramp, or lessons (step values)."""

    option: str
    start: float = 0.0
    end: float = 0.0
    begin: float = 0.0  # the ramp's 'from'
    until: float = 1.0
    lessons: tuple[tuple[float, float], ...] = ()

    def value(self, progress: float) -> float:
        p = min(max(float(progress), 0.0), 1.0)
        if self.lessons:
            current = self.lessons[0][1]
            for at, value in self.lessons:
                if p >= at:
                    current = value
            return current
        if p <= self.begin:
            return self.start
        if p >= self.until:
            return self.end
        return self.start + (self.end - self.start) * (p - self.begin) / (self.until - self.begin)


def _number(where: str, what: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MarlError(f"{where}: {what} must be a finite number, not {value!r}")
    return float(value)


def parse_schedule(option: str, entry: Any, section: str = "curriculum") -> Schedule:
    """One ``[curriculum]`` entry (or another section's schedule, e.g. ``[teacher] weight``) checked; a
    :class:`MarlError` naming the section, the option and what is wrong."""
    where = f"[{section}] {option}"
    if isinstance(entry, (int, float)) and not isinstance(entry, bool):  # one value throughout (a default's off)
        return Schedule(option, lessons=((0.0, _number(where, "its value", entry)),))
    if not isinstance(entry, dict):
        raise MarlError(f"{where} must be a table such as {{ start = 2.0, end = 1.0, until = 0.5 }} "
                        f"or {{ lessons = [[0.0, 2.0], [0.5, 1.0]] }}, or one number, not {entry!r}")
    if "lessons" in entry:
        extra = sorted(set(entry) - {"lessons"})
        if extra:
            raise MarlError(f"{where}: lessons cannot be mixed with {', '.join(extra)}")
        lessons = entry["lessons"]
        if not isinstance(lessons, list) or not lessons or not all(isinstance(x, list) and len(x) == 2
                                                                   for x in lessons):
            raise MarlError(f"{where}: lessons must be a list of [progress, value] pairs, "
                            f"not {lessons!r}")
        pairs = tuple((_number(where, "a lesson's progress", a), _number(where, "a lesson's value", v))
                      for a, v in lessons)
        at = [a for a, _ in pairs]
        if at[0] != 0.0 or any(b <= a for a, b in zip(at, at[1:], strict=False)) or at[-1] > 1.0:
            raise MarlError(f"{where}: lessons must start at progress 0 and rise strictly within "
                            f"[0, 1], not {at}")
        return Schedule(option, lessons=pairs)
    extra = sorted(set(entry) - {"start", "end", "from", "until"})
    if extra or "start" not in entry or "end" not in entry:
        raise MarlError(f"{where}: a ramp takes start, end and optionally from and until (progress "
                        f"0 to 1){'; unknown: ' + ', '.join(extra) if extra else ''}")
    begin = _number(where, "from", entry.get("from", 0.0))
    until = _number(where, "until", entry.get("until", 1.0))
    if not 0.0 <= begin < until <= 1.0:
        raise MarlError(f"{where}: needs 0 <= from < until <= 1, not from {begin} until {until}")
    return Schedule(option, _number(where, "start", entry["start"]), _number(where, "end", entry["end"]),
                    begin, until)


class Curriculum:
    """The schedules of one run, checked against the game: ``values(progress)`` gives every option's value now."""

    def __init__(self, table: dict[str, Any], game: str, live: tuple[str, ...]) -> None:
        if not isinstance(table, dict):
            raise MarlError(f"[curriculum] must be a table of the game's live options, not {table!r}")
        unknown = sorted(set(table) - set(live))
        if unknown:
            known = ", ".join(live) if live else "none: its options are fixed for a game's whole length"
            raise MarlError(f"[curriculum]: {game} cannot change {', '.join(unknown)} during training; its live "
                            f"options: {known}")
        self.schedules = [parse_schedule(name, entry) for name, entry in sorted(table.items())]

    def __bool__(self) -> bool:
        return bool(self.schedules)

    def values(self, progress: float) -> dict[str, float]:
        return {s.option: s.value(progress) for s in self.schedules}

    def check(self, core: Any) -> None:
        """Every value the schedules reach (a ramp's lie between its ends) applied to a core of the game, so a value
        the game refuses (a bat of size 0) fails before the run exists."""
        points = {0.0, 1.0}
        for s in self.schedules:
            points.update(at for at, _ in s.lessons)
            points.update((s.begin, s.until))
        try:
            for p in sorted(points):
                core.set_options(**self.values(p))
        except (TypeError, ValueError) as e:
            raise MarlError(f"[curriculum]: {e}") from None
