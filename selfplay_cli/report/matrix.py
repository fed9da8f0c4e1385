"""The score matrix of the best players: who beats whom, the Nash mixture of that meta-game and its cycles.

:func:`build_matrix` takes the top players of the ladder, ordered by fitted rating, and from every stored rated
game between two of them (either seat order) the row player's mean score against the column player, with the
counts. A pair with fewer than ``min_games`` games is *not measured*: it shows as such, and takes part in
neither the Nash mixture nor the cycle tests.

* Nash mixture (:func:`~selfplay_cli.stats.nash.symmetric_nash`, payoff ``score - 0.5``, or in the game's own
  score units with ``payoff="score"``: :func:`~selfplay_cli.ratings.pairs.pair_payoffs`): solved over the
  measured sub-game of :func:`~selfplay_cli.stats.nash.measured_subgame`, the largest set of players whose pairs
  are all measured (ties: the better-rated set). A missing score is never guessed; the report names the players
  the mixture is over.
* Cycles (:func:`~selfplay_cli.stats.cycles.significant_three_cycles`): 3-cycles whose three edges each pass an
  exact one-sided sign test on game pairs, Holm-corrected over all tested edges at family-wise level ``alpha``.

:func:`write_matrix_png` draws the matrix as a heatmap (matplotlib, Agg).
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..league.store import League, LeagueError
from ..league.variants import value_text, variant_options
from ..ratings.ladder import ladder
from ..ratings.ladder_rows import LadderRow
from ..ratings.pairs import PAYOFFS, pair_payoffs, pair_records
from ..stats.cycles import DEFAULT_ALPHA, Cycle, EdgeTests, significant_three_cycles
from ..stats.nash import NashResult, measured_subgame, symmetric_nash
from .png import new_figure, save_png

__all__ = ["CYCLE_TEST", "MatrixPlayer", "MatrixReport", "build_matrix", "write_matrix_png"]

CYCLE_TEST = ("exact one-sided sign test per edge on game pairs (same seed, seats swapped; unpaired games count "
              "singly; level units dropped), Holm-corrected over all tested edges")

_NASH_NOTE = ("over the measured sub-game: the largest set of players whose pairs all have at least min_games "
              "games (ties: the better-rated set)")


@dataclass(frozen=True)
class MatrixPlayer:
    """A player of the matrix, with its fitted rating."""

    policy: str
    player_id: int
    kind: str
    elo: float
    ci_low: float
    ci_high: float


@dataclass(frozen=True)
class MatrixReport:
    """The score matrix of ``players`` (best-rated first) and what follows from it.

    Matrices are indexed ``[row, column]`` from the row player's side: ``games`` (either seat order), ``wins``,
    ``draws``, ``losses``, ``unit_wins`` (sign-test units won, see :mod:`selfplay_cli.stats.cycles`).
    ``nash_players`` are the indices the mixture ``nash`` is over (None when fewer than two players are all
    measured against each other); ``edges`` the tests of every measured edge; ``cycles`` the significant
    3-cycles.
    """

    env: str
    run: str | None
    players: tuple[MatrixPlayer, ...]
    games: npt.NDArray[np.int64]
    wins: npt.NDArray[np.int64]
    draws: npt.NDArray[np.int64]
    losses: npt.NDArray[np.int64]
    unit_wins: npt.NDArray[np.int64]
    min_games: int
    nash_players: tuple[int, ...]
    nash: NashResult | None
    edges: EdgeTests
    cycles: tuple[Cycle, ...]
    variant: str = ""  # the key of the variant whose games it holds (the default: "")
    payoff: str = "points"  # the Nash meta-game's units (:data:`~selfplay_cli.ratings.pairs.PAYOFFS`)
    payoffs: npt.NDArray[np.float64] | None = None  # payoff "score": the row player's mean payoff in the game's units

    @property
    def n(self) -> int:
        return len(self.players)

    @cached_property
    def scores(self) -> npt.NDArray[np.float64]:
        """Row player's mean score against the column player; NaN without games and on the diagonal."""
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (self.wins + 0.5 * self.draws) / self.games
        s[self.games == 0] = np.nan
        return s

    def cell(self, i: int, j: int) -> tuple[str, float]:
        """Cell ``[i, j]`` as shown (the row player's score in percent, or with ``payoff="score"`` its mean payoff in
        the game's own units) and its colour's place from 0 (loses) to 1 (wins)."""
        if self.payoffs is None:
            return f"{100 * self.scores[i, j]:.0f}", float(self.scores[i, j])
        v = float(self.payoffs[i, j])
        return f"{v:+.2f}", 0.5 + 0.5 * v / self._payoff_scale

    @cached_property
    def _payoff_scale(self) -> float:
        """The largest payoff in size (the colours' ends; 1 when every payoff is 0)."""
        return float(np.nanmax(np.abs(self.payoffs))) or 1.0 if self.payoffs is not None else 1.0

    @property
    def measured(self) -> npt.NDArray[np.bool_]:
        """Pairs with at least ``min_games`` games (False on the diagonal)."""
        return (self.games >= self.min_games) & ~np.eye(self.n, dtype=bool)

    def under_measured(self) -> list[tuple[int, int, int]]:
        """Pairs ``(i, j, games)``, ``i < j``, with fewer than ``min_games`` games."""
        return [(i, j, int(self.games[i, j])) for i in range(self.n) for j in range(i + 1, self.n)
                if self.games[i, j] < self.min_games]

    def fill_command(self, home: str | Path | None = None) -> str | None:
        """The ``marl league tournament`` command that plays the games the under-measured pairs miss (a round
        robin over their players plays only what each pair misses), or None if every pair is measured."""
        pairs = self.under_measured()
        if not pairs:
            return None
        involved = sorted({i for i, _, _ in pairs} | {j for _, j, _ in pairs})
        words = ["marl", "league", "tournament", *(self.players[i].policy for i in involved), "--env", self.env,
                 "--games-per-pair", str(max(self.min_games, 2))]
        for key, value in variant_options(self.variant).items():  # the games of its variant
            words += ["--env-option", f"{key}={value_text(value)}"]
        if home is not None:
            words += ["--home", str(home)]
        return shlex.join(words)

    def to_json(self, home: str | Path | None = None) -> dict[str, Any]:
        """Everything as a JSON-ready dict: no NaN or inf (a score without games is null)."""
        scores = self.scores
        names = [p.policy for p in self.players]

        def matrix(m: npt.NDArray[Any]) -> list[list[int]]:
            return [[int(v) for v in row] for row in m]

        nash: dict[str, Any] | None = None
        if self.nash is not None:
            nash = {
                "players": [names[i] for i in self.nash_players],
                "mixture": [{"policy": names[self.nash_players[k]], "weight": round(float(self.nash.mixture[k]), 6)}
                            for k in self.nash.support],
                "value": round(float(self.nash.value), 6) + 0.0,
                "over": _NASH_NOTE,
                "payoff": self.payoff,
            }
        return {
            "env": self.env,
            "variant": variant_options(self.variant),
            "run": self.run,
            "min_games": self.min_games,
            "players": [{"index": k + 1, "policy": p.policy, "kind": p.kind, "elo": round(p.elo, 1),
                         "ci_low": round(p.ci_low, 1), "ci_high": round(p.ci_high, 1)}
                        for k, p in enumerate(self.players)],
            "score": [[None if math.isnan(v) else round(float(v), 4) for v in row] for row in scores],
            "payoff": self.payoff,
            "payoffs": None if self.payoffs is None else [[None if self.games[i, j] == 0 or i == j
                                                             else round(float(v), 4) for j, v in enumerate(row)]
                                                            for i, row in enumerate(self.payoffs)],
            "games": matrix(self.games),
            "wins": matrix(self.wins),
            "draws": matrix(self.draws),
            "losses": matrix(self.losses),
            "measured": [[bool(v) for v in row] for row in self.measured],
            "nash": nash,
            "cycles": [{"players": [names[i] for i in c.players], "p_values": [float(f"{p:.3g}") for p in c.p_values]}
                       for c in self.cycles],
            "cycle_test": {"test": CYCLE_TEST, "alpha": self.edges.alpha, "tests": self.edges.tests},
            "under_measured": [{"a": names[i], "b": names[j], "games": g} for i, j, g in self.under_measured()],
            "command": self.fill_command(home),
        }


