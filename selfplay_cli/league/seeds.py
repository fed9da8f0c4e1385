"""The seeds of a pair's games, taken before they are played, so that no game is played and stored twice.

Two players that act deterministically play the same game on the same seed, and a game stored twice counts twice.
So a command that starts new games between two players (a tournament's pair, a match, a gate; queued as jobs or
played by the command itself) first takes their seeds: a range of rounds of the pair
(:class:`~selfplay_cli.league.models.SeedRange`), after every seed the pair has stored or taken before.

* **Looking** (:meth:`Seeds.pair_seeds`): each pair's ranges as they stand, with the state of each range's job (a
  range whose job is queued or leased holds games on their way), and the pair's last ``seq``.
* **Taking** (:meth:`Seeds.take_seeds` for the ranges a command plays itself; :meth:`~selfplay_cli.league.queue.
  Queue.enqueue` writes a job's range in the transaction that queues the job): the ranges of a pair are written as its
  next ``seq`` after the look they were planned from. ``(lo, hi, seq)`` is unique, so of two commands that planned the
  same pair from the same look (one tournament queued twice at the same moment), the database keeps the first's
  ranges and refuses the other's whole transaction (:class:`SeedsTaken`): that one looks again and finds the first's
  ranges. No check read before the write stands between them; the unique key does.
* **Settling** (:meth:`Seeds.settle_seeds`): a range a command played itself and ended early (an SPRT decided) is cut
  to the rounds it played, so the pair's next games start right after them.

What a command does with what it finds (joins the games on their way, or starts after them) is the caller's
(:mod:`selfplay_cli.evaluation.seeds`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any, TypeVar

from sqlalchemy import inspect, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from selfplay_cli.league.db import Part
from selfplay_cli.league.failures import LeagueError
from selfplay_cli.league.models import Job, SeedRange, utcnow

__all__ = ["IN_FLIGHT", "Pair", "PairSeeds", "SeedClaim", "SeedRangeRow", "Seeds", "SeedsTaken", "pair_of",
           "variant_tag"]

T = TypeVar("T")
Pair = tuple[int, int]
IN_FLIGHT = frozenset({"queued", "leased"})
"""The states of a job whose games are on their way (it will store them, or a worker that takes it will)."""


def pair_of(a: int, b: int) -> Pair:
    """The pair of two players as a range names it: the lower id first."""
    a, b = int(a), int(b)
    return (a, b) if a <= b else (b, a)


def variant_tag(variant: str) -> str:
    """What a range keeps of a variant's key (:func:`~selfplay_cli.league.variants.variant_key`): ``""`` for the
    game's default, else the key's sha256 (a key is JSON of any length)."""
    return hashlib.sha256(variant.encode()).hexdigest() if variant else ""


@dataclass(frozen=True)
class SeedClaim:
    """Seeds to take: ``rounds`` rounds from ``first_seed`` for ``games`` games of ``a`` against ``b`` in ``variant``
    (its key, as :func:`~selfplay_cli.league.variants.variant_key` gives it)."""

    a: int
    b: int
    first_seed: int
    rounds: int
    games: int
    variant: str = ""

    @property
    def pair(self) -> Pair:
        return pair_of(self.a, self.b)


@dataclass(frozen=True)
class SeedRangeRow:
    """A range as stored, with its job's state and batch (None: a range its command plays itself)."""

    id: int
    pair: Pair
    seq: int
    first_seed: int
    rounds: int
    games: int
    variant: str
    owner: str
    job_id: int | None
    job_state: str | None
    created_at: datetime

    @property
    def end(self) -> int:
        """The first seed after the range."""
        return self.first_seed + self.rounds

    @property
    def queued(self) -> bool:
        """A queued job's range whose games are on their way (its job queued or leased)."""
        return self.job_state in IN_FLIGHT

    def of_variant(self, variant: str) -> bool:
        """Whether its games count in ``variant`` (a variant's key)."""
        return self.variant == variant_tag(variant)

    def overlaps(self, first_seed: int, rounds: int) -> bool:
        """Whether it shares a seed with ``rounds`` rounds from ``first_seed``."""
        return first_seed < self.end and self.first_seed < first_seed + rounds


@dataclass(frozen=True)
class PairSeeds:
    """A pair's ranges as one look found them; ``seq``: the last one's (0: none)."""

    pair: Pair
    seq: int = 0
    ranges: tuple[SeedRangeRow, ...] = ()

    @property
    def end(self) -> int:
        """The first seed after every range of the pair (0: none)."""
        return max((r.end for r in self.ranges), default=0)


class SeedsTaken(LeagueError):
    """Another command took seeds of one of these pairs since the look the ranges were planned from: nothing was
    written; look again."""


