"""`marl elo fit` and `marl elo gate`: ratings from the ledger (or a CSV) and a CI gate on strength."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

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
    LedgerVariantOpt,
    check_env,
    open_league,
    parse_env_options,
    resolve_players,
    shown_variant,
    typed_game,
)
from ._output import console, print_json
from .ladder_view import prior_caption, render_ladder

app = typer.Typer(help="Fit ratings with confidence intervals; gate a model on its strength.", no_args_is_help=True,
                  rich_markup_mode=None)

BootstrapOpt = Annotated[int, typer.Option("--bootstrap", max=100_000, help="Bootstrap resamples for the "
                                           "intervals: 0 (the normal approximation) or at least 20.")]
ANCHOR_HELP = ("Fix one player's rating, e.g. cpu=1200 (default: the anchor the game declares, at 1000: a scripted "
               "player, random unless the game declares another, as marl envs GAME --json says; where it has no "
               "games, random, else the first scripted player with games, else the player with the most games{more})")
AnchorOpt = Annotated[str | None, typer.Option("--anchor", metavar="NAME=RATING", help=ANCHOR_HELP.format(more=""))]
FitAnchorOpt = Annotated[str | None, typer.Option("--anchor", metavar="NAME=RATING", help=ANCHOR_HELP.format(
    more="; with --results: the file's first player"))]
PriorOpt = Annotated[float, typer.Option(
    "--prior", help="BayesElo's prior: N virtual draws spread over the games of each player, so that a perfect "
    "score gets a finite rating (MAP). The default 2 is BayesElo's. 0 gives the plain maximum-likelihood fit.")]


def check_prior(prior: float) -> float:
    if not prior >= 0 or prior == float("inf"):
        raise MarlError(f"--prior must be a number of virtual draws >= 0, not {prior}")
    return float(prior)


def resolve_anchor(league, name: str | None, env: str | None, variant: str = ""):
    """The anchor a user named (any name ``marl`` understands: id, run/name, tag, bot, latest, best), in the env
    and variant the ladder will use; None for the default anchor."""
    if name is None:
        return None
    from ..ratings.ladder import pick_env
    from ..ratings.names import resolve

    return resolve(league, name, pick_env(league, env), variant=variant)


def parse_anchor(anchor: str | None) -> tuple[str | None, float]:
    if anchor is None:
        return None, 1000.0
    name, sep, rating = anchor.rpartition("=")
    try:
        if not sep or not name:
            raise ValueError
        value = float(rating)
    except ValueError:
        raise MarlError(f"--anchor must look like NAME=RATING (e.g. random=1000), not {anchor!r}") from None
    if not math.isfinite(value) or abs(value) > 1e6:
        raise MarlError(f"--anchor {anchor}: the rating must be a finite number of Elo points (e.g. {name}=1000)")
    return name, value


def check_bootstrap(n: int) -> int:
    if n < 0 or 0 < n < 20:
        raise MarlError(f"--bootstrap must be 0 or at least 20, not {n}")
    return n


@app.command("fit")
def fit(
    env: Annotated[str | None, typer.Option("--env", callback=typed_game, help="The game to rate (default: the "
                                            "league's only game).")] = None,
    env_option: LedgerVariantOpt = None,
    anchor: FitAnchorOpt = None,
    bootstrap: BootstrapOpt = DEFAULT_BOOTSTRAP,
    confidence: Annotated[float, typer.Option("--confidence", help="Level of the intervals.")] = 0.95,
    results: Annotated[Path | None, typer.Option("--results", help="Rate the games of a CSV file "
                                                 "(player_a,player_b,result) instead of the league.")] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Bootstrap seed.")] = 0,
    prior: PriorOpt = DEFAULT_PRIOR,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Bradley-Terry ratings over the whole ledger (draw = half a point), 400 Elo scale: MAP under BayesElo's
    prior of 2 virtual draws by default (--prior 0: maximum likelihood), with confidence intervals and ranks.

    One variant of the game at a time: the games under its default options, or under those --env-option asks
    for; a line below the table names the other variants with games."""
    from ..ratings.ladder import ladder
    from ..ratings.results_csv import fit_csv
    from ..ratings.verdicts import verdict_lines

    name, rating = parse_anchor(anchor)
    check_bootstrap(bootstrap)
    prior = check_prior(prior)
    variant = note = None
    if results is not None:
        if env_option:
            raise MarlError("--env-option chooses games of the league; a --results file has no game options")
        rows = fit_csv(results, anchor=name, anchor_rating=rating, bootstrap=bootstrap, confidence=confidence,
                       seed=seed, prior=prior)
        title = f"ratings of {results}"
    else:
        league = open_league(home, db, readonly=True)
        try:
            env, variant = shown_variant(league, check_env(env), env_option)
            rows = ladder(league, env, anchor=resolve_anchor(league, name, env, variant), anchor_rating=rating,
                          bootstrap=bootstrap, confidence=confidence, seed=seed, prior=prior, variant=variant)
            note = other_variants_note(env, league.ledger.variants(env), variant, "marl elo fit")
        finally:
            league.close()
        title = "ratings fitted over the ledger" + (f" ({env}: {describe_variant(variant)})" if variant else "")
    render_ladder(rows, title, json_out=json_out, confidence=confidence, caption=prior_caption(prior, confidence),
                  variant=None if variant is None else variant_options(variant), verdicts=verdict_lines(rows))
    if note and not json_out:
        console.print(note, markup=False)


