"""What a snapshot moment's gauntlet plays, chosen from the run's history alone.

When a run takes its snapshots (one per learner), each new snapshot meets

* its own predecessor (the learner's previous snapshot): did this learner improve?
* the other learners' new snapshots (taken at the same moment): the two paddles against each other;
* the run's best snapshot so far (by fitted rating), a few older snapshots spread over the run: progress
  against the whole history, and the links that let the ladder separate players that never met;
* every scripted player of the game: fixed anchors (at the run's first moment the scripted players also meet each
  other, where no gauntlet of the league has had them meet yet).

This module holds that choice: the moment's :class:`History` (the run's snapshots before it, the scripted players, the
games of the run's earlier gauntlets), its fit (:func:`fit_history`) and the run's best so far (:func:`best_snapshot`),
the opponents (:func:`choose_opponents`), the crews a cooperative game's per-seat snapshots fly as (:func:`crews_of`)
and the moment's plan (:func:`plan_moment`). Playing and storing the matchups is :mod:`.gauntlet`'s.

In a game whose seats hold different roles (:mod:`.roles`) a snapshot meets only players it can be seated against:
a new ``adversary`` snapshot of a game of one adversary against one agent meets the run's ``agent`` snapshots (the
other learner's new one, the best of that side, older ones) and the scripted players, each on its own side; its
predecessor, of its own role, it cannot meet. The run's best is then taken per side (:attr:`History.sided`: such
a game is rated per side).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..envs import get_env
from ..league.game_table import GameTable
from ..league.store import League, PlayerRow
from ..league.variants import variant_key
from ..players.snapshots import run_options
from ..ratings.pairs import design_effect
from ..results import COOPERATIVE, Rules
from ..stats.bradley_terry import DEFAULT_PRIOR, fit_bradley_terry, pair_matrices
from ..stats.intervals import laplace_intervals
from ..stats.predict import PairModel
from .roles import RoleBook

ALL_OLDER = 1_000_000_000
"""``older`` that takes every earlier snapshot of the run (``marl train --opponents nash``: its payoff matrix whole)."""


@dataclass(frozen=True)
class History:
    """All that a snapshot moment's gauntlet may know: the run's snapshots taken before the moment (oldest first),
    the game's scripted players, and the games of the run's earlier gauntlets between them.

    Nothing else reaches the gauntlet's choices (its opponents, the run's best so far), so what it plays depends on
    the run's seed and the order of its snapshots alone: not on a worker that fell behind while later snapshots were
    taken, not on a user's matches or other runs filed meanwhile."""

    snapshots: list[PlayerRow]
    bots: list[PlayerRow]
    table: GameTable
    variant: str = ""  # the game's variant the run plays (its snapshots' options): its games are filed there
    sided: bool = False  # a two-sides game whose sides differ: ratings are fitted per side (GameTable.by_side)


def run_history(league: League, new: Sequence[PlayerRow], *, including: bool = False) -> History:
    """The :class:`History` of the moment whose snapshots are ``new`` (all of one run and game): what came before
    it, or with ``including`` what stands once its gauntlet is played (its own snapshots too)."""
    env, run = new[0].env, new[0].run
    # ids grow in registration order: the moment's own are its newest
    last = max(p.id for p in new) if including else min(p.id for p in new) - 1
    snapshots = [p for p in league.roster.players(env=env, kind="snapshot") if p.run == run and p.id <= last
                 and p.unusable is None]  # (a row that cannot be read is never played: said once)
    bots = league.roster.players(env=env, kind="bot")
    gauntlets = [mid for mid, params in league.ledger.match_params(env, kind="eval").items() if params.get("gauntlet")]
    variant = variant_key(env, run_options(league, run or ""))  # the options the run plays: its ladder
    table = league.ledger.games(env=env, players=[p.id for p in snapshots + bots], variant=variant, pooled=False)
    return History(snapshots, bots, table.select(np.isin(table.match_id, gauntlets)), variant,
                   sided=Rules.of(get_env(env)).sides_differ)


def record_between(table: GameTable, a: int, b: int) -> tuple[int, int, int]:
    """A's wins, draws and losses against B in ``table``."""
    both = ((table.player_a == a) & (table.player_b == b)) | ((table.player_a == b) & (table.player_b == a))
    pts = np.where(table.player_a[both] == a, table.score_a[both], 1.0 - table.score_a[both])
    return int(np.sum(pts > 0.5)), int(np.sum(pts == 0.5)), int(np.sum(pts < 0.5))


