"""Rated play: league players become policies, play fair rounds in the whole-game loop (:mod:`selfplay_cli.play`), and
land in the ledger.

A match between A and B plays *rounds* on shared seeds, as the game's kind asks (:mod:`selfplay_cli.play.schedule`):

* two-sides: game pairs, each seed once with A on the first side and once on the second, so the serve luck and the
  seat cancel out within a pair; statistics and the SPRT count pairs (pentanomial);
* cooperative: each seed once flown by A on every seat and once by B, the higher team return winning (within the
  game's tie tolerance: a draw); one comparison per seed, and the SPRT counts comparisons (trinomial);
* free-for-all: every rotation of the seating on each seed; one result per game from the final order of A's and B's
  scores, the SPRT counting results (trinomial) after each whole round.

In a game whose seats hold different roles each player sits only on seats of its own role (:mod:`.roles`): in a
two-sides game whose sides differ a round is then one game, each on its own side, counted as a result, not a pair
(trinomial); two players of the same role cannot meet, and the match is refused in one line.

Results are stored chunk by chunk, each chunk in one transaction, so a match killed midway leaves whole rounds,
consistent games, in the ledger.

With an SPRT the match checks the log-likelihood ratio after every round (the GSPRT of fishtest and fastchess) and
stops at the first round where it crosses a bound; games played beyond that round in the last batch are discarded,
so the test is exactly sequential.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..errors import MarlError
from ..league.store import League
from ..league.variants import variant_key, variant_options
from ..play import Game, play
from ..play.schedule import CannotMeet, round_of, rounds
from ..players.load import check_fits, env_options_of
from ..policies import Policy
from ..policies.resize import describe_resize, resize_members
from ..results import COOPERATIVE, TWO_SIDES, GameResult, Rules, crew, points_between
from ..signals import signals_held
from ..stats.match import MatchStats, points_stats
from ..stats.sprt import SPRT, round_counts
from .roles import cannot_meet_message, policy_roles


def pentanomial(pair_points: np.ndarray) -> tuple[int, int, int, int, int]:
    """Counts of game pairs by A's points in the pair: (0, 0.5, 1, 1.5, 2) -> (LL, LD, WL+DD, WD, WW)."""
    idx = np.rint(np.asarray(pair_points, dtype=np.float64) * 2).astype(np.int64)
    counts = np.bincount(idx, minlength=5)[:5]
    return tuple(int(c) for c in counts)  # type: ignore[return-value]


@dataclass(frozen=True)
class SPRTSettings:
    elo0: float = 0.0
    elo1: float = 10.0
    alpha: float = 0.05
    beta: float = 0.05

    def __post_init__(self) -> None:
        if not self.elo0 < self.elo1:
            raise MarlError(f"--elo0 ({self.elo0}) must be below --elo1 ({self.elo1})")
        if not (0 < self.alpha < 0.5 and 0 < self.beta < 0.5):
            raise MarlError("--alpha and --beta must lie in (0, 0.5)")


def _number(x: float) -> int | float:
    """A total of scores as it reads best: a whole number as an int (Pong's points), else rounded to 1e-4."""
    return int(x) if float(x).is_integer() else round(float(x), 4)


