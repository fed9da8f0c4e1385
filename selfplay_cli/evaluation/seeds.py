"""Seeds for the new games of pairs of players, taken before the games are played or queued: every command that
starts rated games of a pair (a tournament, a match, a gate; queued or played here) plans them here, so that no game
is played and stored twice, whoever asks for it, how often, and at what moment.

A command asks for games of pairs (:class:`Ask`). A tournament or a gate asks for a pair to *have* games
(``joins``): games of the pair already on their way in the same variant count (the ranges of queued jobs, and ranges
that another command took to play itself since this one first looked), and the command joins them instead of queuing
them again. A match asks for games *more*: they start after them. New games start at the first seed after every
stored game of the pair and every range taken for it, or at the user's ``--seed``, refused in one line where it would
play seeds a queued job is about to play.

:func:`settle` looks (:meth:`~selfplay_cli.league.seeds.Seeds.pair_seeds`), decides each pair's games, and has the
caller write the new ranges: queue their jobs (:meth:`~selfplay_cli.league.queue.Queue.enqueue`) or take them to play
here (:meth:`~selfplay_cli.league.seeds.Seeds.take_seeds`), in one transaction. When another command took seeds of
one of the pairs in between, the pairs' unique key refuses that write whole
(:class:`~selfplay_cli.league.seeds.SeedsTaken`), and :func:`settle` looks again: the other's ranges are then found,
and joined or started after.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from ..errors import MarlError
from ..league.seeds import Pair, PairSeeds, SeedClaim, SeedRangeRow, SeedsTaken, pair_of

__all__ = ["MAX_LOOKS", "Ask", "Settled", "joined_text", "settle"]

T = TypeVar("T")
MAX_LOOKS = 8
"""Looks at the pairs before giving up: each look after the first follows a write another command made at the same
moment to the same pairs, so a few are plenty."""


@dataclass(frozen=True)
class Ask:
    """``games`` games of ``a`` (side A's first player) against ``b`` in ``variant`` (its key): more of them, or
    (``joins``) up to that many counting the games on their way; from the user's ``seed`` when given."""

    a: int
    b: int
    games: int
    variant: str = ""
    joins: bool = False
    seed: int | None = None

    @property
    def pair(self) -> Pair:
        return pair_of(self.a, self.b)


@dataclass(frozen=True)
class Settled:
    """What :func:`settle` decided for one :class:`Ask`: the ranges on their way it joined, and its new games
    (``games`` from ``first_seed``; none when ``games`` is 0), from the pair's ranges as ``look`` found them."""

    ask: Ask
    look: PairSeeds
    joined: tuple[SeedRangeRow, ...]
    first_seed: int | None
    games: int

    @property
    def joined_games(self) -> int:
        return sum(r.games for r in self.joined)

    def claim(self, first_seed: int, rounds: int, games: int) -> SeedClaim:
        """The claim of ``rounds`` rounds (``games`` games) from ``first_seed`` of the new games; refused in one line
        where the user's seed makes them play seeds a queued job of the pair is about to play."""
        if self.ask.seed is not None:
            for r in self.look.ranges:
                if r.queued and r.overlaps(first_seed, rounds):
                    raise MarlError(f"--seed {self.ask.seed}: seeds {r.first_seed}-{r.end - 1} of these players are "
                                    f"queued already, in batch {r.owner} (marl queue --batch {r.owner}): without "
                                    "--seed the new games start after them")
        return SeedClaim(self.ask.a, self.ask.b, int(first_seed), int(rounds), int(games), self.ask.variant)


def settle(league: Any, asks: Sequence[Ask], write: Callable[[list[Settled], Mapping[Pair, int]], T], *,
           looked: Callable[[], None] | None = None) -> tuple[list[Settled], T]:
    """Decide every ask from one look at its pair's seeds and have ``write(settled, seen)`` write the new ranges
    (with ``seen``, each pair's last ``seq`` in that look, as :meth:`~selfplay_cli.league.queue.Queue.enqueue` and
    :meth:`~selfplay_cli.league.seeds.Seeds.take_seeds` take it); look again when another command took seeds of one
    of the pairs in between. ``looked()`` is called after the first look (a test makes two commands look before
    either writes)."""
    pairs = list(dict.fromkeys(a.pair for a in asks))
    played = {p: int(league.ledger.played_seed_end(*p)) for p in pairs}  # (stored games lie in ranges, or before them)
    first: dict[Pair, int] | None = None
    for _ in range(MAX_LOOKS):
        looks = league.seeds.pair_seeds(pairs)
        if first is None:
            first = {p: looks[p].seq for p in pairs}
            if looked is not None:
                looked()
        settled = [_decide(a, looks[a.pair], first[a.pair], played[a.pair]) for a in asks]
        try:
            return settled, write(settled, {p: looks[p].seq for p in pairs})
        except SeedsTaken:
            continue
    raise MarlError("other commands kept taking seeds of the same players at the same moment: run the command again")


def _decide(ask: Ask, look: PairSeeds, first_seq: int, played: int) -> Settled:
    """One ask against its pair's look (``first_seq``: the pair's last seq at the command's first look)."""
    coming = tuple(r for r in look.ranges if r.of_variant(ask.variant)
                   and (r.queued or (r.job_id is None and r.seq > first_seq)))  # (a command's own: since we looked)
    joined = coming if ask.joins else ()
    need = ask.games - sum(r.games for r in joined)
    if need <= 0:
        return Settled(ask, look, joined, None, 0)
    start = ask.seed if ask.seed is not None else max(played, look.end)
    return Settled(ask, look, joined, start, need)


def joined_text(joined: Mapping[str, int], playing: Mapping[str, int]) -> str:
    """``228 games already queued in batch B``, ``and 40 being played by marl@host:12``: what was joined."""
    parts = [f"{n} games already queued in batch {b}" for b, n in joined.items()]
    parts += [f"{n} games being played by {who}" for who, n in playing.items()]
    return ", ".join(parts)
