"""`marl league plot` and `marl league matrix`: views of the league drawn by :mod:`selfplay_cli.report`."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import closing, contextmanager
from pathlib import Path
from typing import Annotated

import typer

from ..errors import MarlError
from ..stats.bradley_terry import DEFAULT_PRIOR
from ._common import (
    MAX_GAMES,
    DbOpt,
    DeviceOpt,
    HomeOpt,
    JsonOpt,
    LeagueEnvOpt,
    VariantOpt,
    check_env,
    open_league,
    progress_bar,
    progress_enabled,
    shown_variant,
    typed_game,
)
from ._output import console, err_console, print_json
from .elo import PriorOpt, check_prior

RunOpt = Annotated[str | None, typer.Option("--run", help="Training run (default: the newest run of the env).")]
OutOpt = Annotated[Path | None, typer.Option("--out", help="Write a PNG image to this .png file.")]


@contextmanager
def _working(message: str) -> Iterator[None]:
    """A spinner on stderr while ratings are fitted, on a terminal only."""
    if progress_enabled():
        with err_console.status(message):
            yield
    else:
        yield


def _width() -> int:
    return min(console.width, 120) if console.is_terminal else 80


def plot_cmd(
    env: Annotated[str | None, typer.Option("--env", callback=typed_game, help="Plot the newest run of this game "
                                            "(default: the newest run; with --run, that run).")] = None,
    env_option: VariantOpt = None,
    run: RunOpt = None,
    out: OutOpt = None,
    prior: PriorOpt = DEFAULT_PRIOR,
    exploitability: Annotated[bool, typer.Option(
        "--exploitability", help="Also each snapshot's exact exploitability against training steps (a game with a "
        "known tree: openspiel:GAME), on its own panel with a log scale: computed by OpenSpiel's best response for "
        "the snapshots that have none filed yet, and filed in their rows (the ladder shows it).")] = False,
    device: DeviceOpt = "auto",
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Each learner's fitted Elo with its 95% interval against training steps (a league run: a line per league role),
    the run's best snapshot (as the ladder marks it) starred, and the scripted players as levels, in the ladder of
    the options the run trained under (--env-option: another variant's); with --exploitability, each snapshot's exact
    exploitability too. Draws in the terminal, or writes a PNG with --out."""
    from dataclasses import replace

    from ..exploit.exact import run_exploitability, run_moments
    from ..report.plots import run_curves, save_run_png
    from ..report.png import check_png_path
    from ..report.terminal import curves_chart, curves_summary, exploitability_table

    env = check_env(env)
    prior = check_prior(prior)
    if out is not None:
        out = check_png_path(out)
    league = open_league(home, db, readonly=True)
    try:
        if run is None:
            runs = league.roster.list_runs(env)
            if not runs:
                raise MarlError(f"no training runs{f' of {env}' if env else ''} in the league yet (marl train ...)")
            run = runs[-1].name
        else:
            info = league.roster.get_run(run)
            if info is not None and env is not None and info.env != env:
                raise MarlError(f"run '{run}' trains {info.env}, not {env}")
        variant = shown_variant(league, env, env_option, run)[1] if env_option else None  # None: the run's own
        moments = run_moments(league, run) if exploitability else []  # (a game without a tree: one line, first)
        with _working("fitting ratings"):
            curves = run_curves(league, run, prior=prior, variant=variant)
    finally:
        league.close()
    if exploitability:  # the figures computed are filed in their rows as they come
        with (closing(open_league(home, db)) as league,
              progress_bar("exact exploitability", len(moments), "snapshots", progress_enabled(json_out)) as tick):
            curves = replace(curves, exploitability=tuple(run_exploitability(league, run, device=device, tick=tick)))
    written = save_run_png(curves, out) if out is not None else None
    if json_out:
        print_json({**curves.to_json(), "png": None if written is None else str(written)})
        return
    if written is not None:
        console.print(f"wrote {written}", markup=False)
        return
    unicode = console.is_terminal
    console.print(curves_chart(curves, width=_width(), unicode=unicode))
    console.print(curves_summary(curves))
    if curves.exploitability is not None:
        console.print(exploitability_table(curves.exploitability))


def matrix_cmd(
    env: LeagueEnvOpt = None,
    env_option: VariantOpt = None,
    top: Annotated[int, typer.Option("--top", min=2, max=100, help="Players in the matrix: the N best by fitted "
                                     "Elo.")] = 10,
    run: Annotated[str | None, typer.Option("--run", help="Only this run's snapshots and the scripted players.")]
    = None,
    min_games: Annotated[int, typer.Option("--min-games", min=1, max=MAX_GAMES, help="Games a pair needs to count "
                                           "as measured (a training run's rating games give 8 per pair).")] = 8,
    payoff: Annotated[str, typer.Option("--payoff", help="The Nash meta-game's payoff: points (win 1, draw 0.5) "
                                        "or score (the game's own scores, e.g. poker's chips: PSRO's expected "
                                        "return).")] = "points",
    out: OutOpt = None,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Score matrix of the best players (row player's score against the column player, with game counts), the
    Nash equilibrium mixture of that meta-game and its statistically significant 3-cycles; pairs with too few
    games come with the command that plays them. One variant of the game: its default options, those --env-option
    asks for, or with --run the run's own."""
    from ..report.matrix import build_matrix, write_matrix_png
    from ..report.png import check_png_path
    from ..report.terminal import matrix_summary, matrix_table

    env = check_env(env)
    if out is not None:
        out = check_png_path(out)
    league = open_league(home, db, readonly=True)
    try:
        if run is not None and league.roster.get_run(run) is None:
            variant = ""  # build_matrix says the run is unknown, listing the runs
        else:
            env, variant = shown_variant(league, env, env_option, run)
        with _working("fitting ratings"):
            report = build_matrix(league, env, top=top, run=run, min_games=min_games, variant=variant,
                                  payoff=payoff)
    finally:
        league.close()
    written = write_matrix_png(report, out) if out is not None else None
    if json_out:
        print_json({**report.to_json(home), "png": None if written is None else str(written)})
        return
    unicode = console.is_terminal
    console.print(matrix_table(report, unicode=unicode))
    console.print(matrix_summary(report, home=home, unicode=unicode))
    if written is not None:
        console.print(f"wrote {written}", markup=False)
