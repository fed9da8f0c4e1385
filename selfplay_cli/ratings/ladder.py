"""Ladders: Bradley-Terry ratings of a whole population, derived from the game ledger (or, through
:mod:`selfplay_cli.ratings.results_csv`, from a results file).

Nothing here is stored: every ladder is refitted from the games, so it always agrees with the ledger.

* :func:`~selfplay_cli.ratings.fit.fit_table` is the generic core (:mod:`selfplay_cli.ratings.fit`: the prior, the
  confidence intervals, the order, ranks, tiers and margins): Bradley-Terry ratings anchored at one player
  (:func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`), MAP under BayesElo's prior of
  ``prior`` virtual draws (default :data:`~selfplay_cli.stats.bradley_terry.DEFAULT_PRIOR` = 2, as BayesElo;
  ``prior=0`` is the plain maximum-likelihood fit), a confidence interval per player and ranks.
* :func:`ladder` (this module) fits the pairwise results of one env of the league
  (:meth:`~selfplay_cli.league.ledger.Ledger.games`: a two-sides game, a cooperative comparison of two episodes on one
  seed, each two players of a free-for-all game), and adds what the league knows: each snapshot's run, the best
  snapshot of each run, every player's record against the env's scripted players, and in cooperative games its mean
  team return.
* :func:`~selfplay_cli.ratings.verdicts.select_rows` keeps one run's snapshots (plus the scripted players) and / or
  the first rows, without changing any rank; :func:`~selfplay_cli.ratings.verdicts.verdict_lines` says who is best,
  and by how much, under the table.

The rows (:class:`~selfplay_cli.ratings.ladder_rows.LadderRow`) are :mod:`selfplay_cli.ratings.ladder_rows`'. Two
players' record and the games a tournament still needs are in :mod:`selfplay_cli.ratings.pairs`.

The best snapshot of each run carries its margin over the run's next best (another name of its own weights, or a
teammate of a cooperative game's team, is not its rival) and the run's snapshots it is not separated from (``tied``):
the ladder says who is best, by how much, and when it cannot tell.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.league.derivation import rules_for_env
from selfplay_cli.league.game_table import GameTable
from selfplay_cli.league.games import declaration
from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.league.variants import variant_options
from selfplay_cli.ratings.fit import Fitted, fit_rows, order_group
from selfplay_cli.ratings.ladder_rows import BotRecord, LadderRow
from selfplay_cli.ratings.pairs import design_effect
from selfplay_cli.results import COOPERATIVE
from selfplay_cli.stats.bradley_terry import DEFAULT_PRIOR
from selfplay_cli.stats.intervals import DEFAULT_BOOTSTRAP

__all__ = [
    "DEFAULT_BOOTSTRAP",
    "DEFAULT_PRIOR",
    "ladder",
    "pick_env",
    "shown_exploitability",
]

def _envs_in_order(league: League) -> list[str]:
    """Envs that have rated results in the ledger (in any variant), in order of their first one."""
    table = league.ledger.games(variant=None)
    if len(table) == 0:
        return []
    env_of = {p.id: p.env for p in league.roster.players(include_removed=True)}
    envs: dict[str, None] = {}
    for pid in table.player_a.tolist():
        e = env_of.get(int(pid))
        if e is not None:
            envs.setdefault(e, None)
    return list(envs)


def pick_env(league: League, env: str | None) -> str:
    """``env``, or the ledger's only env when None (LeagueError when it has none or several)."""
    if env is not None:
        return env
    envs = _envs_in_order(league)
    if not envs:
        raise LeagueError("the league has no rated games yet: train a run (marl train GAME) or play some (marl match "
                          "A B --env GAME, marl league tournament)")
    if len(envs) > 1:
        raise LeagueError(f"several envs in the league ({', '.join(envs)}): pass --env")
    return envs[0]


def declared_anchor(env: str) -> str:
    """The scripted player a game anchors its ratings at (its declaration's ``anchor``: the lander's heuristic),
    ``random`` for a game this process does not know."""
    spec = declaration(env)
    return "random" if spec is None else spec.anchor


def default_anchor(population: list[PlayerRow], games: dict[int, int], preferred: str = "random") -> PlayerRow:
    """The game's anchor bot (``preferred``) if it played, else ``random``, else the first bot (by id) that played,
    else the most active player."""
    bots = [p for p in population if p.is_bot]
    for name in dict.fromkeys((preferred, "random")):
        for p in bots:
            if p.name == name:
                return p
    if bots:
        return bots[0]
    live = [p for p in population if not p.removed] or population
    return max(live, key=lambda p: (games[p.id], -p.id))