@app.command("gate")
def gate(
    candidate: Annotated[str, typer.Argument(metavar="CANDIDATE", help="The policy that must be stronger: a snapshot "
                                             "(s6M-left, ci/candidate), a tag, latest, best or an id.")],
    vs: Annotated[str, typer.Option("--vs", metavar="BASELINE", help="The baseline policy it must beat (same forms, "
                                    "or a scripted player such as cpu).")],
    min_diff: Annotated[float, typer.Option("--min-diff", min=-4000.0, max=4000.0, help="Required lower bound of "
                                            "Elo(CANDIDATE) - Elo(BASELINE).")] = 0.0,
    env: EnvOpt = None,
    env_option: EnvOptionOpt = None,
    games: Annotated[int, typer.Option("--games", "-n", min=2, max=MAX_GAMES, help="Head-to-head games to base the "
                                       "verdict on; stored ones are reused, the rest are played and stored.")] = 400,
    confidence: Annotated[float, typer.Option("--confidence", help="One-sided level of the lower bound.")] = 0.95,
    parallel: Annotated[int, typer.Option("--parallel", min=2, max=MAX_PARALLEL, help="Games played at once.")]
    = 1024,
    queue: Annotated[bool, typer.Option("--queue", help="Put the missing games on the league's work queue as jobs "
                                        "of a few minutes: every marl worker attached plays them, and so does this "
                                        "command.")] = False,
    device: DeviceOpt = "auto",
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Is CANDIDATE at least --min-diff Elo stronger than BASELINE? A verdict from their head-to-head games.

    Stored games are reused and the missing ones played (and stored), all of one variant of the game: the options
    the two were made for, with --env-option over them (best: the best of that variant). Exit 0 (PASS) when the
    one-sided lower confidence bound of Elo(CANDIDATE) - Elo(BASELINE) is at least --min-diff, 1 (FAIL) otherwise;
    2 for a mistake in the command, 4 for an I/O error, 5 for an internal error, so that CI can tell a failed model
    from a broken run."""
    if not 0.5 < confidence < 1:
        raise MarlError(f"--confidence must lie in (0.5, 1), not {confidence}")
    league = open_league(home, db)
    try:
        cand, base = resolve_players(league, [candidate, vs], env, env_option=env_option)
        options = parse_env_options(cand.env, env_option) if env_option else None
        from ..evaluation.gate import gate_check  # (torch: imported when a gate plays, not for every command)

        verdict = gate_check(league, cand, base, min_diff=min_diff, games=games, confidence=confidence,
                             parallel=parallel, device=device, env_options=options, queue=queue)
    finally:
        league.close()
    if json_out:
        print_json(verdict.to_json())
    else:
        word = "[bold green]PASS[/]" if verdict.passed else "[bold red]FAIL[/]"
        console.print(f"{word}: {verdict.reason}")
    raise typer.Exit(0 if verdict.passed else 1)