def choose_opponents(league: League, new: Sequence[PlayerRow], older: int = 2,
                     best: PlayerRow | Sequence[PlayerRow] | None = None, history: History | None = None,
                     meets: Callable[[PlayerRow, PlayerRow], bool] | None = None,
                     ) -> list[tuple[PlayerRow, PlayerRow]]:
    """The matchups of a snapshot moment: ``(new snapshot, opponent)``, each unordered pair once.

    ``new`` are the snapshots just taken (one per learner, all of one run and game); ``best`` the run's best
    snapshot before them (by fitted rating), if known, or the best of each side of a game rated per side. Opponents
    come from the moment's :class:`History` (the run's snapshots taken before it, the scripted players). Older
    snapshots are chosen evenly spread over the run's history (oldest first), skipping the ones already met; where
    ``older`` takes every earlier snapshot a new one may meet, it meets them all in the run's order and ``best`` (one
    of them) is not used (:func:`stands_alone`).
    ``meets(a, b)``: whether two players can play each other (a game whose seats hold different roles,
    :class:`~selfplay_cli.evaluation.roles.RoleBook`); a snapshot's opponents are chosen among those it meets.
    """
    if not new:
        return []
    history = history or run_history(league, new)
    by_id = {p.id: p for p in history.snapshots}
    bests = [best] if isinstance(best, PlayerRow) else list(best or [])
    can = meets or (lambda a, b: True)
    pairs: list[tuple[PlayerRow, PlayerRow]] = []
    seen: set[frozenset[int]] = set()

    def add(a: PlayerRow, b: PlayerRow | None) -> None:
        if b is None or a.id == b.id or frozenset((a.id, b.id)) in seen or not can(a, b):
            return
        seen.add(frozenset((a.id, b.id)))
        pairs.append((a, b))

    for s in new:
        chosen: list[PlayerRow | None] = [by_id.get(s.parent_id) if s.parent_id is not None else None]
        chosen += [o for o in new if o.id != s.id]
        pool = _earlier(history.snapshots, new, s, can)
        if older >= len(pool):  # every earlier snapshot, the best among them: in the run's order, chosen by nothing
            chosen += pool
        else:
            chosen += [b for b in bests if b.id in by_id and can(s, b)][:1]
            taken = {c.id for c in chosen if c is not None}
            rest = [p for p in pool if p.id not in taken]
            if older and rest:
                picks = np.unique(np.linspace(0, len(rest) - 1, num=min(older, len(rest))).round().astype(int))
                chosen += [rest[i] for i in picks.tolist()]
        chosen += history.bots
        for opp in chosen:
            add(s, opp)
    return pairs


def _earlier(snapshots: Sequence[PlayerRow], new: Sequence[PlayerRow], s: PlayerRow,
             can: Callable[[PlayerRow, PlayerRow], bool]) -> list[PlayerRow]:
    """The run's earlier ``snapshots`` that new snapshot ``s`` may meet besides its predecessor (oldest first): those
    its moment's older opponents (and the run's best) are chosen from."""
    mine = {o.id for o in new}
    return [p for p in snapshots if p.id != s.parent_id and p.id not in mine and can(s, p)]


def stands_alone(league: League, snapshot_ids: Sequence[int], older: int) -> bool:
    """Whether the gauntlet of the moment whose snapshots are ``snapshot_ids`` (``older``: as :func:`plan_moment`
    takes it) chooses nothing from the run's earlier gauntlets: each of its snapshots meets every earlier snapshot it
    may meet (a run's final moment, :data:`~.gauntlet_jobs.FINAL_OLDER`, while the run has no more), so no best so far
    is picked. Its plan is then the same before the moments ahead of it are played as after them, and it may be
    played beside them."""
    new = [league.roster.get_player(int(i)) for i in snapshot_ids]
    if not new:
        return True
    env, run = new[0].env, new[0].run
    first = min(p.id for p in new)
    snapshots = [p for p in league.roster.players(env=env, kind="snapshot") if p.run == run and p.id < first
                 and p.unusable is None]
    book = RoleBook(league, env)
    can = book.meets if book.differ and book.rules.kind != COOPERATIVE else (lambda a, b: True)
    return all(older >= len(_earlier(snapshots, new, s, can)) for s in new)