class Seeds(Part):
    """The seed ranges of a league (a part of :class:`~selfplay_cli.league.store.League`; see the module
    docstring)."""

    def _has_seeds(self) -> bool:
        """Whether the database has the ``seed_ranges`` table: always once a command that writes has opened it; a
        league from before it, opened only to read, has none (and so no ranges)."""
        if not self.db.readonly:
            return True
        known = getattr(self, "_seed_table", None)
        if known is None:
            known = self._seed_table = inspect(self.db.engine).has_table("seed_ranges")
        return bool(known)

    def pair_seeds(self, pairs: Iterable[tuple[int, int]]) -> dict[Pair, PairSeeds]:
        """Each pair's ranges (players in either order), in one read."""
        wanted = {pair_of(a, b) for a, b in pairs}
        if not wanted or not self._has_seeds():
            return {p: PairSeeds(p) for p in wanted}
        los, his = sorted({p[0] for p in wanted}), sorted({p[1] for p in wanted})

        def work(s: Session) -> dict[Pair, PairSeeds]:
            q = (select(SeedRange, Job.state).outerjoin(Job, Job.id == SeedRange.job_id)
                 .where(SeedRange.lo.in_(los), SeedRange.hi.in_(his)).order_by(SeedRange.seq))
            found: dict[Pair, list[SeedRangeRow]] = {p: [] for p in wanted}
            for r, state in s.execute(q):
                pair = (int(r.lo), int(r.hi))
                if pair in found:
                    found[pair].append(SeedRangeRow(int(r.id), pair, int(r.seq), int(r.first_seed), int(r.rounds),
                                                    int(r.games), str(r.variant), str(r.owner), r.job_id, state,
                                                    r.created_at))
            return {p: PairSeeds(p, max((r.seq for r in rows), default=0), tuple(rows)) for p, rows in found.items()}

        return self._read(work)

    def seeds_end(self, a: int, b: int) -> int:
        """The first seed after every range of players ``a`` and ``b`` (0: none)."""
        return self.pair_seeds([(a, b)])[pair_of(a, b)].end

    def take_seeds(self, claims: Sequence[SeedClaim], seen: Mapping[Pair, int], owner: str) -> list[int]:
        """Take ``claims`` for ``owner`` (the command that plays them itself) in one transaction, each pair's ranges
        after the ``seq`` that the look they were planned from found (``seen``; a pair missing: none); their ids.
        :class:`SeedsTaken` (nothing written) when another command took a range of one of the pairs since."""
        return self.taking(lambda s: self.write_ranges(s, claims, seen, owner))

    def taking(self, work: Callable[[Session], T]) -> T:
        """``work`` as one unit of work, a range refused by the pairs' unique key said as :class:`SeedsTaken`."""
        try:
            return self._unit(work)
        except IntegrityError as exc:
            if "seed_ranges" not in str(exc.orig):
                raise
            raise SeedsTaken("another command took seeds of the same players at the same time: look again") from None

    def write_ranges(self, s: Session, claims: Sequence[SeedClaim], seen: Mapping[Pair, int], owner: str,
                     job_ids: Sequence[int | None] | None = None) -> list[int]:
        """Insert ``claims`` inside the caller's transaction (``job_ids``: the job of each, queued in it)."""
        if not claims:
            return []
        nxt: dict[Pair, int] = {}
        now = utcnow()
        rows: list[dict[str, Any]] = []
        for i, c in enumerate(claims):
            if c.rounds < 1 or c.games < 1 or c.first_seed < 0:
                raise LeagueError(f"a seed range needs rounds and games, from seed 0 on: {c}")
            seq = nxt.get(c.pair, int(seen.get(c.pair, 0)) + 1)
            nxt[c.pair] = seq + 1
            rows.append({"lo": c.pair[0], "hi": c.pair[1], "seq": seq, "first_seed": int(c.first_seed),
                         "rounds": int(c.rounds), "games": int(c.games), "variant": variant_tag(c.variant),
                         "owner": owner[:200], "job_id": None if job_ids is None else job_ids[i], "created_at": now})
        table = SeedRange.__table__
        return [int(i) for i in s.scalars(table.insert().returning(table.c.id, sort_by_parameter_order=True), rows)]

    def settle_seeds(self, range_id: int, rounds: int, games: int) -> None:
        """Cut a range its command played itself to the ``rounds`` (``games``) it played, from its first seed: the
        seeds after them were never played, and the pair's next games may have them."""

        def work(s: Session) -> None:
            s.execute(update(SeedRange).where(SeedRange.id == int(range_id), SeedRange.rounds >= int(rounds))
                      .values(rounds=max(int(rounds), 1), games=max(int(games), 1)))

        self._unit(work)
