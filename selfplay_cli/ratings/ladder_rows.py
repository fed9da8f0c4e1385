"""The rows of a ladder: :class:`LadderRow` (one player: its rating and interval, rank, tier, margin over the next
row, record, run and marks), :class:`Margin` (how far one player stands above another, and what a match of the two
would measure) and :class:`BotRecord` (a player's record against one scripted player), each with its JSON.

Plain records: the fit that makes them is :mod:`selfplay_cli.ratings.fit`, the ladder of a league
:mod:`selfplay_cli.ratings.ladder`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

from selfplay_cli.stats.belief import Belief
from selfplay_cli.stats.elo import score_to_elo

__all__ = ["MATCH_GAMES", "BotRecord", "LadderRow", "Margin"]

_JSON_KEYS = ("policy", "kind", "elo", "ci_low", "ci_high", "games", "wins", "draws", "losses", "rank",
              "tier", "score", "step", "flag", "anchor", "run", "best", "margin", "best_margin", "tied", "copy_of",
              "copies", "vs", "league_role", "exploitability", "circle")

MATCH_GAMES = 200  # a margin says what a match of this many games between the two would measure


@dataclass(frozen=True)
class BotRecord:
    """A player's record against one scripted player: ``games`` played and ``points`` scored (draw = 1/2)."""

    bot: str
    games: int
    points: float

    @property
    def score(self) -> float | None:
        """Mean points per game, None without games."""
        return self.points / self.games if self.games else None


@dataclass(frozen=True)
class Margin:
    """How far a player stands above another (``over``): the rating difference ``elo`` with its confidence interval
    ``low .. high`` (from the same covariance as the ladder's intervals, so what the two share through the anchor
    cancels). ``separated``: the whole interval lies above 0.

    That interval is about the pair's expected difference; a match of the two measures it with its own luck. So a
    margin also says what a match of :data:`MATCH_GAMES` games would measure (:attr:`match`, from the pair's belief:
    :meth:`~selfplay_cli.stats.predict.Belief.predict`), the figure a user checks the claim with."""

    over: str
    elo: float
    low: float
    high: float
    record: tuple[int, int, int] = (0, 0, 0)  # the two's own results: wins, draws, losses of the first
    belief: Belief | None = field(default=None, repr=False, compare=False)  # None: a flagged bound's margin

    @property
    def separated(self) -> bool:
        return self.low > 0.0

    @cached_property
    def match(self) -> tuple[float | None, float | None] | None:
        """The central 95% range of the Elo difference a :data:`MATCH_GAMES`-game match of the two measures (the
        range of its score, turned into Elo); an end is None where the score's range reaches 0% or 100% (no finite
        Elo). None for a flagged bound's margin (no pair belief)."""
        if self.belief is None:
            return None
        pred = self.belief.predict(MATCH_GAMES)
        return (None if pred.low <= 0.0 else score_to_elo(pred.low),
                None if pred.high >= 1.0 else score_to_elo(pred.high))

    def to_json(self) -> dict[str, Any]:
        m = self.match
        return {"over": self.over, "elo": round(float(self.elo), 1), "low": round(float(self.low), 1),
                "high": round(float(self.high), 1), "separated": self.separated, "head_to_head": list(self.record),
                "match": None if m is None else {"games": MATCH_GAMES,
                                                 "low": None if m[0] is None else round(m[0], 1),
                                                 "high": None if m[1] is None else round(m[1], 1)}}

    def text(self) -> str:
        """``+97 [+12, +182] Elo over NAME (head to head 40-3-17; 200 games would measure +40 to +160)``: the
        two's own record where they met, and the range a 200-game match of the two lands in 95% of the time."""
        w, d, lo = self.record
        met = f"head to head {w}-{d}-{lo}" if w + d + lo else "they never met"
        m = self.match
        if m is not None:
            low, high = m
            span = (f"{low:+.0f} to {high:+.0f}" if low is not None and high is not None else
                    f"{low:+.0f} or more" if low is not None else f"{high:+.0f} or less" if high is not None else
                    "anything")
            met += f"; {MATCH_GAMES} games would measure {span}"
        return f"{self.elo:+.0f} [{self.low:+.0f}, {self.high:+.0f}] Elo over {self.over} ({met})"