@dataclass(frozen=True)
class HistoryFit:
    """The history's players fitted from its games: Bradley-Terry under the ladder's prior, anchored at the game's
    anchor bot where it played, and its pairs as the ladder judges them (:class:`~selfplay_cli.stats.predict.
    PairModel`: the ratings' difference, its uncertainty, the pairs' spread and their own games)."""

    index: dict[int, int]  # player id -> position in the arrays
    ratings: np.ndarray
    flags: list[str | None]
    pairs: PairModel

    def rating(self, pid: int) -> float:
        return float(self.ratings[self.index[pid]])

    def linked(self, pid: int) -> bool:
        """Whether the player's rating is an estimate linked to the anchor."""
        return pid in self.index and self.flags[self.index[pid]] is None

    def separated(self, top: int, other: int, confidence: float) -> bool:
        """Whether ``top`` is above ``other`` beyond doubt: the ``confidence`` interval of their difference lies above
        0, as the ladder would say it."""
        return bool(self.above([top, other], confidence)[0, 1])

    def doubt(self, ids: Sequence[int]) -> np.ndarray:
        """``[a, b]``: the chance player ``ids[a]`` is not above ``ids[b]`` (all linked players; 1 on the diagonal)."""
        out = self.pairs.below([self.index[i] for i in ids])
        np.fill_diagonal(out, 1.0)
        return out

    def above(self, ids: Sequence[int], confidence: float) -> np.ndarray:
        """``[a, b]``: player ``ids[a]`` is above ``ids[b]`` beyond doubt (all linked players)."""
        return self.doubt(ids) < 0.5 * (1.0 - confidence)


def fit_history(history: History, anchor: str = "random") -> HistoryFit | None:
    """The :class:`HistoryFit` of the history's games (None without games). In a game rated per side
    (:attr:`History.sided`) each player is fitted as the side it played (:meth:`GameTable.by_side`: a scripted
    player is one player a side); a snapshot keeps its id, so its rating and its differences with the snapshots of
    its side read as ever, and only those compare."""
    table = history.table
    if not len(table):
        return None
    sides = None
    if history.sided:
        table, sides = table.by_side()
    ids, a, b = table.indexed()
    index = {int(pid): i for i, pid in enumerate(ids.tolist())}
    anchor_ids = {p.id for p in history.bots if p.name == anchor}
    anchors = [i for key, i in index.items() if (sides[key][0] if sides else key) in anchor_ids]
    k = anchors[0] if anchors else 0
    fit = fit_bradley_terry(a, b, table.score_a, ids.size, anchor=k, prior_games=DEFAULT_PRIOR)
    _, _, diff_sd = laplace_intervals(a, b, ids.size, fit.ratings, k, 0.95, DEFAULT_PRIOR)
    points, games = pair_matrices(a, b, table.score_a, ids.size)
    pairs = PairModel(fit.ratings, diff_sd, [f is None for f in fit.flags], points, games, DEFAULT_PRIOR, anchor=k,
                      deff=design_effect(table))
    return HistoryFit(index, fit.ratings, list(fit.flags), pairs)


def best_snapshot(history: History, anchor: str = "random",
                  among: Callable[[PlayerRow], bool] | None = None) -> PlayerRow | None:
    """The highest-rated snapshot of the moment's history (of those ``among`` keeps: the snapshots of one side of
    a game rated per side), fitted from the run's earlier gauntlets alone (its :func:`fit_history`); players the games
    do not link to the ``anchor`` bot count only when none is linked. Ties go to the older snapshot."""
    fit = fit_history(history, anchor)
    rated = [p for p in history.snapshots if fit is not None and p.id in fit.index and (among is None or among(p))]
    if not rated:
        return None
    linked = [p for p in rated if fit.linked(p.id)] or rated
    return max(linked, key=lambda p: (fit.rating(p.id), -p.id))


@dataclass(frozen=True)
class Moment:
    """What one snapshot moment's gauntlet plays (:func:`plan_moment`): its pairs (a cooperative game's crews by
    their first member), the crews by that member's id and the unit's key."""

    pairs: list[tuple[PlayerRow, PlayerRow]]
    crews: dict[int, tuple[PlayerRow, ...]]
    key: str


