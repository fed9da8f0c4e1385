"""The ``games`` kind of queued job: a few minutes of one match.

A ``games`` job holds ``rounds`` rounds between side A (one player, or a cooperative team flying together) and
player B from ``first_seed``. Round ``r`` of a match is always played on seed ``first_seed + r``
(:func:`~selfplay_cli.evaluation.match.run_match`), so a match cut into jobs plays exactly the seeds the whole match
would, whichever worker plays which job, in whatever order. Each job's players are loaded afresh, seeded from the
job's own first seed, so a job played twice (by a worker thought dead, and by the one that took it over) plays the
same games; they are stored once, under the job's key (``job:<id>``), with the job's end. :func:`combine` makes the
one report of a match's jobs. :func:`check_spec` says what a spec must hold, checked when the jobs are made and
before a worker plays one.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from ..errors import MarlError
from ..league.job_rows import JobRow, NewJob
from ..league.ledger import MATCH_KINDS
from ..league.store import League, PlayerRow
from ..players.load import env_options_of, load_player, mix_seed
from ..players.snapshots import share_snapshots
from ..stats.match import match_stats
from . import job_spec
from .match import MatchReport, round_size, run_match
from .played import Played, See
from .seeds import Settled

__all__ = ["GAMES", "JOB_ROUNDS", "MAX_JOB_ROUNDS", "MAX_TEAM", "check_spec", "combine", "games_jobs", "play",
           "summary"]

GAMES = "games"
JOB_ROUNDS = 64
"""Rounds per ``games`` job by default: 128 games of a two-sides game, seconds to a few minutes of play."""
MAX_JOB_ROUNDS = 64 * JOB_ROUNDS
"""Rounds one ``games`` job may hold: 64 times what marl queues in one (a job is minutes of play, so a lease lapsing
and a job played again cost little; a whole match of up to ``MAX_GAMES``, 10 million games, is many jobs)."""
MAX_TEAM = 64
"""Players of side A flying together in one job (a team of a cooperative game: a lander has at most 8)."""


def check_spec(spec: dict[str, Any]) -> None:
    """Refuse (:class:`~selfplay_cli.evaluation.job_spec.BadSpec`) a ``games`` spec a worker cannot play as it stands:
    the keys :func:`games_jobs` writes, each of its type, counts within bounds."""
    job_spec.ids(spec, "a", MAX_TEAM)
    job_spec.whole(spec, "b", 1, job_spec.MAX_PLAYER_ID)
    job_spec.whole(spec, "rounds", 1, MAX_JOB_ROUNDS)
    job_spec.whole(spec, "first_seed", 0, job_spec.MAX_SEED)
    job_spec.text(spec, "match_kind", choices=MATCH_KINDS)
    job_spec.whole(spec, "round", 0, job_spec.MAX_SEED, required=False)
    job_spec.whole(spec, "match_seed", 0, job_spec.MAX_SEED, required=False)
    job_spec.table(spec, "env_options")
    job_spec.table(spec, "params")
    job_spec.text(spec, "team_name", required=False, none=True)
    job_spec.tries(spec)


def games_jobs(league: League, rows_a: Sequence[PlayerRow], row_b: PlayerRow, *, games: int, first_seed: int,
               match_kind: str, env_options: dict[str, Any] | None = None, params: dict[str, Any] | None = None,
               team_name: str | None = None, job_rounds: int = JOB_ROUNDS, device: str = "cpu",
               seeds: Settled | None = None) -> list[NewJob]:
    """The jobs of a match of ``games`` games (rounded up to whole rounds) from ``first_seed``: ``job_rounds`` rounds
    each, the last the rest. The players are loaded once here to know a round's size (and to refuse, in one line, a
    match that cannot be played) and their snapshots' bytes are put in the league, so any worker can fetch them.
    ``seeds``: what :func:`~selfplay_cli.evaluation.seeds.settle` decided for the match; each job then claims its seeds
    (:attr:`~selfplay_cli.league.job_rows.NewJob.claim`), taken when it is queued."""
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
        spec = {"a": [r.id for r in rows_a], "b": row_b.id, "rounds": n, "first_seed": first_seed + start,
                "round": start, "match_seed": first_seed, "env_options": dict(env_options or {}),
                "match_kind": match_kind, "params": dict(params or {}), "team_name": team_name}
        check_spec(spec)  # (what a worker would refuse is refused here, before anything is queued)
        claim = seeds.claim(first_seed + start, n, n * per) if seeds is not None else None
        out.append(NewJob(kind=GAMES, env=row_b.env, spec=spec, claim=claim))
    return out


def play(league: League, job: JobRow, *, device: str, parallel: int,
         on_games: Callable[[int], None] | None, see: See | None = None) -> Played:
    """A ``games`` job: its rounds of one match (handing nothing on: ``see`` unused)."""
    del see
    spec = job.spec
    first = int(spec["first_seed"])
    rows_a = [league.roster.get_player(int(i)) for i in spec["a"]]
    row_b = league.roster.get_player(int(spec["b"]))
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


def summary(report: MatchReport) -> dict[str, Any]:
    """What a job's row keeps of its match: the counts and A's points round by round (what :func:`combine` and an
    SPRT read)."""
    return {"games": report.games, "wins": report.wins, "draws": report.draws, "losses": report.losses,
            "pentanomial": list(report.pentanomial), "points_for": report.points_for,
            "points_against": report.points_against, "truncated": report.truncated, "paired": report.paired,
            "kind": report.kind, "a": report.a, "b": report.b, "variant": report.variant,
            "round_points": report.round_points, "seconds": round(report.seconds, 3),
            "step_limit": report.step_limit, "tie_tolerance": report.tie_tolerance, "game_steps": report.game_steps}


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
                       truncated=total["truncated"], game_steps=sum(_count(p.result.get("game_steps")) for p in parts),  # type: ignore[union-attr]
                       kind=r0["kind"], variant=r0.get("variant", ""), paired=paired,
                       round_points=rounds, step_limit=_whole(r0.get("step_limit")),
                       tie_tolerance=_tolerance(r0.get("tie_tolerance")))


def _count(x: Any) -> int:
    """A job row's count of game steps: a whole number >= 0, else 0 (an older row has none)."""
    return x if isinstance(x, int) and not isinstance(x, bool) and x >= 0 else 0


def _whole(x: Any) -> int | None:
    """A job row's step limit: a whole number >= 1, else None (an older row has none)."""
    return x if isinstance(x, int) and not isinstance(x, bool) and x >= 1 else None


def _tolerance(x: Any) -> float:
    """A job row's tie tolerance: a finite number >= 0, else 0 (an older row has none)."""
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and 0 <= x < float("inf") else 0.0


def _number(x: float) -> int | float:
    return int(x) if float(x).is_integer() else round(float(x), 4)