@dataclass(frozen=True)
class LadderRow:
    """One player of a ladder.

    Attributes:
        policy: display name (bot name, ``run/name`` of a snapshot, or the CSV name).
        player_id: league player id (None for CSV players).
        kind: ``"bot"``, ``"snapshot"`` or ``"player"`` (CSV).
        step: training step of a snapshot (None for bots / CSV players).
        elo: fitted Bradley-Terry rating (finite; MAP under a prior, a bound for ML-flagged players).
        ci_low, ci_high: confidence interval of the rating, relative to the anchor.
        games, wins, draws, losses: the player's record in the fitted games.
        score: mean points per game.
        rank: the place in the ladder's order (1, 2, 3, ...: see :mod:`selfplay_cli.ratings.fit`).
        tier: the group of players that cannot be told apart (1: the top's); None for players whose offset to the
            anchor is unknown.
        flag: None, or the fit's flag: ``perfect``, ``zero`` (prior 0 only), ``disconnected``, ``unrated``.
        anchor: True for the anchor player.
        run: the snapshot's run (None for bots, run-less snapshots and CSV players).
        best: True for the best snapshot of its run (highest rating among the run's live snapshots that are
            comparable with the anchor).
        margin: the difference over the next row of the ladder, with its interval (None for the last row and for
            players without a comparable rating).
        best_margin: for a run's best snapshot, its difference over the run's next best (None alone in its run).
        tied: for a run's best snapshot, the run's snapshots it is not separated from, neither above it nor below it
            beyond doubt (empty: the best beyond doubt, save the snapshots a circle of claims puts above it).
        copy_of / copies: one set of weights is one player: its other names (a run repeated with its seed) get a
            row each, with its rating, right under it (``copy_of`` it), and it lists them (``copies``).
        vs: the record against each scripted player of the env, in the league's bot order (empty for CSV
            ladders); a bot's own entry has no games.
        mean_return: the player's mean team return over its cooperative episodes (None in other games).
        side: in a two-sides game whose sides differ (rated per side: see
            :func:`~selfplay_cli.ratings.ladder.ladder`), the side's role(s) this row is rated on (``adversary``); None
            in every other game.
        league_role: the snapshot's role in its league (``meta["league_role"]``: ``main``, ``main_exploiter``,
            ``league_exploiter``, ``exploiter``); None for ordinary snapshots, bots and CSV players.
        exploitability: the exploitability filed for the player
            (:func:`~selfplay_cli.ratings.ladder.shown_exploitability`): its exact figure where there is one, else its
            lower bound, as filed (``kind``, ``value``, ``low``, ``high``, ...); None where none was measured.
    """

    policy: str
    player_id: int | None
    kind: str
    step: int | None
    elo: float
    ci_low: float
    ci_high: float
    games: int
    wins: int
    draws: int
    losses: int
    score: float
    rank: int
    flag: str | None
    anchor: bool
    run: str | None = None
    best: bool = False
    vs: tuple[BotRecord, ...] = ()
    mean_return: float | None = None
    tier: int | None = None
    margin: Margin | None = None
    best_margin: Margin | None = None
    tied: tuple[str, ...] = ()
    copy_of: str | None = None  # another name of the weights of this player (its row just above): one player
    copies: tuple[str, ...] = ()  # the player's other names (the same weights under another run or name)
    side: str | None = None
    league_role: str | None = None
    exploitability: dict[str, Any] | None = None
    circle: tuple[str, ...] = ()  # a circle of claims beyond doubt it is in: itself, above the next, ..., the last
    # above it (self-play's rock-paper-scissors, measured); empty where there is none

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict: ``policy, kind, elo, ci_low, ci_high, games, wins, draws, losses, rank`` then
        ``score, step, flag, anchor, run, best, vs, league_role, exploitability`` (Elo values rounded to 0.1,
        scores to 1e-4; never NaN / inf; ``league_role`` and ``exploitability`` null where the player has none),
        and ``mean_return`` last for a player of a cooperative game, ``side`` for a row of a game rated per side.
        ``vs`` maps each scripted player to ``{"score": s, "games": n}`` (``score`` null without games)."""
        for value in (self.elo, self.ci_low, self.ci_high, self.score):
            assert math.isfinite(value), f"non-finite value in ladder row {self.policy}: {value}"
        out: dict[str, Any] = {
            "policy": self.policy,
            "kind": self.kind,
            "elo": round(float(self.elo), 1),
            "ci_low": round(float(self.ci_low), 1),
            "ci_high": round(float(self.ci_high), 1),
            "games": int(self.games),
            "wins": int(self.wins),
            "draws": int(self.draws),
            "losses": int(self.losses),
            "rank": int(self.rank),
            "tier": self.tier,
            "score": round(float(self.score), 4),
            "step": None if self.step is None else int(self.step),
            "flag": self.flag,
            "anchor": bool(self.anchor),
            "run": self.run,
            "best": bool(self.best),
            "margin": None if self.margin is None else self.margin.to_json(),
            "best_margin": None if self.best_margin is None else self.best_margin.to_json(),
            "tied": list(self.tied),
            "copy_of": self.copy_of,
            "copies": list(self.copies),
            "vs": {v.bot: {"score": None if v.score is None else round(float(v.score), 4), "games": int(v.games)}
                   for v in self.vs},
            "league_role": self.league_role,
            "exploitability": None if self.exploitability is None else dict(self.exploitability),
            "circle": list(self.circle),
        }
        assert tuple(out) == _JSON_KEYS
        if self.mean_return is not None:
            assert math.isfinite(self.mean_return), f"non-finite mean return in ladder row {self.policy}"
            out["mean_return"] = round(float(self.mean_return), 4)
        if self.side is not None:
            out["side"] = self.side
        return out