def plan_moment(league: League, snapshot_ids: Sequence[int], older: int) -> Moment | None:
    """The gauntlet of one snapshot moment (``older``: earlier snapshots it meets besides the predecessor and the
    best), chosen from the moment's :class:`History` alone, so planned again it is the same: the run's best so
    far, the opponents, the pairs (those whose players, or copies of them, already met in another gauntlet left
    out). None without snapshots."""
    new = [league.roster.get_player(int(i)) for i in snapshot_ids]
    if not new:
        return None
    history = run_history(league, new)
    anchor = get_env(new[0].env).anchor
    book = RoleBook(league, new[0].env)
    # a cooperative game's per-seat snapshots fly as crews (below), each member on its own seat: paired as crews
    meets = book.meets if book.differ and book.rules.kind != COOPERATIVE else None
    best: PlayerRow | list[PlayerRow] | None = None
    if any(older < len(_earlier(history.snapshots, new, s, meets or (lambda a, b: True))) for s in new):
        if meets is not None:  # the best of each role the moment's snapshots can meet
            bests = [best_snapshot(history, anchor, among=lambda p, s=s: book.meets(s, p)) for s in new]
            best = [b for b in bests if b is not None]
        else:
            best = best_snapshot(history, anchor)
    pairs = choose_opponents(league, new, older=older, best=best, history=history, meets=meets)
    crews = crews_of(league, [p for pair in pairs for p in pair])
    if crews:  # a cooperative game's per-lander snapshots fly as their moment's team: one matchup per two teams
        lead = {pid: crew[0] for pid, crew in crews.items()}
        unique: dict[frozenset[int], tuple[PlayerRow, PlayerRow]] = {}
        for a, b in pairs:
            a, b = lead.get(a.id, a), lead.get(b.id, b)
            if a.id != b.id:
                unique.setdefault(frozenset((a.id, b.id)), (a, b))
        pairs = list(unique.values())
    if not history.snapshots:  # the run's first moment: its scripted players meet each other once, so what the ladder
        # says of them rests on their own games too (a league's earlier gauntlets may have played them already)
        pairs += [(x, y) for k, x in enumerate(history.bots) for y in history.bots[k + 1:]
                  if meets is None or meets(x, y)]
    key = f"gauntlet/{min(p.id for p in new)}"
    mine = {match_id for match_id, _ in league.ledger.keyed_matches(f"{key}/").values()}  # (this unit's, played before)
    pairs = [(a, b) for a, b in pairs if not _gauntlet_games(league, a, b, history.variant, ignore=mine)]
    return Moment(pairs, {m.id: crew for crew in crews.values() for m in crew[:1]}, key)


def crews_of(league: League, rows: Sequence[PlayerRow]) -> dict[int, tuple[PlayerRow, ...]]:
    """Cooperative games: the team each per-seat learner's snapshot flies with, its moment's members in seat order
    (``s6M-lander_0``, ``s6M-lander_1``: :func:`~selfplay_cli.ratings.names.teammates`), by player id; snapshots of
    one shared network, bots and the players of other games are not in it. A team flies together, as the run
    trained it: its members alone would each fly every lander, seats it never learned."""
    from ..ratings.names import teammates

    if not rows:
        return {}
    spec = get_env(rows[0].env)
    if spec.kind != COOPERATIVE:
        return {}
    out: dict[int, tuple[PlayerRow, ...]] = {}
    for row in rows:
        if row.kind != "snapshot" or row.id in out:
            continue
        team = teammates(league, row, spec.agents)
        if team is not None and len({m.id for m in team}) > 1:
            for m in team:
                out[m.id] = tuple(team)
    return out


def _gauntlet_games(league: League, a: PlayerRow, b: PlayerRow, variant: str = "",
                    ignore: set[int] | frozenset[int] = frozenset()) -> bool:
    """Whether the ledger holds gauntlet games between ``a`` and ``b``, or copies of them (in ``variant``), in
    matches other than ``ignore``."""
    table = league.ledger.games(a.env, players=[a.id, b.id], variant=variant)
    return any(league.ledger.match_info(int(m))[1].get("gauntlet") for m in np.unique(table.match_id).tolist()
               if int(m) not in ignore)
