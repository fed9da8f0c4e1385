"""Options and helpers shared by the commands: the league home, name resolution, progress bars."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

from ..envs import admit, env_names, get_env
from ..errors import MarlError
from ..league.store import League
from ..policies.bots import league_bots
from ._output import err_console


def typed_game(value: Any) -> Any:
    """The callback of every option and argument that names a game (the game argument, ``--env``): a game the user
    typed is admitted, so that a game of your own (``mygame:env``) is imported when the command asks for it; a game
    named only by the league, a job or a stored config never is (:mod:`selfplay_cli.envs.loading`)."""
    for name in value if isinstance(value, list | tuple) else [value]:
        if isinstance(name, str) and name:
            admit(name)
    return value


HomeOpt = Annotated[
    Path | None,
    typer.Option("--home", envvar="MARL_HOME", help="League home (database, snapshots, videos). Default ./league."),
]
DbOpt = Annotated[
    str | None,
    typer.Option("--db", envvar="MARL_DB", help="Any SQLAlchemy URL for the league (default <home>/league.db)."),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON alone on stdout.")]
EnvOpt = Annotated[str | None, typer.Option("--env", callback=typed_game, help="Game, where the policies do not imply "
                                            "it (a game of your own, module:factory, is imported because you name it "
                                            "here or in MARL_GAMES).")]
DeviceOpt = Annotated[str, typer.Option("--device", help="Where networks run: auto, cpu or cuda.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")]

MAX_GAMES = 10_000_000
"""The most games one command plays (10 million: days of play; a larger number is a typo)."""
MAX_PARALLEL = 65_536
"""The most games played at once in the batched core."""
MAX_SEED = 2**32 - 1
"""Seeds are 32-bit: 0 to 4,294,967,295."""


def open_league(home: Path | None, db: str | None, readonly: bool = False) -> League:
    """The league of ``home`` / ``db``. ``readonly`` (the commands that only read: ladder, matrix, plot, checkpoint
    list / show / export, elo fit) opens an existing league for reading and creates nothing, so a read-only league
    can be listed and reading never creates a league where there was none; otherwise the league is created if new,
    and the temporary files that killed processes left in its folders are removed first (one line on stderr says
    which)."""
    from ..files import describe_removed, sweep_home

    league = League.open(home=home, url=db, readonly=readonly)
    if not readonly and league.home is not None:
        removed = sweep_home(league.home)
        if removed:
            err_console.print(describe_removed(removed, league.home), markup=False)
    return league


def check_env(env: str | None) -> str | None:
    if env is not None:
        get_env(env)  # unknown env -> a clear error
    return env


def _guess(raw: str) -> object:
    """A value of an option whose type the game does not declare: a whole number, a number, true/false or text."""
    text = raw.strip()
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for cast in (int, float):
        try:
            value = cast(text)
        except ValueError:
            continue
        if isinstance(value, float) and not math.isfinite(value):
            raise MarlError(f"--env-option takes finite numbers only, not {text!r}")
        return value
    return text


EnvOptionOpt = Annotated[list[str] | None, typer.Option(
    "--env-option", metavar="KEY=VALUE", help="Game option over those the players were made for, repeatable (e.g. "
    "landers=4 flies a lander team as 4; marl envs NAME lists a game's options).")]


_VARIANT_HELP = ("The variant of the game to rate: its games played under this option (as marl match / marl train "
                 "take it), repeatable, e.g. points_to_win=3. Default: the game's default options{run}. Options a game "
                 "declares neutral (pong's frame_stack) split nothing.")
VariantOpt = Annotated[list[str] | None, typer.Option(
    "--env-option", metavar="KEY=VALUE", help=_VARIANT_HELP.format(run=" (with --run: the options the run trained "
                                                                          "under)"))]
LedgerVariantOpt = Annotated[list[str] | None, typer.Option(
    "--env-option", metavar="KEY=VALUE", help=_VARIANT_HELP.format(run=""))]
"""--env-option of a command that rates the league's games without a --run (marl elo fit)."""
LeagueEnvOpt = Annotated[str | None, typer.Option("--env", callback=typed_game, help="The game (default: the "
                                                  "league's only game; with --run, the run's).")]
"""--env of a command given no policies, that shows one game of the league."""


def parse_env_options(env: str, items: list[str] | None) -> dict:
    """``KEY=VALUE`` game options, each read as the type the game's config declares for it (a whole number, a
    number, true/false, one of a few words), then checked by the game's own config (ranges, unknown options)."""
    from ..typecheck import field_types, from_text

    spec = get_env(env)
    types = field_types(type(spec.config()))
    defaults = spec.config()
    options: dict = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise MarlError(f"--env-option must look like KEY=VALUE (e.g. points_to_win=5), not {item!r}")
        if key not in types:
            options[key] = _guess(raw)
            continue
        try:
            options[key] = from_text(raw, types[key])
        except ValueError as e:
            default = getattr(defaults, key, None)
            example = f" (e.g. {key}={default}, its default)" if default is not None else ""
            raise MarlError(f"--env-option {item}: {env}'s {key} wants {e}, not {raw.strip()!r}{example}") from None
    try:
        spec.config(**options)
    except (TypeError, ValueError) as e:
        raise MarlError(f"--env-option: {env}: {e}") from None
    return options


