"""What `marl train` shows: the progress while it trains (a bar with a status line on a terminal, plain lines in a
log) and the summary at the end, in text or JSON. Every figure comes from the trainer's
:class:`~selfplay_cli.train.progress.Standing` and :class:`~selfplay_cli.train.progress.TrainReport`, which say
what each counts."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.text import Text

from ..evaluation.executors.queue_workers import run_batch
from ._output import err_console

if TYPE_CHECKING:
    from ..train.progress import Standing, TrainReport

QUEUED = ("remote", "ray")
"""The ``--eval`` modes whose gauntlets are jobs of the league's queue (in the run's batch, :func:`run_batch`)."""


def report_json(report: TrainReport, eval: str = "local", actors: int = 0) -> dict[str, Any]:
    """``marl train --json``: the whole run's figures (every session of a resumed run), and this session's
    (``session_*``; the rate and the rating games' time are this session's too). ``eval``: who played the rating
    games (``--eval``); ``rating_batch``: the run's batch in the league's queue (``--eval remote`` or ``ray``), and
    ``rating_jobs_left`` its gauntlets not played yet (``--no-wait``), while ``best`` is null. ``actors``: the Ray
    actors this session's games were stepped on (``--executor ray``; 0: this process), as ``executor``/``actors``."""
    return {"run": report.run, "steps": report.steps, "episodes": report.episodes, "seconds": round(report.seconds, 1),
            "sessions": report.sessions, "rating_games": report.eval_games, "snapshots": report.snapshots,
            "final": [r.to_json() for r in report.finals],
            "plot": str(report.plot) if isinstance(report.plot, Path) else None,
            "session_steps": report.session_steps, "session_seconds": round(report.session_seconds, 1),
            "session_train_seconds": round(report.train_seconds, 1),
            "session_rating_games": report.session_eval_games, "steps_per_second": round(report.steps_per_second),
            "rating_seconds": round(report.eval_seconds, 1), "rating_wait_seconds": round(report.wait_seconds, 1),
            "rating": eval, "rating_batch": run_batch(report.run) if eval in QUEUED or report.rating_left else None,
            "rating_jobs_left": report.rating_left,
            "executor": "ray" if actors else "local", "actors": actors,
            "budget_end": None if report.budget_end is None else report.budget_end.to_json(),
            **({"nash": report.nash} if report.nash is not None else {}),
            "best": (None if report.rating_left  # not decided before the final gauntlet and the playoff are in
                     else [_best_json(r) for r in report.side_bests] if report.side_bests  # a game rated per side
                     else None if report.best is None else _best_json(report.best))}


def describe_init(plan: dict[str, Any]) -> str:
    """The line saying what ``--init-from`` started the learners from (the run's ``init_plan``): ``started from
    l4/s4k (4 members, 3 seats: ...): lander_0 <- l4/s4k-lander_0 (member 0), ...``."""
    learners = plan.get("learners", {})
    each = ", ".join(f"{name} <- {e['snapshot']}" + (f" (member {e['member']})" if len(plan["members"]) > 1 else "")
                     for name, e in learners.items())
    return f"started from {plan['source']} ({plan['rule']}): {each}"


def _best_json(row: Any) -> dict[str, Any]:
    """What the run's JSON says of its best: the ladder row's name, rating, margin and ties (and its side)."""
    keys = ("policy", "elo", "ci_low", "ci_high", "best_margin", "tied") + ("side",) * (row.side is not None)
    return {k: row.to_json()[k] for k in keys}


def describe_run(report: TrainReport, eval: str = "local", actors: int = 0) -> str:
    """The summary's first line: the whole run (every session of a resumed run: steps, episodes, snapshots, rating
    games, wall time), and where the run had more than one session, this session's part and rate. ``eval``: who
    played the rating games (``--eval``); ``actors``: the Ray actors that stepped this session's games (0: none).

    ``run pong-1: 6,000,128 game steps in 92 s (70 s of training at 85,700 steps/s), 256 episodes, 14 snapshots;
    444 rating games (beside training: 82 s, 18 s of it waited for at the end)``"""
    on = f" on {actors} Ray actor{'s' * (actors > 1)}" if actors else ""
    rate = (f"{report.train_seconds:.0f} s of training at {report.steps_per_second:,.0f} steps/s{on}"
            if report.session_steps else "no training left to do")
    if report.sessions == 1:
        when = f"in {report.seconds:.0f} s ({rate})"
    else:
        when = (f"in {report.sessions} sessions, {report.seconds:.0f} s in all (this session: "
                f"{report.session_steps:,} steps in {report.session_seconds:.0f} s, {rate})")
    head = (f"run {report.run}: {report.steps:,} game steps {when}, {report.episodes:,} episodes, "
            f"{len(report.snapshots)} snapshots; {report.eval_games:,} rating games")
    if not report.session_eval_games and not report.rating_left:
        return f"{head} ({describe_no_rating_games(report, eval)})"
    where = {"inline": "inline", "remote": "through the league's queue",
             "ray": "on Ray actors, through the league's queue"}.get(eval, "beside training")
    this = f"{report.session_eval_games:,} of them this session, " if report.sessions > 1 else ""
    if report.rating_left:
        head += f" so far, {report.rating_left} gauntlet{'s' * (report.rating_left > 1)} still queued"
    return (f"{head} ({this}{where}: {report.eval_seconds:.0f} s, {report.wait_seconds:.0f} s of it waited for at "
            "the end)")