def build_matrix(
    league: League,
    env: str | None = None,
    top: int = 10,
    run: str | None = None,
    min_games: int = 8,
    alpha: float = DEFAULT_ALPHA,
    variant: str = "",
    payoff: str = "points",
    rows: list[LadderRow] | None = None,
) -> MatrixReport:
    """The score matrix of the ``top`` best-rated players of ``env`` (default: the ledger's only env), from the
    games of one ``variant`` (its key; the default variant unless given).

    ``payoff``: the Nash meta-game's units (:func:`~selfplay_cli.ratings.pairs.pair_payoffs`): ``points`` (the
    default: the result, as the ladder rates it) or ``score`` (the game's own scores, e.g. poker's chips).

    ``run``: only that run's snapshots and the env's scripted players take part. Ratings come from
    :func:`~selfplay_cli.ratings.ladder.ladder` (its defaults, normal-approximation intervals); the players are
    ordered by fitted Elo, best first. See the module docstring for the Nash mixture and the cycles.

    ``rows``: that ladder (``bootstrap=0``, of ``env`` and ``variant``) fitted already (``marl serve`` keeps it).

    Raises:
        LeagueError: ``top < 2``, ``min_games < 1``, unknown run, an env without rated games, fewer than two
            rated players.
    """
    if top < 2:
        raise LeagueError(f"--top must be at least 2, not {top}")
    if min_games < 1:
        raise LeagueError(f"--min-games must be at least 1, not {min_games}")
    if payoff not in PAYOFFS:
        raise LeagueError(f"--payoff must be one of {', '.join(PAYOFFS)}, not {payoff!r}")
    if run is not None:
        info = league.roster.get_run(run)
        if info is None:
            runs = [r.name for r in league.roster.list_runs(env)]
            raise LeagueError(f"no run named '{run}' (runs: {', '.join(runs[-10:]) if runs else 'none yet'})")
        if env is not None and env != info.env:
            raise LeagueError(f"run '{run}' trains {info.env}, not {env}")
        env = info.env
    if rows is None:
        rows = ladder(league, env, bootstrap=0, variant=variant)
    if not rows:
        raise LeagueError(f"no rated games in {env} yet: play some first (marl match / marl league tournament)")
    pool = {p.id: p for p in league.roster.players(include_removed=True) if p.id in {r.player_id for r in rows}}
    env = pool[rows[0].player_id].env if rows[0].player_id in pool else str(env)
    if run is not None:  # (a player of the same weights as one of the run's is shown under its first name)
        rows = [r for r in rows if r.kind == "bot" or (r.player_id in pool and pool[r.player_id].run == run)
                or any(c.startswith(f"{run}/") for c in r.copies)]
    ranked: list = []  # one set of weights is one player (its other names' rows are left out), and a game rated
    seen: set = set()  # per side lists a scripted player once a side: here it is one player
    for r in sorted(rows, key=lambda r: (-r.elo, r.policy)):
        if r.player_id not in seen and r.copy_of is None:
            seen.add(r.player_id)
            ranked.append(r)
    rows = ranked[:top]
    if len(rows) < 2:
        raise LeagueError(f"fewer than two rated players{f' in run {run!r} and the bots' if run else ''} in {env}")
    players = tuple(MatrixPlayer(r.policy, int(r.player_id), r.kind, r.elo, r.ci_low, r.ci_high)
                    for r in rows if r.player_id is not None)
    ids = [p.player_id for p in players]
    table = league.ledger.games(env=env, players=ids, variant=variant)
    records = pair_records(table, ids)
    games, wins, draws, losses, units = records
    measured = (games >= min_games) & ~np.eye(len(ids), dtype=bool)
    sub = measured_subgame(measured)
    nash = None
    payoffs = pair_payoffs(table, ids, payoff, records=records)
    if len(sub) >= 2:
        nash = symmetric_nash(payoffs[np.ix_(sub, sub)])
    edges, cycles = significant_three_cycles(units, measured, alpha)
    return MatrixReport(env=env, run=run, players=players, games=games, wins=wins, draws=draws, losses=losses,
                        unit_wins=units, min_games=int(min_games), nash_players=tuple(sub) if nash else (),
                        nash=nash, edges=edges, cycles=tuple(cycles), variant=variant, payoff=payoff,
                        payoffs=payoffs if payoff == "score" else None)


