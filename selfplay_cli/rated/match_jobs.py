"""What ``marl match A B`` plays: the matches two names make (one, one per member of a team, or a cooperative team
flying together), refused in one line where they say nothing, their players loaded, and what the ladder predicted
of each. The command parses and prints; this holds what a test would call without the CLI."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..policies import Policy
from .match import MatchReport, load_player, mix_seed
from .names import Team

__all__ = ["MatchJob", "check_distinct_weights", "forecaster", "match_jobs", "pairings", "predict"]


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
    from ..league.forecast import Forecaster
    from ..league.store import LeagueError
    from .snapshots import players_variant

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
    from ..results import COOPERATIVE
    from .snapshots import player_options

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
    same = league.same_weights()
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
