"""A training run's gauntlets as jobs of the league's queue (kind ``gauntlet``): what one holds, and how it is played.

A run's snapshot moment asks for one gauntlet (:func:`~selfplay_cli.evaluation.gauntlet.rate_snapshots`), and the final
moment's is played in full and followed by the run's playoff (:mod:`~selfplay_cli.evaluation.playoff`). Played by the
training process itself (``marl train``'s default, a worker process beside training, or inline) or, with ``marl
train --eval remote``, by any ``marl worker`` that leases it from the queue: the same function plays it either way,
from the same spec, so the games are the same.

A gauntlet stores its own games, each matchup whole under a key of the moment (``gauntlet/<first snapshot id>/...``;
the playoff's rounds under ``playoff/...``), and a gauntlet played again stores only the matchups it is missing and
makes the same choices. So a job finished twice, or played again after its worker went silent, counts once: its
:class:`~selfplay_cli.evaluation.played.Played` carries no games of its own (the queue only marks it done), and a
summary (games, seconds, the snapshots it rated).

What a gauntlet chooses (the run's best so far, the older snapshots it has not met) comes from the run's earlier
gauntlets, so a run's jobs are queued in a chain (each waits for the one before it), played in the order the
snapshots were taken, as the training process plays them.

A moment's matchups, once chosen, are independent of each other. So where other workers take the run's jobs, the worker
that leased a moment plans it (:func:`~selfplay_cli.evaluation.gauntlet_plan.plan_moment`) and queues each matchup not
in the ledger yet as a job of its own (kind ``matchup``, in the run's batch, not chained: whoever is free takes it),
plays those nobody has taken and waits for the rest (:func:`~selfplay_cli.evaluation.jobs.see_through`), then ends the
moment (its playoff, for the final one); the next moment's job waits for it, so for all of them. A matchup's job plays
it as the whole moment's call would (its seeds and its games, stored whole under the moment's key), so a moment
replanned after its worker died finds the matchups stored or queued and queues none twice.
Where no other worker takes the batch, the moment plays whole in one batch (faster on one machine). Matchups played
apart sample their moves in batches of their own, so their games are other draws than the whole moment's of the same
seeds; which matchups are played, on which seeds and how many games, is the same.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from typing import Any

from ..envs import get_env
from ..errors import MarlError
from ..league.job_rows import JobRow, NewJob
from ..league.store import League
from ..players.snapshots import share_snapshots
from ..results import Rules
from ..stats.belief import record_prediction
from . import job_spec
from .gauntlet import GauntletConfig, open_matchups, play_gauntlet, rate_snapshots
from .gauntlet_plan import ALL_OLDER, Moment, crews_of, plan_moment, stands_alone
from .played import JobLost, Played, See

__all__ = ["FINAL_BOT_GAMES", "FINAL_OLDER", "GAUNTLET", "MATCHUP", "MAX_EVAL_GAMES", "MAX_MOMENT", "MAX_OLDER",
           "MAX_PLAYOFF", "PLAYOFF_SEEDS", "PRECISE_PAIRS", "check_matchup_spec", "check_spec", "gauntlet_job",
           "play", "play_gauntlet_spec", "play_matchup", "precise_pairs", "queue_matchups", "stands_alone_spec"]

GAUNTLET = "gauntlet"
MATCHUP = "matchup"  # one matchup of a moment's gauntlet, queued by the worker that plays the moment
FINAL_BOT_GAMES = 8  # a run's final snapshots play this many times --eval-games against each scripted player (64
# at the default 8): the run's summary reports their scores against the bots, and each score's interval (within
# about 28 points for a 200-game match at 50%)
PRECISE_PAIRS = 4  # with a precision (marl train --eval-precision), a matchup (bots too) plays up to this many
# times its pairs: as many as an even record needs to predict a 200-game match of the two that closely (the ladder's
# claims about a pair rest on its games), all at once
FINAL_OLDER = 24  # a run's final snapshots meet this many of its earlier snapshots (all of a default run's), spread
# over the run: is the final stronger than the whole history, and where does it lose what it had (self-play's
# rock-paper-scissors shows between snapshots far apart, which the ratings alone do not predict)
PLAYOFF_SEEDS = 5_000  # a final job's playoff seeds start this far above its gauntlet's (which take a few dozen)
# A gauntlet job's counts at most: marl train's own limits (--eval-games, --eval-playoff), the snapshots of one
# moment (one per learner); older snapshots met: a run's own (ALL_OLDER, all of them, for --opponents nash), so no
# more than the run has whatever the number.
MAX_EVAL_GAMES = 10_000
MAX_OLDER = ALL_OLDER
MAX_PLAYOFF = 100_000
MAX_MOMENT = 256


def check_spec(spec: dict[str, Any]) -> None:
    """Refuse (:class:`~selfplay_cli.evaluation.job_spec.BadSpec`) a ``gauntlet`` spec a worker cannot play as it
    stands: the keys :func:`gauntlet_job` writes (those it added later may be absent: a job queued before them), each of
    its type, counts within ``marl train``'s own limits."""
    _check_moment(spec)
    job_spec.whole(spec, "first_seed", 0, job_spec.MAX_SEED)
    job_spec.whole(spec, "playoff", 0, MAX_PLAYOFF, required=False)
    job_spec.names(spec, "snapshots", MAX_MOMENT, required=False)


