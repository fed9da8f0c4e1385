"""What ``marl record`` makes: the videos a request asks for (new games of lineups, or a stored game replayed
exactly), the file each goes to, and how long each game may run. The command parses and prints; this holds what a
test would call without the CLI."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import MarlError

if TYPE_CHECKING:
    from .recorder import Recording, VideoSettings

__all__ = ["DEFAULT_SECONDS", "RecordJob", "Tick", "limits", "play_job", "replay_job", "targets", "video_format",
           "video_settings"]

Tick = Callable[[int], None]


@dataclass
class RecordJob:
    """The videos to make: their paths, how to make video i, and how many frames it will have (if known)."""

    paths: list[Path]
    run: Callable[[int, Path, VideoSettings, Tick], Recording]
    frames: Callable[[int, VideoSettings], int | None]
    extra: dict[str, Any] = field(default_factory=dict)  # added to every video's JSON
    shows: list[dict[str, Any]] = field(default_factory=list)
    """Per video: the ``players`` it shows (their ids, seat by seat), its ``seed`` and the ``game_id`` it replays
    (None: a new game): what the league registers of it (:meth:`~selfplay_cli.league.videos.Videos.register`)."""


def video_format(fmt: str | None, out: Path | None) -> str:
    """--format, else the suffix of a file given to --out, else mp4; a clash between them is an error."""
    from .video import FORMATS

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


def targets(out: Path | None, home: Path | None, stems: list[str], fmt: str) -> list[Path]:
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


def video_settings(env: str, fps: int | None, size: str | None, fmt: str, hold: float,
                   max_width: int | None) -> VideoSettings:
    """The settings of a recording's videos; ``fps`` None: the game's own pace (a board game: a move or two a
    second), else one frame per step at 60."""
    from ..envs import get_env
    from .recorder import VideoSettings
    from .video import parse_size

    if fps is None:
        fps = get_env(env).render_fps or 60
    return VideoSettings(fps=fps, size=parse_size(size), fmt=fmt, hold=hold, max_width=max_width)


def limits(seconds: float | None, max_steps: int | None, max_rallies: int | None,
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


def replay_job(league: Any, game_id: int, out: Path | None, fmt: str) -> RecordJob:
    """What replaying one stored game needs, read from the ledger (no network is loaded: the actions suffice)."""
    from ..envs import get_env
    from ..evaluation.lineup import safe_filename
    from .recorder import record_replay, renderer_of

    row = league.ledger.game(game_id)
    if row.actions is None:
        raise MarlError(f"game {row.id} ({row.match_kind} #{row.match_id}) was stored without its actions, so it "
                        "cannot be replayed exactly (games stored by an older marl have none)")
    spec = get_env(row.env)
    renderer_of(spec)  # no renderer: say so before anything else
    names = [league.roster.get_player(pid).full_name for pid in row.players]
    stem = safe_filename(f"game{row.id}-{'-vs-'.join(names)}-s{row.seed}")
    env_options = dict(row.match_params.get("env_options") or {})

    def run(i: int, path: Path, settings: VideoSettings, tick: Tick) -> Recording:
        return record_replay(spec, names, row.seed, row.actions, path, settings, length=row.length,
                             scores=row.scores, env_options=env_options, on_frame=tick,
                             heading=f"replay of game {row.id}")

    return RecordJob(targets(out, league.home, [stem], fmt), run, lambda i, s: row.length + 1 + s.hold_frames,
                     {"game_id": row.id, "match_id": row.match_id},
                     [{"players": list(row.players), "seed": row.seed, "game_id": row.id}])


def play_job(league: Any, ups: list[Any], games: int, seed: int, max_steps: int | None, max_rallies: int | None,
              device: str, out: Path | None, fmt: str, stop_label: str | None = None,
              options: dict[str, Any] | None = None) -> RecordJob:
    """For the lineups ``ups``: load the networks once, and play game i with seed ``seed + i``."""
    from ..envs import get_env
    from ..evaluation.lineup import refit
    from ..play import Game
    from ..players.load import check_fits, env_options_of, load_player
    from ..policies import ScriptedPolicy
    from .recorder import record_game, renderer_of, stop_rule

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
    shows = [{"players": [p.id for p in lu.players], "seed": seed + i, "game_id": None} for lu in ups
             for i in range(games)]
    return RecordJob(targets(out, league.home, stems, fmt), run, frames, shows=shows)