def write_matrix_png(report: MatrixReport, path: str | Path) -> Path:
    """The matrix as a heatmap PNG (red: the row player loses, green: it wins; grey: fewer than ``min_games``
    games), each cell with the score in percent and the game count; the Nash weights beside the names. Written
    to a temporary name, then renamed; returns the path.

    Raises:
        LeagueError: the path is not a writable ``.png`` file.
    """
    from matplotlib import colormaps

    n = report.n
    places = np.array([[report.cell(i, j)[1] if i != j else np.nan for j in range(n)] for i in range(n)])
    shown = np.where(report.measured, places, np.nan)
    side = max(4.5, 0.62 * n + 3.0)
    fig = new_figure(side + 1.6, side)
    ax = fig.add_subplot()
    cmap = colormaps["RdYlGn"].with_extremes(bad="0.85")
    im = ax.imshow(np.ma.masked_invalid(shown), cmap=cmap, vmin=0.0, vmax=1.0)
    weights = {}
    if report.nash is not None:
        weights = {report.nash_players[k]: float(w) for k, w in enumerate(report.nash.mixture)}
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            g = int(report.games[i, j])
            if report.measured[i, j]:
                shown_as, _ = report.cell(i, j)
                text = f"{shown_as}{'%' if report.payoffs is None else ''}\n{g}"
            else:
                text = f"n={g}" if g else "none"
            ax.text(j, i, text, ha="center", va="center", fontsize=7 if n > 8 else 8, color="black")
    labels = [f"{p.policy} ({p.elo:.0f})" for p in report.players]
    ylabels = [lab + (f"  Nash {100 * weights[i]:.0f}%" if weights.get(i, 0.0) > 0 else "")
               for i, lab in enumerate(labels)]
    ax.set_xticks(range(n), [str(k + 1) for k in range(n)])
    ax.set_yticks(range(n), [f"{k + 1}. {lab}" for k, lab in enumerate(ylabels)], fontsize=8)
    ax.set_xlabel("column player (numbered as the rows)")
    what = "score" if report.payoffs is None else "mean payoff (half the score margin)"
    ax.set_title(f"{report.env}: row player's {what} against column player\n(top {n} by fitted Elo; grey: fewer "
                 f"than {report.min_games} games)", fontsize=10)
    fig.colorbar(im, ax=ax, shrink=0.7, label="score" if report.payoffs is None else "payoff, scaled to the largest")
    return save_png(fig, path)

