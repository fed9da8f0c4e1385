"""A study's measures of a team: its final snapshot flown at a size on fixed seeds, and its snapshots' returns."""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

import numpy as np

from ..errors import MarlError
from ..evaluation.match import run_match
from ..evaluation.match_jobs import MatchJob
from ..league.store import League, LeagueError
from ..league.variants import variant_key
from ..policies.bots import league_bots
from ..ratings.names import Team, resolve, resolve_or_team

__all__ = ["fly", "mean_interval", "snapshot_returns"]


def fly(league: League, team: str, vs: str, options: dict[str, Any], games: int, seed: int) -> dict[str, Any]:
    """``team`` (a snapshot, or a run's team of per-seat snapshots) flown with the game ``options`` (its size among
    them) for ``games`` episodes on seeds ``seed``, ``seed + 1``, ..., and ``vs`` on the same seeds: each one's mean
    team return per episode with its 95% interval. Not filed in the ledger (the study's table is its record)."""
    found = resolve_or_team(league, team)
    rows = list(found.members) if isinstance(found, Team) else [found]
    env = rows[0].env
    league.roster.ensure_bots(env, league_bots(_spec(env)))
    try:
        opponent = resolve(league, vs, env)
    except LeagueError as e:
        raise MarlError(str(e)) from None
    job = MatchJob(tuple(rows), opponent, found.full_name if isinstance(found, Team) else None)
    pa, pb, _ = job.load(league, seed, "cpu")
    report = run_match(pa[0], pb, games=2 * games, first_seed=seed, env_options=options,
                       team=pa if len(pa) > 1 else None, team_name=job.team_name)
    mine = {p.id for p in pa}
    ours = [sum(r.scores) for r in report.results if set(r.players) <= mine]
    theirs = [sum(r.scores) for r in report.results if set(r.players) == {pb.id}]
    return {**mean_interval(ours), "vs": {"player": pb.id, **mean_interval(theirs)}, "team": team,
            "seating": list(report.seating) if report.seating is not None else None}


def _spec(env: str) -> Any:
    from ..envs import get_env

    return get_env(env)


def snapshot_returns(league: League, env: str, run: str, options: dict[str, Any]) -> list[tuple[int, float]]:
    """(step, mean team return) of each snapshot moment of ``run`` in the variant ``options`` make, from the
    league's cooperative games of its snapshots (its training gauntlets): a team's members, which fly together, the
    mean of theirs. Moments without such games are left out."""
    returns = league.ledger.mean_returns(env, variant=variant_key(env, options))
    by_step: dict[int, list[float]] = defaultdict(list)
    for p in league.roster.players(env=env, kind="snapshot"):
        if p.run == run and not p.removed and p.id in returns:
            by_step[int(p.step or 0)].append(returns[p.id][1])
    return [(step, sum(v) / len(v)) for step, v in sorted(by_step.items())]


def mean_interval(values: Any) -> dict[str, Any]:
    """Mean and its 95% interval (normal approximation) of per-game figures; no interval from one game."""
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        return {"mean": None, "low": None, "high": None, "games": 0}
    m = float(x.mean())
    if x.size < 2:
        return {"mean": round(m, 4), "low": None, "high": None, "games": 1}
    half = 1.96 * float(x.std(ddof=1)) / math.sqrt(x.size)
    return {"mean": round(m, 4), "low": round(m - half, 4), "high": round(m + half, 4), "games": int(x.size)}
