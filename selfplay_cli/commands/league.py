"""`marl league ladder` and `marl league tournament`."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from ..errors import MarlError
from ..league.variants import describe_variant, other_variants_note, variant_options
from ..stats.bradley_terry import DEFAULT_PRIOR
from ..stats.intervals import DEFAULT_BOOTSTRAP
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
    LeagueEnvOpt,
    QuietOpt,
    VariantOpt,
    check_env,
    open_league,
    parse_env_options,
    progress_bar,
    progress_enabled,
    resolve_players,
    shown_variant,
)
from ._output import console, err_console, print_json
from .elo import AnchorOpt, BootstrapOpt, PriorOpt, check_bootstrap, check_prior, parse_anchor, resolve_anchor
from .ladder_view import prior_caption, render_ladder

app = typer.Typer(help="The league: ladder, tournaments, score matrix, rating plots.", no_args_is_help=True,
                  rich_markup_mode=None)


LADDER_HELP = "\n\n".join((
    "The ladder of one game: every player's Elo, fitted from all its stored rated games of one variant: the game's "
    "default options, or those --env-option asks for (with --run: the options the run trained under). Games under "
    "other options are rated apart; a line below the table names them and the command that shows them.",
    "Columns: rank; tier; policy, marked (anchor) for the player whose rating is fixed (--anchor, default the game's "
    "declared anchor at 1000), (best) in bold for the best snapshot of each run ((best, tied) when it is the best by "
    "Elo but not beyond doubt) and (= NAME) for another name of a player's weights; kind (bot or snapshot); "
    "training step; Elo, the Bradley-Terry fit (a draw is half a point); its confidence interval (--confidence, "
    "--bootstrap), relative to the anchor; games and W-D-L; score (points per game); online Elo (the live estimate "
    "updated after every game of the default options; in their ladder only); vs BOT, one column per scripted "
    "player of the game: the score against it and the number of games (blank when none). Only when some row has "
    "one: league role (main, main_exploiter, league_exploiter of a marl train --league alphastar run; exploiter, a "
    "best response marl exploit filed) and exploitability (what a best response wins against the player, in the game's "
    "returns: exact, from marl exploit --exact, or >= a trained best response's lower bound [its 95% interval]).",
    "Ratings are MAP estimates under BayesElo's prior of --prior virtual draws (default 2, BayesElo's default): a "
    "perfect score gets a finite rating, and no interval is narrower than the curvature of the posterior allows. "
    "--prior 0 gives the plain maximum-likelihood fit.",
    "Rank and tier are claims about pairs: one player is above another beyond doubt when the confidence interval of "
    "that pair's difference lies wholly above zero, the pair judged as marl league predict judges it (what the rest "
    "of the ladder says of the two, widened by how far the game's pairs scatter around their ratings, then their own "
    "games). Rank: 1 + the players above it beyond doubt, so players the games cannot order share one; rows go by "
    "rank, then Elo. Tier: a boundary falls only where everyone above it is above everyone below it beyond doubt. "
    "Under the table: the top's margin over the next and each run's best's over the run's next best (the "
    "pair's own figure, as marl league predict and the run's summary give it), or the snapshots the best cannot be "
    "told apart from. --run and --top only choose the rows shown: ranks and tiers stay those of the whole ladder.",
    "Flags next to the Elo: perfect or zero, only with --prior 0: the maximum-likelihood rating is infinite (all "
    "games won or lost against the rest), the Elo shown is a bound and the interval is open on that side; "
    "disconnected: no chain of games links the player to the anchor, so its offset is unknown; unrated: no games.",
))


@app.command("ladder", help=LADDER_HELP)
def ladder_cmd(
    env: LeagueEnvOpt = None,
    env_option: VariantOpt = None,
    run: Annotated[str | None, typer.Option("--run", help="Show only this run's snapshots, plus the scripted "
                                            "players for reference (ranks unchanged).")] = None,
    top: Annotated[int | None, typer.Option("--top", min=1, max=1_000_000, help="Show only the first N rows (ranks "
                                            "unchanged).")] = None,
    anchor: AnchorOpt = None,
    prior: PriorOpt = DEFAULT_PRIOR,
    bootstrap: BootstrapOpt = DEFAULT_BOOTSTRAP,
    confidence: Annotated[float, typer.Option("--confidence", help="Level of the intervals.")] = 0.95,
    include_removed: Annotated[bool, typer.Option("--all", help="Also list removed snapshots.")] = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
    csv_out: Annotated[bool, typer.Option("--csv", help="Print CSV on stdout.")] = False,
) -> None:
    from ..envs.loading import not_named_note
    from ..evaluation.lineup import resized_in_variant
    from ..ratings.ladder import ladder
    from ..ratings.verdicts import select_rows, verdict_lines

    if json_out and csv_out:
        raise MarlError("--json and --csv exclude each other")
    if top is not None and top < 1:
        raise MarlError(f"--top must be at least 1, not {top}")
    name, rating = parse_anchor(anchor)
    prior = check_prior(prior)
    league = open_league(home, db, readonly=True)
    try:
        env = check_env(env)
        if run is not None:
            r = league.roster.get_run(run)
            if r is None:
                known = ", ".join(x.name for x in league.roster.list_runs()[:10])
                raise MarlError(f"no run named '{run}'" + (f"; runs: {known}" if known else ""))
            if env is not None and r.env != env:
                raise MarlError(f"run '{run}' plays {r.env}, not {env}")
            env = r.env
        env, variant = shown_variant(league, env, env_option, run)
        rows = ladder(league, env, anchor=resolve_anchor(league, name, env, variant), anchor_rating=rating,
                      bootstrap=check_bootstrap(bootstrap), confidence=confidence, include_removed=include_removed,
                      prior=prior, variant=variant)
        # A player has one online Elo, moved by the default variant's games only: no column beside another's.
        online = {p.id: p.elo for p in league.roster.players(include_removed=True)} if not variant else None
        note = other_variants_note(env, league.ledger.variants(env), variant, "marl league ladder")
        shown = select_rows(rows, run=run, top=top)
        flown = resized_in_variant(league, env, shown, variant_options(variant)) if env is not None else {}
    finally:
        league.close()
    title = "league ladder" + (f": run {run}" if run else "") + (f" ({env}: {describe_variant(variant)})"
                                                                  if variant else "")
    verdicts = [line for line in verdict_lines(rows) if run is None or f"best of {run}:" in line]
    render_ladder(shown, title, json_out=json_out, csv_out=csv_out, online=online, confidence=confidence,
                  caption=prior_caption(prior, confidence), variant=variant_options(variant), verdicts=verdicts,
                  flown=flown)
    if run is not None and not json_out and not csv_out and not any(r.run == run for r in rows):
        console.print(f"run {run} has no snapshot with rated games yet")
    if note and not json_out and not csv_out:
        console.print(note, markup=False)
    unnamed = not_named_note([env] if env is not None else [])
    if unnamed:  # a game nobody here named: its ladder is read from the ledger, its players cannot play here
        err_console.print(unnamed, markup=False, highlight=False)


@app.command("predict")
def predict_cmd(
    a: Annotated[str, typer.Argument(help="First policy (a snapshot, a tag, best, latest, an id, a scripted player).")],
    b: Annotated[str, typer.Argument(help="Second policy (same forms).")],
    games: Annotated[int, typer.Option("--games", "-n", min=1, max=MAX_GAMES, help="Games of the match to "
                                       "predict.")] = 200,
    env: EnvOpt = None,
    env_option: EnvOptionOpt = None,
    confidence: Annotated[float, typer.Option("--confidence", help="Level of the predicted interval.")] = 0.95,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """What the ladder predicts of a match not yet played: A's score over --games games against B, with the interval
    a real match falls in with probability --confidence. It rests on their ratings' difference and its
    uncertainty, how far the league's pairs scatter around their ratings, and the two's own games; `marl match`
    prints the same prediction beside the games it plays."""
    from ..players.snapshots import players_variant
    from ..ratings.forecast import Forecaster

    if not 0.5 < confidence < 1:
        raise MarlError(f"--confidence must lie in (0.5, 1), not {confidence}")
    league = open_league(home, db, readonly=True)
    try:
        env = check_env(env)
        if env is not None and not league.ledger.count_games(env):  # (nothing to predict from, nor bots to name)
            raise MarlError(f"{env} has no rated games in this league yet: nothing to predict from (marl match or "
                            "marl train first)")
        row_a, row_b = resolve_players(league, [a, b], env, env_option=env_option)
        if row_a.env != row_b.env:
            raise MarlError(f"{row_a.full_name} plays {row_a.env}, {row_b.full_name} plays {row_b.env}")
        options = parse_env_options(row_a.env, env_option) if env_option else None
        variant = players_variant(league, row_a.env, [row_a, row_b], options)  # the ladder a match of them is in
        forecast = Forecaster.of_league(league, row_a.env, variant=variant)
        pair = forecast.belief(row_a.full_name, row_b.full_name)
        p = pair.predict(games, confidence)
        low, high = pair.interval(confidence)
        met_points, met = forecast.met(row_a.full_name, row_b.full_name)
    finally:
        league.close()
    if json_out:
        print_json({"a": row_a.full_name, "b": row_b.full_name, **p.to_json(), "elo_low": round(low, 1),
                    "elo_high": round(high, 1), "spread": round(forecast.spread, 1), "met": met,
                    "met_score": round(met_points / met, 4) if met else None})
        return
    console.print(f"{row_a.full_name} against {row_b.full_name} over {games} games: {100 * p.score:.1f}% "
                  f"[{100 * p.low:.1f}%, {100 * p.high:.1f}%] ({100 * confidence:g}% of such matches fall in it)",
                  markup=False, highlight=False)
    console.print(f"  the pair's Elo difference {p.diff:+.0f} [{low:+.0f}, {high:+.0f}] (the ladder's margin; pairs' "
                  f"spread around their ratings {forecast.spread:.0f}); "
                  + (f"they met in {met} rated results: {100 * met_points / met:.0f}%" if met else "they never met"),
                  markup=False, highlight=False)


@app.command("tournament")
def tournament(
    players: Annotated[list[str] | None, typer.Argument(metavar="PLAYERS", help="Policies to include (snapshots, "
                                                        "teams of per-seat snapshots such as s6M: each member, tags, "
                                                        "ids, scripted players).")] = None,
    env: EnvOpt = None,
    env_option: EnvOptionOpt = None,
    run: Annotated[str | None, typer.Option("--run", help="Include every snapshot of this run.")] = None,
    top: Annotated[int | None, typer.Option("--top", max=10_000, help="Include the top K of the current ladder.")]
    = None,
    vs: Annotated[str | None, typer.Option("--vs", help="Gauntlet: every player meets only this one.")] = None,
    games_per_pair: Annotated[int, typer.Option("--games-per-pair", min=2, max=MAX_GAMES, help="Games each pair must "
                                                "have in the ledger; only the missing ones are played.")] = 100,
    seed: Annotated[int | None, typer.Option("--seed", min=0, max=MAX_SEED, help="Seed of the first new game of "
                                             "every pair (default: for each pair, the first seed it has not "
                                             "played, so no stored game is played and counted again).")] = None,
    parallel: Annotated[int, typer.Option("--parallel", min=2, max=MAX_PARALLEL, help="Games played at once.")]
    = 1024,
    bootstrap: BootstrapOpt = DEFAULT_BOOTSTRAP,
    queue: Annotated[bool, typer.Option("--queue", help="Put the missing games on the league's work queue as jobs "
                                        "of a few minutes: every marl worker attached plays them, and so does this "
                                        "command.")] = False,
    wait: Annotated[bool, typer.Option("--wait/--no-wait", help="With --queue: wait for the games (default), or "
                                       "only queue them and leave them to the workers (marl queue shows them).")]
    = True,
    device: DeviceOpt = "auto",
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Round robin (or gauntlet with --vs) over chosen policies, playing only the games still missing, then
    refit and print the ladder.

    The games are played under the options the players were made for, with --env-option over them, and count in
    that variant of the game: its stored games are the ones reused, its ladder is the one printed."""
    from ..evaluation.seeds import joined_text
    from ..evaluation.tournament import TournamentPlan
    from ..ratings.ladder import ladder
    from ..ratings.verdicts import verdict_lines

    if games_per_pair < 2:
        raise MarlError(f"--games-per-pair must be at least 2, not {games_per_pair}")
    league = open_league(home, db)
    try:
        env, unique, anchor = _field(league, players, env, env_option, run, top, vs)
        options = parse_env_options(env, env_option) if env_option else None
        plan = TournamentPlan.of(league, env, unique, anchor, games_per_pair, options)
        if not wait and not queue:
            raise MarlError("--no-wait leaves queued games to the workers: add --queue")
        if queue:
            sub = plan.enqueue(league, seed, device)
            if not wait:
                if json_out:
                    print_json(sub.to_json())
                else:
                    console.print(_queued_line(sub), markup=False)
                return
            if not quiet and (not json_out or sub.joined_games):  # (--json: stdout holds the ladder alone)
                err_console.print(_queued_line(sub, waiting=True), markup=False)
        else:
            sub = plan.take(league, seed, device)
            with progress_bar("tournament", sub.games, "games", progress_enabled(quiet or json_out)) as tick:
                plan.play_taken(league, sub, parallel, device, on_games=tick)
            if sub.joined_games and not quiet:
                err_console.print(f"joined {joined_text(sub.joined, sub.playing)} (of these pairs: not played "
                                  "again)" + ("; playing them with the workers attached" if sub.joined else ""),
                                  markup=False)
        _see_through(league, sub.batch, sub.joined_jobs, (sub.games if queue else 0) + sum(sub.joined.values()),
                     parallel, device, quiet or json_out)
        if not json_out:
            joined = f"; {sub.joined_games} on their way already were joined" if sub.joined_games else ""
            console.print(f"{len(plan.pairs)} pairs needed games, {sub.games} played{joined}" if plan.pairs else
                          f"every pair has its {games_per_pair} games already: nothing played", markup=False)
            if plan.apart:
                console.print(f"{len(plan.apart)} pair{'s' * (len(plan.apart) != 1)} cannot meet and were left out "
                              f"(in {env} a snapshot plays only seats of its own role: two of one role are rated "
                              "through the players they both meet)", markup=False)
        rows = ladder(league, env, bootstrap=check_bootstrap(bootstrap), variant=plan.variant)
    finally:
        league.close()
    variant = plan.variant
    title = f"{env} ladder after the tournament" + (f" ({describe_variant(variant)})" if variant else "")
    render_ladder(rows, title, json_out=json_out, caption=prior_caption(DEFAULT_PRIOR),
                  variant=variant_options(variant), verdicts=verdict_lines(rows))