def describe_no_rating_games(report: TrainReport, eval: str = "local") -> str:
    """Why a session played no rating games, and what the time its gauntlets took went to (no game was waited
    for): ``none needed: its snapshots are the same weights as run kuhn_poker-1's, already rated; 3 s at the end
    waiting for the rating worker to find that``. Rating games off: ``--eval-games 0``."""
    if not report.rating:
        return "--eval-games 0"
    others = sorted({name.split("/", 1)[0] for name in report.same_weights.values()})
    if others and len(report.same_weights) == len(report.snapshots):
        runs = " and ".join(f"run {r}'s" for r in others)
        why = f"its snapshots are the same weights as {runs}, already rated"
    else:
        why = "its gauntlets had nothing left to play"
    why = f"none of them this session: {why}" if report.sessions > 1 else f"none needed: {why}"
    if eval == "inline":  # the gauntlets' checks, in the training process
        seconds, who = report.eval_seconds, "inline"
    else:
        who = {"remote": "at the end waiting for the league's queue",
               "ray": "at the end waiting for the league's queue"}.get(eval, "at the end waiting for the rating worker")
        seconds = report.wait_seconds
    return why if round(seconds) < 1 else f"{why}; {seconds:.0f} s {who} to find that"


def still_coming(report: TrainReport) -> list[str]:
    """What a run that left its gauntlets to the league's workers (``--no-wait``) says instead of its best: that the
    ratings are still coming, and where to see them arrive."""
    n = report.rating_left
    return [f"ratings still coming: {n} gauntlet{'s' * (n > 1)} of this run (the final one with its playoff, which "
            "names the run's best) wait in the league's queue for its workers (marl worker --until-empty plays them "
            "on this machine)",
            f"  progress: marl queue --batch {run_batch(report.run)}; the final ratings and the best, once they are "
            f"played: marl league ladder --run {report.run}"]


def elo_text(rec: Any) -> str:
    """``Elo 2301 [2220, 2388]``: a snapshot's fitted rating with its interval; "" when it has none."""
    return f"Elo {rec.elo:.0f} [{rec.ci_low:.0f}, {rec.ci_high:.0f}]" if rec.elo is not None else ""


def describe_record(rec: Any, pending: bool = False) -> str:
    """``pong-1/ep37-left: Elo 2301 [2220, 2388]; vs random 100% [89%, 100%] of 32 games, vs cpu 94% [...] of 32
    games``: every figure measured on that snapshot (its stored games and its fitted rating), each score with its
    95% interval and what was counted (a cooperative game's results are comparisons). ``pending``: its gauntlet is
    still queued (``--no-wait``), so the figures, if any, are not its last. A snapshot that holds an earlier one's
    weights says so: its figures are that player's."""
    parts = [elo_text(rec)] if rec.elo is not None else []

    def score(bot: str) -> str:
        low, high = rec.interval(bot)
        return f"{100 * rec.score(bot):.0f}% [{100 * low:.0f}%, {100 * high:.0f}%] of {sum(rec.vs[bot])} {rec.unit}"

    vs = ", ".join(f"vs {bot} {score(bot)}" for bot in rec.vs)
    if vs:
        parts.append(vs)
    name = rec.name + (f" (the same weights as {rec.same_as}: one player, its games)" if rec.same_as else "")
    if pending:
        return f"{name}: " + ("; ".join(parts) + " so far" if parts else "not rated yet (its gauntlet is queued)")
    return f"{name}: " + ("; ".join(parts) if parts else "not rated (--eval-games 0)")


