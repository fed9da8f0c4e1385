"""`marl record`: games as videos, new ones (--ckpt) or stored ones replayed exactly (--game)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from ..errors import MarlError
from ._common import (
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
)
from ._output import console, err_console, print_json

if TYPE_CHECKING:
    from ..record import Recording, VideoSettings

Tick = Callable[[int], None]


@dataclass
class _Job:
    """The videos to make: their paths, how to make video i, and how many frames it will have (if known)."""

    paths: list[Path]
    run: Callable[[int, Path, VideoSettings, Tick], Recording]
    frames: Callable[[int, VideoSettings], int | None]
    extra: dict[str, Any] = field(default_factory=dict)  # added to every video's JSON


def _format_of(fmt: str | None, out: Path | None) -> str:
    """--format, else the suffix of a file given to --out, else mp4; a clash between them is an error."""
    from ..record import FORMATS

    suffix = out.suffix.lower().lstrip(".") if out is not None and not _is_dir(out) else ""
    if suffix and suffix not in FORMATS:
        raise MarlError(f"--out {out}: the file must end in .mp4 or .gif")
    if fmt is not None:
        fmt = fmt.lower()
        if fmt not in FORMATS:
            raise MarlError(f"--format must be one of {', '.join(FORMATS)}, not {fmt!r}")
        if suffix and suffix != fmt:
            raise MarlError(f"--out {out} is a .{suffix} file but --format is {fmt}")
        return fmt
    return suffix or "mp4"


def _is_dir(out: Path) -> bool:
    """--out is a folder when it is one already, or when it has no suffix (a file needs .mp4 or .gif)."""
    return out.is_dir() or not out.suffix


def _targets(out: Path | None, home: Path | None, stems: list[str], fmt: str) -> list[Path]:
    """One file per game: under <home>/videos by default, under --out if it is a folder, or --out itself."""
    if out is None or _is_dir(out):
        folder = out if out is not None else (home or Path("league")) / "videos"
        return [folder / f"{stem}.{fmt}" for stem in stems]
    if len(stems) > 1:
        raise MarlError(f"--out {out} names one file but {len(stems)} games were asked for: give --out a folder, "
                        "or leave it out for one file per game under <home>/videos")
    return [out]


DEFAULT_SECONDS = 60
"""Without a limit of their own, recordings stop after this many seconds of play (3,600 steps at 60 fps): a
length a person watches. A pong game between trained players runs to its 5-minute time limit."""


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 60}:{s % 60:02d}"


def score_text(env: str, scores: tuple[float, ...]) -> str:
    """A game's score for people: ``3-1`` (two seats), ``team return -34.9`` (cooperative), ``scores 2, -1, 0``."""
    from ..envs import get_env
    from ..results import COOPERATIVE, format_score

    if get_env(env).kind == COOPERATIVE:
        return f"team return {sum(scores):.1f}"
    shown = [format_score(round(s, 2)) for s in scores]
    if len(scores) == 2 and min(scores) >= 0:
        return "-".join(shown)
    return "scores " + ", ".join(shown)


def _line(rec: Recording, default_cap: bool) -> str:
    """``<path>  A vs B 3-1 (stopped at 1:00 by --seconds 60 ...), 3,600 steps, 1:01 of video, rendered in 8.4 s``."""
    from ..record.recorder import ENDED_STOPPED, ENDED_TIME_LIMIT
    from ..record.video import GIF_FPS

    r = rec.result
    score = score_text(r.env, r.scores)
    play = r.length / rec.settings.fps
    if rec.ended == ENDED_STOPPED:
        how = f" (stopped at {_clock(play)} by {rec.stopped_by}"
        how += "; the default cap: --seconds 0 records the whole game)" if default_cap else ")"
    elif rec.ended == ENDED_TIME_LIMIT:
        how = f" (the game's time limit: {r.length:,} steps, decided by the score)"
    else:
        how = ""
    if rec.settings.fmt == "gif":
        frames = f"{rec.stored:,} frames stored of {rec.frames:,}: each picture once, at most {GIF_FPS} a second"
    else:
        frames = f"{rec.frames:,} frames at {rec.settings.fps} fps"
    return (f"{rec.path}  {' vs '.join(r.players)} {score}{how}, {r.length:,} steps, {_clock(rec.video_seconds)} of "
            f"video ({frames}), rendered in {rec.seconds:.1f} s")


