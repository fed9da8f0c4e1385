"""The end of a run: its best candidates meet until the best is separated, or the ladder can say they are tied.

A gauntlet gives every snapshot a handful of games against each opponent: enough to rate a run's history, not to
name its best. Two snapshots of the same moment, or of neighbouring ones, commonly stand within each other's
intervals after it, and the one a ladder marks "best" is then the prior's choice; a 200-game match afterwards may
well reverse it. So after the run's final gauntlet, the playoff:

1. fits the run's snapshots from the run's own rating games (its gauntlets and this playoff, nothing else: the
   history of the moment after the last, so the playoff repeats with the run's seed);
2. takes the top snapshot (as the ladder orders them: by rank, then Elo) and every snapshot of the run it is not
   separated from (the confidence interval of their difference, as the ladder judges the pair, covers 0), the closest
   ``rivals`` of them;
3. plays the top against each rival one round of ``round_games`` games (seat-swapped pairs, or the game kind's
   rounds), all of the round's pairs in one batch, and goes back to 1, until the top is separated from every
   snapshot of the run, or every pair of top and rival has ``max_games`` games between them.

Each round is a unit of work keyed by the run's final moment and the round's first seed: a playoff played again
(its worker killed, the run resumed) skips the rounds it stored, and plays the one it was cut in again from the
history that round saw, storing only what is missing (:func:`~selfplay_cli.evaluation.gauntlet.play_gauntlet`).

A game whose sides differ (a hunter against a runner) is rated per side: each side has its top and its rivals,
and two snapshots of one side cannot meet, so each of them plays the other side's best instead (their difference
is measured through that common opponent), until the top is separated or the rival has ``max_games`` games
against it.

The games are stored like the gauntlet's (kind ``eval``, flagged ``playoff``): they count in every rating, and the
ladder shows the best with its margin over the next, or the snapshots it is tied with.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..envs import get_env
from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..play.schedule import round_size
from ..results import COOPERATIVE, Rules
from ..stats.ranks import claims_order
from .gauntlet import GauntletConfig, play_gauntlet
from .gauntlet_plan import History, crews_of, fit_history, record_between, run_history
from .roles import RoleBook

__all__ = ["PlayoffConfig", "playoff"]


@dataclass(frozen=True)
class PlayoffConfig:
    """How far the playoff goes (games are counted between the top and one rival)."""

    max_games: int = 100  # results a pair of top and rival may reach (games; a cooperative game's comparisons)
    round_games: int = 50  # results a pair adds in one round (a round lasts its longest game whatever its games:
    # in pong between two top snapshots nearly every game runs to the step limit, so few big rounds wait least)
    rivals: int = 3  # rivals at most in a round, the closest to the top first
    confidence: float = 0.95  # the level at which the best must be separated
    max_rounds: int = 20  # a bound on the rounds whatever the top does (it may change between rounds)

    def __post_init__(self) -> None:
        if self.max_games < 0 or self.round_games < 2 or self.rivals < 1 or self.max_rounds < 1:
            raise MarlError("a playoff needs max_games >= 0, round_games >= 2, rivals >= 1 and max_rounds >= 1")
        if not 0.5 < self.confidence < 1.0:
            raise MarlError(f"the playoff's confidence must lie in (0.5, 1), not {self.confidence}")


def playoff(league: League, final_ids: Sequence[int], *, first_seed: int, config: PlayoffConfig | None = None,
            device: str = "cpu", on_games: Callable[[int], None] | None = None) -> int:
    """Play the playoff of the run whose final snapshots are ``final_ids`` (see the module docstring); returns the
    number of games played. Seeds start at ``first_seed``, one range per round."""
    cfg = config or PlayoffConfig()
    final = [league.roster.get_player(int(i)) for i in final_ids]
    if not final or cfg.max_games == 0:
        return 0
    spec = get_env(final[0].env)
    anchor = spec.anchor
    rules = Rules.of(spec)
    # results a round gives: one comparison, one game of each on its own side, or a seat-swapped pair
    per_round = 1 if rules.kind == COOPERATIVE or rules.sides_differ else round_size(rules, 2)
    book = RoleBook(league, final[0].env)
    played, seed = 0, first_seed
    key = f"playoff/{min(p.id for p in final)}"  # a round's unit of work: f"{key}/{its first seed}"
    # one set of weights is one player: a final snapshot that holds an earlier one's weights (a budget that ended
    # before the next update) is that player, never its rival
    same = league.ledger.same_weights(final[0].env)
    for _ in range(cfg.max_rounds):
        history = _before(league, run_history(league, final, including=True), key, seed)
        fit = fit_history(history, anchor)
        if fit is None:
            return played
        crews = crews_of(league, history.snapshots)
        lead = {pid: crew[0] for pid, crew in crews.items()}  # a team of per-seat snapshots plays as one
        by_weights: dict[int, PlayerRow] = {}
        for p in history.snapshots:
            if not p.removed and fit.linked(p.id):
                q = lead.get(p.id, p)
                by_weights.setdefault(same.get(q.id, q.id), q)
        players = list(by_weights.values())
        if len(players) < 2:
            return played
        players.sort(key=lambda p: (-fit.rating(p.id), p.id))
        now: dict[frozenset[int], tuple[PlayerRow, PlayerRow, int]] = {}  # this round's pairs, with their rounds
        for group in _comparable(book, players, history.sided):
            sure = fit.above([p.id for p in group], cfg.confidence)  # as the ladder orders them (claims_order)
            order, _, _ = claims_order(sure, [fit.rating(p.id) for p in group])
            group = [group[k] for k in order]
            top, taken = group[0], 0
            for rival in group[1:]:
                if taken == cfg.rivals:
                    break
                if fit.separated(top.id, rival.id, cfg.confidence):
                    continue
                pairs, left = _meeting(book, history, players, top, rival, cfg.max_games)
                if not pairs or left <= 0:
                    continue
                taken += 1
                n = max(1, min(cfg.round_games, left) // per_round)
                for a, b in pairs:
                    now.setdefault(frozenset((a.id, b.id)), (a, b, n))
        if not now:
            return played
        # One batch for the whole round: its wall time is its longest game's, whatever the games in it.
        unique = list(now.values())
        matchups = play_gauntlet(league, [(a, b) for a, b, _ in unique], first_seed=seed,
                                 config=GauntletConfig(older=0), device=device, on_games=on_games, label="playoff",
                                 key=f"{key}/{seed}", crews={m.id: crew for crew in crews.values() for m in crew[:1]},
                                 sizes=[n for _, _, n in unique])
        played += sum(m.games for m in matchups)
        seed += sum(n for _, _, n in unique)
    return played


def _before(league: League, history: History, key: str, seed: int) -> History:
    """The history as the round starting at ``seed`` saw it the first time: without the games of that round and
    later ones (stored before the process playing them was killed; played again now, see :func:`play_gauntlet`)."""
    later = [mid for k, (mid, _) in league.ledger.keyed_matches(f"{key}/").items() if int(k.split("/")[2]) >= seed]
    if not later:
        return history
    return replace(history, table=history.table.select(~np.isin(history.table.match_id, later)))


def _comparable(book: RoleBook, players: list[PlayerRow], sided: bool) -> list[list[PlayerRow]]:
    """The groups whose ratings compare, each best first: all the players, or in a game rated per side the
    snapshots of each side (role)."""
    if not sided:
        return [players]
    groups: dict[frozenset[str] | None, list[PlayerRow]] = {}
    for p in players:
        groups.setdefault(book.roles(p), []).append(p)
    return [g for g in groups.values() if len(g) > 1]


def _meeting(book: RoleBook, history: History, players: list[PlayerRow], top: PlayerRow, rival: PlayerRow,
             max_games: int) -> tuple[list[tuple[PlayerRow, PlayerRow]], int]:
    """What separates ``top`` from ``rival`` and how many more results it may take: their own games, or, where
    they cannot meet (one side of a game whose sides differ), each one's games against the best player that meets
    both (the other side's best: the difference of two ratings measured through a common opponent)."""
    if book.rules.kind == COOPERATIVE or book.meets(top, rival):  # a cooperative game's snapshots meet as crews
        return [(top, rival)], max_games - sum(record_between(history.table, top.id, rival.id))
    common = next((p for p in players if book.meets(top, p) and book.meets(rival, p)), None)
    if common is None:
        return [], 0
    return [(top, common), (rival, common)], max_games - sum(record_between(history.table, rival.id, common.id))