def _find_anchor(population: list[PlayerRow], anchor: PlayerRow | int | str, env: str) -> PlayerRow:
    """The anchor among the players with games: a player row, an id (``17``, ``"#17"``) or a full name."""
    if isinstance(anchor, PlayerRow):
        pid: int | None = anchor.id
        label = anchor.full_name
    elif isinstance(anchor, int | np.integer):
        pid, label = int(anchor), f"#{int(anchor)}"
    else:
        label = str(anchor).strip()
        digits = label[1:] if label.startswith("#") else label
        pid = int(digits) if digits.isdigit() else None
        if pid is None:
            named = [p for p in population if p.full_name == label]
            if named:
                return named[0]
    for p in population:
        if p.id == pid:
            return p
    shown = ", ".join(p.full_name for p in population[:12]) + (", ..." if len(population) > 12 else "")
    raise LeagueError(f"anchor '{label}' has no games in {env}; players with games: {shown}")


def _bot_records(ids: npt.NDArray[np.int64], a: npt.NDArray[np.int64], b: npt.NDArray[np.int64],
                 score_a: npt.NDArray[np.float64], bots: list[PlayerRow]) -> dict[int, tuple[BotRecord, ...]]:
    """Every player's games and points against each bot (draw = 1/2), keyed by player id."""
    n = ids.size
    games = np.zeros((n, n))
    points = np.zeros((n, n))
    np.add.at(games, (a, b), 1.0)
    np.add.at(games, (b, a), 1.0)
    np.add.at(points, (a, b), score_a)
    np.add.at(points, (b, a), 1.0 - score_a)
    index = {int(pid): i for i, pid in enumerate(ids.tolist())}
    out = {}
    for pid, i in index.items():
        recs = []
        for bot in bots:
            j = index.get(bot.id)
            g = 0 if j is None else int(round(games[i, j]))
            recs.append(BotRecord(bot=bot.name, games=g, points=0.0 if j is None else float(points[i, j])))
        out[pid] = tuple(recs)
    return out


def _mark_best(rows: list[LadderRow], removed: set[int], fitted: Fitted, teams: bool = False) -> list[LadderRow]:
    """``best=True`` on each run's highest-rated live snapshot; players comparable with the anchor first (a
    ``disconnected`` or ``unrated`` rating only counts when no snapshot of the run has a comparable one). The best
    carries its margin over the run's next best and the run's snapshots it is not separated from. Neither counts
    another name of the best's own weights, nor, where ``teams`` (a cooperative game, whose per-seat snapshots of
    one moment fly as one team), the best's teammates or their copies: the best is not compared with itself."""
    by_run: dict[str, list[LadderRow]] = defaultdict(list)
    for r in rows:  # in the ladder's order: the first comparable one of a run is its best
        if r.kind == "snapshot" and r.run is not None and r.player_id not in removed:
            by_run[r.run].append(r)
    index = {name: i for i, name in enumerate(fitted.names)}
    by_name = {r.policy: r for r in rows}

    def moment(r: LadderRow) -> int:
        """The step of the weights' first name (a copy's teammates are its original's)."""
        first = by_name.get(r.copy_of) if r.copy_of else None
        return (first or r).step

    marked: dict[str, LadderRow] = {}
    for members in by_run.values():
        comparable = [r for r in members if not order_group(r.flag)] or members
        best = comparable[0]
        i = index[best.copy_of or best.policy]
        rest = [r for r in comparable[1:] if index[r.copy_of or r.policy] != i
                and not (teams and moment(r) == moment(best))]
        margin = replace(fitted.margin(i, index[rest[0].copy_of or rest[0].policy]), over=rest[0].policy) \
            if rest else None
        sure = fitted.above([i] + [index[r.copy_of or r.policy] for r in rest]) if rest else np.zeros((1, 1), bool)
        tied = tuple(r.policy for k, r in enumerate(rest, start=1) if not sure[0, k] and not sure[k, 0])
        marked[best.policy] = replace(best, best=True, best_margin=margin, tied=tied)
    return [marked.get(r.policy, r) for r in rows]


