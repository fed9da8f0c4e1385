"""What a run says of itself: where it stands while it trains (:class:`Standing`), what the ledger says of its
newest snapshots (:class:`SnapshotRecord`), and its report at the end (:class:`TrainReport`); its :class:`Heartbeat`
says where it stands at least every :data:`HEARTBEAT_SECONDS`, however long one step, update or gauntlet takes.
`marl train` shows them (:mod:`selfplay_cli.commands.train_view`)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

HEARTBEAT_SECONDS = 1.0
"""A run's progress is told at least this often (real seconds), whatever its main thread is busy with."""


@dataclass(frozen=True)
class SnapshotRecord:
    """What the ledger says of one snapshot right after its gauntlet: its record against each scripted player
    (``{bot: (wins, draws, losses)}``, every stored game between the two) and its fitted rating with the interval,
    None when evaluation is off."""

    name: str
    learner: str
    step: int
    vs: dict[str, tuple[int, int, int]]
    elo: float | None = None
    ci_low: float | None = None
    ci_high: float | None = None
    unit: str = "games"  # what a result against a bot is: a game, or a cooperative game's comparison of two
    points: dict[str, float] = field(default_factory=dict)  # its points against each bot, where results are worth
    # more than a win, a draw or a loss (a game played for stakes: poker's chips); else from the record
    same_as: str = ""  # the snapshot whose weights it holds (taken before it, in this run or another): one player,
    # whose games and rating these are (a budget that ends before the next update leaves the last snapshot a copy)

    def score(self, bot: str) -> float:
        """Its mean points against ``bot`` (a draw half a point; a hand of poker what its chips are worth)."""
        w, d, lo = self.vs[bot]
        n = max(w + d + lo, 1)
        return self.points[bot] / n if bot in self.points else (w + 0.5 * d) / n

    def interval(self, bot: str) -> tuple[float, float]:
        """The score's 95% interval (Wilson: honest with a handful of results and at 0 % or 100 %; for points worth
        any value in [0, 1] it errs wide, their variance being at most a coin's of the same mean)."""
        from ..stats.match import score_interval

        w, d, lo = self.vs[bot]
        n = w + d + lo
        s = self.score(bot)
        return score_interval(s * n, 0, n - s * n) if bot in self.points else score_interval(w, d, lo)

    def to_json(self) -> dict[str, Any]:
        return {"snapshot": self.name, "learner": self.learner, "step": self.step,
                "same_weights_as": self.same_as or None,
                "elo": None if self.elo is None else round(self.elo, 1),
                "ci_low": None if self.ci_low is None else round(self.ci_low, 1),
                "ci_high": None if self.ci_high is None else round(self.ci_high, 1),
                "vs": {bot: {"score": round(self.score(bot), 4), "score_low": round(self.interval(bot)[0], 4),
                             "score_high": round(self.interval(bot)[1], 4), self.unit: sum(wdl), "wins": wdl[0],
                             "draws": wdl[1], "losses": wdl[2]} for bot, wdl in self.vs.items()}}


@dataclass(frozen=True)
class Standing:
    """Where a run stands, for a progress display, in counts that hold for every game (none of them assumes a
    game's shape). Counts are of the whole run, every session of a resumed run included, unless they say
    ``session``. Games that all end together (every game of a batch cut by the same time limit) leave
    ``episodes`` at 0 for most of a run: ``playing`` and ``game_steps`` then say how far they are."""

    progress: float  # share of the budget spent: steps of the budget, or minutes of all sessions (0 to 1)
    steps: int  # game steps played: one step of each of the games played at once counts as that many
    episodes: int  # training games finished
    playing: int  # training games under way (the games played at once); once training has ended, those it left
    game_steps: float  # steps since the games under way began, averaged over them
    time_limit: int | None  # the most steps one game lasts, as the game declares it (None: it declares none)
    snapshots: int  # snapshots taken (one per learner and snapshot moment)
    rated: int  # of them, those whose gauntlet has finished (0 with rating games off)
    newest: tuple[SnapshotRecord, ...]  # the newest rated moment's snapshots, as the ledger rates them
    session_steps: int  # game steps played by this process (a resumed run: since it resumed)
    steps_per_second: float | None  # this process's training rate (rating games played inline left out); None
    # before it has played a step
    remaining: float | None  # seconds left, estimated (None before the rate is known)
    ended: bool = False  # training has ended (what remains is the wait for the last rating games)


