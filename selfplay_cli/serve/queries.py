"""What the pages of ``marl serve`` show, read through the library the CLI reads through: the ladder
(:func:`~selfplay_cli.ratings.ladder.ladder`, its rows' own JSON, as ``marl league ladder --json``), the matrix
(:func:`~selfplay_cli.report.matrix.build_matrix`, as ``marl league matrix``), a run's curves
(:func:`~selfplay_cli.report.plots.run_curves`), a prediction (:class:`~selfplay_cli.ratings.forecast.Forecaster`, as
``marl league predict``), the queue (``league.queue``, as ``marl queue``) and the recordings (``league.videos``).

A :class:`Reader` holds one league opened read-only (the connection itself cannot write). Its ladder, matrix and
forecaster fit on every call: the pages never call them, they read what :class:`~selfplay_cli.serve.fits.FitCache`
fitted in its background thread (a fit of a large league takes far longer than a page may)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import func, select

from selfplay_cli.league.job_rows import JOB_STATES
from selfplay_cli.league.ledger import MATCH_KINDS
from selfplay_cli.league.models import Game, Match, Player, Tag, Video, utcnow
from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.league.variants import describe_variant, variant_options
from selfplay_cli.ratings.forecast import Forecaster
from selfplay_cli.ratings.ladder import ladder
from selfplay_cli.ratings.ladder_rows import LadderRow
from selfplay_cli.ratings.pairs import rounds_of
from selfplay_cli.ratings.shown import default_variant
from selfplay_cli.ratings.verdicts import verdict_lines
from selfplay_cli.report.matrix import MatrixReport, build_matrix
from selfplay_cli.report.plots import RunCurves, run_curves
from selfplay_cli.stats.sprt import SPRT, round_counts

__all__ = ["Ladder", "NotFound", "Reader"]


class NotFound(LookupError):
    """A page of something the league does not hold (a game, run, player, recording): a 404 saying which."""


@dataclass(frozen=True)
class Ladder:
    """A fitted ladder as the page shows it: its rows, their JSON (``marl league ladder --json``'s very records)
    and the lines under it."""

    env: str
    variant: str
    rows: list[LadderRow]
    records: list[dict[str, Any]]
    verdicts: list[str]


class Reader:
    """One league, read-only (see the module docstring)."""

    def __init__(self, home: Path | None, url: str | None) -> None:
        self.league = League.open(home=home, url=url, readonly=True, read_only_connection=True)
        self._run_variants: tuple[tuple, dict[str, str]] = ((), {})

    def close(self) -> None:
        self.league.close()

    def changes(self) -> tuple:
        """A tuple that changes whenever a game, match, player, tag or recording is added, or a player removed (a few
        indexed maxima and counts: cheap at any size)."""

        videos = self.league.videos.held()

        def work(s: Any) -> tuple:
            return (s.scalar(select(func.max(Game.id))), s.scalar(select(func.max(Match.id))),
                    s.scalar(select(func.max(Player.id))), s.scalar(select(func.count()).where(Player.removed)),
                    s.scalar(select(func.count(Tag.id))), s.scalar(select(func.max(Video.id))) if videos else None)

        return self.league._read(work)

    def players_meta(self) -> int:
        """A hash of every player's meta (a filed exploitability, a league role: what a ladder shows and no count
        says)."""
        return hash(tuple((p.id, repr(sorted(p.meta.items(), key=lambda kv: kv[0])))
                          for p in self.league.roster.players(include_removed=True)))

    # ------------------------------------------------------------------ games, runs, players

    def games(self) -> list[dict[str, Any]]:
        """Every game of the league with its variants (key, options text, rated games) and runs."""
        envs = sorted({p.env for p in self.league.roster.players(include_removed=True)})
        runs = self.league.roster.list_runs()
        out = []
        for env in envs:
            variants = self.league.ledger.variants(env)
            out.append({"env": env, "variants": [{"key": k, "text": describe_variant(k), "games": n}
                                                 for k, n in sorted(variants.items())],
                        "runs": [r for r in runs if r.env == env]})
        return out

    def check_game(self, env: str | None, variant: str | None, run: str | None = None) -> tuple[str, str]:
        """The game and variant a page shows: those asked for, checked against the league (NotFound where it holds
        no such game, variant or run), else the one the CLI shows by default."""
        envs = {g["env"]: g for g in self.games()}
        if run is not None:
            info = self.league.roster.get_run(run)
            if info is None:
                raise NotFound(f"no run named {run!r} in this league")
            if env is not None and info.env != env:
                raise NotFound(f"run {run!r} plays {info.env}, not {env!r}")
            env = info.env
        if env is not None and env not in envs:
            raise NotFound(f"no game named {env!r} in this league")
        if env is None and not envs:
            raise NotFound("this league holds no players yet")
        if variant is None:
            if run is not None:
                return env, self.run_variant(run)  # type: ignore[return-value]
            rated = [g["env"] for g in envs.values() if any(v["games"] for v in g["variants"])]
            if env is None and len(rated) == 1:
                env = rated[0]  # (the ledger's only game, as pick_env finds it, without reading the whole ledger)
            try:
                return default_variant(self.league, env, run)
            except LeagueError as e:
                raise NotFound(str(e)) from None
        env = env if env is not None else next(iter(envs))
        if variant not in {v["key"] for v in envs[env]["variants"]}:
            raise NotFound(f"{env} has no rated games under the options {variant!r}")
        return env, variant

    def run_variant(self, run: str) -> str:
        """The variant (key) of a run's snapshots, as :func:`~selfplay_cli.ratings.shown.default_variant` finds it,
        kept until a player is added or removed (it may read each snapshot's file header; the background fits warm
        it)."""
        changes = self.changes()[2:4]
        if self._run_variants[0] != changes:
            self._run_variants = (changes, {})
        known = self._run_variants[1]
        if run not in known:
            known[run] = default_variant(self.league, None, run)[1]
        return known[run]

    def player(self, player_id: int) -> PlayerRow:
        try:
            return self.league.roster.get_player(player_id)
        except LeagueError:
            raise NotFound(f"no player with id {player_id}") from None

    # ------------------------------------------------------------------ ratings

    def ladder(self, env: str, variant: str) -> Ladder:
        """The ladder ``marl league ladder --env ENV [--env-option ...] --json`` prints (its defaults: the game's
        anchor, BayesElo's prior, 200 bootstrap replicates, 95%)."""

        rows = ladder(self.league, env, variant=variant)
        options = variant_options(variant)
        return Ladder(env, variant, rows, [r.to_json() | {"variant": options} for r in rows], verdict_lines(rows))

    def matrix(self, env: str, variant: str, top: int, run: str | None, min_games: int, payoff: str,
               rows: list[LadderRow] | None = None) -> MatrixReport:
        """The matrix ``marl league matrix`` prints; ``rows``: its ladder (``bootstrap=0``) fitted already."""
        return build_matrix(self.league, env, top=top, run=run, min_games=min_games, variant=variant, payoff=payoff,
                            rows=rows)

    def curves(self, run: str, rows: list[LadderRow]) -> RunCurves:
        """A run's curves (``marl league plot --run RUN --json``) from the ladder of its own variant (``rows``)."""
        return run_curves(self.league, run, rows=rows)

    def forecaster(self, env: str, variant: str) -> Forecaster:
        """``marl league predict``'s fitted population, its spread measured."""
        fitted = Forecaster.of_league(self.league, env, variant=variant)
        _ = fitted.spread  # (measured once here, not by the first page that predicts)
        return fitted

    def predict(self, env: str, variant: str, a: PlayerRow, b: PlayerRow, games: int = 200,
                confidence: float = 0.95, forecast: Forecaster | None = None) -> dict[str, Any]:
        """``marl league predict A B --json``'s record (LeagueError where the ladder cannot predict the pair);
        ``forecast``: the forecaster fitted already."""
        forecast = forecast if forecast is not None else Forecaster.of_league(self.league, env, variant=variant)
        pair = forecast.belief(a.full_name, b.full_name)
        p = pair.predict(games, confidence)
        low, high = pair.interval(confidence)
        met_points, met = forecast.met(a.full_name, b.full_name)
        return {"a": a.full_name, "b": b.full_name, **p.to_json(), "elo_low": round(low, 1),
                "elo_high": round(high, 1), "spread": round(forecast.spread, 1), "met": met,
                "met_score": round(met_points / met, 4) if met else None}

    def opponents(self, player: PlayerRow, variant: str) -> list[dict[str, Any]]:
        """The player's rated results by opponent in ``variant``: games, W-D-L and score, most games first."""
        table = self.league.ledger.games(env=player.env, players=[player.id], any_seat=True, variant=variant)
        same = self.league.ledger.same_weights(player.env)
        me = same.get(player.id, player.id)
        mine_a = table.player_a == me
        other = np.where(mine_a, table.player_b, table.player_a)
        pts = np.where(mine_a, table.score_a, 1.0 - table.score_a)
        names = {p.id: p for p in self.league.roster.players(env=player.env, include_removed=True)}
        out = []
        for opp in np.unique(other).tolist():
            mask = other == opp
            p = pts[mask]
            row = names.get(int(opp))
            out.append({"id": int(opp), "policy": row.full_name if row else f"#{opp}", "results": int(mask.sum()),
                        "wins": int((p > 0.5).sum()), "draws": int((p == 0.5).sum()), "losses": int((p < 0.5).sum()),
                        "score": round(float(p.mean()), 4)})
        return sorted(out, key=lambda r: (-r["results"], r["policy"]))

    def lineage(self, player: PlayerRow) -> tuple[list[PlayerRow], list[PlayerRow]]:
        """The player's ancestors (parent first, at most 100) and its children."""
        everyone = {p.id: p for p in self.league.roster.players(env=player.env, include_removed=True)}
        up, seen, pid = [], {player.id}, player.parent_id
        while pid is not None and pid in everyone and pid not in seen and len(up) < 100:
            seen.add(pid)
            up.append(everyone[pid])
            pid = everyone[pid].parent_id
        return up, [p for p in everyone.values() if p.parent_id == player.id]

    # ------------------------------------------------------------------ matches, queue, videos

    def matches(self, env: str | None, kind: str | None) -> list[dict[str, Any]]:
        """The matches (newest first) with their parameters and, where one ran, their SPRT and its record."""
        out = []
        for k in MATCH_KINDS if kind is None else (kind,):
            for mid, params in self.league.ledger.match_params(env=env, kind=k).items():
                out.append({"id": mid, "kind": k, "params": params})
        return sorted(out, key=lambda m: -m["id"])

    def match_rows(self, ids: list[int]) -> dict[int, tuple[str, int]]:
        """Each of the matches ``ids``: its game and how many games the ledger holds of it (one grouped query)."""

        def work(s: Any) -> dict[int, tuple[str, int]]:
            q = (select(Match.id, Match.env, func.count(Game.id)).outerjoin(Game, Game.match_id == Match.id)
                 .where(Match.id.in_(ids)).group_by(Match.id, Match.env))
            return {int(m): (str(env), int(n)) for m, env, n in s.execute(q).all()}

        return self.league._read(work) if ids else {}

    def sprt_record(self, env: str, match: dict[str, Any], ids: dict[str, int]) -> dict[str, Any] | None:
        """A match's SPRT (its settings as stored) and the LLR of its stored games, in rounds as a head-to-head record
        pairs them (:func:`~selfplay_cli.ratings.pairs.rounds_of`, :func:`~selfplay_cli.stats.sprt.round_counts`);
        None for a match without an SPRT."""
        params = match["params"]
        settings = params.get("sprt")
        if not isinstance(settings, dict):
            return None
        try:
            test = SPRT(**{k: settings[k] for k in ("elo0", "elo1", "alpha", "beta") if k in settings})
        except (TypeError, ValueError):
            return None
        a, b = (ids.get(x) if isinstance(x, str) else x for x in (params.get("a"), params.get("b")))
        if not isinstance(a, int) or not isinstance(b, int):  # (a match names its players; ``ids``: name -> id)
            return None
        # (a match's games are between its two players, under the names they played as)
        table = self.league.ledger.games(env=env, variant=None, players=[a, b], pooled=False)
        _, rounds, _, _ = rounds_of(table.select(table.match_id == match["id"]), a)
        counts, model = round_counts(rounds, bool(rounds) and all(len(r) == 2 for r in rounds))
        llr = test.llr(counts, model=model) if sum(counts) else 0.0
        return {"elo0": test.elo0, "elo1": test.elo1, "alpha": test.alpha, "beta": test.beta, "llr": round(llr, 4),
                "lower": round(test.lower, 4), "upper": round(test.upper, 4), "decision": test.decide(llr),
                "counts": counts, "model": model}

    def queue(self, batch: str | None, states: list[str] | None, last: int) -> dict[str, Any]:
        """``marl queue --json``'s record (``--batch``, ``--state``, ``--last``)."""
        for s in states or []:
            if s not in JOB_STATES:
                raise ValueError(f"a job's state is one of {', '.join(JOB_STATES)}, not {s!r}")
        batches = self.league.queue.batches()
        if batch is not None and batch not in dict(batches):
            raise NotFound(f"no batch {batch!r} in the queue")
        workers = self.league.queue.workers()
        jobs = self.league.queue.jobs(batch=batch, states=states, limit=last)
        now = utcnow()
        return {"batches": [{"batch": b, **counts} for b, counts in batches],
                "workers": [{**w.to_json(), "status": w.status(now)} for w in workers],
                "jobs": [j.to_json() for j in jobs]}
