"""The ledger's games as their readers get them: a stored game with everything needed to replay it
(:class:`GameRow`), and the pairwise results that rating fits read, as numpy arrays (:class:`GameTable`; its ``kind``
column coded by :data:`KIND_CODES`). Plain records: the ledger that stores the games is
:mod:`selfplay_cli.league.ledger`, how its table is derived from them :mod:`selfplay_cli.league.derivation`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.results import COOPERATIVE, FREE_FOR_ALL, TWO_SIDES

__all__ = ["KIND_CODES", "GameRow", "GameTable"]

KIND_CODES = {TWO_SIDES: 0, COOPERATIVE: 1, FREE_FOR_ALL: 2}
"""The ``kind`` column of a :class:`GameTable`: what made each row."""


@dataclass(frozen=True)
class GameRow:
    """One stored game with everything needed to replay it: :meth:`~selfplay_cli.league.ledger.Ledger.game`.

    ``players`` are player ids per seat; ``match_params`` are the parameters of the match that played it (for
    rated and training matches, ``env_options``: the game options it was played under); ``actions`` the encoded
    action record, None for games stored without one (by an older marl).
    """

    id: int
    match_id: int
    match_kind: str
    match_params: dict[str, Any]
    env: str
    seed: int
    length: int
    truncated: bool
    players: tuple[int, ...]
    scores: tuple[float, ...]
    outcome: tuple[float, ...]
    actions: bytes | None
    created_at: datetime


@dataclass(frozen=True)
class GameTable:
    """The pairwise results of the ledger as numpy arrays, in game-id order, for rating fits (see
    :mod:`selfplay_cli.league.derivation`): one row per result between two different players (a player against
    itself carries no rating information).

    ``score_a`` is ``player_a``'s points (1 / 0.5 / 0; the mean over its seats' pairings for a free-for-all player on
    several seats); ``player_a`` is the first side's player (two-sides), the player of the earlier episode
    (cooperative) or of the lower seat (free-for-all). ``game_id``, ``length`` and ``truncated`` are the game's (a
    cooperative comparison: its later episode's id and length, truncated if either episode was); ``kind`` is the
    :data:`KIND_CODES` code of the game's kind. ``margin_a`` is half of ``player_a``'s score minus ``player_b``'s (the
    game's own units: chips, goals; a player on several seats: the mean of its seats' scores; cooperative: the two
    team returns): in a zero-sum game of two seats, exactly ``player_a``'s return. NaN where not known (a table built
    from rows without it).
    """

    game_id: npt.NDArray[np.int64]
    match_id: npt.NDArray[np.int64]
    player_a: npt.NDArray[np.int64]
    player_b: npt.NDArray[np.int64]
    score_a: npt.NDArray[np.float64]
    seed: npt.NDArray[np.int64]
    length: npt.NDArray[np.int64]
    truncated: npt.NDArray[np.bool_]
    kind: npt.NDArray[np.int8] = field(default=None)  # type: ignore[assignment]
    margin_a: npt.NDArray[np.float64] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.kind is None:
            object.__setattr__(self, "kind", np.zeros(self.game_id.size, dtype=np.int8))
        if self.margin_a is None:
            object.__setattr__(self, "margin_a", np.full(self.game_id.size, np.nan))
    def __len__(self) -> int:
        return int(self.game_id.size)

    def player_ids(self) -> npt.NDArray[np.int64]:
        """Sorted distinct player ids that appear in the table."""
        return np.unique(np.concatenate([self.player_a, self.player_b])).astype(np.int64)

    def indexed(
        self, ids: Sequence[int] | npt.ArrayLike | None = None
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Map player ids to indices ``0..n-1`` for :func:`~selfplay_cli.stats.bradley_terry.fit_bradley_terry`.

        Args:
            ids: the population (default :meth:`player_ids`); every player in the table must be in it.

        Returns:
            ``(ids, a, b)``: the id of each index and the per-game index arrays of seat 0 and seat 1.
        """
        pop = self.player_ids() if ids is None else np.asarray(ids, dtype=np.int64).ravel()
        order = np.argsort(pop, kind="stable")
        sorted_ids = pop[order]

        def lookup(x: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
            pos = np.searchsorted(sorted_ids, x)
            pos = np.clip(pos, 0, max(sorted_ids.size - 1, 0))
            if x.size and (sorted_ids.size == 0 or np.any(sorted_ids[pos] != x)):
                raise ValueError("GameTable.indexed: a player of the table is missing from ids")
            return order[pos].astype(np.int64)

        return pop, lookup(self.player_a), lookup(self.player_b)


    def select(self, mask: npt.NDArray[np.bool_]) -> GameTable:
        """The sub-table of the rows where ``mask`` is True."""
        return GameTable(*(getattr(self, f)[mask] for f in _GAME_TABLE_FIELDS))

    def by_side(self) -> tuple[GameTable, dict[int, tuple[int, int]]]:
        """The table with each player as the side it played (``player_a`` the first side's, ``player_b`` the
        second's; two-sides rows), for a game whose sides differ, where a player's rating means something only
        against the other side's. A player seen on both sides (a scripted player) becomes two players, keyed
        ``-(2 * id + side) - 1``; one seen on one side keeps its id. Returns the table and, for every key in it,
        ``(player id, side)`` (side 0 or 1)."""
        both = np.intersect1d(self.player_a, self.player_b)
        a = np.where(np.isin(self.player_a, both), -(2 * self.player_a) - 1, self.player_a)
        b = np.where(np.isin(self.player_b, both), -(2 * self.player_b + 1) - 1, self.player_b)
        sides: dict[int, tuple[int, int]] = {}
        for keys, side in ((a, 0), (b, 1)):
            for key in np.unique(keys).tolist():
                sides[int(key)] = ((-int(key) - 1) // 2, side) if key < 0 else (int(key), side)
        return replace(self, player_a=a.astype(np.int64), player_b=b.astype(np.int64)), sides

    def games_played(self) -> int:
        """How many ledger games the rows stand for: two per cooperative comparison (its two episodes), one per
        other row."""
        return int(self.game_id.size + np.count_nonzero(self.kind == KIND_CODES[COOPERATIVE]))

    @classmethod
    def empty(cls) -> GameTable:
        """A table without games."""
        i = np.zeros(0, dtype=np.int64)
        return cls(i, i.copy(), i.copy(), i.copy(), np.zeros(0), i.copy(), i.copy(), np.zeros(0, dtype=bool))

    @classmethod
    def of_rows(cls, rows: Sequence[tuple]) -> GameTable:
        """A table of ``(game_id, match_id, player_a, player_b, score_a, seed, length, truncated, kind[, margin_a])``
        rows (all with the margin or none)."""
        if not rows:
            return cls.empty()
        cols = list(zip(*rows, strict=True))
        margin = np.asarray(cols[9], dtype=np.float64) if len(cols) > 9 else None
        return cls(game_id=np.asarray(cols[0], dtype=np.int64), match_id=np.asarray(cols[1], dtype=np.int64),
                   player_a=np.asarray(cols[2], dtype=np.int64), player_b=np.asarray(cols[3], dtype=np.int64),
                   score_a=np.asarray(cols[4], dtype=np.float64), seed=np.asarray(cols[5], dtype=np.int64),
                   length=np.asarray(cols[6], dtype=np.int64), truncated=np.asarray(cols[7], dtype=bool),
                   kind=np.asarray(cols[8], dtype=np.int8), margin_a=margin)


_GAME_TABLE_FIELDS = ("game_id", "match_id", "player_a", "player_b", "score_a", "seed", "length", "truncated", "kind",
                      "margin_a")

