"""`marl match A B`: rated games between two policies, with an optional sequential test."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape

from ..errors import MarlError
from ..league.variants import describe_variant, variant_flags
from ._common import (
    MAX_GAMES,
    MAX_PARALLEL,
    MAX_SEED,
    DbOpt,
    DeviceOpt,
    EnvOpt,
    EnvOptionOpt,
    HomeOpt,
    JsonOpt,
    QuietOpt,
    open_league,
    parse_env_options,
    progress_bar,
    progress_enabled,
    resolve_players,
)
from ._output import console, err_console, print_json

if TYPE_CHECKING:  # (the match's library is imported when a match plays: torch, for every command, cost 1.3 s)
    from ..evaluation.match import MatchReport


def _points(mine: float, theirs: float) -> str:
    """``points 63-41`` (pong's points); ``return +12 against -12`` where scores can be negative (summed rewards)."""
    from ..results import format_score

    if mine >= 0 and theirs >= 0:
        return f"points {format_score(mine)}-{format_score(theirs)}"
    return f"return {'+' * (mine > 0)}{format_score(mine)} against {'+' * (theirs > 0)}{format_score(theirs)}"


def played(r: MatchReport) -> str:
    """The games played and what the W/D/L that follows counts: ``200 games in 100 seat-swapped pairs``; ``200
    games: 100 comparisons of team returns on shared seeds`` (cooperative: one episode each a seed); ``30 games, every
    rotation of the seating on each seed`` (free-for-all: a result a game)."""
    from ..results import COOPERATIVE, TWO_SIDES

    if r.kind == COOPERATIVE:
        return (f"{r.games} games: {r.n_results} comparisons of team returns on shared seeds (each flies every seat "
                "on the same seed)")
    if r.kind == TWO_SIDES:
        if not r.paired:  # sides that differ: no seat swap
            return f"{r.games} games, one a seed: each plays only its own side"
        return f"{r.games} games in {r.games // 2} seat-swapped pairs"
    return f"{r.games} games, every rotation of the seating on each seed (a result a game, from {r.a}'s and {r.b}'s " \
        "scores)"


def truncated(r: MatchReport, of: str = "") -> str:
    """How many of the games were cut short: ``all 200 truncated (cut unfinished; step limit 300)``, ``150 of 200
    truncated (...)``, with ``of="games"`` ``3 of 200 games truncated (...)`` (the limit where the game declares
    one)."""
    limit = f"; step limit {r.step_limit:,}" if r.step_limit else ""
    share = f"all {r.games}" if r.truncated >= r.games else f"{r.truncated} of {r.games}"
    return f"{share}{' ' + of if of else ''} truncated (cut unfinished{limit})"


def render_report(r: MatchReport) -> None:
    from ..results import COOPERATIVE, truncated_rule

    s = r.stats
    mostly_cut = 2 * r.truncated > r.games  # the results are mostly scores at a cut: the headline says so first
    cut = f", {truncated(r)}" if mostly_cut else ""
    console.print(f"[bold]{r.env}[/]: {r.a} vs {r.b}, {played(r)}{cut}, {r.games_per_second:,.1f} games/s")
    if mostly_cut:
        console.print(f"  {truncated_rule(r.kind, r.tie_tolerance)}", markup=False, highlight=False)
    if r.kind == COOPERATIVE:  # a result is one comparison of team returns on one seed; returns read best as means
        half = max(r.games // 2, 1)  # A flies half the episodes
        shown = f"mean team return {r.points_for / half:.2f} against {r.points_against / half:.2f}"
    else:
        shown = _points(r.points_for, r.points_against)
    console.print(f"  {r.a}: {r.wins} W  {r.draws} D  {r.losses} L of {r.n_results} {r.result_unit}s   score "
                  f"{100 * s.score:.1f}%   {shown}")
    if r.seating is not None and len(set(r.seating)) > 1:  # a team of distinct members at another size
        console.print(f"  {r.a} flew {len(r.seating)} seats: " + ", ".join(r.seating) + f" ({r.seating_rule})",
                      markup=False, highlight=False)
    bound = " (bound: no game lost or none won)" if s.bounded else ""
    console.print(f"  Elo difference {s.elo:+.1f}  [{100 * s.confidence:g}% CI {s.elo_low:+.1f}, {s.elo_high:+.1f}]"
                  f"{bound}   LOS {100 * s.los:.1f}%")
    if sum(r.pentanomial):  # game pairs: two-sides games only
        console.print(f"  pairs (LL LD WL+DD WD WW): {' '.join(map(str, r.pentanomial))}")
    if r.truncated and not mostly_cut:  # a few: said below, with what they count as
        console.print(f"  {truncated(r, 'games')}; {truncated_rule(r.kind, r.tie_tolerance)}", markup=False,
                      highlight=False)
    if r.sprt:
        t = r.sprt
        verdict = {"H1": "H1 accepted", "H0": "H0 accepted"}.get(t["decision"], "undecided (--max-games reached)")
        console.print(f"  SPRT [{t['elo0']:g}, {t['elo1']:g}] alpha={t['alpha']:g} beta={t['beta']:g}: "
                      f"LLR {t['llr']:.2f} ({t['lower']:.2f}, {t['upper']:.2f}) -> {verdict}")
    if r.predicted is not None:
        p = r.predicted
        console.print(f"  the ladder predicted {100 * p.score:.0f}% [{100 * p.low:.0f}%, {100 * p.high:.0f}%] over "
                      f"these {p.games} results: " + ("held" if r.held else "did not hold (marl league ladder has "
                                                      "these two wrong; these games now count in it)"))
    if r.match_id is not None:
        ids = r.game_ids
        games = (f", games #{ids[0]}-#{ids[-1]} (marl record --game ID replays one)"
                 if ids and ids[-1] - ids[0] + 1 == len(ids) else "")
        console.print(f"  stored as match #{r.match_id}{games}")
        if r.variant:  # games under options that change the game: rated apart, in a ladder of their own
            console.print(f"  rated under {escape(describe_variant(r.variant))}, apart from {r.env}'s default "
                          f"ladder: marl league ladder --env {r.env} {escape(variant_flags(r.variant))}")


def interrupted(r: MatchReport, stored: bool) -> None:
    """Ctrl-C: one line on stderr saying what was kept."""
    if not stored:
        err_console.print(f"interrupted after {r.games} games (--no-store: none stored)", markup=False)
    elif r.match_id is None:
        err_console.print("interrupted before a pair of games finished: no game stored", markup=False)
    else:
        err_console.print(f"interrupted: {r.games} games stored as match #{r.match_id} (whole rounds: {r.wins} W "
                          f"{r.draws} D {r.losses} L of {r.n_results} {r.result_unit}s for {r.a}); they count in the "
                          "ratings", markup=False)


def match(
    a: Annotated[str, typer.Argument(help="First policy: a snapshot (s6M-left, pong-1/s6M-left), a team of "
                                     "per-seat snapshots (s6M: each member plays B in turn), a tag, latest, best, an "
                                     "id or a scripted player (cpu, random).")],
    b: Annotated[str, typer.Argument(help="Second policy (same forms).")],
    games: Annotated[int, typer.Option("--games", "-n", min=1, max=MAX_GAMES, help="Games to play (whole pairs: "
                                       "each seed in both seat orders).")] = 200,
    env: EnvOpt = None,
    env_option: EnvOptionOpt = None,
    seed: Annotated[int | None, typer.Option("--seed", min=0, max=MAX_SEED, help="First game seed; pair i uses "
                                             "seed + i (default: the first seed the two have not played, so no "
                                             "stored game is played and counted again).")] = None,
    parallel: Annotated[int, typer.Option("--parallel", min=2, max=MAX_PARALLEL, help="Games played at once in the "
                                          "batched core.")] = 1024,
    store: Annotated[bool, typer.Option("--store/--no-store", help="Record the games in the ledger.")] = True,
    sprt: Annotated[bool, typer.Option("--sprt", help="Sequential test: stop once H0 (elo0) or H1 (elo1) wins.")]
    = False,
    elo0: Annotated[float, typer.Option("--elo0", help="SPRT H0: Elo(A) - Elo(B) = elo0.")] = 0.0,
    elo1: Annotated[float, typer.Option("--elo1", help="SPRT H1: Elo(A) - Elo(B) = elo1.")] = 10.0,
    alpha: Annotated[float, typer.Option("--alpha", help="SPRT false-positive rate.")] = 0.05,
    beta: Annotated[float, typer.Option("--beta", help="SPRT false-negative rate.")] = 0.05,
    max_games: Annotated[int | None, typer.Option("--max-games", min=1, max=MAX_GAMES, help="SPRT game budget "
                                                  "(default --games).")] = None,
    confidence: Annotated[float, typer.Option("--confidence", help="Level of the Elo interval.")] = 0.95,
    k: Annotated[float, typer.Option("--k", min=0.0, max=1000.0, help="K factor of the online Elo updated after "
                                     "each stored game (0: no update).")] = 16.0,
    queue: Annotated[bool, typer.Option("--queue", help="Put the games on the league's work queue as jobs of a "
                                        "few minutes (with --sprt: batches, the rest cancelled once decided): every "
                                        "marl worker attached plays them, and so does this command.")] = False,
    device: DeviceOpt = "auto",
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Play rated games between two policies: W/D/L, Elo difference with its interval, LOS, optional SPRT.

    A team name (s6M: the snapshots s6M-left and s6M-right of one moment of a run) plays each of its members
    against the other policy, one match after the other; in a cooperative game (the lander) the team flies
    together instead, each member on its own seat, in one match.

    Exit code: 0, or with --sprt: 0 when H1 is accepted, 1 when H0 is, 3 when --max-games ends it undecided.
    """
    if not 0.5 < confidence < 1:
        raise MarlError(f"--confidence must lie in (0.5, 1), not {confidence}")
    if queue and not store:
        raise MarlError("--queue stores every game (its workers write them to the league): drop --no-store")
    from ..evaluation.match import SPRTSettings, sprt_exit_code
    from ..evaluation.match_jobs import forecaster, match_jobs, predict
    from ..ratings.names import Team

    settings = SPRTSettings(elo0, elo1, alpha, beta) if sprt else None
    budget = (max_games or games) if sprt else games
    league = open_league(home, db)
    league.elo_k = k
    reports: list[MatchReport] = []
    try:
        side_a, side_b = resolve_players(league, [a, b], env, teams=True, env_option=env_option)
        game = side_b.env
        options = parse_env_options(game, env_option) if env_option else None
        jobs, crew = match_jobs(league, a, side_a, b, side_b, sprt=sprt, options=options)
        forecast = forecaster(league, jobs[0].row_b.env, [r for job in jobs for r in (*job.rows_a, job.row_b)],
                              options)
        for job in jobs:
            if queue:
                report, batch = _queued(league, job, budget, seed, options, settings, confidence, device, parallel,
                                        quiet or json_out)
            elif store:  # (its seeds taken first: after every seed the pair has, queued ones too)
                taken = job.take_here(league, budget, seed, options, device)
                _said_after(taken, quiet or json_out)
                report, batch = _local(league, store, job, budget, taken.first_seed, options, settings, confidence,
                                       device, parallel, quiet, loaded=taken.loaded), None
                report.after_queued = taken.after
                job.settle_here(league, taken, report)
            else:
                first = league.ledger.fresh_seed(job.rows_a[0].id, job.row_b.id) if seed is None else seed
                report, batch = _local(league, store, job, budget, first, options, settings, confidence, device,
                                       parallel, quiet), None
            if forecast is not None and job.team_name is None:
                report.predicted = predict(forecast, job.rows_a[0], job.row_b, report)
            reports.append(report)
            if not json_out:
                render_report(report)
                if batch is not None:
                    console.print(f"  stored as the jobs of batch {batch} (one match each: marl queue --batch "
                                  f"{batch})", markup=False)
    finally:
        league.close()
    team = next((side.full_name for side in (side_a, side_b) if isinstance(side, Team)), None) if not crew else None
    if json_out:
        print_json(reports[0].to_json() if team is None else {"team": team, "matches": [r.to_json() for r in reports]})
    if settings is not None:
        raise typer.Exit(sprt_exit_code(reports[0]))


def _said_after(taken, quiet: bool) -> None:
    """One line on stderr when the pair's games queued already made the match start after them."""
    if taken.after and not quiet:
        from ..evaluation.seeds import joined_text

        err_console.print(f"{joined_text(taken.after, {})} for these players: this match plays new seeds, from "
                          f"{taken.first_seed}", markup=False)


def _local(league, store: bool, job, games: int, first: int, options, settings, confidence: float, device: str,
           parallel: int, quiet: bool, loaded=None) -> MatchReport:
    """One match of ``marl match``, played here (and stored, with ``store``); Ctrl-C: what was kept, exit 130.
    ``loaded``: its players, loaded from ``first`` already."""
    from ..evaluation.match import MatchInterrupted, run_match

    pa, pb, ids = loaded or job.load(league, first, device)
    try:
        with progress_bar(f"{job.team_name or pa[0].id} vs {pb.id}", games + games % 2, "games",
                          progress_enabled(quiet)) as tick:
            return run_match(pa[0], pb, games=games, first_seed=first, parallel=parallel,
                             league=league if store else None, player_ids=ids, sprt=settings, confidence=confidence,
                             on_games=tick, env_options=options, team=pa if job.team_name else None,
                             team_name=job.team_name)
    except MatchInterrupted as stop:
        interrupted(stop.report, stored=store)
        raise typer.Exit(130) from None


def _queued(league, job, games: int, seed: int | None, options, settings, confidence: float, device: str,
            parallel: int, quiet: bool) -> tuple[MatchReport, str]:
    """One match of ``marl match --queue``: queued as jobs (on seeds after every seed the pair has, queued ones too),
    played by the workers and this command, reported as one."""
    queued, taken = job.take_queued(league, games, seed, options, sprt=settings, confidence=confidence, device=device)
    _said_after(taken, quiet)
    if not quiet:
        n = len(league.queue.jobs(batch=queued.batch))
        err_console.print(f"queued {n} jobs as batch {queued.batch} (marl queue --batch {queued.batch}); playing them "
                          "with the workers attached", markup=False)
    try:
        done = [0]

        with progress_bar(f"{job.team_name or job.rows_a[0].full_name} vs {job.row_b.full_name} (queued)",
                          games + games % 2, "games", progress_enabled(quiet)) as tick:
            def on_jobs(jobs) -> None:
                n = sum(int((j.result or {}).get("games", 0)) for j in jobs if j.state == "done")
                tick(n - done[0])
                done[0] = n

            report = queued.see_through(device=device, parallel=parallel, on_jobs=on_jobs)
            report.after_queued = taken.after
            return report, queued.batch
    except KeyboardInterrupt:
        n = league.queue.cancel_jobs(batch=queued.batch)
        err_console.print(f"interrupted: {n} jobs of {queued.batch} cancelled; the games of the jobs done are stored "
                          "and count in the ratings", markup=False)
        raise typer.Exit(130) from None
