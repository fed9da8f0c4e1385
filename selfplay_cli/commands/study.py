"""`marl study team-size`: seed 001's team-size method as one command (:mod:`selfplay_cli.study.team_size`)."""

from __future__ import annotations

import contextlib
from typing import Annotated, Any

import typer
from rich.table import Table

from ..envs import get_env
from ..errors import EXIT_INTERRUPTED, EXIT_TERMINATED
from ..signals import Terminated, stop_on_sigterm
from ._common import DbOpt, HomeOpt, JsonOpt, QuietOpt, open_league, parse_env_options, typed_game
from ._output import console, err_console, print_json

app = typer.Typer(no_args_is_help=True)


@app.command("team-size")
def team_size(
    env: Annotated[str, typer.Argument(callback=typed_game, help="The game (its team size must be an option: the "
                                       "lander's landers, pursuit's n_pursuers).")],
    train: Annotated[str, typer.Option("--train", metavar="SIZES", help="The team sizes to train, e.g. 2,3,4 or "
                                       "2-4: one run each, then each adapted to each other.")] = "2,3",
    eval_sizes: Annotated[str, typer.Option("--eval", metavar="SIZES", help="The team sizes each trained team "
                                            "flies, e.g. 1-6.")] = "1-4",
    steps: Annotated[int | None, typer.Option("--steps", help="Game steps per run (as marl train takes them).")]
    = None,
    minutes: Annotated[float | None, typer.Option("--minutes", help="Minutes per run (as marl train takes them).")]
    = None,
    size_option: Annotated[str | None, typer.Option("--size-option", metavar="NAME", help="The game option that "
                                                    "sets the team size (default: the game's own, the lander's "
                                                    "landers; a PettingZoo game's must be named: n_pursuers).")]
    = None,
    sharing: Annotated[str, typer.Option("--sharing", help="fups: one network for the team (flies any size); "
                                         "nops: one network a seat (flies another size by seed 001's rule).")]
    = "fups",
    algo: Annotated[str | None, typer.Option("--algo", help="The learner (default: marl train's, ppo).")] = None,
    kind: Annotated[str | None, typer.Option("--kind", help="The game's kind, for a game that does not declare it "
                                             "(pursuit: cooperative).")] = None,
    env_option: Annotated[list[str] | None, typer.Option("--env-option", metavar="KEY=VALUE", help="Another game "
                                                         "option for every run and evaluation, repeatable.")] = None,
    config: Annotated[str | None, typer.Option("--config", metavar="FILE", help="A marl train settings file for "
                                               "every run.")] = None,
    games: Annotated[int | None, typer.Option("--games", help="Games played side by side in training (marl "
                                              "train --games).")] = None,
    eval_games: Annotated[int, typer.Option("--eval-games", help="Episodes each team flies at each size (and the "
                                            "opponent on the same seeds).")] = 50,
    vs: Annotated[str, typer.Option("--vs", help="The opponent whose team return is shown beside each.")]
    = "random",
    snapshots: Annotated[int, typer.Option("--snapshots", help="Snapshots per run with --steps (the curves' "
                                           "points).")] = 8,
    seed: Annotated[int, typer.Option("--seed", help="Every run's seed.")] = 0,
    name: Annotated[str | None, typer.Option("--name", help="The study's name (its runs are NAME-n3, NAME-n3-to4; "
                                             "default: team-size-GAME). The same command again goes on with it.")]
    = None,
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Train teams of several sizes, fly each at fewer and more agents, and adapt each to the other sizes from its
    snapshot against training that size afresh (seed 001's method); a table of returns by size, the comparison, and
    each run's wall time, CPU use and peak memory.

    Each run is a marl train run of the league (NAME-nN, NAME-nN-toM), in its own process, which stops with the
    study (Ctrl-C, SIGTERM, or the study killed). A study stopped midway goes on where it stopped when the same
    command is typed again."""
    from ..league.store import check_name
    from ..study import TeamSizePlan, parse_sizes, run_study
    from ..train.settings import check_kind

    spec = get_env(env)
    option = size_option or spec.size_option
    if option is None:
        raise typer.BadParameter(f"{env} names no team-size option: give it with --size-option (e.g. n_pursuers)",
                                 param_hint="--size-option")
    if kind is not None:
        check_kind(spec, kind)
    if sharing not in ("fups", "nops"):
        raise typer.BadParameter(f"a team-size study trains fups or nops teams, not {sharing!r}",
                                 param_hint="--sharing")
    study_name = name or f"team-size-{spec.name.rsplit('.', 1)[-1].split(':')[-1]}"
    check_name("study name", study_name)
    plan = TeamSizePlan(name=study_name, env=spec.name, size_option=option,
                        train=tuple(parse_sizes(train, "--train")), eval=tuple(parse_sizes(eval_sizes, "--eval")),
                        steps=steps, minutes=minutes, sharing=sharing, algo=algo, kind=kind,
                        env_options=parse_env_options(env, env_option), eval_games=eval_games, vs=vs, seed=seed,
                        snapshots=snapshots, config=config, games=games)
    for size in sorted({*plan.train, *plan.eval}):  # every size the game must take, before anything runs
        try:
            spec.config(**plan.options(size))
        except (TypeError, ValueError) as e:
            raise typer.BadParameter(f"{env} at {option}={size}: {e}", param_hint="--train/--eval") from None
    league = open_league(home, db)
    try:
        with _progress(quiet or json_out, len(plan.runs())) as on_progress, stop_on_sigterm():
            report = run_study(league, plan, on_progress,
                               on_note=lambda line: err_console.print(f"marl study: {line}", markup=False))
    except (Terminated, KeyboardInterrupt) as stop:  # its training child has stopped too (and was waited for)
        why = "SIGTERM" if isinstance(stop, Terminated) else "Ctrl-C"
        err_console.print(f"marl: study {plan.name} stopped ({why}); what it did is kept: type the same command "
                          "again to go on", markup=False)
        raise typer.Exit(EXIT_TERMINATED if isinstance(stop, Terminated) else EXIT_INTERRUPTED) from None
    finally:
        league.close()
    if json_out:
        print_json(report)
        return
    render(report)


@contextlib.contextmanager
def _progress(quiet: bool, n_runs: int) -> Any:
    """A rich bar over the study's runs (the current one's share of its budget, its steps and steps/s), on stderr at
    a terminal."""
    from ._common import progress_enabled

    if not progress_enabled(quiet):
        yield lambda key, done, detail="": None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=err_console,
                  transient=True) as prog:
        task = prog.add_task("study", total=1.0)
        runs: dict[str, float] = {}

        def on_progress(key: str, done: float, detail: str = "") -> None:
            if not key.startswith("eval "):
                runs[key] = done
            shown = f"{key} ({detail})" if detail else key
            prog.update(task, description=f"study: {shown}", completed=min(1.0, sum(runs.values()) / max(n_runs, 1)))

        yield on_progress


def _ci(cell: dict[str, Any] | None) -> str:
    if not cell or cell.get("mean") is None:
        return "-"
    if cell.get("low") is None:
        return f"{cell['mean']:.1f}"
    return f"{cell['mean']:.1f} [{cell['low']:.1f}, {cell['high']:.1f}]"


def render(r: dict[str, Any]) -> None:
    """The study's three tables and where its files are."""
    t = Table(title=f"{r['env']}: mean team return by size trained (rows) x flown (columns), {r['eval_games']} "
                    f"episodes each, 95% intervals")
    t.add_column("trained")
    for m in r["eval"]:
        t.add_column(f"{r['size_option']}={m}", justify="right")
    for n in r["train"]:
        cells = {c["evaluated"]: c for c in r["returns"] if c["trained"] == n}
        t.add_row(str(n), *[_ci(cells.get(m)) for m in r["eval"]])
    vs = {c["evaluated"]: c["vs"] for c in r["returns"] if c["trained"] == r["train"][0]}
    t.add_row(r["vs"], *[_ci(vs.get(m)) for m in r["eval"]])
    console.print(t)
    a = Table(title="adapted from another size vs trained afresh (same budget): return at the end, and when the "
                    "adapted run reached the fresh run's final return (its snapshots flown on the same seeds)")
    for col in ("from -> to", "adapted", "fresh", "adapted reached fresh's final at", "fresh took"):
        a.add_column(col)
    for x in r["adaptive"]:
        reached = ("not reached" if x["steps_to_reach"] is None
                   else f"{x['steps_to_reach']:,} steps, {x['minutes_to_reach']:.1f} min ({x['reached_return']:.1f})")
        took = "-" if x["fresh_steps"] is None else f"{x['fresh_steps']:,} steps, {x['fresh_minutes']:.1f} min"
        a.add_row(f"{x['from']} -> {x['to']}", _ci(x["return"]), _ci(x["fresh_return"]), reached, took)
    console.print(a)
    f = Table(title="runs: wall time, CPU (mean cores busy), peak memory")
    for col in ("run", "size", "from", "steps", "wall", "CPU", "peak memory"):
        f.add_column(col)
    for x in r["runs"]:
        f.add_row(x["run"], str(x["size"]), "-" if x["from"] is None else str(x["from"]),
                  "-" if x["steps"] is None else f"{x['steps']:,}", f"{x['wall_seconds'] / 60:.1f} min",
                  f"{x['mean_cpu']:.2f}", f"{x['peak_mb']:,.0f} MB")
    console.print(f)
    plots = r.get("plots") or {}
    console.print(f"study {r['study']}: {r['dir']} (report.json" + (f", {plots['returns']}, {plots['curves']}"
                                                                    if plots else "") + ")",
                  markup=False, highlight=False)
