"""What ``marl match A B`` plays: the matches two names make (one, one per member of a team, or a cooperative team
flying together), refused in one line where they say nothing, their players loaded, and what the ladder predicted
of each. The command parses and prints; this holds what a test would call without the CLI."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import MarlError
from ..league.seeds import Pair
from ..league.store import League, PlayerRow
from ..players.load import load_player, mix_seed
from ..policies import Policy
from ..ratings.names import Team
from .match import MatchReport, round_size
from .seeds import Ask, Settled, settle

__all__ = ["MatchJob", "Taken", "check_distinct_weights", "forecaster", "match_jobs", "on_their_way", "pairings",
           "predict"]


@dataclass(frozen=True)
class MatchJob:
    """One match of ``marl match``: A's rows (one player, or a cooperative team flying together), B's row, and the
    team's name when A is one."""

    rows_a: tuple[PlayerRow, ...]
    row_b: PlayerRow
    team_name: str | None = None

    def load(self, league: League, first_seed: int, device: str) -> tuple[list[Policy], Policy, dict[str, int]]:
        """A's policies, B's, and the player id of each policy id; each seeded from the match's first seed."""
        pa = [load_player(league, r, device=device, seed=mix_seed(first_seed, 0 if i == 0 else 1 + i))
              for i, r in enumerate(self.rows_a)]
        pb = load_player(league, self.row_b, device=device, seed=mix_seed(first_seed, 1))
        ids = {**{p.id: r.id for p, r in zip(pa, self.rows_a, strict=True)}, pb.id: self.row_b.id}
        return pa, pb, ids

    def ask(self, league: League, games: int, seed: int | None, options: dict[str, Any] | None) -> Ask:
        """The match's games as :func:`~selfplay_cli.evaluation.seeds.settle` takes them: ``games`` more, after every
        seed the pair has (or from the user's ``seed``), in the variant the players and ``options`` make."""
        from ..players.snapshots import players_variant

        variant = players_variant(league, self.row_b.env, [*self.rows_a, self.row_b], options)
        return Ask(self.rows_a[0].id, self.row_b.id, games, variant, seed=seed)

    def take_here(self, league: League, games: int, seed: int | None, options: dict[str, Any] | None,
                  device: str, looked: Callable[[], None] | None = None) -> Taken:
        """Take the seeds of the match's ``games`` to play them in this process (:mod:`selfplay_cli.evaluation.seeds`;
        ``looked``: see :func:`~selfplay_cli.evaluation.seeds.settle`), its players loaded from the first of them."""
        from .jobs import worker_name

        def write(settled: list[Settled], seen: Mapping[Pair, int]) -> Taken:
            (d,) = settled
            first = int(d.first_seed)  # type: ignore[arg-type]
            pa, pb, ids = self.load(league, first, device)
            per = round_size(pa[0], pb, first_seed=first, env_options=options,
                             team=pa if self.team_name else None)
            rounds = -(-games // per)
            (rid,) = league.seeds.take_seeds([d.claim(first, rounds, rounds * per)], seen, worker_name("marl"))
            return Taken(first, rounds, on_their_way(d), rid, (pa, pb, ids))

        return settle(league, [self.ask(league, games, seed, options)], write, looked=looked)[1]

    def take_queued(self, league: League, games: int, seed: int | None, options: dict[str, Any] | None, *,
                    sprt: Any = None, confidence: float = 0.95, device: str = "cpu") -> tuple[Any, Taken]:
        """Queue the match's ``games`` as jobs that take their seeds as they are queued
        (:func:`~selfplay_cli.evaluation.queued.queue_match`); the :class:`~selfplay_cli.evaluation.queued.QueuedMatch`
        and its seeds."""
        from .queued import queue_match

        def write(settled: list[Settled], seen: Mapping[Pair, int]) -> Any:
            (d,) = settled
            first = int(d.first_seed)  # type: ignore[arg-type]
            return queue_match(league, list(self.rows_a), self.row_b, games=games, first_seed=first,
                               env_options=options, team_name=self.team_name, sprt=sprt, confidence=confidence,
                               device=device, seeds=d, seen=seen)

        (d,), queued = settle(league, [self.ask(league, games, seed, options)], write)
        rounds = sum(int(j.spec["rounds"]) for j in league.queue.jobs(batch=queued.batch))
        return queued, Taken(int(d.first_seed), rounds, on_their_way(d))  # type: ignore[arg-type]

    def settle_here(self, league: League, taken: Taken, report: MatchReport) -> None:
        """After the match ended of itself (an SPRT decided before its last game), cut its seeds to the rounds it
        played: the pair's next games start right after them."""
        played = len(report.round_points)
        if taken.range_id is not None and not report.interrupted and 0 < played < taken.rounds:
            league.seeds.settle_seeds(taken.range_id, played, report.games)


@dataclass(frozen=True)
class Taken:
    """The seeds a match took: ``rounds`` rounds from ``first_seed`` (the range ``range_id``, when taken to be played
    here, and its players loaded from it: ``loaded``); ``after``: the games of the pair on their way already, that it
    starts after (batch or command -> games)."""

    first_seed: int
    rounds: int
    after: dict[str, int]
    range_id: int | None = None
    loaded: tuple[list[Policy], Policy, dict[str, int]] | None = None


def on_their_way(settled: Settled) -> dict[str, int]:
    """The games of the pair on their way in queued jobs, whatever their variant, that ``settled``'s new games start
    after: batch -> games."""
    out: dict[str, int] = {}
    for r in settled.look.ranges:
        if r.queued:
            out[r.owner] = out.get(r.owner, 0) + r.games
    return out


def match_jobs(league: League, a: str, side_a: PlayerRow | Team, b: str, side_b: PlayerRow | Team,
               sprt: bool = False, options: dict[str, Any] | None = None) -> tuple[list[MatchJob], Team | None]:
    """The matches ``marl match A B`` plays, and the team flying together in one of them (None: each member of a
    team, if one is named, plays alone); refused in one line as :func:`pairings` and
    :func:`check_distinct_weights` say. ``options``: the command's ``--env-option`` (the game's kind may follow
    them, and the options the team was made for)."""
    crew = _flying_team(league, side_a, side_b, a, b, options)
    jobs = ([MatchJob(tuple(crew.members), side_b, crew.full_name)] if crew is not None  # type: ignore[arg-type]
            else [MatchJob((row_a,), row_b) for row_a, row_b in pairings(a, side_a, b, side_b, sprt=sprt)])
    check_distinct_weights(league, [(r, job.row_b) for job in jobs for r in job.rows_a])
    return jobs, crew


def forecaster(league: Any, env: str, rows: list[PlayerRow], options: dict[str, Any] | None) -> Any:
    """The ladder's forecaster of the variant the match is filed in, as it stands before the match (None when that
    ladder has no rated games)."""
    from ..league.store import LeagueError
    from ..players.snapshots import players_variant
    from ..ratings.forecast import Forecaster

    try:
        return Forecaster.of_league(league, env, variant=players_variant(league, env, rows, options))
    except (LeagueError, MarlError):
        return None


def predict(forecast: Any, a: PlayerRow, b: PlayerRow, report: MatchReport) -> Any:
    """What the ladder before the match predicted of its results (None for players it cannot predict)."""
    from ..league.store import LeagueError

    results = report.wins + report.draws + report.losses
    try:
        return forecast.predict(a.full_name, b.full_name, results) if results else None
    except LeagueError:
        return None


def _flying_team(league: League, side_a: Any, side_b: Any, a: str, b: str,
                 options: dict[str, Any] | None = None) -> Team | None:
    """The team that flies together in one match (a cooperative game's per-seat snapshots, named first; the game as
    the team's options, and ``options`` over them, make it: a PettingZoo game trained with ``--kind cooperative``),
    or None (each member then plays alone, as in a two-sides game)."""
    from ..envs import get_env
    from ..players.snapshots import player_options
    from ..results import COOPERATIVE

    team = side_a if isinstance(side_a, Team) else side_b if isinstance(side_b, Team) else None
    if team is None:
        return None
    spec = get_env(team.env)
    if spec.make_kind is not None:  # a game whose options may choose its kind
        try:
            spec = spec.for_options(**{**player_options(league, team.members[0]), **(options or {})})
        except (TypeError, ValueError) as e:
            raise MarlError(f"{team.full_name}: {e}") from None
    if spec.kind != COOPERATIVE:
        return None
    if team is side_b:
        raise MarlError(f"'{b}' is a team that flies together: name it first (marl match {b} {a})")
    if isinstance(side_b, Team):
        raise MarlError(f"'{a}' and '{b}' are both teams: match each against a scripted player")
    return team


def check_distinct_weights(league: Any, pairs: list[tuple[PlayerRow, PlayerRow]]) -> None:
    """Refuse, in one line, a match between two names of the same weights: one player (a run repeated with its
    seed), whose games against itself would say nothing."""
    same = league.ledger.same_weights()
    for x, y in pairs:
        if same.get(x.id, x.id) == same.get(y.id, y.id):
            raise MarlError(f"{x.full_name} and {y.full_name} hold the same weights: they are one player, rated as one "
                            "(marl league ladder shows it once, its other names under it)")


def pairings(a: str, side_a: PlayerRow | Team, b: str, side_b: PlayerRow | Team,
             sprt: bool = False) -> list[tuple[PlayerRow, PlayerRow]]:
    """The matches ``marl match A B`` plays: one, or one per member when one side names a team. Refused in one line:
    the same player twice (``latest best`` when the newest snapshot is also the best), two teams, a team under
    ``--sprt`` (one test, one verdict)."""
    if isinstance(side_a, Team) and isinstance(side_b, Team):
        raise MarlError(f"'{a}' and '{b}' are both teams: match one member of each, e.g. marl match "
                        f"{side_a.members[0].full_name} {side_b.members[0].full_name}")
    team = side_a if isinstance(side_a, Team) else side_b if isinstance(side_b, Team) else None
    if team is not None and sprt:
        name = a if team is side_a else b
        raise MarlError(f"--sprt tests one pair of policies, and '{name}' is a team ({team.describe()}): name one "
                        "member")
    if team is None:
        pairs = [(side_a, side_b)]
    elif team is side_a:
        pairs = [(m, side_b) for m in team.members]
    else:
        pairs = [(side_a, m) for m in team.members]
    for x, y in pairs:  # type: ignore[misc]
        if x.id == y.id:
            said = f"'{a}' and '{b}' are the same player, {x.full_name}" if a != b else f"'{a}' on both sides"
            other = "cpu" if not x.is_bot or x.name != "cpu" else "random"
            raise MarlError(f"{said}: a match needs two different players (e.g. marl match {x.full_name} {other}; "
                            "marl checkpoint list shows the snapshots)")
    return pairs  # type: ignore[return-value]