def describe_queue(q: Any, games: int) -> str:
    """Where a run's queued gauntlets stand (:class:`~selfplay_cli.evaluation.executors.queue_workers.QueueStanding`):
    ``2 gauntlets left in the queue, played by worker@a:12, worker@b:7``, or ``1 gauntlet left in the queue, played
    here: no worker takes it (40 games so far)``."""
    left = f"{q.left} gauntlet{'s' * (q.left != 1)} left in the queue"
    if q.here:
        return f"{left}, played here: no worker takes {'them' if q.left != 1 else 'it'} ({games:,} games so far)"
    if q.workers:
        return f"{left}, played by {', '.join(q.workers)}"
    return f"{left}, waiting for one of {q.attached} worker{'s' * (q.attached != 1)}"


def _clock(seconds: float) -> str:
    s = int(max(seconds, 0) + 0.5)
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


PLAIN_LINE_SECONDS = 30.0
"""Without a terminal (a log, CI), a plain progress line comes at most every this many seconds ..."""
PLAIN_LINE_SHARE = 0.05
"""... and only once this share of the budget more is spent: whichever is rarer (a 90-second run: every 30 s; a
30-minute run: every 90 s, 5% of it). Every rated snapshot moment prints a line besides."""


def describe_rate(standing: Standing) -> str:
    """This session's rate: ``77,937 steps/s``; ``- steps/s`` before it has played a step."""
    rate = standing.steps_per_second
    return "- steps/s" if rate is None else f"{rate:,.0f} steps/s"


def describe_games(standing: Standing) -> str:
    """What the training games are doing: ``games: 0 finished, 256 under way (14,336 steps in on average, of at most
    18,000)``. Games that all end together near a time limit finish nothing for most of a run; how far the games
    under way are says that they run."""
    limit = f", of at most {standing.time_limit:,}" if standing.time_limit else ""
    how = "left unfinished" if standing.ended else "under way"
    return (f"games: {standing.episodes:,} finished, {standing.playing:,} {how} ({standing.game_steps:,.0f} steps in "
            f"on average{limit})")


def describe_snapshots(standing: Standing, rating: bool) -> str:
    """``snapshots: 8 taken, 6 rated``: snapshots taken so far and, of them, those whose rating games are done."""
    if not rating:
        return f"snapshots: {standing.snapshots} taken (rating games off)"
    return f"snapshots: {standing.snapshots} taken, {standing.rated} rated"


def describe_elo(rec: Any) -> str:
    """``s2M-left Elo 1432 [1300, 1560]``: a snapshot's fitted rating with its interval, by its short name."""
    return f"{rec.name.split('/', 1)[-1]} {elo_text(rec) or 'not rated'}"


class _StatusProgress(Progress):
    """A progress bar with a line of status under it (the games, the snapshots, the newest ratings)."""

    status = ""

    def get_renderables(self) -> Iterator[Any]:
        yield self.make_tasks_table(self.tasks)
        if self.status:
            yield Text(self.status, no_wrap=True, overflow="ellipsis")


