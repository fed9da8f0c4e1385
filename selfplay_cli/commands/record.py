"""`marl record`: games as videos, new ones (--ckpt) or stored ones replayed exactly (--game)."""

from __future__ import annotations

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
    from ..record.jobs import RecordJob


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
    from ..record.jobs import video_format

    if (ckpt is None) == (game_id is None):
        raise MarlError("say what to record: --ckpt POLICY (new games) or --game ID (a stored game)")
    if game_id is not None:
        _refuse_with_game(vs=vs, max_steps=max_steps, max_rallies=max_rallies, seconds=seconds, games=games,
                          seed=seed, env_option=env_option)
    fmt = video_format(fmt, out)
    league = open_league(home, db)
    try:
        from ..evaluation.lineup import lineups
        from ..record.jobs import limits, play_job, replay_job, video_settings

        # the players seated once (one lineup, or one per member of a team recorded against --vs)
        ups = lineups(league, ckpt, vs, env) if game_id is None else []  # type: ignore[arg-type]
        game = league.ledger.game(game_id).env if game_id is not None else ups[0].env
        if game_id is not None and env is not None and env != game:  # (--env names a game of your own to replay)
            raise MarlError(f"game {game_id} was played in {game}, not {env}")
        settings = video_settings(game, fps, size, fmt, hold, max_width)
        max_steps, max_rallies, stop_label, default_cap = limits(seconds, max_steps, max_rallies, settings.fps)
        if game_id is not None:
            job = replay_job(league, game_id, out, fmt)
        else:
            options = parse_env_options(game, env_option) if env_option else None
            job = play_job(league, ups, games, seed, max_steps, max_rallies, device, out, fmt, stop_label, options)
    finally:
        league.close()
    _write(job, settings, default_cap, progress_enabled(quiet), json_out, (home, db))


def _refuse_with_game(*, games: int, seed: int, env_option: list[str] | None, **flags: Any) -> None:
    """--game replays a stored game as it was: the options that make new games are refused, in one line."""
    given = [f"--{name.replace('_', '-')}" for name, value in flags.items() if value is not None]
    given += ["--games"] * (games != 1) + ["--seed"] * (seed != 0) + ["--env-option"] * bool(env_option)
    if given:
        verb = "does" if len(given) == 1 else "do"
        raise MarlError(f"--game replays a stored game as it was played: {', '.join(given)} {verb} not apply")


def _write(job: RecordJob, settings: VideoSettings, default_cap: bool, show: bool, json_out: bool,
           where: tuple[Any, Any] = (None, None)) -> None:
    """Make the job's videos, one progress bar each, printing a line per video (or their JSON at the end); each one
    written under the league home's videos folder is registered in the league (``where``: its home and URL) as
    soon as it is written (what ``marl serve`` plays)."""
    from ..record import check_writable

    for path in job.paths:
        check_writable(path)
    done: list[dict[str, Any]] = []
    try:
        for i, path in enumerate(job.paths):
            with progress_bar(path.name, job.frames(i, settings), "frames", show) as tick:
                rec = job.run(i, path, settings, tick)
            video_id = _register(job, i, rec, where)
            done.append({**rec.to_json(), **job.extra} | ({"video_id": video_id} if video_id is not None else {}))
            if not json_out:
                console.print(_line(rec, default_cap), markup=False)
    except KeyboardInterrupt:
        err_console.print(f"interrupted: {len(done)} of {len(job.paths)} videos written, no partial file left")
        raise typer.Exit(130) from None
    if json_out:
        print_json(done)




def _register(job: RecordJob, i: int, rec: Recording, where: tuple[Any, Any]) -> int | None:
    """Register video ``i`` in the league when it lies under the home's videos folder; its row id, else None."""
    if i >= len(job.shows):
        return None
    home, db = where
    league = open_league(home, db)
    try:
        if league.videos.relative(rec.path) is None:
            return None
        shows = job.shows[i]
        r = rec.result
        meta = {"names": list(r.players), "scores": [float(x) for x in r.scores], "fps": rec.settings.fps,
                "seconds": round(rec.video_seconds, 2), "ended": rec.ended}
        row = league.videos.register(env=r.env, path=rec.path, fmt=rec.settings.fmt, players=shows["players"],
                                     seed=shows["seed"], length=r.length, game_id=shows["game_id"], meta=meta)
        return None if row is None else row.id
    finally:
        league.close()
