"""The decayed win-rate book PFSP reads (:class:`WinRates`), and the sentinel opponent it leaves out.

:class:`WinRates` keeps, per ``(learner, opponent)`` pair, an exponentially decayed record. A game with
the learner's points ``score`` (1 win, 0.5 draw, 0 loss) does::

    wins  = decay * wins  + score
    games = decay * games + 1

(the decay, default 0.99, is applied once per game *against that opponent*, not per wall-clock step), and::

    P[learner beats opponent] = (wins + 0.5 * prior) / (games + prior)

i.e. a prior of ``prior`` (default 1) pseudo-games at 50 %. An unseen pair has ``P = 0.5``. Games with
the opponent :data:`LATEST_LEARNER` are ignored (they carry no PFSP information). Learner ids are opaque
keys: they may be player ids or learner indices (a learner key equal to a snapshot id is not special).

The book works on plain data (integer player ids and results), so it is testable without a database;
:func:`load_win_rates` is the one bridge to a :class:`~selfplay_cli.league.store.League`. The matchmaker that
reads it is :mod:`.matchmaking`'s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from selfplay_cli.errors import MarlError

if TYPE_CHECKING:  # pragma: no cover
    from selfplay_cli.league.store import League

__all__ = ["LATEST_LEARNER", "WinRates", "load_win_rates"]


LATEST_LEARNER = -1
"""Sentinel opponent id: the learner itself / its current partner (never a player id of the league)."""


class WinRates:
    """Exponentially decayed win rates per ``(learner, opponent)`` pair (see the module docstring).

    Attributes:
        decay: factor applied to a pair's record before each new game of that pair, in (0, 1].
        prior: weight in games of the 50 % prior, >= 0.
    """

    def __init__(self, decay: float = 0.99, prior: float = 1.0) -> None:
        if not (0.0 < float(decay) <= 1.0):
            raise ValueError(f"decay must lie in (0, 1], got {decay}")
        if not (math.isfinite(float(prior)) and float(prior) >= 0.0):
            raise ValueError(f"prior must be >= 0, got {prior}")
        self.decay = float(decay)
        self.prior = float(prior)
        self._book: dict[tuple[int, int], tuple[float, float]] = {}

    def __len__(self) -> int:
        return len(self._book)

    def __repr__(self) -> str:
        return f"WinRates(decay={self.decay}, prior={self.prior}, pairs={len(self._book)})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, WinRates):
            return NotImplemented
        return (self.decay, self.prior, self._book) == (other.decay, other.prior, other._book)

    __hash__ = None  # type: ignore[assignment]  # mutable

    @staticmethod
    def _check_score(score: float) -> float:
        s = float(score)
        if not (0.0 <= s <= 1.0):
            raise ValueError(f"score must lie in [0, 1] (1 win, 0.5 draw, 0 loss), got {score}")
        return s

    def update(self, learner: int, opponent: int, score: float) -> None:
        """Record one game: ``wins = decay*wins + score``, ``games = decay*games + 1`` for this pair.

        ``score`` is the learner's points (1 / 0.5 / 0). Games against :data:`LATEST_LEARNER` are ignored.
        """
        s = self._check_score(score)
        learner, opponent = int(learner), int(opponent)
        if opponent == LATEST_LEARNER:
            return
        w, g = self._book.get((learner, opponent), (0.0, 0.0))
        self._book[(learner, opponent)] = (self.decay * w + s, self.decay * g + 1.0)

    def update_many(self, learner: int, opponents: npt.ArrayLike, scores: npt.ArrayLike) -> None:
        """Record several games of one learner, in array order (same result as calling :meth:`update` in order)."""
        opp = np.asarray(opponents, dtype=np.int64).ravel()
        sc = np.asarray(scores, dtype=np.float64).ravel()
        if opp.shape != sc.shape:
            raise ValueError(f"opponents and scores differ in length ({opp.size} vs {sc.size})")
        self._apply(np.full(opp.shape, int(learner), dtype=np.int64), opp, sc)

    def _apply(self, learners: npt.NDArray[np.int64], opponents: npt.NDArray[np.int64],
               scores: npt.NDArray[np.float64]) -> None:
        """Vectorised in-order updates: per pair with ``m`` new games, the ``i``-th of them followed by ``k_i``
        later ones contributes ``decay**k_i``, and the old record is multiplied by ``decay**m``."""
        if scores.size and (np.any(~(scores >= 0.0)) or np.any(~(scores <= 1.0))):
            raise ValueError("scores must lie in [0, 1] (1 win, 0.5 draw, 0 loss)")
        keep = opponents != LATEST_LEARNER
        learners, opponents, scores = learners[keep], opponents[keep], scores[keep]
        if scores.size == 0:
            return
        pairs, inv = np.unique(np.stack([learners, opponents], axis=1), axis=0, return_inverse=True)
        inv = inv.ravel()
        counts = np.bincount(inv, minlength=len(pairs))
        order = np.argsort(inv, kind="stable")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        pos = np.empty(inv.size, dtype=np.int64)
        pos[order] = np.arange(inv.size) - np.repeat(starts, counts)  # index of each game within its pair
        later = counts[inv] - 1 - pos  # games of the same pair after this one
        w = self.decay ** later.astype(np.float64)
        add_wins = np.bincount(inv, weights=w * scores, minlength=len(pairs))
        add_games = np.bincount(inv, weights=w, minlength=len(pairs))
        scale = self.decay ** counts.astype(np.float64)
        for j, (a, b) in enumerate(pairs.tolist()):
            old_w, old_g = self._book.get((a, b), (0.0, 0.0))
            self._book[(a, b)] = (float(scale[j] * old_w + add_wins[j]), float(scale[j] * old_g + add_games[j]))

    def record(self, learner: int, opponent: int) -> tuple[float, float]:
        """The decayed ``(wins, games)`` of a pair (``(0, 0)`` if unseen)."""
        return self._book.get((int(learner), int(opponent)), (0.0, 0.0))

    def p_win(self, learner: int, opponent: int) -> float:
        """``(wins + 0.5*prior) / (games + prior)``; 0.5 for an unseen pair."""
        w, g = self.record(learner, opponent)
        if g + self.prior <= 0.0:
            return 0.5
        return (w + 0.5 * self.prior) / (g + self.prior)

    def p_win_many(self, learner: int, opponents: Iterable[int]) -> npt.NDArray[np.float64]:
        """:meth:`p_win` for each opponent."""
        return np.array([self.p_win(learner, o) for o in opponents], dtype=np.float64)

    def pairs(self) -> list[tuple[int, int]]:
        """The ``(learner, opponent)`` pairs with a record, sorted."""
        return sorted(self._book)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable state: ``{"decay", "prior", "pairs": [[learner, opponent, wins, games], ...]}``."""
        return {
            "decay": self.decay,
            "prior": self.prior,
            "pairs": [[a, b, self._book[(a, b)][0], self._book[(a, b)][1]] for a, b in sorted(self._book)],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> WinRates:
        """Inverse of :meth:`to_dict`. Raises MarlError on a malformed state (e.g. a corrupt resume file)."""
        try:
            rates = cls(decay=float(data["decay"]), prior=float(data["prior"]))
            for a, b, w, g in data["pairs"]:
                w, g = float(w), float(g)
                if not (math.isfinite(w) and math.isfinite(g) and 0.0 <= w <= g + 1e-9):
                    raise ValueError(f"bad record {w}/{g}")
                rates._book[(int(a), int(b))] = (w, g)
        except (KeyError, TypeError, ValueError) as exc:
            raise MarlError(f"malformed win-rate state: {exc}") from None
        return rates

    @classmethod
    def from_ledger(cls, table_like: Any, learner_ids: Iterable[int], decay: float = 0.99,
                    prior: float = 1.0) -> WinRates:
        """Replay 2-seat games in order (e.g. a :class:`~selfplay_cli.league.store.GameTable`).

        ``table_like`` needs the arrays ``player_a``, ``player_b`` and ``score_a`` (seat 0's points), in
        game order. Every game whose seat-0 player is a learner updates ``(player_a, player_b)`` with
        ``score_a``; every game whose seat-1 player is a learner updates ``(player_b, player_a)`` with
        ``1 - score_a`` (both, if both are learners). The result equals calling :meth:`update` game by game.
        """
        rates = cls(decay=decay, prior=prior)
        pa = np.asarray(table_like.player_a, dtype=np.int64).ravel()
        pb = np.asarray(table_like.player_b, dtype=np.int64).ravel()
        sa = np.asarray(table_like.score_a, dtype=np.float64).ravel()
        if not (pa.shape == pb.shape == sa.shape):
            raise ValueError("player_a, player_b and score_a must have the same length")
        learners = np.fromiter((int(x) for x in learner_ids), dtype=np.int64)
        in_a, in_b = np.isin(pa, learners), np.isin(pb, learners)
        # Interleave the two perspectives of each game in game order (the pairs differ, so the order
        # between the two views of one game does not matter).
        idx = np.concatenate([np.flatnonzero(in_a), np.flatnonzero(in_b)])
        me = np.concatenate([pa[in_a], pb[in_b]])
        opp = np.concatenate([pb[in_a], pa[in_b]])
        sc = np.concatenate([sa[in_a], 1.0 - sa[in_b]])
        order = np.argsort(idx, kind="stable")
        rates._apply(me[order], opp[order], sc[order])
        return rates


def load_win_rates(league: League, env: str, learner_ids: Iterable[int], decay: float = 0.99,
                   prior: float = 1.0, variant: str = "") -> WinRates:
    """The win-rate book of ``learner_ids`` replayed from the league ledger of ``env`` in the run's ``variant`` (for
    a resumed run).

    Uses :meth:`~selfplay_cli.league.ledger.Ledger.games` (2-seat games between different players, in game-id order)
    restricted to games in which a learner sat, then :meth:`WinRates.from_ledger`.
    """
    ids = [int(x) for x in learner_ids]
    table = league.ledger.games(env, players=ids, any_seat=True, rated=False, variant=variant, pooled=False)
    return WinRates.from_ledger(table, ids, decay=decay, prior=prior)