def shown_variant(league: League, env: str | None, env_option: list[str] | None,
                  run: str | None = None) -> tuple[str, str]:
    """The game and the variant (its key) a command that reads ratings shows: the one ``--env-option`` asks for (over
    the game's defaults); without, :func:`~selfplay_cli.ratings.shown.default_variant` (the run's own, else the one
    the game's newest run with rated games played, else the default, else the one with the most games)."""
    from ..league.variants import variant_key
    from ..ratings.ladder import pick_env
    from ..ratings.shown import default_variant

    if env_option:
        if run is not None:
            info = league.roster.get_run(run)
            env = env or (info.env if info is not None else None)
        env = pick_env(league, env)
        return env, variant_key(env, parse_env_options(env, env_option))
    return default_variant(league, env, run)


def resolve_players(league: League, names: list[str], env: str | None, teams: bool = False,
                    env_option: list[str] | None = None) -> list:
    """Resolve names to players (:mod:`selfplay_cli.ratings.names`). Snapshots imply their game; bot names need the
    game from them or --env. With ``teams`` a name may also stand for a team of per-seat snapshots (``s6M``:
    ``s6M-left`` and ``s6M-right``), returned as a :class:`~selfplay_cli.ratings.names.Team`; without, such a
    name is refused in one line that names the members. ``best`` is the best of the variant ``env_option`` (the
    command's ``--env-option``) makes, the default one without."""
    from ..ratings.names import resolve, resolve_or_team

    find = resolve_or_team if teams else resolve
    env = check_env(env)
    best = [i for i, n in enumerate(names) if env_option and str(n).strip() == "best"]  # once the game is known
    named = [i for i in range(len(names)) if i not in best]
    rows: dict[int, Any] = {}
    pending = []
    for i in named:
        try:
            rows[i] = find(league, names[i], env)
        except MarlError:
            pending.append(i)
    if pending:
        snapshots = {r.env for r in rows.values() if not getattr(r, "is_bot", False)}
        if env is None and len(snapshots) == 1:  # a snapshot implies its game
            env = snapshots.pop()
        elif env is None and not snapshots:  # scripted players only: the game they belong to, all of them
            env = _game_of_bots(league, [names[i] for i in named])
            pending = named if env is not None else pending
        if env is not None:
            league.roster.ensure_bots(env, league_bots(get_env(env)))
        for i in pending:
            rows[i] = find(league, names[i], env)  # raises the precise error (unknown, ambiguous, team...)
    if best:  # the best of the variant the options make
        from ..league.variants import variant_key
        from ..ratings.ladder import pick_env

        game = env or next((r.env for r in rows.values()), None) or pick_env(league, None)
        variant = variant_key(game, parse_env_options(game, env_option))
        for i in best:
            rows[i] = find(league, names[i], game, variant=variant)
    return [rows[i] for i in range(len(names))]


def _game_of_bots(league: League, names: list[str]) -> str | None:
    """The game scripted players named alone (``marl match cpu random``) belong to: the one registered game, the one
    game with all of them, or the one of those the league holds players of. None: the resolver then says what is
    missing; names of scripted players of several games ask for --env."""
    games = env_names()
    if len(games) == 1:
        return games[0]
    having = [g for g in games if all(n in league_bots(get_env(g)) for n in names)]
    if len(having) == 1:
        return having[0]
    held = {p.env for p in league.roster.players()} & set(having)
    if len(held) == 1:
        return held.pop()
    if len(having) > 1:
        raise MarlError(f"{' and '.join(sorted(set(names)))}: scripted players of several games "
                        f"({', '.join(having)}): say which with --env")
    return None


class RateColumn(ProgressColumn):
    """Items per second, e.g. ``57 games/s``."""

    def __init__(self, unit: str) -> None:
        super().__init__()
        self.unit = unit

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        return Text(f"{speed:,.0f} {self.unit}/s" if speed else f"- {self.unit}/s")


def progress_enabled(quiet: bool = False) -> bool:
    return not quiet and err_console.is_terminal


@contextmanager
def progress_bar(description: str, total: int | None, unit: str, enabled: bool) -> Iterator[Callable[..., None]]:
    """A rich progress bar on stderr (rate and ETA) when it is a terminal; a no-op otherwise.

    ``total`` None (work of unknown size, e.g. a game to 21) shows a pulsing bar with the count and the rate."""
    if not enabled:
        yield lambda n=1: None
        return
    columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), RateColumn(unit),
               TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn()]
    with Progress(*columns, console=err_console, transient=True) as prog:
        task = prog.add_task(description, total=total)
        yield lambda n=1: prog.advance(task, n)