def _queued_line(sub: Any, waiting: bool = False) -> str:
    """What ``--queue`` did: the games it queued, and those of its pairs on their way already that it joined."""
    from ..evaluation.seeds import joined_text

    if not sub.games and not sub.joined_games:
        return "every pair has its games already: nothing queued"
    said = []
    if sub.games:
        said.append(f"queued {sub.games} games of {sub.pairs} pairs as batch {sub.batch}")
    if sub.joined_games:
        said.append(("and joined " if said else "nothing queued twice: joined ") + joined_text(sub.joined, sub.playing)
                    + " (of these pairs)")
    follow = [b for b in (sub.batch, *sub.joined) if b]
    tail = ("; playing them with the workers attached" if waiting else
            ": marl worker plays them, " + ", ".join(f"marl queue --batch {b}" for b in follow) + " follows them"
            if follow else "")
    return " ".join(said) + tail


def _see_through(league: Any, own: str | None, joined: dict[str, list[int]], total: int, parallel: int,
                 device: str, quiet: bool) -> None:
    """See the command's own batch and the jobs it joined (by batch) through, one batch after the other: play the
    jobs that no worker has taken, with the workers attached, until every one has ended (a job that died: one line,
    exit 2, after the games that were played are stored). ``total``: the games the progress bar waits for. Ctrl-C
    cancels the command's own batch; a joined job is someone else's, and goes back to the queue if in play here."""
    from ..evaluation.jobs import see_through
    from ..evaluation.queued import dead_jobs_error

    work: list[tuple[str, list[int] | None]] = [(own, None)] if own else []
    work += [(b, ids) for b, ids in joined.items() if b != own]
    if not work:
        return
    done: dict[str, int] = {}
    with progress_bar("tournament (queued)", total, "games", progress_enabled(quiet)) as tick:
        for batch, ids in work:
            def on_change(jobs: list[Any], batch: str = batch) -> bool:
                n = sum(int((j.result or {}).get("games", 0)) for j in jobs if j.state == "done")
                tick(n - done.get(batch, 0))
                done[batch] = n
                return False

            try:
                jobs = see_through(league, batch, device=device, parallel=parallel, on_change=on_change, ids=ids)
            except KeyboardInterrupt:
                if ids is None:
                    n = league.queue.cancel_jobs(batch=batch)
                    err_console.print(f"interrupted: {n} jobs of {batch} cancelled; the games of the jobs done are "
                                      "stored", markup=False)
                raise
            dead = dead_jobs_error(jobs)
            if dead is not None:
                raise dead