def _check_moment(spec: dict[str, Any]) -> None:
    """The fields of a moment's gauntlet that its spec and each of its matchups' specs carry (:func:`_config`'s)."""
    job_spec.ids(spec, "snapshot_ids", MAX_MOMENT)
    job_spec.whole(spec, "games", 0, MAX_EVAL_GAMES)
    job_spec.whole(spec, "older", 0, MAX_OLDER)
    job_spec.flag(spec, "full")
    job_spec.flag(spec, "whole", required=False)  # (a job queued by a marl before every matchup played whole)
    job_spec.number(spec, "precision", 0.0, 1.0, required=False)
    job_spec.tries(spec)


def gauntlet_job(league: League, snapshot_ids: Sequence[int], *, first_seed: int, games: int, older: int,
                 full: bool = False, playoff: int = 0, precision: float = 0.0) -> NewJob:
    """The queue's job of one moment's gauntlet (``full``: the final moment's, with a ``playoff`` of up to that many
    games a pair). The snapshots' bytes are put in the league where it keeps them, so a worker on another machine
    can fetch them."""
    rows = [league.roster.get_player(int(i)) for i in snapshot_ids]
    spec = {"snapshot_ids": [int(i) for i in snapshot_ids], "first_seed": int(first_seed), "games": int(games),
            "older": int(older), "full": bool(full), "playoff": int(playoff), "precision": float(precision),
            "snapshots": [r.full_name for r in rows]}
    check_spec(spec)  # (what a worker would refuse is refused here, before anything is queued)
    share_snapshots(league, rows)
    return NewJob(kind=GAUNTLET, env=rows[0].env, spec=spec)