def ladder(
    league: League,
    env: str | None = None,
    anchor: PlayerRow | int | str | None = None,
    anchor_rating: float = 1000.0,
    bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    include_removed: bool = False,
    *,
    prior: float = DEFAULT_PRIOR,
    variant: str = "",
) -> list[LadderRow]:
    """The ladder of ``env``: a :func:`~selfplay_cli.ratings.fit.fit_table` over all pairwise results of that env in
    the ledger, in one ``variant`` (its key, :func:`~selfplay_cli.league.variants.variant_key`; the default variant
    unless given).

    ``env=None`` uses the ledger's only env (LeagueError if it has several, or no games at all); an env
    without games gives an empty list. Only players with games appear. ``prior``: BayesElo's prior in virtual
    draws (default :data:`DEFAULT_PRIOR` = 2, BayesElo's default; 0 = maximum likelihood).

    The default anchor is the env's ``random`` bot if it played, else the first bot (lowest id) that played,
    else the (non-removed) player with the most games. ``anchor`` may be a player row (e.g. from
    :func:`selfplay_cli.ratings.names.resolve`, which understands every name a user types), a player id
    (``17`` or ``"#17"``) or a full name as shown in the ladder (``"r1/ep90"``, ``"cpu"``); the anchor must
    have games in the env. Removed snapshots are fitted (their games count) but left out of the rows and the
    ranks unless ``include_removed``.

    Each row also carries its ``run``, ``best`` (the best snapshot of its run) and ``vs`` (its record
    against each scripted player of the env: ``league.roster.players(env=env, kind="bot")``) and, in a cooperative game,
    ``mean_return`` (its mean team return over its episodes).
    """
    env = pick_env(league, env)
    table = league.ledger.games(env=env, variant=variant)
    if len(table) == 0:
        return []
    rules = rules_for_env(env, variant_options(variant))
    if rules.sides_differ:
        return _ladder_by_side(league, env, table, rules.side_roles(), anchor, anchor_rating, bootstrap, confidence,
                               seed, include_removed, prior, variant)
    ids, a, b = table.indexed()
    known = {p.id: p for p in league.roster.players(env=env, include_removed=True)}
    population = [known[int(i)] if int(i) in known else league.roster.get_player(int(i)) for i in ids.tolist()]
    games = dict(zip(ids.tolist(), (np.bincount(a, minlength=ids.size) + np.bincount(b, minlength=ids.size))
                     .tolist(), strict=True))
    anchor_player = (default_anchor(population, games, declared_anchor(env)) if anchor is None
                     else _find_anchor(population, anchor, env))
    removed = {p.id for p in population if p.removed}
    hidden = set() if include_removed else {p.full_name for p in population if p.removed}
    if anchor_player.full_name in hidden:
        hidden.discard(anchor_player.full_name)  # an explicitly chosen removed anchor stays visible
    names = [p.full_name for p in population]
    rows, fitted = fit_rows(
        names, a, b, table.score_a, anchor_player.full_name, anchor_rating, bootstrap, confidence, seed,
        {p.full_name: p.kind for p in population}, {p.full_name: p.step for p in population if not p.is_bot},
        {p.full_name: p.id for p in population}, prior=prior, hidden=hidden, deff=design_effect(table),
    )
    bots = league.roster.players(env=env, kind="bot", include_removed=True)
    records = _bot_records(ids, a, b, table.score_a, bots)
    run_of = {p.id: p.run for p in population if not p.is_bot}
    returns = league.ledger.mean_returns(env, variant=variant)
    rows = [replace(r, run=run_of.get(int(r.player_id)), vs=records.get(int(r.player_id), ()),
                    mean_return=returns[int(r.player_id)][1] if int(r.player_id) in returns else None)
            if r.player_id is not None else r for r in rows]
    rows = _with_copies(league, env, rows, include_removed)
    teams = rules.kind == COOPERATIVE
    return _with_league_marks(_mark_best(rows, removed, fitted, teams), known | {p.id: p for p in population})


def shown_exploitability(meta: dict[str, Any]) -> dict[str, Any] | None:
    """The exploitability a player's row shows, from its ``meta["exploitability"]`` (filed by
    :meth:`~selfplay_cli.league.roster.Roster.set_exploitability`): the exact figure where there is one (it says how
    beatable the player is), else the lower bound (a trained best response's return: the player is at least that
    beatable), as filed with its ``kind``; None where nothing was measured (or what is filed is not a number)."""
    book = meta.get("exploitability") or {}
    if not isinstance(book, dict):
        return None
    for kind in ("exact", "lower_bound"):
        record = book.get(kind)
        # (a row is another member's input: a figure that is not a finite number is no figure)
        if isinstance(record, dict) and _number(record.get("value")):
            return {**{k: v for k, v in record.items() if k not in ("low", "high") or _number(v)}, "kind": kind}
    return None


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _with_league_marks(rows: list[LadderRow], players: dict[int, PlayerRow]) -> list[LadderRow]:
    """Each row's league role and filed exploitability, read from its player's meta (a copy's from its own row)."""
    out = []
    for r in rows:
        p = players.get(r.player_id) if r.player_id is not None else None
        meta = p.meta if p is not None else {}
        role = meta.get("league_role")
        out.append(replace(r, league_role=str(role) if role else None, exploitability=shown_exploitability(meta)))
    return out