def _field(league: Any, players: list[str] | None, env: str | None, env_option: list[str] | None, run: str | None,
           top: int | None, vs: str | None) -> tuple[str, dict[int, Any], Any]:
    """The tournament's game, its players by id (named, a run's snapshots, the ladder's top) and the player every
    one meets (--vs), from what the user typed; refused in one line where they make no tournament."""
    from ..ratings.ladder import ladder
    from ..ratings.names import Team

    found = (resolve_players(league, list(players or []), check_env(env), teams=True, env_option=env_option)
             if players else [])
    chosen = [m for f in found for m in (f.members if isinstance(f, Team) else (f,))]  # a team: its members
    env = env or (chosen[0].env if chosen else None)
    if run is not None:
        r = league.roster.get_run(run)
        if r is None:
            raise MarlError(f"no run named '{run}'")
        env = env or r.env
        chosen += [p for p in league.roster.players(env=r.env, kind="snapshot") if p.run == run]
    if top is not None:
        if top < 2:
            raise MarlError(f"--top must be at least 2, not {top}")
        top_env, top_variant = shown_variant(league, env, env_option)  # the top of the variant asked for
        rows = ladder(league, top_env, bootstrap=0, variant=top_variant)
        env = env or top_env
        chosen += [league.roster.get_player(r.player_id) for r in rows[:top] if r.player_id is not None]
    anchor = resolve_players(league, [vs], env, env_option=env_option)[0] if vs else None
    unique = {p.id: p for p in chosen if anchor is None or p.id != anchor.id}
    if len(unique) + (anchor is not None) < 2:
        raise MarlError("a tournament needs at least two players (list them, or use --run / --top)")
    envs = {p.env for p in unique.values()} | ({anchor.env} if anchor else set())
    if len(envs) > 1:
        raise MarlError(f"players of several games in one tournament: {', '.join(sorted(envs))}")
    return envs.pop(), unique, anchor

from .league_views import matrix_cmd, plot_cmd  # noqa: E402  (views of the league: commands/league_views.py)

app.command("plot")(plot_cmd)
app.command("matrix")(matrix_cmd)