def _limits(seconds: float | None, max_steps: int | None, max_rallies: int | None,
            fps: int) -> tuple[int | None, int | None, str | None, bool]:
    """(max steps, max rallies, the label of the limit, whether it is the default cap) from the options: at most one
    of --seconds, --max-steps, --max-rallies; none given means --seconds 60."""
    given = [flag for flag, value in (("--seconds", seconds), ("--max-steps", max_steps),
                                      ("--max-rallies", max_rallies)) if value is not None]
    if len(given) > 1:
        raise MarlError(f"{' and '.join(given)} exclude each other: give one limit")
    if max_steps is not None:
        return max_steps, None, f"--max-steps {max_steps}", False
    if max_rallies is not None:
        return None, max_rallies, f"--max-rallies {max_rallies}", False
    default = seconds is None
    seconds = DEFAULT_SECONDS if seconds is None else seconds
    if seconds == 0:
        return None, None, None, False
    return max(1, round(seconds * fps)), None, f"--seconds {seconds:g}", default


def record(
    ckpt: Annotated[str | None, typer.Option("--ckpt", metavar="POLICY", help="Policy to record: a snapshot "
                                             "(s6M-left, pong-1/s6M-left), a tag, latest, best, an id or a scripted "
                                             "player. A run with one network per seat: s6M is the team (s6M-left vs "
                                             "s6M-right); with --vs, one video per member.")] = None,
    vs: Annotated[str | None, typer.Option("--vs", metavar="POLICY", help="Opponent (same forms). Default: the "
                                           "snapshot's teammates from the same moment, else cpu.")] = None,
    game_id: Annotated[int | None, typer.Option("--game", metavar="ID", min=1, help="Re-render game ID of the "
                                                "ledger exactly as it was played (the games of marl match, "
                                                "tournaments, gates and training).")] = None,
    env: EnvOpt = None,
    env_option: EnvOptionOpt = None,
    games: Annotated[int, typer.Option("--games", "-n", min=1, max=1_000, help="Games to record, one file each; "
                                       "game i uses seed --seed + i.")] = 1,
    seconds: Annotated[float | None, typer.Option("--seconds", metavar="S", min=0.0, max=86_400.0, help="Stop each "
                                                  "game after S seconds of video (S x fps game steps). Default 60 "
                                                  "when no other limit is given; 0 records the whole game (it ends by "
                                                  "its own rules: pong's time limit is 5 minutes).")] = None,
    max_steps: Annotated[int | None, typer.Option("--max-steps", min=1, max=10_000_000, help="Stop each game after "
                                                  "N steps instead.")] = None,
    max_rallies: Annotated[int | None, typer.Option("--max-rallies", min=1, max=100_000, help="Stop each game after "
                                                    "N rallies instead (serves played out: a point, a re-serve or a "
                                                    "drawn rally).")] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Seed of the first game.")] = 0,
    fps: Annotated[int | None, typer.Option("--fps", help="Frames per second; one frame per game "
                                            "step, so 60 is real time. Default: the game's own pace if it states "
                                            "one (a PettingZoo game's render_fps), else 60. A GIF stores at most 20 "
                                            "a second, dropping the others, at the same pace.")] = None,
    size: Annotated[str | None, typer.Option("--size", metavar="WxH", help="WIDTHxHEIGHT of the video, even "
                                             "numbers. Default: the game's picture and the caption band under it "
                                             "(pong 800x456).")] = None,
    max_width: Annotated[int | None, typer.Option("--max-width", metavar="W", min=0, max=4096, help="Scale "
                                                  "wider videos down to W pixels, keeping their shape; 0: no limit. "
                                                  "Default: 640 for a GIF, no limit for an mp4.")] = None,
    fmt: Annotated[str | None, typer.Option("--format", metavar="mp4|gif", help="mp4 (H.264, plays in browsers) or "
                                            "gif. Default: from --out, else mp4.")] = None,
    hold: Annotated[float, typer.Option("--hold", min=0.0, max=60.0, help="Seconds the final frame stays on "
                                        "screen.")] = 1.0,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="A .mp4/.gif file (one game), or a folder for "
                                             "one file per game. Default: a file in <home>/videos named after the "
                                             "players and the seed.")] = None,
    device: DeviceOpt = "auto",
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Record games as mp4/gif videos (under every frame: the players' names per seat, the running score, the step
    and the game's number), or replay a stored game exactly.

    A game plays until it is won, until its own time limit, or until the recording's limit: by default 60 seconds
    of video (--seconds 0 for the whole game; --max-steps or --max-rallies instead). The last frame and the printed
    line say which ended it."""
    from ..record import VideoSettings, check_writable, parse_size

    if (ckpt is None) == (game_id is None):
        raise MarlError("say what to record: --ckpt POLICY (new games) or --game ID (a stored game)")
    if game_id is not None:
        given = [flag for flag, value in (("--vs", vs), ("--env", env), ("--max-steps", max_steps),
                                          ("--max-rallies", max_rallies), ("--seconds", seconds)) if value is not None]
        given += ["--games"] * (games != 1) + ["--seed"] * (seed != 0) + ["--env-option"] * bool(env_option)
        if given:
            verb = "does" if len(given) == 1 else "do"
            raise MarlError(f"--game replays a stored game as it was played: {', '.join(given)} {verb} not apply")
    fmt = _format_of(fmt, out)
    league = open_league(home, db)
    try:
        from ..envs import get_env
        from ..rated.lineup import lineups

        # the players seated once (one lineup, or one per member of a team recorded against --vs)
        ups = lineups(league, ckpt, vs, env) if game_id is None else []  # type: ignore[arg-type]
        game = league.game(game_id).env if game_id is not None else ups[0].env
        if fps is None:  # the game's own pace (a board game: a move or two a second), else one frame per step
            fps = get_env(game).render_fps or 60
        settings = VideoSettings(fps=fps, size=parse_size(size), fmt=fmt, hold=hold, max_width=max_width)
        max_steps, max_rallies, stop_label, default_cap = _limits(seconds, max_steps, max_rallies, fps)
        if game_id is not None:
            job = _replay_job(league, game_id, out, fmt)
        else:
            options = parse_env_options(game, env_option) if env_option else None
            job = _play_job(league, ups, games, seed, max_steps, max_rallies, device, out, fmt, stop_label, options)
    finally:
        league.close()
    for path in job.paths:
        check_writable(path)

    done: list[dict[str, Any]] = []
    show = progress_enabled(quiet)
    try:
        for i, path in enumerate(job.paths):
            with progress_bar(path.name, job.frames(i, settings), "frames", show) as tick:
                rec = job.run(i, path, settings, tick)
            done.append({**rec.to_json(), **job.extra})
            if not json_out:
                console.print(_line(rec, default_cap), markup=False)
    except KeyboardInterrupt:
        err_console.print(f"interrupted: {len(done)} of {len(job.paths)} videos written, no partial file left")
        raise typer.Exit(130) from None
    if json_out:
        print_json(done)


def _replay_job(league: Any, game_id: int, out: Path | None, fmt: str) -> _Job:
    """What replaying one stored game needs, read from the ledger (no network is loaded: the actions suffice)."""
    from ..envs import get_env
    from ..rated.lineup import safe_filename
    from ..record import record_replay, renderer_of

    row = league.game(game_id)
    if row.actions is None:
        raise MarlError(f"game {row.id} ({row.match_kind} #{row.match_id}) was stored without its actions, so it "
                        "cannot be replayed exactly (games stored by an older marl have none)")
    spec = get_env(row.env)
    renderer_of(spec)  # no renderer: say so before anything else
    names = [league.get_player(pid).full_name for pid in row.players]
    stem = safe_filename(f"game{row.id}-{'-vs-'.join(names)}-s{row.seed}")
    env_options = dict(row.match_params.get("env_options") or {})

    def run(i: int, path: Path, settings: VideoSettings, tick: Tick) -> Recording:
        return record_replay(spec, names, row.seed, row.actions, path, settings, length=row.length,
                             scores=row.scores, env_options=env_options, on_frame=tick,
                             heading=f"replay of game {row.id}")

    return _Job(_targets(out, league.home, [stem], fmt), run, lambda i, s: row.length + 1 + s.hold_frames,
                {"game_id": row.id, "match_id": row.match_id})


def _play_job(league: Any, ups: list[Any], games: int, seed: int, max_steps: int | None, max_rallies: int | None,
              device: str, out: Path | None, fmt: str, stop_label: str | None = None,
              options: dict[str, Any] | None = None) -> _Job:
    """For the lineups ``ups``: load the networks once, and play game i with seed ``seed + i``."""
    from ..arena import Game
    from ..envs import get_env
    from ..policies import ScriptedPolicy
    from ..rated.lineup import refit
    from ..rated.match import check_fits, env_options_of, load_player
    from ..record import record_game, renderer_of, stop_rule

    spec = get_env(ups[0].env)
    renderer = renderer_of(spec)
    networks = {p.id: load_player(league, p, device=device) for lu in ups for p in lu.players if not p.is_bot}
    env_options = {**env_options_of(*networks.values()), **(options or {})}
    spec = spec.for_options(**env_options)
    check_fits(spec, env_options, *networks.values())
    ups = [refit(lu, spec.n_seats, seed) for lu in ups]  # a team flown with more or fewer seats than it has
    stop = stop_rule(spec, env_options, max_steps, max_rallies)
    seats = tuple(range(len(ups[0].players)))

    def policies(lu: Any, game_seed: int) -> list[Any]:
        # bots draw from generators seeded by the game, so a game looks the same whatever was recorded before it
        return [networks[p.id] if not p.is_bot else ScriptedPolicy(p.env, p.name, seed=game_seed * len(seats) + s)
                for s, p in enumerate(lu.players)]

    def seating(lu: Any) -> tuple[int, ...]:
        """Each seat's index into the policies: a network on several seats is one player there (a joint agent
        flies its whole team at once), each scripted player its own."""
        first: dict[int, int] = {}
        return tuple(s if p.is_bot else first.setdefault(p.id, s) for s, p in enumerate(lu.players))

    def run(i: int, path: Path, settings: VideoSettings, tick: Tick) -> Recording:
        lu, game_seed = ups[i // games], seed + i % games
        return record_game(spec, policies(lu, game_seed), Game(game_seed, seating(lu)), path, settings,
                           env_options=env_options, labels=lu.names, stop_when=stop, on_frame=tick, renderer=renderer,
                           stop_label=stop_label, heading=f"game {i + 1} of {len(ups) * games}")

    limit = getattr(spec.config(**env_options), "max_steps", None) or None  # the game's own time limit, if any

    def frames(i: int, settings: VideoSettings) -> int | None:
        """At most this many frames (the bar's total): the serve, one per step up to the nearer limit, the hold."""
        caps = [c for c in (max_steps, limit) if c is not None]
        return min(caps) + 1 + settings.hold_frames if caps else None

    stems = [lu.file_stem(seed + i) for lu in ups for i in range(games)]
    return _Job(_targets(out, league.home, stems, fmt), run, frames)
