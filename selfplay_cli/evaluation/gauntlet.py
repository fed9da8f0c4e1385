"""The gauntlet every new snapshot of a training run plays, so that every snapshot is rated, and rated well.

What a snapshot moment plays (its predecessor, the other learners' new snapshots, the run's best so far, older
snapshots, the scripted players) is chosen from the run's history alone (:mod:`.gauntlet_plan`); this module plays
those matchups and stores them.

Every matchup is played in rounds on shared seeds, as its game's kind asks (:mod:`selfplay_cli.play.schedule`):
seat-swapped pairs of a two-sides game (each seed once with either player on each side, so the serve luck and the
seat cancel within a pair), one episode of each player on each seed of a cooperative game (compared by team
return), every rotation of the seating of a free-for-all game. In a cooperative game the per-seat snapshots of one
moment (a run with one network per lander) are one player, a crew: they fly together, each on its own seat, and a
comparison counts for every member (:func:`~.gauntlet_plan.crews_of`). A "pair" below is one such round. All matchups of
one snapshot moment are played together, in one batched call of :func:`selfplay_cli.play.play` (or, on a league's
workers, each matchup as a job of its own: :func:`open_matchups`, :mod:`.gauntlet_jobs`).

Every matchup plays all its rounds at once (``pairs``, ``bot_pairs`` against a scripted player, or the ``sizes``
a playoff round gives), in one batch with the moment's other matchups: nothing waits on a matchup's first games to
decide whether it plays on. Each such wait would cost the length of the batch's longest game (pong's trained players
rally to the step limit, 18,000 steps), and a moment's chain of them cost more than all its games played at once
(docs/benchmarks.md). A matchup's games are stored in the ledger together once they are all in (kind ``eval``, one
match per matchup, one transaction), so a matchup is in the ledger whole or not at all.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ..envs import EnvSpec, get_env
from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..play import Game, play
from ..play.schedule import CannotMeet, round_of
from ..players.load import env_options_of, load_player, mix_seed
from ..policies import Policy
from ..results import GameResult, Rules, points_between
from .gauntlet_plan import Moment, plan_moment
from .roles import cannot_meet_message, policy_roles


@dataclass(frozen=True)
class GauntletConfig:
    """How much a new snapshot plays (the defaults keep evaluation well below the training time)."""

    pairs: int = 4  # rounds (seat-swapped pairs of a two-sides game) of every matchup
    older: int = 2  # older snapshots of the run besides the predecessor and the best
    bot_pairs: int = 0  # rounds against each scripted player, if more than ``pairs`` (a run's final snapshots:
    # their figures against the bots are what the run reports)
    parallel: int = 1024  # games at once

    def __post_init__(self) -> None:
        if self.pairs < 1:
            raise MarlError(f"a gauntlet matchup plays at least one pair, not {self.pairs}")
        if self.older < 0:
            raise MarlError(f"older snapshots must not be negative, not {self.older}")


@dataclass
class Matchup:
    """Two players of a gauntlet and what they scored: ``a`` is a new snapshot (the focus), ``b`` its opponent."""

    a: PlayerRow
    b: PlayerRow
    first_seed: int
    wins: int = 0
    draws: int = 0
    losses: int = 0
    pairs: int = 0
    match_id: int | None = None
    game_ids: list[int] = field(default_factory=list)

    @property
    def games(self) -> int:
        return self.wins + self.draws + self.losses

    @property
    def score(self) -> float:
        return (self.wins + 0.5 * self.draws) / self.games if self.games else 0.5


def play_gauntlet(
    league: League,
    pairs: Sequence[tuple[PlayerRow, PlayerRow]],
    *,
    first_seed: int,
    config: GauntletConfig | None = None,
    device: str = "cpu",
    policies: dict[int, Policy] | None = None,
    on_games: Callable[[int], None] | None = None,
    crews: dict[int, tuple[PlayerRow, ...]] | None = None,
    label: str | None = None,
    key: str | None = None,
    sizes: Sequence[int] | None = None,
) -> list[Matchup]:
    """Play and store the matchups ``pairs`` (see the module docstring); returns each matchup's record.

    ``policies`` may hold already loaded players by player id (scripted players are loaded afresh otherwise);
    seeds start at ``first_seed``, a disjoint range per matchup. ``on_games(n)`` is told of finished games.
    ``crews`` (cooperative games): the per-seat members a player flies with (:func:`~.gauntlet_plan.crews_of`), by
    player id; a player without one flies every seat itself. ``label``: a flag set in the matches' parameters besides
    ``gauntlet`` (``playoff``). ``sizes``: the pairs each matchup plays (a playoff round, whose pairs have different
    numbers of games left), instead of ``config``'s; each matchup's seeds then span its own size.

    ``key``: the unit of work these matchups are (a run's gauntlet of one moment, a round of its playoff), where it
    may be played twice (its process killed, then the run resumed; a rating worker replaced): each matchup is
    stored whole, in one transaction, under the key ``<key>/<first seed>/<a>/<b>`` (:meth:`League.
    create_match_with_games`), so a matchup is in the ledger entirely or not at all, and never twice. Played again,
    a unit whose matchups are all stored plays nothing (their records come from the ledger); one cut short is
    played whole again, the same games on the same seeds in the same batch (so the same moves, where players sample),
    and stores only the matchups that are missing: the ledger ends as an uninterrupted run leaves it.
    """
    cfg = config or GauntletConfig()
    if not pairs:
        return []
    env = pairs[0][0].env
    spec = get_env(env)
    crews = dict(crews or {})
    loaded: dict[int, Policy] = dict(policies or {})
    for a, b in pairs:
        for row in (a, b, *crews.get(a.id, ()), *crews.get(b.id, ())):
            if row.env != env:
                raise MarlError(f"a gauntlet plays one game: {row.full_name} plays {row.env}, not {env}")
            if row.id not in loaded:
                loaded[row.id] = load_player(league, row, device=device, seed=mix_seed(first_seed, row.id))
    if sizes is not None and (len(sizes) != len(pairs) or min(sizes) < 1):
        raise ValueError(f"sizes must give each of the {len(pairs)} matchups at least one pair, not {list(sizes)}")
    gauntlet = _Gauntlet(league, cfg, loaded, crews, label, spec)
    matchups, keys = _matchups(pairs, first_seed, cfg, key, sizes)
    stored = league.ledger.keyed_matches(f"{key}/") if key is not None else {}
    if key is not None and all(k in stored for k in keys):  # done before: what the ledger holds of it
        for m, k in zip(matchups, keys, strict=True):
            m.match_id, params = stored[k]
            m.wins, m.draws, m.losses, m.pairs = (int(x) for x in params.get("record", (0, 0, 0, 0)))
        return matchups
    gauntlet.plan(matchups, keys, stored)
    for k, size in enumerate(_sizes(matchups, cfg, sizes)):
        gauntlet.schedule_pairs(k, size)
    play(gauntlet.spec, gauntlet.roster, gauntlet.schedule, parallel=cfg.parallel, env_options=gauntlet.options,
         record_actions=True, on_result=lambda r: gauntlet.finished(r, on_games))
    return matchups


class _Gauntlet:
    """One call of :func:`play_gauntlet` with its players loaded: the roster they play as, the schedule and what is
    still to come of each matchup."""

    def __init__(self, league: League, cfg: GauntletConfig, loaded: dict[int, Policy],
                 crews: dict[int, tuple[PlayerRow, ...]], label: str | None, spec: EnvSpec) -> None:
        self.league, self.cfg, self.loaded, self.crews, self.label = league, cfg, loaded, crews, label
        ids = list(loaded)
        self.index = {pid: i for i, pid in enumerate(ids)}
        self.roster = [loaded[pid] for pid in ids]
        self.options = env_options_of(*self.roster)
        self.spec = spec = spec.for_options(**self.options)
        self.rules = rules = Rules.of(spec)
        self.seated = {pid: _seat_crew(crew, rules.n_seats) for pid, crew in crews.items()}
        self.roles = {i: policy_roles(p, spec) for i, p in enumerate(self.roster)}  # who may sit where (None: any)
        self.schedule: list[Game] = []
        self.owner: list[tuple[int, int]] = []  # per game: its matchup's index and its round
        self.rounds: dict[tuple[int, int], list[GameResult]] = {}  # the finished games of rounds still incomplete

    def player(self, row: PlayerRow) -> int | tuple[int, ...]:
        """A player's place in a round: its roster index, or its crew's, seat by seat."""
        crew = self.seated.get(row.id)
        return self.index[row.id] if crew is None else tuple(self.index[m.id] for m in crew)

    def result_id(self, row: PlayerRow) -> object:
        """How a round's results name a player: its policy id, or its crew's (a tuple: see results.crew)."""
        crew = self.seated.get(row.id)
        return self.loaded[row.id].id if crew is None else tuple(dict.fromkeys(self.loaded[m.id].id for m in crew))

    def round_games(self, m: Matchup, seed: int) -> list[Game]:
        try:
            return round_of(self.rules, (self.player(m.a), self.player(m.b)), seed, self.roles)
        except CannotMeet:
            roles, index = self.roles, self.index
            raise MarlError(cannot_meet_message(self.spec.name, self.rules, m.a.full_name, roles[index[m.a.id]],
                                                m.b.full_name, roles[index[m.b.id]])) from None

    def plan(self, matchups: list[Matchup], keys: list[str | None], stored: dict) -> None:
        """The matchups to play, their keys and those already stored; the games in a round of each."""
        self.matchups, self.keys, self.stored = matchups, keys, stored
        self.per = [len(self.round_games(m, m.first_seed)) for m in matchups]  # seatings that fit
        self.in_flight = dict.fromkeys(range(len(matchups)), 0)  # games scheduled but not finished, per matchup
        self.pending: dict[int, list[GameResult]] = {k: [] for k in range(len(matchups))}

    def schedule_pairs(self, k: int, n: int) -> None:
        """``n`` more rounds of matchup ``k`` onto the schedule."""
        m = self.matchups[k]
        for p in range(m.pairs, m.pairs + n):
            games = self.round_games(m, m.first_seed + p)
            self.schedule.extend(games)
            self.owner.extend((k, p) for _ in games)
        m.pairs += n
        self.in_flight[k] += self.per[k] * n

    def finished(self, r: GameResult, on_games: Callable[[int], None] | None) -> None:
        """A game is in: count its round once whole; once a matchup's games are all in, store them."""
        k, p = self.owner[r.index]
        m = self.matchups[k]
        got = self.rounds.setdefault((k, p), [])
        got.append(r)
        if len(got) == self.per[k]:  # a whole round: its results between the two
            del self.rounds[(k, p)]
            got.sort(key=lambda g: g.index)
            for points in points_between(self.rules, got, self.result_id(m.a), self.result_id(m.b)):
                m.wins += points > 0.5
                m.draws += points == 0.5
                m.losses += points < 0.5
        self.pending[k].append(r)
        self.in_flight[k] -= 1
        if on_games:
            on_games(1)
        if self.in_flight[k] == 0:  # every game of the matchup is in: store them all
            key = self.keys[k]
            if key not in self.stored:
                _store(self.league, m, self.pending[k], self.loaded, self.options, self.crews, self.label, key)
                self.pending[k] = []
            else:  # stored the first time round: these are the same games
                m.match_id = self.stored[key][0]


def _store(league: League, m: Matchup, results: list[GameResult], loaded: dict[int, Policy],
           options: dict, crews: dict[int, tuple[PlayerRow, ...]], label: str | None = None,
           key: str | None = None) -> None:
    """A settled matchup: its match row and all its games in one transaction, under ``key`` if given (its record,
    wins, draws, losses and rounds, in the row's parameters: what a second playing of the unit reads back)."""
    if not results:
        return
    pa, pb = loaded[m.a.id], loaded[m.b.id]
    info = {"a": pa.id, "b": pb.id, "first_seed": m.first_seed, "env_options": options, "gauntlet": True,
            "record": [m.wins, m.draws, m.losses, m.pairs]}
    if label:
        info[label] = True
    for side, row in (("a_crew", m.a), ("b_crew", m.b)):
        if row.id in crews:
            info[side] = [loaded[c.id].id for c in crews[row.id]]
    player = {loaded[r.id].id: r.id for r in (m.a, m.b, *crews.get(m.a.id, ()), *crews.get(m.b.id, ()))}
    m.match_id, ids = league.ledger.create_match_with_games(m.a.env, "eval", info,
                                                            [r.with_players(player) for r in results], key=key)
    m.game_ids += ids


def rate_snapshots(league: League, snapshot_ids: Sequence[int], *, first_seed: int, config: GauntletConfig,
                   device: str = "cpu", on_games: Callable[[int], None] | None = None,
                   moment: Moment | None = None) -> list[Matchup]:
    """The whole gauntlet of one snapshot moment (:func:`~.gauntlet_plan.plan_moment`, or ``moment`` where the caller
    planned it already), played.

    Idempotent: the gauntlet is one unit of work keyed by the moment (``gauntlet/<its first snapshot id>``,
    :func:`play_gauntlet`'s ``key``): played again (cut short by a kill, then run again on resume; its matchups
    played as jobs of their own, :func:`open_matchups`), it stores what is missing and nothing twice, with the same
    choices. A pair whose players, or copies of them (the same weights,
    :meth:`~selfplay_cli.league.ledger.Ledger.same_weights`: another run with the same seed), already met in another
    gauntlet is left out.
    """
    moment = moment or plan_moment(league, snapshot_ids, config.older)
    if moment is None:
        return []
    return play_gauntlet(league, moment.pairs, first_seed=first_seed, config=config, device=device,
                         on_games=on_games, crews=moment.crews, key=moment.key)


def open_matchups(league: League, moment: Moment, *, first_seed: int, config: GauntletConfig) -> list[Matchup]:
    """The matchups of a planned moment not in the ledger yet, each with its seeds as :func:`play_gauntlet` would
    give them: what a matchup played on its own (``play_gauntlet([(a, b)], first_seed=m.first_seed,
    key=moment.key)``) plays, with the same seeds and under the same key as the whole moment's call."""
    matchups, keys = _matchups(moment.pairs, first_seed, config, moment.key)
    stored = league.ledger.keyed_matches(f"{moment.key}/")
    return [m for m, k in zip(matchups, keys, strict=True) if k not in stored]


def _matchups(pairs: Sequence[tuple[PlayerRow, PlayerRow]], first_seed: int, cfg: GauntletConfig,
              key: str | None, sizes: Sequence[int] | None = None) -> tuple[list[Matchup], list[str | None]]:
    """The matchups of ``pairs``, each with its own range of seeds (one per round: ``sizes[k]``, or the most any
    matchup of ``cfg`` plays), and their keys under ``key`` (``<key>/<first seed>/<a>/<b>``)."""
    spans = list(sizes) if sizes is not None else [max(cfg.pairs, cfg.bot_pairs)] * len(pairs)
    starts = itertools.accumulate(spans, initial=first_seed)  # (one more than the pairs: where the last range ends)
    matchups = [Matchup(a, b, start) for (a, b), start in zip(pairs, starts, strict=False)]
    return matchups, [None if key is None else f"{key}/{m.first_seed}/{m.a.id}/{m.b.id}" for m in matchups]


def _sizes(matchups: Sequence[Matchup], cfg: GauntletConfig, sizes: Sequence[int] | None) -> list[int]:
    """The rounds each matchup plays: ``sizes``, else ``cfg.pairs``, or ``cfg.bot_pairs`` where more against a
    scripted player (the final's figures against the bots)."""
    if sizes is not None:
        return list(sizes)
    return [max(cfg.pairs, cfg.bot_pairs) if m.b.is_bot else cfg.pairs for m in matchups]


def _seat_crew(crew: tuple[PlayerRow, ...], n_seats: int) -> tuple[PlayerRow, ...]:
    """A crew on a game of ``n_seats`` seats (options may change them), as :func:`~.lineup.refit` seats a
    team: extra seats copy members chosen at random (a fixed draw), fewer seats keep the first members."""
    from .lineup import Lineup, refit

    return refit(Lineup(crew[0].env, crew, 0), n_seats, seed=0).players
