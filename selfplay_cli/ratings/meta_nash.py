"""The Nash mixture of a run's snapshots: PSRO's meta-strategy, from the games the ledger holds.

The meta-game of a run: each of two sides picks one of the run's snapshots, and the row side gets its mean payoff
against the column side over their rated games (:func:`~selfplay_cli.ratings.pairs.pair_payoffs`, the matrix
``marl league matrix`` shows, in ``points`` or in the game's ``score`` units). Its equilibrium
(:func:`~selfplay_cli.stats.nash.symmetric_nash`) is a mixture of snapshots that no single snapshot beats on
average: ``marl train --opponents nash`` draws its training opponents from it (one learner as PSRO's oracle),
``marl exploit --vs-mixture nash`` trains a best response against it.

A pair is measured once it has ``min_games`` rated games (by default one: with ``--opponents nash`` a run's
gauntlets give each pair of its snapshots all its ``--eval-games`` games, none cut short where a result looks
clear). A missing score is never guessed: the mixture is over the measured sub-game
(:func:`~selfplay_cli.stats.nash.measured_subgame`, the largest set of snapshots whose pairs are all measured; ties:
the newer set), and the snapshots outside it weigh 0.

Payoff units: ``points`` is the default, as in ``marl league matrix``: a result is what the ladder rates, and the
matrix of points is antisymmetric for every game kind. ``score`` is PSRO's own payoff where a game's scores are
zero-sum returns (OpenSpiel's ``kuhn_poker`` and ``leduc_poker``, whose scores are chips won): there a mixture that
loses small pots to win big ones is worth what it wins, which points cannot see.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..league.store import League, LeagueError, PlayerRow
from ..league.variants import variant_key
from ..players.snapshots import run_options
from ..stats.nash import measured_subgame, symmetric_nash
from .pairs import PAYOFFS, pair_payoffs, pair_records

__all__ = ["RunNash", "nash_mixture", "run_nash"]


@dataclass(frozen=True)
class RunNash:
    """The Nash mixture of a run's snapshots.

    Attributes:
        run: the run's name.
        payoff: the meta-game's units, ``points`` or ``score``.
        snapshots: the run's snapshots, oldest first (every one, measured or not).
        weights: player id -> weight for every snapshot (0 outside the support; the weights sum to 1).
        over: the ids the mixture was solved over (the measured sub-game), oldest first.
        value: the game's value for the row side (0 up to rounding: a symmetric game).
        games: the rated games between the run's snapshots it was solved from.
    """

    run: str
    payoff: str
    snapshots: tuple[PlayerRow, ...]
    weights: dict[int, float]
    over: tuple[int, ...]
    value: float
    games: int

    @property
    def support(self) -> dict[int, float]:
        """Player id -> weight of the snapshots with a positive weight, heaviest first (ties: the older)."""
        return dict(sorted(((p, w) for p, w in self.weights.items() if w > 0.0), key=lambda pw: (-pw[1], pw[0])))

    def by_name(self) -> dict[str, float]:
        """:attr:`support` by the snapshots' full names (``run/name``)."""
        names = {p.id: p.full_name for p in self.snapshots}
        return {names[p]: w for p, w in self.support.items()}


def run_nash(league: League, run: str, payoff: str = "points", min_games: int = 1,
             until_step: int | None = None) -> RunNash | None:
    """The Nash mixture of the snapshots of ``run`` (see the module docstring), from the rated games between them in
    the variant the run plays; None while there is none to solve: no snapshot, or two or more of which no pair is
    measured yet. A run of one snapshot: that snapshot, weight 1. ``until_step``: only the snapshots taken at that
    training step or before (the mixture the run had then, from the games the ledger holds now).

    Raises:
        LeagueError: an unknown run or ``payoff``, ``min_games < 1``.
    """
    if payoff not in PAYOFFS:
        raise LeagueError(f"unknown payoff {payoff!r} (expected one of {', '.join(PAYOFFS)})")
    if min_games < 1:
        raise LeagueError(f"min_games must be at least 1, not {min_games}")
    info = league.roster.get_run(run)
    if info is None:
        raise LeagueError(f"no run named '{run}'")
    snapshots = tuple(p for p in league.roster.players(env=info.env, kind="snapshot")
                      if p.run == run and (until_step is None or p.step <= until_step))
    if not snapshots:
        return None
    ids = [p.id for p in snapshots]
    if len(ids) == 1:
        return RunNash(run, payoff, snapshots, {ids[0]: 1.0}, (ids[0],), 0.0, 0)
    newest_first = ids[::-1]  # (the sub-game's ties go to the set whose indices come first: the newer snapshots)
    table = league.ledger.games(env=info.env, players=ids, variant=variant_key(info.env, run_options(league, run)))
    records = pair_records(table, newest_first)
    sub = measured_subgame((records[0] >= min_games) & ~np.eye(len(ids), dtype=bool))
    if len(sub) < 2:
        return None
    nash = symmetric_nash(pair_payoffs(table, newest_first, payoff, records=records)[np.ix_(sub, sub)])
    weights = dict.fromkeys(ids, 0.0)
    for k, i in enumerate(sub):
        weights[newest_first[i]] = float(nash.mixture[k])
    return RunNash(run, payoff, snapshots, weights, tuple(sorted(newest_first[i] for i in sub)), float(nash.value),
                   len(table))


def nash_mixture(league: League, run: str, payoff: str = "points", min_games: int = 1) -> dict[str, float]:
    """The Nash mixture of ``run``'s snapshots as ``{full name: weight}`` (positive weights, heaviest first, summing
    to 1): what ``marl exploit --vs-mixture nash --run R`` and the benchmarks play against. :func:`run_nash` with
    these arguments.

    Raises:
        LeagueError: an unknown run or payoff; a run without snapshots, or whose snapshots have not met yet.
    """
    found = run_nash(league, run, payoff=payoff, min_games=min_games)
    if found is None:
        raise LeagueError(f"run '{run}' has no Nash mixture yet: it needs snapshots with rated games between them "
                          f"(marl league tournament --run {run})")
    return found.by_name()