def _with_copies(league: League, env: str, rows: list[LadderRow], include_removed: bool) -> list[LadderRow]:
    """Every other name of a rated player's weights (a run repeated with its seed, in the same league), as a row of
    its own right under the player's: the same rating, rank and tier, ``copy_of`` the player; the player's row
    lists them in ``copies``."""
    same = league.ledger.same_weights(env)
    if not same:
        return rows
    by_lead: dict[int, list[PlayerRow]] = defaultdict(list)
    known = {p.id: p for p in league.roster.players(env=env, kind="snapshot", include_removed=True)}
    for pid, lead in same.items():
        p = known[pid]
        if include_removed or not p.removed:
            by_lead[lead].append(p)
    out = []
    for r in rows:
        copies = by_lead.get(r.player_id, []) if r.player_id is not None else []
        out.append(replace(r, copies=tuple(p.full_name for p in copies)) if copies else r)
        out += [replace(r, policy=p.full_name, player_id=p.id, run=p.run, step=p.step, anchor=False,
                        copy_of=r.policy, copies=()) for p in copies]
    return out


def _ladder_by_side(league: League, env: str, table: GameTable, labels: tuple[str, ...],
                    anchor: PlayerRow | int | str | None, anchor_rating: float, bootstrap: int, confidence: float,
                    seed: int, include_removed: bool, prior: float, variant: str = "") -> list[LadderRow]:
    """The ladder of a two-sides game whose sides differ (``labels``: each side's role): one table per side.

    A player of one side meets only the other side's players, so its rating compares only with its own side's:
    each player is fitted as the side it played (:meth:`GameTable.by_side`; a scripted player, which plays either
    side, is one player a side), and each side's table is anchored at its own anchor (the anchor bot playing that
    side, at ``anchor_rating``), its rows carrying ``side``. Everything else reads as in :func:`ladder`, per side:
    ranks, tiers, margins, each run's best and the records against the scripted players (on the other side)."""
    sided, sides = table.by_side()
    keys, a, b = sided.indexed()
    known = {p.id: p for p in league.roster.players(env=env, include_removed=True)}
    row_of = {int(k): known.get(sides[int(k)][0]) or league.roster.get_player(sides[int(k)][0]) for k in keys.tolist()}
    side_of = {int(k): sides[int(k)][1] for k in keys.tolist()}
    counts = np.bincount(a, minlength=keys.size) + np.bincount(b, minlength=keys.size)
    bots = league.roster.players(env=env, kind="bot", include_removed=True)
    returns = league.ledger.mean_returns(env, variant=variant)
    chosen = None if anchor is None else _find_anchor(list({p.id: p for p in row_of.values()}.values()), anchor, env)
    out: list[LadderRow] = []
    for side, label in enumerate(labels):
        mine = [k for k in row_of if side_of[k] == side]
        if not mine:
            continue
        names = [row_of[k].full_name if side_of[k] == side else f"{row_of[k].full_name} ({labels[side_of[k]]})"
                 for k in keys.tolist()]
        population = [row_of[k] for k in mine]
        games = {row_of[k].id: int(counts[i]) for i, k in enumerate(keys.tolist()) if side_of[k] == side}
        lead = (chosen if chosen is not None and chosen.id in games
                else default_anchor(population, games, declared_anchor(env)))
        removed = {p.id for p in population if p.removed}
        hidden = {n for n, k in zip(names, keys.tolist(), strict=True) if side_of[k] != side}
        if not include_removed:
            hidden |= {p.full_name for p in population if p.removed and p.id != lead.id}
        rows, fitted = fit_rows(
            names, a, b, sided.score_a, lead.full_name, anchor_rating, bootstrap, confidence, seed,
            {p.full_name: p.kind for p in population}, {p.full_name: p.step for p in population if not p.is_bot},
            {p.full_name: p.id for p in population}, prior=prior, hidden=hidden, deff=design_effect(table),
        )
        key_of = {row_of[k].id: k for k in mine}
        # each row's record against the scripted players, as they played the other side
        other = {row_of[k].id: k for k in row_of if side_of[k] != side}
        theirs = [replace(bot, id=other.get(bot.id, -(2 * bot.id + 1 - side) - 1)) for bot in bots]  # (or no games)
        records = _bot_records(keys, a, b, sided.score_a, theirs)
        rows = [replace(r, run=row_of[key_of[int(r.player_id)]].run, side=label,
                        vs=records.get(key_of[int(r.player_id)], ()),
                        mean_return=returns[int(r.player_id)][1] if int(r.player_id) in returns else None)
                for r in rows]
        out += _mark_best(rows, removed, fitted)
    return _with_league_marks(out, known | {p.id: p for p in row_of.values()})