@dataclass(frozen=True)
class BudgetEnd:
    """How a ``--minutes`` budget ended training: ``overrun`` seconds past it (the update or step under way when the
    time ran out), and the update it fell in (:attr:`update`): ``"cut"`` (an update under way ended early: each cut
    learner's gradient steps done and due, at least one done), ``"not begun"`` (``unlearned`` game steps played
    since the last update, a rollout not full yet: not learned from), or ``"whole"`` (it fell at an update's end)."""

    seconds: float  # the budget
    overrun: float  # training ended this long after it
    cut: dict[str, tuple[int, int]] = field(default_factory=dict)  # learner -> (gradient steps done, due)
    unlearned: int = 0  # game steps played since the learners' last update (0 when one was cut)

    @classmethod
    def of(cls, seconds: float, overrun: float, learners: dict[str, Any], unlearned: int) -> BudgetEnd:
        """From the learners (name -> learner) as training left them: each says whether its last update was cut
        (its ``cut``: done and due, None when whole)."""
        cut = {name: tuple(learner.cut) for name, learner in learners.items() if learner.cut}
        return cls(seconds, max(overrun, 0.0), cut, 0 if cut else max(unlearned, 0))

    @property
    def update(self) -> str:
        return "cut" if self.cut else "not begun" if self.unlearned else "whole"

    def describe(self) -> str:
        """``budget of 60 s: training ended 0.4 s past it, its last update cut after 3 of 80 gradient steps``."""
        head = f"budget of {self.seconds:g} s: training ended {self.overrun:.1f} s past it, "
        if self.update == "cut":
            each = "; ".join(f"{d:,} of {n:,} gradient steps" + (f" ({name})" if len(self.cut) > 1 else "")
                             for name, (d, n) in self.cut.items())
            return head + f"its last update cut after {each}"
        if self.update == "not begun":
            return head + (f"an update not begun: the last {self.unlearned:,} game steps played (since the last "
                           "update, or the start) are not learned from")
        return head + "at an update's end"

    def to_json(self) -> dict[str, Any]:
        return {"seconds": self.seconds, "overrun_seconds": round(self.overrun, 2), "last_update": self.update,
                "cut": {name: {"done": d, "due": n} for name, (d, n) in self.cut.items()},
                "unlearned_steps": self.unlearned}


@dataclass
class TrainReport:
    """What a finished run says of itself: the whole run (every session of a resumed run), and this session's part
    where a field says so."""

    run: str
    steps: int  # game steps of the whole run
    episodes: int  # training games finished in the whole run
    seconds: float  # wall time of the whole run: each earlier session's up to its last snapshot moment (what the
    # next one continued from: a killed session's later work was done again), then all of this session's
    eval_games: int  # games the run's gauntlets played, every session (as the ledger holds them)
    snapshots: list[str]  # the whole run's snapshots, oldest first
    finals: list[SnapshotRecord]  # each learner's final snapshot, as the ledger rates it
    sessions: int  # processes that trained the run: the first, then one per resume from a snapshot moment
    session_steps: int  # game steps this session played
    session_seconds: float  # wall time of this session, rating games and the wait for the last ones included
    train_seconds: float  # of it, training: the loop of games and updates (rating games played inline left out)
    session_eval_games: int  # rating games this session stored: the ledger's count of the run's (``eval_games``)
    # now, less its count when the session began (a gauntlet a killed session had finished is played again on
    # resume and stores nothing: it adds none)
    eval_seconds: float  # this session: time the gauntlets took (beside training, unless inline)
    wait_seconds: float  # this session: time spent after training waiting for the last gauntlets
    plot: Path | str | None = None  # the rating curves' PNG, or why there is none
    best: Any = None  # the run's best snapshot as the ladder has it at the end (a LadderRow), None unrated
    side_bests: list[Any] = field(default_factory=list)  # a game rated per side: the run's best of each side
    nash: dict[str, float] | None = None  # --opponents nash: the run's Nash mixture at the end (name -> weight)
    rating_left: int = 0  # gauntlets not played yet (--eval remote --no-wait: the league's workers play them
    # later); while any is left the ratings above are not the run's last, and its best is not decided
    rating: bool = True  # the run plays rating games (False: --eval-games 0)
    budget_end: BudgetEnd | None = None  # --minutes: how the budget ended training (None: a budget of steps)
    same_weights: dict[str, str] = field(default_factory=dict)  # the run's snapshots whose weights another run's
    # snapshot holds too (a repeated command and seed): name -> the other's name; one set of weights is one player,
    # rated once, so such a snapshot's gauntlet finds its games already played

    @property
    def steps_per_second(self) -> float:
        """This session's training rate: its game steps over its training time."""
        return self.session_steps / self.train_seconds if self.train_seconds > 0 else 0.0


class Heartbeat:
    """Tells a run's progress events to ``tell``, one at a time (:meth:`tell`, from the run's thread), and, from a
    thread of its own, the event ``make()`` returns (None: nothing to tell) whenever none was told for
    :data:`HEARTBEAT_SECONDS`: a display hears of the run while its thread is busy in one long piece of work (a
    game's slow step, an update of minutes, a gauntlet played inline), and a log's line comes on time. An error
    ``tell`` raises in the heartbeat's thread stops the heartbeat and is raised in the run's thread by
    :meth:`check`."""

    def __init__(self, tell: Callable[[dict[str, Any]], None], make: Callable[[], dict[str, Any] | None]) -> None:
        self._tell, self._make = tell, make
        self._lock = threading.Lock()
        self._last = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def tell(self, event: dict[str, Any]) -> None:
        with self._lock:
            self._last = time.monotonic()
            self._tell(event)

    def beat(self) -> None:
        """Tell ``make()``'s event if none was told for :data:`HEARTBEAT_SECONDS`."""
        if time.monotonic() - self._last >= HEARTBEAT_SECONDS:
            event = self._make()
            if event is not None:
                self.tell(event)

    def check(self) -> None:
        """Raise the error that stopped the heartbeat, if one did."""
        if self.error is not None:
            error, self.error = self.error, None
            raise error

    def _run(self) -> None:
        while not self._stop.wait(HEARTBEAT_SECONDS / 4):
            try:
                self.beat()
            except BaseException as e:  # (raised in the run's thread by check())
                self.error = e
                return

    def __enter__(self) -> Heartbeat:
        self._last = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="marl-progress", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
