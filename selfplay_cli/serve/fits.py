"""The fits behind ``marl serve``'s pages, made in one background thread so that no request ever fits.

A fit of a large league (500 players, 100,000 games: a ladder with its 200 bootstrap replicates, ranks and tiers)
takes tens of seconds, far longer than a page may. :class:`FitCache` runs one thread that, when the server starts and
whenever the league has changed, fits each game and variant the league holds: the ladder as ``marl league ladder
--json`` fits it, the ladder ``marl league matrix`` orders its players by (``bootstrap=0``), the default matrix, and
the forecaster of ``marl league predict`` with its spread. One fit at a time, in that thread only; a request reads
the latest finished fit (:meth:`FitCache.state`) under a lock held for a dict lookup, never during a fit.

Change detection is cheap: every :data:`CHECK_SECONDS` the thread reads :meth:`~.queries.Reader.changes` (a few
indexed maxima and counts); only when they moved does it count each variant's games and refit the game and variants
whose games or players changed (and, every :data:`META_SECONDS`, a hash of the players' meta: a filed
exploitability, a league role). A fit that fails keeps its one-line error (shown on the pages, logged once) and the
fit before it, and is tried again when the league next changes.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from selfplay_cli.league.store import LeagueError
from selfplay_cli.ratings.forecast import Forecaster
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.ratings.ladder_rows import LadderRow
from selfplay_cli.report.matrix import MatrixReport
from selfplay_cli.serve.queries import Ladder, Reader

__all__ = ["CHECK_SECONDS", "FitCache", "Fitted", "KeyState", "fit_game"]

log = logging.getLogger("marl.serve")

CHECK_SECONDS = 3.0
"""How often the thread looks whether the league changed."""
META_SECONDS = 30.0
"""How often it also hashes the players' meta (what no count shows)."""
MATRICES = 32
"""Matrices kept per fit (one per top, run, min games and payoff asked for)."""
DEFAULT_MATRIX = (10, None, 8, "points")

Key = tuple[str, str]  # (game, variant key)


def one_line(e: BaseException) -> str:
    """An error as one line: its kind and its first 300 characters."""
    return f"{type(e).__name__}: {' '.join(str(e).split())[:300]}"


@dataclass
class Fitted:
    """One game and variant, fitted: what its pages show."""

    env: str
    variant: str
    ladder: Ladder
    matrix_rows: list[LadderRow]
    forecaster: Forecaster | None
    forecast_error: str | None
    games: int
    fitted_at: float  # (wall clock, when the fit finished)
    seconds: float
    matrices: dict[tuple, MatrixReport] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def matrix(self, reader: Reader, top: int, run: str | None, min_games: int, payoff: str) -> MatrixReport:
        """The matrix of these rows (built once per parameters, from the rows fitted: no fit)."""
        key = (top, run, min_games, payoff)
        with self.lock:
            hit = self.matrices.get(key)
        if hit is None:
            hit = reader.matrix(self.env, self.variant, top, run, min_games, payoff, rows=self.matrix_rows)
            with self.lock:
                if len(self.matrices) >= MATRICES:
                    self.matrices.pop(next(k for k in self.matrices if k != DEFAULT_MATRIX))
                self.matrices[key] = hit
        return hit


def fit_game(reader: Reader, env: str, variant: str, games: int) -> Fitted:
    """Everything the pages of ``env`` in ``variant`` need that takes a fit (see the module docstring)."""
    started = time.monotonic()
    lad = reader.ladder(env, variant)
    rows = ladder(reader.league, env, bootstrap=0, variant=variant)
    try:
        forecaster, error = reader.forecaster(env, variant), None
    except LeagueError as e:  # (a ladder without a prediction: its pages say why)
        forecaster, error = None, str(e)
    fitted = Fitted(env, variant, lad, rows, forecaster, error, games, time.time(), time.monotonic() - started)
    with contextlib.suppress(LeagueError):  # (too few players for a matrix: its page says so when asked)
        fitted.matrices[DEFAULT_MATRIX] = reader.matrix(env, variant, *DEFAULT_MATRIX, rows=rows)
    return fitted


@dataclass(frozen=True)
class KeyState:
    """What a page of one game and variant can show: the latest finished fit (None before the first), the fit
    running now (its start, monotonic, and its games) and the latest attempt's error."""

    fitted: Fitted | None
    running_since: float | None
    running_games: int | None
    error: str | None
    queued: bool


