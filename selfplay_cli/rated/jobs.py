"""Rating work as jobs of the league's queue (:mod:`selfplay_cli.league.queue`): what a job holds, how one is played,
and how a command that queued a batch sees it through.

A ``games`` job is a few minutes of one match: ``rounds`` rounds between side A (one player, or a cooperative team
flying together) and player B from ``first_seed``. Round ``r`` of a match is always played on seed
``first_seed + r`` (:func:`~selfplay_cli.rated.match.run_match`), so a match cut into jobs plays exactly the seeds
the whole match would, whichever worker plays which job, in whatever order. Each job's players are loaded afresh,
seeded from the job's own first seed, so a job played twice (by a worker thought dead, and by the one that took it
over) plays the same games; its games are stored once, under the job's key (``job:<id>``), with the job's end.

:func:`play_leased` plays one leased job while a thread beats its heart, then finishes it (or fails it, with the
error's first line, to be tried again after a backoff). The worker (:mod:`selfplay_cli.work`) and
:func:`see_through` both use it: a command that queued a batch plays the batch's jobs that no worker has taken, and
waits for those that workers play, so queued work is done even with no worker attached.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..errors import MarlError
from ..league.queue import BEAT_SECONDS, ENDED, SCAVENGE_SECONDS, JobRow, NewJob
from ..league.store import League, PlayerRow
from ..stats.match import match_stats
from .match import MatchReport, env_options_of, load_player, mix_seed, round_size, run_match

__all__ = ["GAMES", "JOB_ROUNDS", "KINDS", "JobLost", "Outcome", "Played", "combine", "games_jobs", "play_job",
           "play_leased", "see_through", "share_snapshots", "sprt_verdict", "summary", "worker_name"]

GAMES = "games"
JOB_ROUNDS = 64
"""Rounds per ``games`` job by default: 128 games of a two-sides game, seconds to a few minutes of play."""


class JobLost(Exception):
    """The job in play is no longer this worker's (cancelled, or taken over after its lease lapsed)."""


def worker_name(role: str = "worker") -> str:
    """``role@host:pid``: how a worker is listed."""
    return f"{role}@{socket.gethostname()}:{os.getpid()}"