@dataclass
class MatchReport:
    env: str
    a: str
    b: str
    games: int  # games played (a cooperative comparison is two of them)
    wins: int  # A's results against B: per game (two-sides, free-for-all) or per comparison (cooperative)
    draws: int
    losses: int
    points_for: int | float  # A's scores summed over all games (its sides' points, its team returns, its seats')
    points_against: int | float
    pentanomial: tuple[int, int, int, int, int]  # game pairs of a two-sides game (zeros for the other kinds)
    stats: MatchStats
    seconds: float
    match_id: int | None
    first_seed: int
    sprt: dict[str, Any] | None = None
    truncated: int = 0
    game_steps: int = 0  # steps of every game played, summed (one step of one game, all its seats acting)
    results: list[GameResult] = field(default_factory=list, repr=False)
    game_ids: list[int] = field(default_factory=list, repr=False)  # ledger ids of the stored games, in order
    interrupted: bool = False  # stopped by Ctrl-C: the whole rounds finished by then
    kind: str = TWO_SIDES  # the game's kind
    variant: str = ""  # the key of the variant its games were played in (and are rated in): "" for the default
    predicted: Any = None  # what the ladder predicted of these games before they were played (a ScorePrediction)
    round_points: list[list[float]] = field(default_factory=list, repr=False)  # A's points in each round, in order
    seating: tuple[str, ...] | None = None  # a team flown at another size: its member on each seat
    seating_rule: str = ""  # and the rule that seated them, in words (describe_resize)
    step_limit: int | None = None  # the most steps a game lasts, as the game declares it for these options
    tie_tolerance: float = 0.0  # scores closer than this are level (a draw), as the game declares it
    after_queued: dict[str, int] = field(default_factory=dict)  # games of the pair queued already when it started,
    # by batch: it played new seeds after theirs

    @property
    def held(self) -> bool | None:
        """Whether the measured score lies in the ladder's predicted interval (None without a prediction)."""
        return None if self.predicted is None else self.predicted.holds(self.stats.score)
    paired: bool = True  # a two-sides game's rounds are seat-swapped pairs (False: one game a seed, sides that differ)

    @property
    def games_per_second(self) -> float:
        return self.games / self.seconds if self.seconds > 0 else float("inf")

    @property
    def result_unit(self) -> str:
        """What one of A's wins, draws or losses is: a ``comparison`` of team returns (cooperative: two episodes,
        one each, on one seed) or a ``game`` (two-sides: a game, scored in pairs too; free-for-all: a game, from
        the order of A's and B's scores)."""
        return "comparison" if self.kind == COOPERATIVE else "game"

    @property
    def n_results(self) -> int:
        """A's results against B, each a :attr:`result_unit`: what W + D + L add up to."""
        return self.wins + self.draws + self.losses

    @property
    def mean_returns(self) -> tuple[float, float] | None:
        """A's and B's mean team return per episode (cooperative games), else None."""
        if self.kind != COOPERATIVE or not self.results:
            return None
        per = max(self.games // 2, 1)
        return float(self.points_for) / per, float(self.points_against) / per

    def to_json(self) -> dict[str, Any]:
        s = self.stats
        out = {
            "env": self.env, "a": self.a, "b": self.b, "games": self.games,
            "results": self.n_results, "result_unit": self.result_unit,  # what W + D + L count
            "wins": self.wins, "draws": self.draws, "losses": self.losses,
            "score": round(s.score, 4), "points_for": self.points_for, "points_against": self.points_against,
            "elo": round(s.elo, 1), "elo_low": round(s.elo_low, 1), "elo_high": round(s.elo_high, 1),
            "confidence": s.confidence, "bounded": s.bounded, "los": round(s.los, 4),
            "pentanomial": list(self.pentanomial), "truncated_games": self.truncated, "step_limit": self.step_limit,
            "seconds": round(self.seconds, 3), "games_per_second": round(self.games_per_second, 1),
            "game_steps": self.game_steps,
            "game_steps_per_second": round(self.game_steps / self.seconds) if self.seconds > 0 else None,
            "match_id": self.match_id, "first_seed": self.first_seed, "sprt": self.sprt,
            "game_ids": self.game_ids, "interrupted": self.interrupted, "kind": self.kind,
            "variant": variant_options(self.variant),
            "predicted": None if self.predicted is None else {**self.predicted.to_json(), "held": self.held},
            "paired": self.paired,
            "after_queued": [{"batch": b, "games": n} for b, n in self.after_queued.items()],
        }
        if self.seating is not None:
            out["seating"] = list(self.seating)
            out["seating_rule"] = self.seating_rule
        if self.mean_returns is not None:
            out["mean_return"] = {"a": round(self.mean_returns[0], 4), "b": round(self.mean_returns[1], 4)}
        return out


class MatchInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_match`. The whole rounds finished by then are stored (their match row says
    ``status: interrupted`` and how many games it holds); ``report`` describes them. A ``KeyboardInterrupt``, so
    code that does not know it stops as before."""

    def __init__(self, report: MatchReport) -> None:
        super().__init__(f"interrupted after {report.games} games")
        self.report = report


def run_match(
    a: Policy,
    b: Policy,
    *,
    games: int,
    first_seed: int = 0,
    parallel: int = 1024,
    league: League | None = None,
    player_ids: dict[str, int] | None = None,
    kind: str = "match",
    sprt: SPRTSettings | None = None,
    confidence: float = 0.95,
    on_games: Callable[[int], None] | None = None,
    env_options: dict[str, Any] | None = None,
    team: Sequence[Policy] | None = None,
    team_name: str | None = None,
    rounds: int | None = None,
) -> MatchReport:
    """Play up to ``games`` games (rounded up to whole rounds, see the module docstring) between ``a`` and ``b`` and
    report from A's view.

    With ``league`` (and ``player_ids`` mapping policy ids to player ids) every chunk of games is stored as it
    finishes, each chunk in one transaction; the match row is created with the first chunk (so it never exists
    without games) and its ``params`` say ``status``: ``running``, then ``finished``, ``interrupted`` or ``failed``,
    with ``games_stored``. With ``sprt`` the match stops at the first round whose LLR crosses a bound.
    ``env_options`` override the game options the players were made for (``landers=4`` flies a team trained with
    2 landers as 4); each network must still fit the seats those options make.

    ``team`` (a cooperative game only): A is that team of policies flying together, member i on seat i (a team
    flown at another number of seats is seated by :func:`~selfplay_cli.policies.resize.resize_members`, drawn from
    ``first_seed``: the report's ``seating`` names the member on each seat); ``a`` is then its first member and
    ``team_name`` names it in the report.

    ``rounds``: play exactly this many rounds (``games`` then only has to be positive): round ``r`` is played on seed
    ``first_seed + r``, so the rounds ``[k, k + n)`` of a match are the match of ``n`` rounds from seed
    ``first_seed + k`` (a queued match is cut into jobs that way).

    Ctrl-C raises :class:`MatchInterrupted` after storing the whole rounds already finished (of the chunk in play
    too: half a pair would leave its seed's seat luck uncancelled, half a comparison compares nothing; they are
    dropped).
    """
    match = _setup(a, b, games=games, first_seed=first_seed, league=league, player_ids=player_ids, kind=kind,
                   confidence=confidence, on_games=on_games, env_options=env_options, team=team, team_name=team_name)
    n_rounds = -(-games // match.per) if rounds is None else int(rounds)
    chunk_rounds = max(1, parallel // match.per)
    if sprt is not None:
        chunk_rounds = max(1, min(chunk_rounds, 64))  # smaller batches waste fewer games past the decision
        match.test = SPRT(elo0=sprt.elo0, elo1=sprt.elo1, alpha=sprt.alpha, beta=sprt.beta)
    match.params = {"a": match.a_name, "b": b.id, "games": games if rounds is None else n_rounds * match.per,
                    "first_seed": first_seed, "env_options": match.options, "status": "running"}
    if match.team_seats is not None:  # who flew each seat (a team at another size: seed 001's rule's draw)
        match.params["seating"] = [match.roster[i].id for i in match.team_seats]
    if sprt is not None:
        match.params["sprt"] = asdict(sprt)
    match.play(n_rounds, chunk_rounds, parallel)
    out = match.report()
    if sprt is not None:
        test = match.test
        assert test is not None
        out.sprt = {"elo0": sprt.elo0, "elo1": sprt.elo1, "alpha": sprt.alpha, "beta": sprt.beta,
                    "llr": round(match.llr, 4), "lower": round(test.lower, 4), "upper": round(test.upper, 4),
                    "decision": match.decision, "pairs": len(match.round_points)}
        if not match.paired:
            out.sprt["model"] = "trinomial"
    return out


def round_size(a: Policy, b: Policy, *, first_seed: int = 0, env_options: dict[str, Any] | None = None,
               team: Sequence[Policy] | None = None) -> int:
    """The games of one round of a match between ``a`` and ``b`` (see the module docstring), refused in one line
    where :func:`run_match` would refuse them."""
    return _setup(a, b, games=1, first_seed=first_seed, env_options=env_options, team=team).per


def _setup(a: Policy, b: Policy, *, games: int, first_seed: int, league: League | None = None,
           player_ids: dict[str, int] | None = None, kind: str = "match", confidence: float = 0.95,
           on_games: Callable[[int], None] | None = None, env_options: dict[str, Any] | None = None,
           team: Sequence[Policy] | None = None, team_name: str | None = None) -> _Match:
    """The :class:`_Match` of :func:`run_match`'s arguments, checked, its rounds planned."""
    members = list(team) if team else [a]
    for m in members:
        if m.env != b.env:
            raise MarlError(f"{m.id} plays {m.env} but {b.id} plays {b.env}")
        if m.id == b.id:
            raise MarlError(f"a match needs two different players, got {b.id} twice")
    if games < 1:
        raise MarlError(f"--games must be at least 1, not {games}")
    if league is not None and player_ids is None:
        raise ValueError("player_ids are needed to store games")
    options = {**env_options_of(*members, b), **(env_options or {})}
    spec = get_env(b.env).for_options(**options)
    check_fits(spec, options, *members, b)
    match = _Match(spec=spec, rules=Rules.of(spec), options=options, a=a, b=b, roster=[a, b], a_name=team_name or a.id,
                   first_seed=first_seed, confidence=confidence, league=league, player_ids=player_ids, kind=kind,
                   on_games=on_games)
    if team:
        match.seat_team(members)
    match.plan_rounds()
    return match


@dataclass
class _Match:
    """One call of :func:`run_match` once its players are checked: what it plays (the game, the roster of policies,
    how A is seated and known in the results, the seatings of one round), the games it has kept and filed, and the
    SPRT's state."""

    spec: EnvSpec
    rules: Rules
    options: dict[str, Any]
    a: Policy
    b: Policy
    roster: list[Policy]
    a_name: str
    first_seed: int
    confidence: float
    league: League | None
    player_ids: dict[str, int] | None
    kind: str
    on_games: Callable[[int], None] | None
    a_key: Any = None  # what A is in the results: a policy's id, or the ids of a team's members
    team_seats: tuple[int, ...] | None = None
    roles: dict[int, Any] = field(default_factory=dict)
    per: int = 1  # games per round
    paired: bool = False  # rounds are seat-swapped pairs: pentanomial statistics
    test: SPRT | None = None
    params: dict[str, Any] = field(default_factory=dict)
    match_id: int | None = None
    kept: list[GameResult] = field(default_factory=list)
    game_ids: list[int] = field(default_factory=list)
    round_points: list[list[float]] = field(default_factory=list)  # A's points in each round's results against B
    decision: str | None = None
    llr: float = 0.0
    in_play: list[GameResult] = field(default_factory=list)
    start: float = 0.0

    def __post_init__(self) -> None:
        self.a_key = self.a.id

    def seat_team(self, members: list[Policy]) -> None:
        """A is a team flying together: member i on seat i; at another number of seats, seated by seed 001's rule
        (:func:`~selfplay_cli.policies.resize.resize_members`, drawn from the first seed)."""
        rules = self.rules
        if rules.kind != COOPERATIVE:
            raise MarlError(f"a team flies together only in a cooperative game; {self.spec.name} is {rules.kind}")
        self.roster = [*members, self.b]
        self.team_seats = tuple(resize_members(len(members), rules.n_seats, self.first_seed))
        self.a_key = tuple(sorted({members[i].id for i in self.team_seats}))

    def plan_rounds(self) -> None:
        """Who may sit where, and the games of one round (a two-sides game whose sides differ: one)."""
        rules, roster = self.rules, self.roster
        self.roles = roles = {i: policy_roles(p, self.spec) for i, p in enumerate(roster)}  # None: anywhere
        b_index = len(roster) - 1
        try:
            self.per = len(round_of(rules, (self.team_seats if self.team_seats is not None else 0, b_index),
                                    self.first_seed, roles))
        except CannotMeet:
            raise MarlError(cannot_meet_message(self.spec.name, rules, self.a_name, roles[0], self.b.id,
                                                roles[b_index])) from None
        self.paired = rules.kind == TWO_SIDES and self.per == 2

    def schedule(self, done: int, n: int) -> list[Game]:
        """The games of ``n`` rounds from the ``done``-th on."""
        first, rules = self.first_seed + done, self.rules
        if self.team_seats is None:
            return rounds(rules, (0, 1), n, first_seed=first, roles=self.roles)
        # the team's episode and B's on each seed: one comparison
        b_index = len(self.roster) - 1
        return [g for r in range(n)
                for g in (Game(first + r, self.team_seats), Game(first + r, (b_index,) * rules.n_seats))]

    def play(self, n_rounds: int, chunk_rounds: int, parallel: int) -> None:
        """Play chunk after chunk of rounds until ``n_rounds`` or an SPRT decision, keeping and filing each
        chunk's whole rounds; the match row's status says how it ended (:class:`MatchInterrupted` on Ctrl-C)."""
        self.start = time.perf_counter()
        done = 0
        try:
            while done < n_rounds and self.decision is None:
                n = min(chunk_rounds, n_rounds - done)
                self.in_play = []
                play(self.spec, self.roster, self.schedule(done, n), parallel=parallel, env_options=self.options,
                     on_result=self.on_result, record_actions=self.league is not None)
                self.keep()
                done += n
        except KeyboardInterrupt:
            self.keep()
            self.set_status("interrupted")
            interrupted = self.report()
            interrupted.interrupted = True
            raise MatchInterrupted(interrupted) from None
        except BaseException:
            with contextlib.suppress(Exception):  # say so on the row, if the database still takes it (a full disk
                self.set_status("failed")  # may not)
            raise
        self.set_status("finished")

    def on_result(self, r: GameResult) -> None:
        self.in_play.append(r)
        if self.on_games is not None:
            self.on_games(1)

    def keep(self) -> None:
        """The whole rounds of the chunk in play, kept and filed (the rest dropped)."""
        new = self.take(self.in_play)
        self.in_play = []
        self.store(new)
        self.kept += new

    def take(self, finished: list[GameResult]) -> list[GameResult]:
        """The whole rounds among ``finished`` (results of one chunk), in order, up to an SPRT decision."""
        per = self.per
        by_index = {r.index: r for r in finished}
        new: list[GameResult] = []
        for i in sorted({r.index // per for r in finished}):
            got = [by_index.get(per * i + k) for k in range(per)]
            if any(g is None for g in got):
                continue
            new += got  # type: ignore[arg-type]
            self.round_points.append(points_between(self.rules, got, self.a_key, self.b.id))  # type: ignore[arg-type]
            if self.test is not None:
                self.llr = self.test.llr(*round_counts(self.round_points, self.paired))
                self.decision = self.test.decide(self.llr)
                if self.decision is not None:
                    break
        return new

    def store(self, new: list[GameResult]) -> None:
        """File ``new`` in one transaction (the match row with the first of them)."""
        if self.league is None or not new:
            return
        records = [r.with_players(self.player_ids) for r in new]  # type: ignore[arg-type]
        with signals_held():  # a Ctrl-C now waits until the games are stored and counted
            if self.match_id is None:
                self.match_id, ids = self.league.ledger.create_match_with_games(self.spec.name, self.kind, self.params,
                                                                                records)
            else:
                ids = self.league.ledger.record_games(self.match_id, records)
            self.game_ids.extend(ids)

    def set_status(self, status: str) -> None:
        if self.match_id is not None:
            self.league.ledger.update_match(self.match_id, status=status,  # type: ignore[union-attr]
                                            games_stored=len(self.game_ids))

    def report(self) -> MatchReport:
        out = _report(self.spec.name, self.rules, self.paired, self.a_name, self.a_key, self.b, self.kept,
                      self.round_points, time.perf_counter() - self.start, self.match_id, self.first_seed,
                      self.confidence, self.game_ids)
        out.variant = variant_key(self.spec.name, self.options)
        out.step_limit = self.spec.max_steps(self.spec.config(**self.options))
        if self.team_seats is not None and len(self.team_seats) != len(self.roster) - 1:  # a team resized
            out.seating = tuple(self.roster[i].id for i in self.team_seats)
            out.seating_rule = describe_resize(len(self.roster) - 1, len(self.team_seats),
                                               f"the match's first seed ({self.first_seed})")
        return out


def _report(env: str, rules: Rules, paired: bool, a_name: str, a_key: Any, b: Policy, kept: list[GameResult],
            round_points: list[list[float]], seconds: float, match_id: int | None, first_seed: int, confidence: float,
            game_ids: list[int]) -> MatchReport:
    pts = np.array([x for p in round_points for x in p])
    wins, draws, losses = int((pts > 0.5).sum()), int((pts == 0.5).sum()), int((pts < 0.5).sum())
    penta = pentanomial(np.array([sum(p) for p in round_points])) if paired else (0, 0, 0, 0, 0)
    return MatchReport(
        env=env, a=a_name, b=b.id, games=len(kept), wins=wins, draws=draws, losses=losses,
        points_for=_number(sum(_score_of(r, a_key) for r in kept)),
        points_against=_number(sum(r.score_of(b.id) for r in kept)),
        pentanomial=penta, stats=points_stats(round_points, paired, confidence),
        seconds=seconds, match_id=match_id, first_seed=first_seed, truncated=sum(r.truncated for r in kept),
        game_steps=sum(r.length for r in kept),
        results=kept, game_ids=game_ids, kind=rules.kind, paired=paired, round_points=round_points,
        tie_tolerance=rules.tie_tolerance,
    )


def _score_of(r: GameResult, key: Any) -> float:
    """A's score in one game: its seats' (a policy's id), or the team return of its crew's episodes (a team)."""
    if isinstance(key, tuple):
        return float(sum(r.scores)) if frozenset(r.players) == crew(key) else 0.0
    return r.score_of(key)


def sprt_exit_code(report: MatchReport) -> int:
    """0 when H1 is accepted, 1 when H0 is, 3 when the game budget ran out first."""
    assert report.sprt is not None
    return {"H1": 0, "H0": 1}.get(report.sprt["decision"], 3)