class FitCache:
    """The background fits of one :class:`~.queries.Reader` (see the module docstring). ``fit``: how one game and
    variant is fitted (tests wrap :func:`fit_game` to hold a fit or make one fail)."""

    def __init__(self, reader: Reader, fit: Callable[[Reader, str, str, int], Fitted] = fit_game,
                 every: float = CHECK_SECONDS) -> None:
        self.reader, self.fit, self.every = reader, fit, every
        self._lock = threading.Condition()
        self._fitted: dict[Key, Fitted] = {}
        self._errors: dict[Key, str] = {}
        self._stamps: dict[Key, tuple] = {}  # what each key was last fitted (or failed) at
        self._wanted: set[Key] = set()
        self._running: tuple[Key, float, int] | None = None
        self._requested = self._served = 0
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._looked: tuple | None = None
        self._meta: tuple[float, int] | None = None
        self.cycle_error: str | None = None

    # ------------------------------------------------------------------ the thread

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="marl-serve-fits", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 30.0) -> bool:
        """Stop the thread (after the fit it is in, waiting at most ``timeout`` s); True when it has ended."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                log.warning("marl serve: a fit is still running; it ends with the process")
                return False
        return True

    def _loop(self) -> None:
        while not self._stop.is_set():
            self._wake.clear()
            with self._lock:
                seen = self._requested
            try:
                self._cycle()
                self.cycle_error = None
            except Exception as e:  # (the league unreadable for a moment: said, and tried again)
                if self.cycle_error != one_line(e):
                    log.error("marl serve: reading the league for its fits: %s", one_line(e))
                self.cycle_error = one_line(e)
            with self._lock:
                self._served = seen
                self._lock.notify_all()
            self._wake.wait(self.every)

    def _stale(self) -> list[tuple[Key, int, tuple]]:
        """The keys to fit now, wanted ones first, with their games and stamps."""
        changes = self.reader.changes()
        now = time.monotonic()
        if self._meta is None or now - self._meta[0] >= META_SECONDS:
            self._meta = (now, self.reader.players_meta())
        look = (changes, self._meta[1])
        with self._lock:
            unfitted = self._wanted - set(self._stamps)
        if look == self._looked and not unfitted:
            return []
        self._looked = look
        players = (changes[2], changes[3], changes[4], self._meta[1])  # (a new, removed or tagged player; meta)
        games = self.reader.games()
        for run in (r for g in games for r in g["runs"]):  # (a run's variant, for its curves page, read here)
            with contextlib.suppress(Exception):
                self.reader.run_variant(run.name)
        counts = {(g["env"], v["key"]): v["games"] for g in games for v in g["variants"] if v["games"]}
        todo = [(key, n, (n, players)) for key, n in counts.items() if self._stamps.get(key) != (n, players)]
        todo.sort(key=lambda t: (t[0] not in unfitted, t[0]))
        return todo

    def _cycle(self) -> None:
        for key, games, stamp in self._stale():
            if self._stop.is_set():
                return
            with self._lock:
                self._running = (key, time.monotonic(), games)
            try:
                fitted = self.fit(self.reader, key[0], key[1], games)
            except Exception as e:
                error = one_line(e)
                log.error("marl serve: fitting %s (%s): %s", key[0], key[1] or "default options", error)
                with self._lock:
                    self._errors[key] = error
            else:
                with self._lock:
                    self._fitted[key] = fitted
                    self._errors.pop(key, None)
            finally:
                with self._lock:
                    self._stamps[key] = stamp
                    self._wanted.discard(key)
                    self._running = None

    # ------------------------------------------------------------------ what requests read

    def state(self, env: str, variant: str) -> KeyState:
        """What the pages of ``env`` in ``variant`` can show now (a lookup: never waits for a fit). A key without a
        fit yet is put first in the thread's queue."""
        key = (env, variant)
        with self._lock:
            fitted, error = self._fitted.get(key), self._errors.get(key)
            running = self._running if self._running is not None and self._running[0] == key else None
            queued = fitted is None and error is None and running is None
            if queued and key not in self._wanted:
                self._wanted.add(key)
                self._wake.set()
        return KeyState(fitted, running[1] if running else None, running[2] if running else None, error, queued)

    def poke(self) -> int:
        """Have the thread look at the league now; the number :meth:`wait` waits for."""
        with self._lock:
            self._requested += 1
            self._wake.set()
            return self._requested

    def wait(self, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) until the thread has looked at the league since this call and fitted what
        changed: True when it has (tests, the benchmark; no page waits)."""
        want = self.poke()
        deadline = time.monotonic() + timeout
        with self._lock:
            while self._served < want:
                left = deadline - time.monotonic()
                if left <= 0 or self._thread is None or not self._thread.is_alive():
                    return False
                self._lock.wait(left)
        return True

    def health(self) -> dict[str, Any]:
        """The fits as ``/health`` reports them."""
        with self._lock:
            running = self._running
            return {
                "ok": True,
                "fitting": None if running is None else {"env": running[0][0], "variant": running[0][1],
                                                         "games": running[2],
                                                         "seconds": round(time.monotonic() - running[1], 1)},
                "fitted": [{"env": k[0], "variant": k[1], "games": f.games, "seconds": round(f.seconds, 2),
                            "at": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(f.fitted_at))}
                           for k, f in sorted(self._fitted.items())],
                "errors": [{"env": k[0], "variant": k[1], "error": e} for k, e in sorted(self._errors.items())],
                "checks": self._served,
            }
