"""The strength gate: is Elo(candidate) - Elo(baseline) at least D, with confidence?"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..league.seeds import Pair
from ..league.store import League, PlayerRow
from ..players.load import load_player, mix_seed
from ..players.snapshots import players_variant
from ..stats.match import MatchStats, match_stats, points_stats
from .match import round_size, run_match
from .seeds import Settled


@dataclass(frozen=True)
class GateVerdict:
    candidate: str
    baseline: str
    min_diff: float
    confidence: float
    stats: MatchStats  # two-sided interval at level 2 * confidence - 1: its low end is the one-sided bound
    stored_games: int
    played_games: int
    passed: bool

    @property
    def reason(self) -> str:
        s = self.stats
        cmp = ">=" if self.passed else "<"
        return (f"Elo({self.candidate}) - Elo({self.baseline}) = {s.elo:+.1f}, {100 * self.confidence:g}% lower "
                f"bound {s.elo_low:+.1f} {cmp} {self.min_diff:+g} over {s.games} games "
                f"({s.wins} W {s.draws} D {s.losses} L; {self.stored_games} stored, {self.played_games} played)")

    def to_json(self) -> dict[str, Any]:
        s = self.stats
        return {"candidate": self.candidate, "baseline": self.baseline, "passed": self.passed,
                "min_diff": self.min_diff, "confidence": self.confidence, "elo": round(s.elo, 1),
                "lower_bound": round(s.elo_low, 1), "games": s.games, "wins": s.wins, "draws": s.draws,
                "losses": s.losses, "stored_games": self.stored_games, "played_games": self.played_games,
                "reason": self.reason}


def gate_check(league: League, cand: PlayerRow, base: PlayerRow, *, min_diff: float, games: int,
               confidence: float = 0.95, parallel: int = 1024, device: str = "cpu",
               env_options: dict[str, Any] | None = None, queue: bool = False) -> GateVerdict:
    """Reuse the stored head-to-head games, play (and store) the missing ones, then test the lower bound. With
    ``queue`` the missing games go on the league's work queue, played by the workers attached and by this process.

    The games are those of one variant: played under the options the two were made for with ``env_options`` (a
    command's ``--env-option``) over them, and only the stored games of that variant count.

    The bound comes from the pairwise results of the game's kind (:func:`~selfplay_cli.ratings.pairs.head_to_head`):
    its variance from the game pairs of a two-sides game (pentanomial), from the results themselves otherwise."""
    from ..ratings.pairs import head_to_head

    if cand.id == base.id:
        from ..errors import MarlError

        raise MarlError(f"the candidate and the baseline are the same player ({cand.full_name})")
    same = league.ledger.same_weights(cand.env)
    if same.get(cand.id, cand.id) == same.get(base.id, base.id):
        from ..errors import MarlError

        raise MarlError(f"{cand.full_name} and {base.full_name} hold the same weights: one player, not stronger "
                        "than itself")
    variant = players_variant(league, cand.env, [cand, base], env_options)
    h2h = head_to_head(league, cand.id, base.id, variant=variant)
    stored = h2h["games"]  # ledger games (a cooperative comparison is two episodes)
    report, played = None, 0
    if stored < games:
        joined, report = _play(league, cand, base, games - stored, variant, env_options, queue, device, parallel)
        if joined:  # the pair's games another command queued, seen through: in the ledger now, with ours
            h2h, report = head_to_head(league, cand.id, base.id, variant=variant), None
        played = h2h["games"] - stored + (report.games if report is not None else 0)
    wins, draws, losses = h2h["wins"], h2h["draws"], h2h["losses"]
    penta = list(h2h["pentanomial"])
    rounds = list(h2h["rounds"])
    if report is not None:
        wins, draws, losses = wins + report.wins, draws + report.draws, losses + report.losses
        penta = [x + y for x, y in zip(penta, report.pentanomial, strict=True)]
        rounds += report.round_points
    if any(x not in (0.0, 0.5, 1.0) for r in rounds for x in r):  # a game played for stakes: by the points won
        stats = points_stats(rounds, paired=True, confidence=2 * confidence - 1)
    else:
        stats = match_stats(wins, draws, losses, pentanomial=tuple(penta) if sum(penta) else None,
                            confidence=2 * confidence - 1)
    return GateVerdict(cand.full_name, base.full_name, min_diff, confidence, stats, stored, played,
                       passed=stats.elo_low >= min_diff)


def _play(league: League, cand: PlayerRow, base: PlayerRow, games: int, variant: str,
          env_options: dict[str, Any] | None, queue: bool, device: str, parallel: int) -> tuple[bool, Any]:
    """The ``games`` the pair misses (:mod:`.seeds`): those on their way in the queue already (another gate of the pair
    queued at the same moment, a tournament) joined and seen through, played here with the workers attached; the
    rest played and stored on seeds after every seed the pair has, queued or here. Whether any were joined, and the
    report of the new games (None: none)."""
    from .jobs import see_through, worker_name
    from .queued import dead_jobs_error, queue_match
    from .seeds import Ask, settle

    def write(settled: list[Settled], seen: Mapping[Pair, int]) -> Any:
        (d,) = settled
        if not d.games:
            return None
        first = int(d.first_seed)  # type: ignore[arg-type]
        if queue:
            return queue_match(league, [cand], base, games=d.games, first_seed=first, match_kind="gate",
                               env_options=env_options, device=device, seeds=d, seen=seen)
        pa = load_player(league, cand, device=device, seed=mix_seed(first, 0))
        pb = load_player(league, base, device=device, seed=mix_seed(first, 1))
        per = round_size(pa, pb, first_seed=first, env_options=env_options)
        rounds = -(-d.games // per)
        league.seeds.take_seeds([d.claim(first, rounds, rounds * per)], seen, worker_name("marl"))
        return first, d.games, pa, pb

    (d,), new = settle(league, [Ask(cand.id, base.id, games, variant, joins=True)], write)
    by_batch: dict[str, list[int]] = {}
    for r in d.joined:
        if r.job_id is not None:
            by_batch.setdefault(r.owner, []).append(r.job_id)
    for batch, ids in by_batch.items():
        dead = dead_jobs_error(see_through(league, batch, device=device, parallel=parallel, ids=ids))
        if dead is not None:
            raise dead
    if new is None:
        report = None
    elif queue:
        report = new.see_through(device=device, parallel=parallel)
    else:
        first, n, pa, pb = new
        report = run_match(pa, pb, games=n, first_seed=first, parallel=parallel, league=league,
                           player_ids={pa.id: cand.id, pb.id: base.id}, kind="gate", env_options=env_options)
    return bool(d.joined), report