def games_jobs(league: League, rows_a: Sequence[PlayerRow], row_b: PlayerRow, *, games: int, first_seed: int,
               match_kind: str, env_options: dict[str, Any] | None = None, params: dict[str, Any] | None = None,
               team_name: str | None = None, job_rounds: int = JOB_ROUNDS, device: str = "cpu") -> list[NewJob]:
    """The jobs of a match of ``games`` games (rounded up to whole rounds) from ``first_seed``: ``job_rounds`` rounds
    each, the last the rest. The players are loaded once here to know a round's size (and to refuse, in one line, a
    match that cannot be played) and their snapshots' bytes are put in the league, so any worker can fetch them."""
    if games < 1:
        raise MarlError(f"--games must be at least 1, not {games}")
    pa = [load_player(league, r, device=device, seed=mix_seed(first_seed, i)) for i, r in enumerate(rows_a)]
    pb = load_player(league, row_b, device=device, seed=mix_seed(first_seed, 1))
    team = pa if len(pa) > 1 or team_name else None
    per = round_size(pa[0], pb, first_seed=first_seed, env_options=env_options, team=team)
    share_snapshots(league, [*rows_a, row_b])
    total = -(-games // per)
    out = []
    for start in range(0, total, job_rounds):
        n = min(job_rounds, total - start)
        out.append(NewJob(kind=GAMES, env=row_b.env, spec={
            "a": [r.id for r in rows_a], "b": row_b.id, "rounds": n, "first_seed": first_seed + start,
            "round": start, "match_seed": first_seed, "env_options": dict(env_options or {}),
            "match_kind": match_kind, "params": dict(params or {}), "team_name": team_name}))
    return out


def share_snapshots(league: League, rows: Sequence[PlayerRow]) -> None:
    """Put the snapshot files of ``rows`` in the league (by their sha256) where it has them not yet, so a worker on
    any machine can fetch them; a :class:`MarlError` naming the first that cannot be (its file not here)."""
    from .snapshots import check_legacy_file

    report = league.ensure_blobs([r for r in rows if not r.is_bot], check_legacy=check_legacy_file)
    for name in (*report.missing, *report.refused):
        raise MarlError(f"{name}: {report.reasons.get(name, 'its file is not on this machine')}; workers elsewhere "
                        "could not play it")


@dataclass
class Played:
    """A job played: its games (league player ids per seat), the match they are filed as, and a summary."""

    games: list[Any]
    match_kind: str
    params: dict[str, Any]
    result: dict[str, Any]
    seconds: float
    played: int | None = None  # games played, where they are not ``games`` (a gauntlet stores its own as it plays)

    @property
    def count(self) -> int:
        return len(self.games) if self.played is None else self.played


def play_job(league: League, job: JobRow, *, device: str = "cpu", parallel: int = 1024,
             on_games: Callable[[int], None] | None = None) -> Played:
    """Play ``job`` in this process (nothing stored) by the player of its kind (:data:`KINDS`)."""
    player = KINDS.get(job.kind)
    if player is None:
        raise MarlError(f"job {job.id} is of kind {job.kind!r}, which this marl does not play: upgrade marl")
    return player(league, job, device=device, parallel=parallel, on_games=on_games)


def _play_games(league: League, job: JobRow, *, device: str, parallel: int,
                on_games: Callable[[int], None] | None) -> Played:
    """A ``games`` job: its rounds of one match."""
    spec = job.spec
    first = int(spec["first_seed"])
    rows_a = [league.get_player(int(i)) for i in spec["a"]]
    row_b = league.get_player(int(spec["b"]))
    pa = [load_player(league, r, device=device, seed=mix_seed(first, 0 if i == 0 else 1 + i))
          for i, r in enumerate(rows_a)]
    pb = load_player(league, row_b, device=device, seed=mix_seed(first, 1))
    team_name = spec.get("team_name")
    team = pa if len(pa) > 1 or team_name else None
    options = spec.get("env_options") or {}
    start = time.perf_counter()
    report = run_match(pa[0], pb, games=1, rounds=int(spec["rounds"]), first_seed=first, parallel=parallel,
                       on_games=on_games, env_options=options, team=team, team_name=team_name)
    seconds = time.perf_counter() - start
    ids = {**{p.id: r.id for p, r in zip(pa, rows_a, strict=True)}, pb.id: row_b.id}
    played = {**env_options_of(*pa, pb), **options}
    params = {"a": report.a, "b": report.b, "games": report.games, "first_seed": first, "env_options": played,
              "status": "finished", "games_stored": report.games, **(spec.get("params") or {})}
    return Played(games=[r.with_players(ids) for r in report.results], match_kind=str(spec["match_kind"]),
                  params=params, result=summary(report), seconds=seconds)


KINDS: dict[str, Callable[..., Played]] = {GAMES: _play_games}
"""The player of each kind of job: ``player(league, job, device=, parallel=, on_games=) -> Played``. A kind's module
adds itself here."""


def summary(report: MatchReport) -> dict[str, Any]:
    """What a job's row keeps of its match: the counts and A's points round by round (what :func:`combine` and an
    SPRT read)."""
    return {"games": report.games, "wins": report.wins, "draws": report.draws, "losses": report.losses,
            "pentanomial": list(report.pentanomial), "points_for": report.points_for,
            "points_against": report.points_against, "truncated": report.truncated, "paired": report.paired,
            "kind": report.kind, "a": report.a, "b": report.b, "variant": report.variant,
            "round_points": report.round_points, "seconds": round(report.seconds, 3)}


def combine(jobs: Sequence[JobRow], *, confidence: float = 0.95) -> MatchReport | None:
    """One report of the done ``jobs`` of one match (their rounds in order), None when none is done."""
    parts = sorted((j for j in jobs if j.state == "done" and j.result), key=lambda j: int(j.spec.get("round", 0)))
    if not parts:
        return None
    r0 = parts[0].result
    assert r0 is not None
    total = {k: sum(p.result[k] for p in parts) for k in ("games", "wins", "draws", "losses", "truncated")}  # type: ignore[index]
    penta = tuple(int(sum(p.result["pentanomial"][i] for p in parts)) for i in range(5))  # type: ignore[index]
    rounds = [pts for p in parts for pts in p.result["round_points"]]  # type: ignore[index]
    paired = bool(r0["paired"])
    stats = match_stats(total["wins"], total["draws"], total["losses"], pentanomial=penta if paired else None,
                        confidence=confidence)
    pf = sum(float(p.result["points_for"]) for p in parts)  # type: ignore[index]
    pa = sum(float(p.result["points_against"]) for p in parts)  # type: ignore[index]
    return MatchReport(env=parts[0].env, a=r0["a"], b=r0["b"], games=total["games"], wins=total["wins"],
                       draws=total["draws"], losses=total["losses"], points_for=_number(pf), points_against=_number(pa),
                       pentanomial=penta, stats=stats, seconds=sum(float(p.result["seconds"]) for p in parts),  # type: ignore[index]
                       match_id=None, first_seed=int(parts[0].spec.get("match_seed", parts[0].spec["first_seed"])),
                       truncated=total["truncated"], kind=r0["kind"], variant=r0.get("variant", ""), paired=paired,
                       round_points=rounds)


def _number(x: float) -> int | float:
    return int(x) if float(x).is_integer() else round(float(x), 4)


class _Heart:
    """A thread that beats a worker's heart on the job it plays every ``beat`` seconds; ``lost`` is set when the job
    is no longer the worker's."""

    def __init__(self, league: League, worker_id: int, job_id: int, beat: float) -> None:
        self.league, self.worker_id, self.job_id, self.beat = league, worker_id, job_id, beat
        self.lost = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"heart-{job_id}", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.beat):
            try:
                if not self.league.worker_beat(self.worker_id, self.job_id):
                    self.lost.set()
                    return
            except Exception:  # the database away for a moment: the next beat tries again (the lease lapses late)
                continue

    def __enter__(self) -> _Heart:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


