"""Rated play: league players become policies, play paired games in the batched runner, and land in the ledger.

A match between A and B plays game pairs: each seed once with A on the left and once with A on the right, so
the serve luck and the seat cancel out within a pair. Results are stored chunk by chunk, each chunk in one
transaction, so a match killed midway leaves whole, consistent games in the ledger.

With an SPRT the match checks the log-likelihood ratio after every pair (pentanomial GSPRT, as fishtest and
fastchess do) and stops at the first pair where it crosses a bound; games played beyond that pair in the last
batch are discarded, so the test is exactly sequential.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..arena import GameResult, paired_schedule, play
from ..envs import get_env
from ..errors import MarlError
from ..league.store import GameRecord, League, PlayerRow
from ..policies import Policy, ScriptedPolicy
from ..stats.match import MatchStats, match_stats
from ..stats.sprt import SPRT


def plays_greedy(row: PlayerRow) -> bool:
    """How a snapshot plays, in every game it is rated by: as its algorithm trained it. A DQN snapshot takes the
    action of highest value; a policy-gradient snapshot (PPO) samples from its policy, which is what PPO optimises
    (its argmax is another, untrained player, and against a deterministic opponent it can loop in endless rallies).
    """
    return row.algo == "dqn"


def load_player(league: League, row: PlayerRow, device: str = "cpu", greedy: bool | None = None,
                seed: int = 0) -> Policy:
    """The policy a league player stands for: a scripted bot, or a network loaded from its snapshot file, playing
    as :func:`plays_greedy` says unless ``greedy`` is given; ``seed`` seeds its sampling.

    The file is validated in full before anything is built from it (:func:`~selfplay_cli.policies.snapshot.
    read_snapshot`) and must be the file the row registered (:func:`~selfplay_cli.rated.snapshots.check_file`):
    a file copied over it, or edited, is refused with an error naming it, so no game is ever played or stored under
    the wrong identity."""
    if row.is_bot:
        return ScriptedPolicy(row.env, row.name, seed=seed)
    from ..policies.snapshot import policy_of, read_snapshot  # torch is imported only when a network is needed
    from .snapshots import check_file, snapshot_file

    _inference_threads(device)
    if row.removed:
        raise MarlError(f"{row.full_name} was removed from the league; its games stay in the ledger")
    path = snapshot_file(league, row)
    snap = read_snapshot(path, expect_env=row.env)
    check_file(row, snap, path)
    return policy_of(snap, path, id=row.full_name, device=device,
                     greedy=plays_greedy(row) if greedy is None else greedy, seed=seed)


def _inference_threads(device: str) -> None:
    """Small networks evaluated in batches run fastest on one CPU thread: torch's default of one thread per
    core costs more in synchronisation than it gains (measured 55 ms vs 0.8 ms per 1000-observation batch)."""
    import torch

    if device in ("cpu", "auto") and not torch.cuda.is_available():
        torch.set_num_threads(1)


def env_options_of(*policies: Policy) -> dict[str, Any]:
    """The game options the players were trained with (frame stack, rules...); they must agree."""
    found: dict[str, Any] | None = None
    owner = ""
    for p in policies:
        opts = getattr(getattr(p, "meta", None), "env_options", None)
        if opts is None:
            continue
        if found is not None and opts != found:
            raise MarlError(f"{owner} and {p.id} were made for different game options ({found} vs {opts})")
        found, owner = dict(opts), p.id
    return found or {}


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


@dataclass
class MatchReport:
    env: str
    a: str
    b: str
    games: int
    wins: int
    draws: int
    losses: int
    points_for: int  # raw points scored by A over all games
    points_against: int
    pentanomial: tuple[int, int, int, int, int]
    stats: MatchStats
    seconds: float
    match_id: int | None
    first_seed: int
    sprt: dict[str, Any] | None = None
    truncated: int = 0
    results: list[GameResult] = field(default_factory=list, repr=False)
    game_ids: list[int] = field(default_factory=list, repr=False)  # ledger ids of the stored games, in order
    interrupted: bool = False  # stopped by Ctrl-C: the whole pairs finished by then

    @property
    def games_per_second(self) -> float:
        return self.games / self.seconds if self.seconds > 0 else float("inf")

    def to_json(self) -> dict[str, Any]:
        s = self.stats
        return {
            "env": self.env, "a": self.a, "b": self.b, "games": self.games,
            "wins": self.wins, "draws": self.draws, "losses": self.losses,
            "score": round(s.score, 4), "points_for": self.points_for, "points_against": self.points_against,
            "elo": round(s.elo, 1), "elo_low": round(s.elo_low, 1), "elo_high": round(s.elo_high, 1),
            "confidence": s.confidence, "bounded": s.bounded, "los": round(s.los, 4),
            "pentanomial": list(self.pentanomial), "truncated_games": self.truncated,
            "seconds": round(self.seconds, 3), "games_per_second": round(self.games_per_second, 1),
            "match_id": self.match_id, "first_seed": self.first_seed, "sprt": self.sprt,
            "game_ids": self.game_ids, "interrupted": self.interrupted,
        }


def _records(ids: dict[str, int], results: list[GameResult]) -> list[GameRecord]:
    """Games as the ledger stores them, with their actions so that `marl record --game ID` can replay any of them."""
    return [GameRecord(env=r.env, players=tuple(ids[p] for p in r.players), seed=r.seed, scores=r.scores,
                       outcome=r.outcome, length=r.length, truncated=r.truncated, actions=r.actions)
            for r in results]


class MatchInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_match`. The whole pairs finished by then are stored (their match row says
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
) -> MatchReport:
    """Play up to ``games`` games (rounded up to whole pairs) between ``a`` and ``b`` and report from A's view.

    With ``league`` (and ``player_ids`` mapping policy ids to player ids) every chunk of games is stored as it
    finishes, each chunk in one transaction; the match row is created with the first chunk (so it never exists
    without games) and its ``params`` say ``status``: ``running``, then ``finished``, ``interrupted`` or ``failed``,
    with ``games_stored``. With ``sprt`` the match stops at the first pair whose LLR crosses a bound.

    Ctrl-C raises :class:`MatchInterrupted` after storing the whole pairs already finished (of the chunk in play
    too: a half pair would leave its seed's seat luck uncancelled, and is dropped).
    """
    if a.env != b.env:
        raise MarlError(f"{a.id} plays {a.env} but {b.id} plays {b.env}")
    if a.id == b.id:
        raise MarlError(f"a match needs two different players, got {a.id} twice")
    if games < 1:
        raise MarlError(f"--games must be at least 1, not {games}")
    if league is not None and player_ids is None:
        raise ValueError("player_ids are needed to store games")
    spec = get_env(a.env)
    options = env_options_of(a, b)
    n_pairs = (games + 1) // 2
    chunk_pairs = max(1, parallel // 2)
    test = None
    if sprt is not None:
        chunk_pairs = max(1, min(chunk_pairs, 64))  # smaller batches waste fewer games past the decision
        test = SPRT(elo0=sprt.elo0, elo1=sprt.elo1, alpha=sprt.alpha, beta=sprt.beta)
    params: dict[str, Any] = {"a": a.id, "b": b.id, "games": games, "first_seed": first_seed, "env_options": options,
                              "status": "running"}
    if sprt is not None:
        params["sprt"] = asdict(sprt)

    match_id: int | None = None
    kept: list[GameResult] = []
    game_ids: list[int] = []
    pair_points: list[float] = []
    decision: str | None = None
    llr = 0.0

    def take(finished: list[GameResult]) -> list[GameResult]:
        """The whole pairs among ``finished`` (results of one chunk), in order, up to an SPRT decision."""
        nonlocal decision, llr
        by_index = {r.index: r for r in finished}
        new: list[GameResult] = []
        for i in sorted({r.index // 2 for r in finished}):
            g1, g2 = by_index.get(2 * i), by_index.get(2 * i + 1)
            if g1 is None or g2 is None:
                continue
            new += [g1, g2]
            pair_points.append(g1.points_of(a.id) + g2.points_of(a.id))
            if test is not None:
                llr = test.llr(pentanomial(np.array(pair_points)))
                decision = test.decide(llr)
                if decision is not None:
                    break
        return new

    def store(new: list[GameResult]) -> None:
        nonlocal match_id
        if league is None or not new:
            return
        records = _records(player_ids, new)  # type: ignore[arg-type]
        if match_id is None:
            match_id, ids = league.create_match_with_games(spec.name, kind, params, records)
        else:
            ids = league.record_games(match_id, records)
        game_ids.extend(ids)

    def on_result(r: GameResult) -> None:
        in_play.append(r)
        if on_games is not None:
            on_games(1)

    start = time.perf_counter()
    pair = 0
    in_play: list[GameResult] = []
    try:
        while pair < n_pairs and decision is None:
            n = min(chunk_pairs, n_pairs - pair)
            schedule = paired_schedule(2 * n, first_seed=first_seed + pair)
            in_play = []
            play(spec, [a, b], schedule, parallel=parallel, env_options=options, on_result=on_result,
                 record_actions=league is not None)
            new = take(in_play)
            in_play = []
            store(new)
            kept += new
            pair += n
    except KeyboardInterrupt:
        new = take(in_play)
        store(new)
        kept += new
        if match_id is not None:
            league.update_match(match_id, status="interrupted", games_stored=len(game_ids))  # type: ignore[union-attr]
        report = _report(spec.name, a, b, kept, pair_points, time.perf_counter() - start, match_id, first_seed,
                         confidence, game_ids)
        report.interrupted = True
        raise MatchInterrupted(report) from None
    except BaseException:
        if match_id is not None:  # say so on the row, if the database still takes it (a full disk may not)
            with contextlib.suppress(Exception):
                league.update_match(match_id, status="failed", games_stored=len(game_ids))  # type: ignore[union-attr]
        raise
    if match_id is not None:
        league.update_match(match_id, status="finished", games_stored=len(game_ids))  # type: ignore[union-attr]
    report = _report(spec.name, a, b, kept, pair_points, time.perf_counter() - start, match_id, first_seed,
                     confidence, game_ids)
    if sprt is not None:
        assert test is not None
        report.sprt = {"elo0": sprt.elo0, "elo1": sprt.elo1, "alpha": sprt.alpha, "beta": sprt.beta,
                       "llr": round(llr, 4), "lower": round(test.lower, 4), "upper": round(test.upper, 4),
                       "decision": decision, "pairs": len(pair_points)}
    return report


def _report(env: str, a: Policy, b: Policy, kept: list[GameResult], pair_points: list[float], seconds: float,
            match_id: int | None, first_seed: int, confidence: float, game_ids: list[int]) -> MatchReport:
    pts = np.array([r.points_of(a.id) for r in kept])
    wins, draws, losses = int((pts == 1).sum()), int((pts == 0.5).sum()), int((pts == 0).sum())
    penta = pentanomial(np.array(pair_points))
    return MatchReport(
        env=env, a=a.id, b=b.id, games=len(kept), wins=wins, draws=draws, losses=losses,
        points_for=sum(r.scores[r.players.index(a.id)] for r in kept),
        points_against=sum(r.scores[r.players.index(b.id)] for r in kept),
        pentanomial=penta, stats=match_stats(wins, draws, losses, pentanomial=penta, confidence=confidence),
        seconds=seconds, match_id=match_id, first_seed=first_seed, truncated=sum(r.truncated for r in kept),
        results=kept, game_ids=game_ids,
    )


def sprt_exit_code(report: MatchReport) -> int:
    """0 when H1 is accepted, 1 when H0 is, 3 when the game budget ran out first."""
    assert report.sprt is not None
    return {"H1": 0, "H0": 1}.get(report.sprt["decision"], 3)