def _config(league: League, spec: dict[str, Any]) -> GauntletConfig:
    """The gauntlet's settings a moment's spec (or one of its matchups', which carries the moment's) asks for."""
    games, older, full = int(spec["games"]), int(spec["older"]), bool(spec.get("full", False))
    # games in a round of two players: a seat-swapped pair, or one game where each plays only its own side
    per = 1 if Rules.of(get_env(league.roster.get_player(int(spec["snapshot_ids"][0])).env)).sides_differ else 2
    n = max(games // per, 1)
    pairs = precise_pairs(n, per, float(spec.get("precision", 0.0)))  # (a job queued before it: eval_games exactly)
    return GauntletConfig(pairs=pairs, older=max(older, FINAL_OLDER) if full else older,
                          bot_pairs=max(pairs, FINAL_BOT_GAMES * games // per) if full else 0)


def stands_alone_spec(league: League, spec: dict[str, Any]) -> bool:
    """Whether the moment's gauntlet ``spec`` asks for chooses nothing from the run's earlier gauntlets
    (:func:`~.gauntlet_plan.stands_alone`: a run's final moment, which meets every earlier snapshot): it may then be
    played before the jobs ahead of it are done, the same games."""
    return stands_alone(league, [int(i) for i in spec["snapshot_ids"]], _config(league, spec).older)


@functools.lru_cache(maxsize=256)  # (about 1 ms a width: a run asks the same few settings for every moment and matchup)
def precise_pairs(pairs: int, per: int, precision: float) -> int:
    """The rounds a matchup plays (of ``per`` games each; ``pairs`` at least, from ``--eval-games``) for
    ``precision``: the fewest with which an even record would predict a 200-game match of the two within
    ``precision`` score points (:func:`~selfplay_cli.stats.belief.record_prediction`), at most :data:`PRECISE_PAIRS`
    times ``pairs`` (0: ``pairs`` exactly). An even record is the widest: one that leans one way is narrower with as
    many games. At the defaults (0.3, ``--eval-games`` 8) that is the cap, 32 games, for every game: an even record
    of 32 games still predicts 0.36 wide (of 64, 0.27).

    All of them are played at once, not added while the record is open: each addition would wait for the longest
    game of the batch (pong's trained players rally to the step limit), and a moment's chain of them took longer
    than its games played at once (docs/benchmarks.md)."""
    if not precision:
        return pairs
    for k in range(pairs, PRECISE_PAIRS * pairs):
        games = k * per
        if record_prediction(games // 2, games % 2, games // 2, 200).width <= precision:
            return k
    return PRECISE_PAIRS * pairs


def play_gauntlet_spec(league: League, spec: dict[str, Any], *, device: str = "cpu",
                       on_games: Callable[[int], None] | None = None, moment: Moment | None = None
                       ) -> tuple[int, float]:
    """Play one moment's gauntlet (and, for the final one, the playoff) as ``spec`` says (:func:`gauntlet_job`'s
    fields), storing its games; the games played and the seconds they took (its matchups stored before, by jobs of
    their own, count with their games, played nothing here). ``moment``: its plan, where the caller made it."""
    from .playoff import PlayoffConfig, playoff

    ids = [int(i) for i in spec["snapshot_ids"]]
    first_seed = int(spec["first_seed"])
    t0 = time.perf_counter()
    matchups = rate_snapshots(league, ids, first_seed=first_seed, config=_config(league, spec), device=device,
                              on_games=on_games, moment=moment)
    played = sum(m.games for m in matchups)
    if int(spec.get("playoff", 0)):
        played += playoff(league, ids, first_seed=first_seed + PLAYOFF_SEEDS,
                          config=PlayoffConfig(max_games=int(spec["playoff"])), device=device, on_games=on_games)
    return played, time.perf_counter() - t0


def play(league: League, job: JobRow, *, device: str, parallel: int,
         on_games: Callable[[int], None] | None, see: See | None = None) -> Played:
    """A ``gauntlet`` job: its games are stored as it plays them (keyed: once), so the job's end stores none. Where
    other workers take the job's batch, its matchups go to them first (:func:`_share`, through ``see``)."""
    del parallel  # a gauntlet plays all its matchups in one batch of its own size
    moment = None
    if see is not None and _helpers(league, job):
        cfg = _config(league, job.spec)
        moment = plan_moment(league, [int(i) for i in job.spec["snapshot_ids"]], cfg.older)
        if moment is not None:
            _share(league, job, queue_matchups(league, job, moment, cfg), see, on_games)
    games, seconds = play_gauntlet_spec(league, job.spec, device=device, on_games=on_games, moment=moment)
    return Played(games=[], match_kind="eval", params={}, seconds=seconds, played=games,
                  result={"games": games, "seconds": round(seconds, 3), "snapshots": job.spec.get("snapshots", [])})


def _helpers(league: League, job: JobRow) -> int:
    """How many workers besides the one that holds ``job`` take its batch and are free now (their heart beating, no
    job in hand): where a moment's matchups would wait for none of them, the moment plays whole."""
    from ..league.job_rows import SCAVENGE_SECONDS

    return sum(1 for w in league.queue.workers(alive_within=SCAVENGE_SECONDS, taking=job.batch)
               if w.id != job.worker_id and not w.holding)


def _share(league: League, job: JobRow, ids: list[int], see: See, on_games: Callable[[int], None] | None) -> None:
    """See the moment's matchup jobs ``ids`` (:func:`queue_matchups`) through: play those no worker takes and wait
    for the rest (``see``); a matchup's job that died fails the moment with its error."""
    if not ids:
        return
    lost = False

    def counted(n: int) -> None:  # (the moment's own lease lost while a matchup plays: that matchup ends first)
        nonlocal lost
        try:
            if on_games is not None:
                on_games(n)
        except JobLost:
            lost = True

    def looked(_jobs: list[JobRow]) -> bool:
        if lost:
            raise JobLost
        return False

    ended = see(job.batch, ids, on_games=counted, on_change=looked)
    dead = [j for j in ended if j.state == "dead"]
    if dead:
        raise MarlError(f"matchup job {dead[0].id} ({' against '.join(dead[0].spec.get('snapshots', []))}) of this "
                        f"gauntlet failed: {dead[0].error or 'no error recorded'}")


def queue_matchups(league: League, job: JobRow, moment: Moment, cfg: GauntletConfig) -> list[int]:
    """The matchups of the moment job ``job`` (planned: ``moment``, ``cfg``) that are not in the ledger yet
    (:func:`~selfplay_cli.evaluation.gauntlet.open_matchups`) as ``matchup`` jobs of its batch: those already queued (by
    an earlier playing of the moment whose worker died) as they are, the others queued now; their ids."""
    spec = job.spec
    todo = open_matchups(league, moment, first_seed=int(spec["first_seed"]), config=cfg)
    if not todo:
        return []
    base = {k: spec[k] for k in ("snapshot_ids", "games", "older", "full", "precision") if k in spec}
    queued = {(j.spec.get("a"), j.spec.get("b"), j.spec.get("first_seed")): j.id
              for j in league.queue.jobs(batch=job.batch) if j.kind == MATCHUP and j.state not in ("dead", "cancelled")
              and j.spec.get("snapshot_ids") == spec["snapshot_ids"]}
    ids, new = [], []
    for m in todo:
        known = queued.get((m.a.id, m.b.id, m.first_seed))
        if known is not None:
            ids.append(known)
        else:
            new.append(NewJob(kind=MATCHUP, env=m.a.env, spec={
                **base, "a": m.a.id, "b": m.b.id, "first_seed": m.first_seed,
                "snapshots": [m.a.full_name, m.b.full_name]}))
    return ids + (league.queue.enqueue(job.batch, new) if new else [])


def check_matchup_spec(spec: dict[str, Any]) -> None:
    """Refuse (:class:`~selfplay_cli.evaluation.job_spec.BadSpec`) a ``matchup`` spec a worker cannot play as it stands:
    its moment's gauntlet fields (:func:`check_spec`'s), the two players and the matchup's first seed."""
    _check_moment(spec)
    job_spec.whole(spec, "a", 1, job_spec.MAX_PLAYER_ID)
    job_spec.whole(spec, "b", 1, job_spec.MAX_PLAYER_ID)
    job_spec.whole(spec, "first_seed", 0, job_spec.MAX_SEED)
    job_spec.names(spec, "snapshots", 2, required=False)


def play_matchup(league: League, job: JobRow, *, device: str, parallel: int,
                 on_games: Callable[[int], None] | None, see: See | None = None) -> Played:
    """A ``matchup`` job: one matchup of a moment's gauntlet, played and stored as the whole moment's call would
    (:func:`~selfplay_cli.evaluation.gauntlet.open_matchups`): its seeds, its games, under the moment's key (so once,
    whoever plays it)."""
    del parallel, see
    spec = job.spec
    t0 = time.perf_counter()
    a, b = league.roster.get_player(int(spec["a"])), league.roster.get_player(int(spec["b"]))
    crews = {crew[0].id: crew for crew in crews_of(league, [a, b]).values()}
    (m,) = play_gauntlet(league, [(a, b)], first_seed=int(spec["first_seed"]), config=_config(league, spec),
                         device=device, on_games=on_games, crews=crews, key=f"gauntlet/{min(spec['snapshot_ids'])}")
    seconds = time.perf_counter() - t0
    return Played(games=[], match_kind="eval", params={}, seconds=seconds, played=m.games,
                  result={"games": m.games, "seconds": round(seconds, 3), "snapshots": spec.get("snapshots", [])})