class TrainProgress:
    """What a run shows while it trains. On a terminal: a rich progress bar (phase, steps, this session's steps/s,
    elapsed time, ETA) with a status line under it (games finished and under way, snapshots taken and rated, the
    newest rated snapshots' Elo), removed when the run ends so the summary stands alone. Without a terminal (a log,
    CI): a plain line on stderr every :data:`PLAIN_LINE_SECONDS` and :data:`PLAIN_LINE_SHARE` of the budget,
    whichever is rarer. Both: one plain line per rated snapshot moment. ``lines`` False (``--quiet``): no lines.
    ``clock``: seconds (tests pass their own)."""

    def __init__(self, cfg: Any, bar: bool, lines: bool, clock: Callable[[], float] = time.perf_counter) -> None:
        self.cfg = cfg
        self.lines = lines
        self.clock = clock
        self.start = self.last_line = clock()
        self.line_share = 0.0  # the budget's share spent at the last plain line
        self.progress = _StatusProgress(TextColumn("{task.description}"), BarColumn(),
                                        TextColumn("{task.fields[info]}"), TimeElapsedColumn(),
                                        TextColumn("{task.fields[eta]}"), console=err_console, disable=not bar,
                                        transient=True)
        self.task = self.progress.add_task(f"train {cfg.run}", total=1000, info="", eta="")

    def __enter__(self) -> TrainProgress:
        self.progress.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.__exit__(*exc)

    def update(self, event: dict[str, Any]) -> None:
        kind, standing = event["event"], event["standing"]
        eta = "" if standing.remaining is None else f"ETA {_clock(standing.remaining)}"
        status = f"{describe_games(standing)}; {describe_snapshots(standing, bool(self.cfg.eval_games))}"
        if standing.newest:
            status += "; newest rated " + ", ".join(describe_elo(r) for r in standing.newest)
        self.progress.status = status
        if kind == "training":
            self.progress.update(self.task, description=f"train {self.cfg.run}", eta=eta,
                                 completed=int(1000 * standing.progress),
                                 info=f"{standing.steps:,} steps  {describe_rate(standing)}")
            if self._due(standing.progress):
                self._print(self._where(standing))
        elif kind == "evaluating":  # training is over: no time is estimated, the gauntlets left are counted
            short = [n.split("/", 1)[-1] for n in event["snapshots"]]
            names = ", ".join(short) if len(short) <= 2 else f"{short[0]} and {len(short) - 1} more snapshots"
            queued = event.get("queue")
            info = f"{event['games']} games played" if queued is None else describe_queue(queued, event["games"])
            left = event["gauntlets"] if queued is None else queued.left
            waiting = f"waiting for its rating games: {left} gauntlet{'s' * (left != 1)} left"
            self.progress.update(self.task, description=f"rating {names}", eta=f"{waiting} (Ctrl-C: queue them)",
                                 info=info)
            if self._due(None):
                where = (f"{waiting} ({names}), {event['games']:,} played in this session so far" if queued is None
                         else f"rating {names} ({info})")  # (the queue's standing counts the gauntlets left)
                self._print(f"{self._done(standing)}; {where}; {self._elapsed()} elapsed; Ctrl-C leaves them to the "
                            "league's queue")
        elif kind == "note":  # something the run met and went on from (a rollout actor restarted)
            self._print(f"{self.cfg.run}: {event['line']}")
        elif kind == "snapshot":
            recs = "; ".join(
                f"{r.name.split('/', 1)[-1]} (step {r.step:,}): "
                + ", ".join([f"{bot} {100 * r.score(bot):.0f}% of {sum(wdl)}" for bot, wdl in r.vs.items()]
                            + ([elo_text(r)] if r.elo is not None else []))
                or "unrated" for r in event["records"])
            if standing.ended:  # (a gauntlet done in the final wait: the training figures stand still by now)
                self._print(f"{self._done(standing)}; {describe_snapshots(standing, bool(self.cfg.eval_games))}; "
                            f"rated {recs}; {self._elapsed()} elapsed")
            else:
                self._print(self._where(standing, f"; rated {recs}"))

    def _due(self, share: float | None) -> bool:
        """Whether a plain line is due: no terminal, lines wanted, :data:`PLAIN_LINE_SECONDS` since the last line
        and, while training (``share``: the budget spent), :data:`PLAIN_LINE_SHARE` more of the budget."""
        if not self.progress.disable or not self.lines or self.clock() - self.last_line < PLAIN_LINE_SECONDS:
            return False
        return share is None or share - self.line_share >= PLAIN_LINE_SHARE

    def _done(self, standing: Standing) -> str:
        """``pong-1: training done (6,000,128 steps)``: how a line of the final wait begins."""
        return f"{self.cfg.run}: training done ({standing.steps:,} steps)"

    def _elapsed(self) -> str:
        return _clock(self.clock() - self.start)

    def _where(self, standing: Standing, rated: str = "") -> str:
        """``pong-1: 61% (3,670,016 of 6,000,000 steps, 77,937 steps/s); games: ...; snapshots: ...; 0:00:47
        elapsed, ~0:00:44 left``: where training stands (with --minutes, time is the budget)."""
        budget = (f"{standing.steps:,} steps" if self.cfg.minutes is not None
                  else f"{standing.steps:,} of {self.cfg.steps:,} steps")
        done = standing.progress >= 1.0
        left = "" if standing.remaining is None or done else f", ~{_clock(standing.remaining)} left"
        self.line_share = standing.progress
        return (f"{self.cfg.run}: {100 * standing.progress:.0f}% ({budget}, {describe_rate(standing)}); "
                f"{describe_games(standing)}; {describe_snapshots(standing, bool(self.cfg.eval_games))}{rated}; "
                f"{self._elapsed()} elapsed{left}")

    def _print(self, line: str) -> None:
        if not self.lines:
            return
        self.last_line = self.clock()
        if self.progress.disable:
            err_console.print(line, markup=False, highlight=False, soft_wrap=True)
        else:
            self.progress.console.print(line, markup=False, highlight=False)