@dataclass
class Outcome:
    """What became of one leased job: ``done`` (stored now), ``counted`` (finished before by another: not stored
    again), ``lost`` (cancelled or taken over while in play), or ``failed`` (with ``error``)."""

    job: JobRow
    state: str
    games: int = 0
    seconds: float = 0.0
    error: str | None = None
    error_kind: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def play_leased(league: League, worker_id: int, job: JobRow, *, beat: float = BEAT_SECONDS, device: str = "cpu",
                parallel: int = 1024, on_games: Callable[[int], None] | None = None,
                base_backoff: float | None = None, retry: Callable[[Callable[[], Any]], Any] = lambda fn: fn()
                ) -> Outcome:
    """Play a job this worker leased while its heart beats, then store it (:meth:`League.finish_job`), or put it back
    as failed with its error's first line; ``retry`` runs each write (a worker tries again while the database is
    away, so games played are not played again). A :class:`KeyboardInterrupt` (Ctrl-C, SIGTERM) propagates: the
    caller gives the job back."""
    from ..errors import MarlIOError

    with _Heart(league, worker_id, job.id, beat) as heart:
        def counted(n: int) -> None:
            if heart.lost.is_set():
                raise JobLost
            if on_games is not None:
                on_games(n)

        try:
            played = play_job(league, job, device=device, parallel=parallel, on_games=counted)
        except JobLost:
            return Outcome(job, "lost")
        except (MarlError, OSError, ValueError, RuntimeError) as exc:
            kind = "io" if isinstance(exc, MarlIOError | OSError) else "usage" if isinstance(exc, MarlError) else \
                "internal"
            line = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            kwargs = {} if base_backoff is None else {"base_backoff": base_backoff}
            error = f"{type(exc).__name__}: {line}"
            state = retry(lambda: league.fail_job(job.id, worker_id, error, **kwargs))
            return Outcome(job, "failed", error=line, error_kind=kind, extra={"state": state})
    stored = retry(lambda: league.finish_job(job.id, worker_id, games=played.games, match_kind=played.match_kind,
                                             params=played.params, result=played.result, seconds=played.seconds,
                                             played=played.count))
    return Outcome(job, "done" if stored else "counted", games=played.count, seconds=played.seconds)


def see_through(league: League, batch: str, *, device: str = "cpu", parallel: int = 1024, play: bool = True,
                beat: float = BEAT_SECONDS, scavenge: float = SCAVENGE_SECONDS, poll: float = 0.5,
                on_games: Callable[[int], None] | None = None,
                on_change: Callable[[list[JobRow]], bool] | None = None, role: str = "marl") -> list[JobRow]:
    """See a queued batch through: play its jobs that no worker has taken (``play``), wait for those that workers
    play, until every job has ended; the batch's jobs then. ``on_change(jobs)`` is called whenever a job ended (and
    once at the start); when it returns True the batch's remaining jobs are cancelled (a decided SPRT) and this
    returns. Ctrl-C gives a job in play back to the queue."""
    worker_id = league.add_worker(worker_name(role), socket.gethostname(), os.getpid()) if play else None
    ended: set[int] = set()
    try:
        while True:
            jobs = league.jobs(batch=batch)
            now_ended = {j.id for j in jobs if j.state in ENDED}
            if (now_ended != ended or not ended) and on_change is not None and on_change(jobs):
                league.cancel_jobs(batch=batch)
                return league.jobs(batch=batch)
            ended = now_ended
            if len(ended) == len(jobs):
                return jobs
            job = league.claim(worker_id, batches=[batch], scavenge=scavenge) if worker_id is not None else None
            if job is None:
                time.sleep(poll)
                if worker_id is not None:
                    league.worker_beat(worker_id)
                continue
            play_leased(league, worker_id, job, beat=beat, device=device, parallel=parallel,  # type: ignore[arg-type]
                        on_games=on_games)
    finally:
        if worker_id is not None:
            league.stop_worker(worker_id)


def sprt_verdict(jobs: Sequence[JobRow], test: Any, paired: bool) -> tuple[float, str | None, int]:
    """The SPRT over the done jobs' rounds in order, up to the first job not done: the LLR, the decision (None while
    undecided) and the rounds it counted. Rounds are checked one by one, so the decision falls where a single
    match playing them in order would have stopped."""
    rounds: list[list[float]] = []
    for j in sorted(jobs, key=lambda j: int(j.spec.get("round", 0))):
        if j.state != "done" or not j.result:
            break
        rounds += j.result["round_points"]
    llr, decision, n = 0.0, None, 0
    counts = [0] * (5 if paired else 3)
    for pts in rounds:
        n += 1
        if paired:  # the pair's points 0, 0.5, 1, 1.5, 2: LL, LD, WL+DD, WD, WW
            counts[int(round(2 * sum(pts)))] += 1
        else:
            for x in pts:
                counts[0 if x < 0.5 else 1 if x == 0.5 else 2] += 1
        llr = test.llr(counts, "pentanomial" if paired else "trinomial")
        decision = test.decide(llr)
        if decision is not None:
            break
    return llr, decision, n



from . import gauntlet_jobs  # noqa: E402,F401  (registers the "gauntlet" kind: a training run's gauntlets)
