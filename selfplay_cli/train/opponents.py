"""A run's opponents: who sits in the opponent seats of its training games, and what their games teach PFSP.

The :class:`~.matchmaking.Matchmaker` draws an opponent id for each opponent slot of a game starting (a scripted
player, one of the run's snapshots, or :data:`~.win_rates.LATEST_LEARNER`); :class:`Opponents` turns the ids into
policies (the snapshots loaded once, then kept), keeps a slot's opponent until the next swap with ``--swap-every``,
keeps the matchmaker's pool the run's snapshots, and reads each finished game into the win-rate book and the ledger.
In a league (``--league alphastar``) each learner's role draws its opponents instead (:mod:`.league_roles`), and a
learner's games against the learners as they are now go into its win-rate book too.
With ``--opponents nash`` it also keeps the matchmaker's Nash mixture, solved again from the ledger
(:func:`~selfplay_cli.ratings.meta_nash.run_nash`) whenever the pool changes, at each snapshot moment, once the
gauntlets of the moments before it are in (the trainer waits for them there): only rated games change the matrix, and
solving it then, not whenever a gauntlet happens to finish, keeps a run with a fixed seed the same run.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from collections.abc import Iterable
from typing import Any

import numpy as np

from ..evaluation.roles import RoleBook
from ..league.store import League, LeagueError
from ..players.load import load_player
from ..policies import Policy
from ..ratings.meta_nash import RunNash, run_nash
from ..results import GameResult
from .config import TrainConfig
from .league_roles import LeagueRoles, Past, live, live_learner
from .matchmaking import Matchmaker
from .win_rates import LATEST_LEARNER, WinRates

POLICY_CACHE = 32
"""Opponent snapshots kept loaded, the most recently drawn (a run's pool is its last ``--window`` snapshots): memory
stays flat however many snapshots the league holds. A game keeps the policy it started with."""


def fixed_opponents(league: League, env: str, names: Iterable[str], bot_ids: dict[str, int]) -> dict[str, int]:
    """The league players among ``names`` (``[opponents] bots``) that are not scripted players of the game, by id:
    a snapshot named by its full name (``run/name``) is drawn with its probability as a bot is, and plays as it is
    rated (``marl exploit`` trains a best response against such a fixed target). A name the league does not hold
    is left to the matchmaker's one-line refusal."""
    from ..ratings.names import resolve

    out = {}
    for name in names:
        if name in bot_ids:
            continue
        try:
            row = resolve(league, name, env)
        except LeagueError:
            continue
        out[name] = row.id
    return out


def fixed_teams(league: League, cfg: TrainConfig, bot_ids: dict[str, int]) -> dict[int, tuple[int, ...]]:
    """The fixed opponents of ``[opponents] bots`` that are per-seat learners' snapshots whose whole team is fixed
    too: each member's id -> its team's ids in seat order."""
    from ..ratings.names import teammates

    agents = cfg.game().agents
    out: dict[int, tuple[int, ...]] = {}
    fixed = {bot_ids[name] for name in cfg.opponents.bots if name in bot_ids}
    for pid in fixed:
        row = league.roster.get_player(pid)
        team = teammates(league, row, agents) if row.kind == "snapshot" else None
        if team is not None and all(m.id in fixed for m in team):
            out[pid] = tuple(m.id for m in team)
    return out


class PolicyCache:
    """League players loaded as policies by id, the :data:`POLICY_CACHE` most recently used kept."""

    def __init__(self, load: Any, size: int = POLICY_CACHE) -> None:
        self._load, self.size = load, size
        self._kept: OrderedDict[int, Policy] = OrderedDict()

    def get(self, pid: int) -> Policy:
        if pid in self._kept:
            self._kept.move_to_end(pid)
            return self._kept[pid]
        policy = self._kept[pid] = self._load(pid)
        while len(self._kept) > self.size:
            self._kept.popitem(last=False)
        return policy

    def __len__(self) -> int:
        return len(self._kept)


class Opponents:
    """The opponents of one run's training games.

    ``home``: the learner of each seat when learners hold every seat (its 'latest' opponent, -1 where none does);
    ``learner_of_game``: the learner in each game; ``seat_roles``: each seat's role where seats differ (None: one
    role); ``opponent_slots``: the flat ``seat * games + game`` slots that opponents hold; ``live``: each learner's
    live policy, the 'latest' opponent; ``roles``: a league's roles (their learners' names are its snapshots')."""

    def __init__(self, league: League, cfg: TrainConfig, bot_ids: dict[str, int], *, n_seats: int,
                 home: tuple[int, ...], learner_of_game: np.ndarray, seat_roles: tuple[str, ...] | None,
                 opponent_slots: np.ndarray, live: list[Policy], device: str,
                 roles: LeagueRoles | None = None, names: list[str] | None = None) -> None:
        self.league, self.cfg, self.device = league, cfg, device
        self.n_seats, self.home, self.learner_of_game = n_seats, home, learner_of_game
        self.seat_roles, self.opponent_slots, self.live = seat_roles, opponent_slots, live
        self.matchmaker = Matchmaker(cfg.opponents, np.random.default_rng(cfg.seed), bot_ids)
        self.rates = WinRates(decay=cfg.opponents.decay, prior=cfg.opponents.prior)
        self._can_play: dict[str, set[int]] = {}  # per role, the pool's snapshots that can play it
        self._policies = PolicyCache(self._load)
        self._player_of: dict[str, int] = dict(bot_ids)  # policy id in game results -> league player id
        self._assigned: np.ndarray | None = None  # opponent id per game slot, with --swap-every
        self._team_of = fixed_teams(league, cfg, bot_ids)  # a fixed per-seat snapshot -> its team, seat by seat
        self._next_swap = 0
        self.roles, self.names = roles, names
        self.nash: RunNash | None = None  # --opponents nash: the mixture drawn from, as last solved
        self.nash_step: int | None = None  # ... and the run's step then (None: solved as a resumed run began)

    def policy(self, pid: int, seat: int, learner: int) -> Policy:
        """The policy of opponent ``pid`` in ``seat`` of a game of ``learner``."""
        if pid == LATEST_LEARNER:  # ML-Agents' "latest model": the learner that holds this seat when learners hold
            home = self.home[seat]  # every seat, as it is now (pong: the other learner; one learner: itself)
            return self.live[home if home >= 0 else learner]
        if pid <= live(0):  # a league learner as it is now
            return self.live[live_learner(pid)]  # type: ignore[index]
        return self._policies.get(pid)

    def _load(self, pid: int) -> Policy:
        """Opponent ``pid`` as a policy: a pool snapshot sampling from its policy (diverse games), a player the
        config names in ``bots`` (a scripted player, or a fixed league player: ``marl exploit``'s target) as it
        plays when rated."""
        named = pid in self.matchmaker.bot_ids.values()
        policy = load_player(self.league, self.league.roster.get_player(pid), device=self.device,
                             greedy=None if named else False, seed=pid)
        self._player_of[policy.id] = pid
        return policy

    def _draw(self, slots: np.ndarray) -> np.ndarray:
        """Opponent ids for the opponent ``slots`` (flat ``seat * games + game``), each drawn by the matchmaker for
        the learner that plays that game."""
        ids = np.empty(len(slots), dtype=np.int64)
        learners = self.learner_of_game[slots % self.cfg.games]
        if self.roles is not None:  # a league: each learner's role draws its opponents
            for i in np.unique(learners).tolist():
                mine = learners == i
                ids[mine] = self.roles.sample(i, int(mine.sum()), self.rates)
            return ids
        if self.seat_roles is None:
            for i in np.unique(learners).tolist():
                mine = learners == i
                ids[mine] = self.matchmaker.sample(i, int(mine.sum()), self.rates)
            return self._own_seats(ids, slots)
        roles = np.asarray(self.seat_roles, dtype=object)[slots // self.cfg.games]
        for i in np.unique(learners).tolist():  # a seat's opponents: the run's snapshots of the seat's role
            for role in dict.fromkeys(roles[learners == i].tolist()):
                mine = (learners == i) & (roles == role)
                ids[mine] = self.matchmaker.sample(i, int(mine.sum()), self.rates, among=self._can_play.get(role, ()))
        return self._own_seats(ids, slots)

    def _own_seats(self, ids: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """A fixed team of per-seat snapshots holds each seat with its own member: a member drawn for another seat
        gives it to the teammate that learned it (``marl exploit`` of a team)."""
        if not self._team_of:
            return ids
        seats = (slots // self.cfg.games).tolist()
        return np.array([self._team_of[i][s] if i in self._team_of else i for i, s in zip(ids.tolist(), seats,
                                                                                         strict=True)], dtype=np.int64)

    def _assignment(self, steps: int) -> np.ndarray:
        """--swap-every: the opponent of every game slot, drawn afresh when a swap is due."""
        if self._assigned is None or steps >= self._next_swap:
            self._assigned = np.zeros(self.n_seats * self.cfg.games, dtype=np.int64)
            self._assigned[self.opponent_slots] = self._draw(self.opponent_slots)
            self._next_swap = steps + self.cfg.swap_every
        return self._assigned

    def shard_table(self, steps: int) -> dict[str, Any]:
        """What rollout actors draw their games' opponents from (:class:`~.shards.ShardOpponents`), the run at
        ``steps``: with --swap-every the opponent id of every game slot; otherwise, per learner and seat role (None:
        one role), the matchmaker's probabilities over opponent ids as the pool and the win rates stand now."""
        if self.cfg.swap_every:
            return {"assigned": self._assignment(steps).copy()}
        draws: dict[tuple[int, str | None], dict[int, float]] = {}
        roles = [None] if self.seat_roles is None else list(dict.fromkeys(self.seat_roles))
        for i in np.unique(self.learner_of_game).tolist():
            for role in roles:
                among = None if role is None else self._can_play.get(role, ())
                draws[(i, role)] = self.matchmaker.probabilities(i, self.rates, among=among)
        return {"draws": draws}

    def know_players(self, players: dict[str, int]) -> None:
        """Policy ids (in game results) of league players that rollout actors loaded, so their games are filed."""
        self._player_of.update(players)

    def choose(self, slots: np.ndarray, steps: int) -> list[Policy]:
        """Opponents for the opponent ``slots`` of the games starting now, the run at ``steps``, one each: drawn afresh
        for every game, or with --swap-every kept per slot until the next swap (ML-Agents' swap_steps, counted in
        game steps)."""
        ids = self._assignment(steps)[slots] if self.cfg.swap_every else self._draw(slots)
        n = self.cfg.games
        return [self.policy(int(i), int(slot) // n, int(self.learner_of_game[slot % n]))
                for i, slot in zip(ids, slots, strict=True)]

    def set_pool(self, env: str, steps: int | None = None) -> None:
        """The matchmaker's pool: the run's snapshots, oldest first; in a game whose seats hold different roles,
        also which of them can play each role (a snapshot only its own). ``steps``: the run's step now (the Nash
        mixture's, which is solved again here)."""
        pool = [p for p in self.league.roster.players(env=env, kind="snapshot") if p.run == self.cfg.run
                and p.unusable is None]  # (a row that cannot be read is never played: said once)
        self.matchmaker.set_pool([p.id for p in pool])
        if self.roles is not None:
            self.roles.set_pool([Past(p.id, self.names.index(p.meta["learner"])) for p in pool  # type: ignore[union-attr]
                                 if p.meta.get("learner") in self.names])  # type: ignore[operator]
        if self.seat_roles is not None:
            book = RoleBook(self.league, env)
            self._can_play = {role: {p.id for p in pool if book.roles(p) is None or role in book.roles(p)}
                              for role in set(self.seat_roles)}
        self.resolve_nash(steps)

    def resolve_nash(self, steps: int | None = None) -> None:
        """``--opponents nash``: solve the run's Nash mixture again from the ledger's rated games and draw from it, the
        run at ``steps`` (nothing in other modes)."""
        cfg = self.cfg.opponents
        if cfg.mode != "nash":
            return
        self.nash = run_nash(self.league, self.cfg.run, payoff=cfg.nash_payoff)
        self.nash_step = steps
        self.matchmaker.set_mixture(None if self.nash is None else self.nash.weights)

    def nash_metrics(self) -> dict[str, Any]:
        """The mixture drawn from, for a metrics line: ``nash/support`` (snapshots with a positive weight),
        ``nash/over`` (snapshots it was solved over), ``nash/games`` (rated games it was solved from),
        ``nash/solved_step`` (null: solved as a resumed run began) and ``nash/weights`` (full name -> weight); before
        the first mixture, a support of 0 and no weights (the draws are uniform over the pool then); nothing in other
        modes."""
        if self.cfg.opponents.mode != "nash":
            return {}
        n = self.nash
        return {"nash/support": len(n.support) if n else 0, "nash/over": len(n.over) if n else 0,
                "nash/games": n.games if n else 0,
                "nash/solved_step": self.nash_step,
                "nash/weights": {name: round(w, 6) for name, w in n.by_name().items()} if n else {}}

    def file_games(self, finished: list[GameResult], learner_players: dict[str, int], match_id: int) -> None:
        """File finished training games in the ledger (under ``match_id``), each learner as the player of its
        latest snapshot (``learner_players``: learner id in game results -> player id); a learner's result against
        an opponent of the league also goes into its win-rate book (PFSP)."""
        learner_ids = list(learner_players)
        records = []
        for r in finished:
            ids = [learner_players[p] if p in learner_players else self._player_of.get(p, 0) for p in r.players]
            if self.roles is not None:  # (its own latest snapshot too, which the ledger cannot tell from it)
                self._league_rates(r, ids, learner_ids)
            if 0 in ids or len(set(ids)) < 2:
                continue  # the learners among themselves (or a live copy) carry no rating information
            records.append(r.with_players(dict(zip(r.players, ids, strict=True))))
            if self.roles is not None:
                continue
            learners = {learner_ids.index(p) for p in r.players if p in learner_ids}
            if len(learners) == 1:  # a learner against the league: its win rate against each opponent (PFSP)
                (i,) = learners
                mine = learner_ids[i]
                points = r.points_of(mine)
                for opponent in dict.fromkeys(q for p, q in zip(r.players, ids, strict=True) if p != mine):
                    self.rates.update(i, opponent, points)
        if records:
            self.league.ledger.record_games(match_id, records)

    def _league_rates(self, r: GameResult, ids: list[int], learner_ids: list[str]) -> None:
        """A league game into the win-rate book of the learner whose game it is: against each opponent, a snapshot
        by its player id, a learner as it is now by its :func:`~.league_roles.live` id."""
        i = int(self.learner_of_game[r.index])
        mine = learner_ids[i]
        points = r.points_of(mine)
        for p, q in dict.fromkeys(zip(r.players, ids, strict=True)):
            if p != mine:
                self.rates.update(i, live(learner_ids.index(p)) if p in learner_ids else q, points)

    def state_dict(self) -> dict[str, Any]:
        """What the run state keeps of the opponents (under the keys it has always had): the matchmaker's generator
        and pool, and the win-rate book, each as JSON text."""
        return {"matchmaker": json.dumps(self.matchmaker.state_dict()), "rates": json.dumps(self.rates.to_dict())}

    def load_state_dict(self, state: dict[str, Any], env: str) -> None:
        """Restore :meth:`state_dict`; the pool is the league's (the run's snapshots as they are now)."""
        self.matchmaker.load_state_dict(json.loads(state["matchmaker"]))
        self.set_pool(env)
        self.rates = WinRates.from_dict(json.loads(state["rates"]))
