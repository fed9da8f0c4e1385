"""``marl league tournament``'s games: the pairs of a chosen field that still miss games in the variant they are
filed in (those that cannot meet, in a game of roles, set apart), and the missing games queued or played, each player
loaded once, on seeds each pair takes first (:mod:`.seeds`): the games of a pair on their way already (the same
tournament queued before, or by someone else at the same moment) are joined, never queued or played again. The
command chooses the field and prints; this holds what a test would call without the CLI."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..league.seeds import Pair
from ..league.store import League, PlayerRow
from ..players.load import load_player, mix_seed
from ..players.snapshots import players_variant
from ..ratings.pairs import PairPlan, plan_tournament
from .games_jobs import JOB_ROUNDS, games_jobs
from .match import round_size, run_match
from .roles import RoleBook
from .seeds import Ask, Settled, settle

__all__ = ["Submitted", "TournamentPlan"]


@dataclass(frozen=True)
class TournamentPlan:
    """The pairs of a tournament that still need games (``pairs``) and those that cannot meet (``apart``), in
    ``env`` under ``options``, filed in ``variant``; ``total``: the games to play (whole pairs)."""

    env: str
    variant: str
    options: dict[str, Any] | None
    pairs: list[PairPlan]
    apart: list[PairPlan]

    @property
    def total(self) -> int:
        return sum(p.missing + p.missing % 2 for p in self.pairs)

    @classmethod
    def of(cls, league: League, env: str, players: dict[int, PlayerRow], anchor: PlayerRow | None,
           games_per_pair: int, options: dict[str, Any] | None) -> TournamentPlan:
        """A round robin of ``players`` (by id), or with ``anchor`` a gauntlet against it: every pair up to
        ``games_per_pair`` games."""
        everyone = [*players.values(), *([anchor] if anchor else [])]
        variant = players_variant(league, env, everyone, options)  # where the games are filed
        book = RoleBook(league, env)  # a game whose seats hold different roles: who can meet whom
        plan = plan_tournament(league, env, list(players), games_per_pair, vs=anchor.id if anchor else None,
                               variant=variant, meets=(lambda x, y: book.meets(league.roster.get_player(x),
                                                                              league.roster.get_player(y)))
                               if book.differ else None)
        return cls(env, variant, options, [p for p in plan if p.meets], [p for p in plan if not p.meets])

    def asks(self, seed: int | None) -> list[Ask]:
        """Each pair's games as :func:`~selfplay_cli.evaluation.seeds.settle` takes them: up to what it misses, the
        games of the pair on their way counted (joined), from ``seed`` (None: after every seed the pair has)."""
        return [Ask(p.a_id, p.b_id, p.missing, self.variant, joins=True, seed=seed) for p in self.pairs]

    def enqueue(self, league: League, seed: int | None, device: str, job_rounds: int = JOB_ROUNDS,
                looked: Callable[[], None] | None = None) -> Submitted:
        """Queue the games every pair still misses as jobs (:func:`~selfplay_cli.evaluation.games_jobs.games_jobs`) in
        one new batch, each pair's on seeds of its own (:func:`~selfplay_cli.evaluation.seeds.settle`: after every seed
        the pair has, or from ``seed``); games of a pair on their way already are joined, not queued again. What was
        queued and joined (``looked``: see :func:`~selfplay_cli.evaluation.seeds.settle`)."""
        from .queued import batch_name

        batch = batch_name("tournament", self.env)

        def write(settled: list[Settled], seen: Mapping[Pair, int]) -> int:
            jobs = []
            for d in settled:
                if d.games and d.first_seed is not None:
                    jobs += games_jobs(league, [league.roster.get_player(d.ask.a)], league.roster.get_player(d.ask.b),
                                       games=d.games, first_seed=d.first_seed, match_kind="tournament",
                                       env_options=self.options, job_rounds=job_rounds, device=device, seeds=d)
            if jobs:
                league.queue.enqueue(batch, jobs, seen=seen)
            return len(jobs)

        settled, n = settle(league, self.asks(seed), write, looked=looked)
        return Submitted.of(settled, batch if n else None, n)

    def take(self, league: League, seed: int | None, device: str,
             looked: Callable[[], None] | None = None) -> Submitted:
        """Take the seeds of the games every pair still misses, to play them in this process (:meth:`play_taken`);
        games of a pair on their way already (queued, or taken by another command at the same moment) are joined, not
        played again. What is to be played here and what was joined."""
        from .jobs import worker_name

        policies: dict[int, Any] = {}  # each player's file read and checked once, whatever its pairs

        def write(settled: list[Settled], seen: Mapping[Pair, int]) -> list[tuple[Settled, int]]:
            claims, todo = [], []
            for d in settled:
                if not d.games or d.first_seed is None:
                    continue
                for pid in (d.ask.a, d.ask.b):
                    if pid not in policies:
                        policies[pid] = load_player(league, league.roster.get_player(pid), device=device,
                                                    seed=mix_seed(d.first_seed, pid))
                per = round_size(policies[d.ask.a], policies[d.ask.b], first_seed=d.first_seed,
                                 env_options=self.options)
                rounds = -(-d.games // per)
                claims.append(d.claim(d.first_seed, rounds, rounds * per))
                todo.append(d)
            ids = league.seeds.take_seeds(claims, seen, worker_name("marl"))
            return list(zip(todo, ids, strict=True))

        settled, todo = settle(league, self.asks(seed), write, looked=looked)
        out = Submitted.of(settled, None, 0)
        out.here = [(d.ask.a, d.ask.b, int(d.first_seed), d.games) for d, _ in todo]  # type: ignore[arg-type]
        out.policies = policies
        return out

    def play_taken(self, league: League, taken: Submitted, parallel: int, device: str,
                   on_games: Callable[[int], None] | None = None) -> None:
        """Play and store the games :meth:`take` took for this process."""
        policies = taken.policies
        for a, b, first, games in taken.here:
            for pid in (a, b):
                if pid not in policies:
                    policies[pid] = load_player(league, league.roster.get_player(pid), device=device,
                                                seed=mix_seed(first, pid))
            pa, pb = policies[a], policies[b]
            run_match(pa, pb, games=games, first_seed=first, parallel=parallel, league=league,
                      player_ids={pa.id: a, pb.id: b}, kind="tournament", on_games=on_games,
                      env_options=self.options)

    def play(self, league: League, seed: int | None, parallel: int, device: str,
             on_games: Callable[[int], None] | None = None) -> Submitted:
        """Take (:meth:`take`) and play (:meth:`play_taken`) every pair's missing games in this process; the games of
        a pair queued already are joined, not played (see them through with
        :func:`~selfplay_cli.evaluation.jobs.see_through`)."""
        taken = self.take(league, seed, device)
        self.play_taken(league, taken, parallel, device, on_games=on_games)
        return taken


@dataclass
class Submitted:
    """What a tournament's new games became: ``games`` of ``pairs`` pairs queued as ``jobs`` jobs in ``batch`` (None:
    none queued), or to be played in this process (``here``: player A, player B, first seed, games); and the games of
    its pairs already on their way that it joined: ``joined`` (batch -> games queued there) and ``playing`` (another
    command -> games it plays itself)."""

    batch: str | None
    jobs: int
    games: int
    pairs: int
    joined: dict[str, int]
    playing: dict[str, int]
    joined_jobs: dict[str, list[int]] = field(default_factory=dict)
    """The jobs of each joined batch that hold the joined games."""
    here: list[tuple[int, int, int, int]] = field(default_factory=list)
    policies: dict[int, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, settled: list[Settled], batch: str | None, jobs: int) -> Submitted:
        joined: dict[str, int] = {}
        playing: dict[str, int] = {}
        ids: dict[str, list[int]] = {}
        for d in settled:
            for r in d.joined:
                into = joined if r.job_id is not None else playing
                into[r.owner] = into.get(r.owner, 0) + r.games
                if r.job_id is not None:
                    ids.setdefault(r.owner, []).append(r.job_id)
        new = [d for d in settled if d.games]
        return cls(batch, jobs, sum(d.games + d.games % 2 for d in new), len(new), joined, playing, ids)

    @property
    def joined_games(self) -> int:
        return sum(self.joined.values()) + sum(self.playing.values())

    def to_json(self) -> dict[str, Any]:
        return {"batch": self.batch, "jobs": self.jobs, "games": self.games, "pairs": self.pairs,
                "joined": [{"batch": b, "games": n, "jobs": self.joined_jobs.get(b, [])}
                           for b, n in self.joined.items()],
                "playing": [{"by": who, "games": n} for who, n in self.playing.items()]}
