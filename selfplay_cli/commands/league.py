"""`marl league ladder` and `marl league tournament`."""

from __future__ import annotations

from typing import Annotated

import typer

from ..errors import MarlError
from ._common import (
    DbOpt,
    DeviceOpt,
    EnvOpt,
    HomeOpt,
    JsonOpt,
    QuietOpt,
    check_env,
    open_league,
    progress_bar,
    progress_enabled,
    resolve_players,
)
from ._output import console
from .elo import AnchorOpt, BootstrapOpt, check_bootstrap, parse_anchor
from .ladder_view import render_ladder

app = typer.Typer(help="The ladder of the league and round-robin / gauntlet tournaments.", no_args_is_help=True)


@app.command("ladder")
def ladder_cmd(
    env: EnvOpt = None,
    anchor: AnchorOpt = None,
    bootstrap: BootstrapOpt = 200,
    confidence: Annotated[float, typer.Option("--confidence", help="Level of the intervals.")] = 0.95,
    include_removed: Annotated[bool, typer.Option("--all", help="Also list removed snapshots.")] = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
    csv_out: Annotated[bool, typer.Option("--csv", help="Print CSV on stdout.")] = False,
) -> None:
    """Rank, policy, kind, step, Elo with its interval, games, W-D-L and score. A player's rank counts only the
    players whose whole interval lies above its own."""
    from ..league.ladder import ladder

    if json_out and csv_out:
        raise MarlError("--json and --csv exclude each other")
    name, rating = parse_anchor(anchor)
    league = open_league(home, db)
    try:
        rows = ladder(league, check_env(env), anchor=name, anchor_rating=rating, bootstrap=check_bootstrap(bootstrap),
                      confidence=confidence, include_removed=include_removed)
        online = {p.full_name: p.elo for p in league.players(env=env, include_removed=include_removed)}
    finally:
        league.close()
    render_ladder(rows, "league ladder", json_out=json_out, csv_out=csv_out, online=online)


@app.command("tournament")
def tournament(
    players: Annotated[list[str] | None, typer.Argument(help="Policies to include (names, tags, ids, bots).")]
    = None,
    env: EnvOpt = None,
    run: Annotated[str | None, typer.Option("--run", help="Include every snapshot of this run.")] = None,
    top: Annotated[int | None, typer.Option("--top", help="Include the top K of the current ladder.")] = None,
    vs: Annotated[str | None, typer.Option("--vs", help="Gauntlet: every player meets only this one.")] = None,
    games_per_pair: Annotated[int, typer.Option("--games-per-pair", help="Games each pair must have in the "
                                                "ledger; only the missing ones are played.")] = 100,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the first new game.")] = 0,
    parallel: Annotated[int, typer.Option("--parallel", help="Games played at once.")] = 1024,
    bootstrap: BootstrapOpt = 200,
    device: DeviceOpt = "auto",
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Round robin (or gauntlet with --vs) over chosen policies, playing only the games still missing, then
    refit and print the ladder."""
    from ..league.ladder import ladder, plan_tournament
    from ..rated.match import load_player, run_match

    if games_per_pair < 2:
        raise MarlError(f"--games-per-pair must be at least 2, not {games_per_pair}")
    league = open_league(home, db)
    try:
        chosen = resolve_players(league, list(players or []), check_env(env)) if players else []
        env = env or (chosen[0].env if chosen else None)
        if run is not None:
            r = league.get_run(run)
            if r is None:
                raise MarlError(f"no run named '{run}'")
            env = env or r.env
            chosen += [p for p in league.players(env=r.env, kind="snapshot") if p.run == run]
        if top is not None:
            if top < 2:
                raise MarlError(f"--top must be at least 2, not {top}")
            rows = ladder(league, env, bootstrap=0)
            env = env or (league.get_player(rows[0].player_id).env if rows else None)
            chosen += [league.get_player(r.player_id) for r in rows[:top] if r.player_id is not None]
        anchor = resolve_players(league, [vs], env)[0] if vs else None
        unique = {p.id: p for p in chosen if anchor is None or p.id != anchor.id}
        if len(unique) + (anchor is not None) < 2:
            raise MarlError("a tournament needs at least two players (list them, or use --run / --top)")
        envs = {p.env for p in unique.values()} | ({anchor.env} if anchor else set())
        if len(envs) > 1:
            raise MarlError(f"players of several games in one tournament: {', '.join(sorted(envs))}")
        env = envs.pop()
        plan = plan_tournament(league, env, list(unique), games_per_pair, vs=anchor.id if anchor else None)
        total = sum(p.missing + p.missing % 2 for p in plan)
        policies = {}
        next_seed = seed
        with progress_bar("tournament", total, "games", progress_enabled(quiet or json_out)) as tick:
            for p in plan:
                rows_ = [league.get_player(p.a_id), league.get_player(p.b_id)]
                for row in rows_:
                    if row.id not in policies:
                        policies[row.id] = load_player(league, row, device=device, seed=row.id)
                pa, pb = policies[p.a_id], policies[p.b_id]
                run_match(pa, pb, games=p.missing, first_seed=next_seed, parallel=parallel, league=league,
                          player_ids={pa.id: p.a_id, pb.id: p.b_id}, kind="tournament", on_games=tick)
                next_seed += (p.missing + 1) // 2
        if not json_out:
            console.print(f"{len(plan)} pairs needed games, {total} played")
        rows = ladder(league, env, bootstrap=check_bootstrap(bootstrap))
    finally:
        league.close()
    render_ladder(rows, f"{env} ladder after the tournament", json_out=json_out)


from .league_views import matrix_cmd, plot_cmd  # noqa: E402  (views of the league: commands/league_views.py)

app.command("plot")(plot_cmd)
app.command("matrix")(matrix_cmd)
