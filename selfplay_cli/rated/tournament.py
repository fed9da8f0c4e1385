"""``marl league tournament``'s games: the pairs of a chosen field that still miss games in the variant they are
filed in (those that cannot meet, in a game of roles, set apart), and the missing games played, each player loaded
once. The command chooses the field and prints; this holds what a test would call without the CLI."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..league.pairs import PairPlan, plan_tournament
from ..league.store import League, PlayerRow
from .games_jobs import JOB_ROUNDS, games_jobs
from .match import load_player, mix_seed, run_match
from .roles import RoleBook
from .snapshots import players_variant

__all__ = ["TournamentPlan"]


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
                               variant=variant, meets=(lambda x, y: book.meets(league.get_player(x),
                                                                              league.get_player(y)))
                               if book.differ else None)
        return cls(env, variant, options, [p for p in plan if p.meets], [p for p in plan if not p.meets])

    def enqueue(self, league: League, seed: int | None, device: str, job_rounds: int = JOB_ROUNDS) -> str:
        """Queue every pair's missing games as jobs (:func:`~selfplay_cli.rated.jobs.games_jobs`) in one new batch,
        each pair from ``seed`` (None: its first seed not played); the batch's name."""
        from .queued import batch_name

        batch = batch_name("tournament", self.env)
        jobs = []
        for p in self.pairs:
            first = league.fresh_seed(p.a_id, p.b_id) if seed is None else seed
            jobs += games_jobs(league, [league.get_player(p.a_id)], league.get_player(p.b_id), games=p.missing,
                               first_seed=first, match_kind="tournament", env_options=self.options,
                               job_rounds=job_rounds, device=device)
        league.enqueue(batch, jobs)
        return batch

    def play(self, league: League, seed: int | None, parallel: int, device: str,
             on_games: Callable[[int], None] | None = None) -> None:
        """Play and store every pair's missing games, from ``seed`` (None: each pair's first seed not played)."""
        policies: dict[int, Any] = {}  # each player's file read and checked once, whatever its pairs
        for p in self.pairs:
            first = league.fresh_seed(p.a_id, p.b_id) if seed is None else seed
            for pid in (p.a_id, p.b_id):
                if pid not in policies:
                    policies[pid] = load_player(league, league.get_player(pid), device=device,
                                                seed=mix_seed(first, pid))
            pa, pb = policies[p.a_id], policies[p.b_id]
            run_match(pa, pb, games=p.missing, first_seed=first, parallel=parallel, league=league,
                      player_ids={pa.id: p.a_id, pb.id: p.b_id}, kind="tournament", on_games=on_games,
                      env_options=self.options)
