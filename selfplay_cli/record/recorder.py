"""A game to a video: the game loop plays it, the env's renderer draws each state, the writer encodes it.

The game is played by the same game loop as every match (:func:`selfplay_cli.play.play`), one game at a time, with
a hook that renders every state it passes through and streams the frame to the encoder at once: one frame for the
serve, one per step, then the final frame held for ``hold`` seconds so the result can be read. Nothing is kept
but the latest frame, so memory does not grow with the game's length.

A replay (``marl record --game ID``) is the same game with the stored actions standing in for the players; it
must end with the stored score after the stored number of steps, or the video is thrown away.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..envs.contract import BatchedCore
from ..errors import MarlError
from ..play import Game, GameResult, play
from ..play.replay import check_replay, decode_actions, replay_policies
from .overlay import CaptionBand
from .video import GIF_MAX_WIDTH, MAX_SIDE, MIN_SIDE, VideoWriter, check_format

if TYPE_CHECKING:
    from ..policies import Policy


@dataclass(frozen=True)
class VideoSettings:
    """How a game becomes a file: ``fps`` frames per second (one frame per game step, so 60 plays Pong at the
    speed it was designed for), ``size`` (width, height) or None for the frames' own (the game's picture and its
    caption band), ``fmt`` mp4 or gif, ``hold`` seconds of the final frame at the end, and ``max_width``: frames
    wider are scaled down to it (None: :data:`~.video.GIF_MAX_WIDTH` for a GIF, no limit for an mp4; 0: no limit)."""

    fps: int = 60
    size: tuple[int, int] | None = None
    fmt: str = "mp4"
    hold: float = 1.0
    max_width: int | None = None

    def __post_init__(self) -> None:
        check_format(self.fmt, self.fps)
        if not 0 <= self.hold <= 60:
            raise MarlError(f"--hold must lie between 0 and 60 seconds, not {self.hold:g}")
        if self.max_width is not None and self.max_width != 0 and not MIN_SIDE <= self.max_width <= MAX_SIDE:
            raise MarlError(f"--max-width must be 0 (no limit) or lie between {MIN_SIDE} and {MAX_SIDE}, not "
                            f"{self.max_width}")

    @property
    def width_limit(self) -> int:
        """The widest frame the file keeps (0: no limit)."""
        if self.max_width is not None:
            return self.max_width
        return GIF_MAX_WIDTH if self.fmt == "gif" else 0

    @property
    def hold_frames(self) -> int:
        return round(self.hold * self.fps)


ENDED_RESULT = "result"  # the game was won (or drawn) by its rules
ENDED_TIME_LIMIT = "time limit"  # the game's own time limit ended it (pong: max_steps), the score decided
ENDED_STOPPED = "stopped"  # a limit of the recording (--seconds, --max-steps, --max-rallies) cut it short


@dataclass(frozen=True)
class Recording:
    """A finished video: where it is, the game it shows and how long rendering and encoding took.

    ``ended`` says how the game ended: :data:`ENDED_RESULT`, :data:`ENDED_TIME_LIMIT` (the game's own rule) or
    :data:`ENDED_STOPPED` (cut by the recording's limit, named in ``stopped_by``, e.g. ``--seconds 60``)."""

    path: Path
    result: GameResult
    frames: int
    seconds: float
    settings: VideoSettings
    size: tuple[int, int]  # width, height of the file's frames
    ended: str = ENDED_RESULT
    stopped_by: str | None = None
    stored: int = 0  # frames the file holds (a GIF stores fewer than it was given: see video.VideoWriter)

    @property
    def video_seconds(self) -> float:
        """How long the video plays: its frames at its frame rate (the held final frame included)."""
        return self.frames / self.settings.fps

    def to_json(self) -> dict[str, Any]:
        r = self.result
        return {
            "path": str(self.path), "env": r.env, "seed": r.seed, "players": list(r.players),
            "scores": [int(x) if float(x).is_integer() else x for x in r.scores], "outcome": list(r.outcome),
            "length": r.length, "truncated": r.truncated,
            "ended": self.ended, "stopped_by": self.stopped_by,
            "frames": self.frames, "stored_frames": self.stored, "fps": self.settings.fps,
            "video_seconds": round(self.video_seconds, 2),
            "size": f"{self.size[0]}x{self.size[1]}", "format": self.settings.fmt, "seconds": round(self.seconds, 3),
            "frames_per_second": round(self.frames / self.seconds, 1) if self.seconds > 0 else None,
        }


def stop_rule(spec: EnvSpec, env_options: dict[str, Any], max_steps: int | None = None,
              max_rallies: int | None = None) -> Callable[[BatchedCore], np.ndarray] | None:
    """:func:`selfplay_cli.play.play`'s ``stop_when`` for a recording cut short after ``max_steps`` steps or
    ``max_rallies`` rallies (serves played out, whether they ended in a point, a re-serve or the rally cap; only
    cores that count serves)."""
    if max_steps is not None and max_rallies is not None:
        raise MarlError("--max-steps and --max-rallies exclude each other")
    if max_steps is not None:
        if max_steps < 1:
            raise MarlError(f"--max-steps must be at least 1, not {max_steps}")
        return lambda core: core.steps >= max_steps
    if max_rallies is not None:
        if max_rallies < 1:
            raise MarlError(f"--max-rallies must be at least 1, not {max_rallies}")
        if not hasattr(spec.core(1, **env_options), "serves"):
            raise MarlError(f"{spec.name} has no rallies to count: use --max-steps")
        return lambda core: core.serves - 1 >= max_rallies  # the first serve opens rally 1
    return None


def renderer_of(spec: EnvSpec) -> Any:
    if spec.make_renderer is None:
        raise MarlError(f"{spec.name} has no renderer, so its games cannot be recorded")
    return spec.make_renderer()


def record_game(
    env: str | EnvSpec,
    policies: Sequence[Policy],
    game: Game,
    path: str | Path,
    settings: VideoSettings | None = None,
    *,
    env_options: dict[str, Any] | None = None,
    labels: Sequence[str] | None = None,
    stop_when: Callable[[BatchedCore], np.ndarray] | None = None,
    check: Callable[[GameResult], None] | None = None,
    on_frame: Callable[[int], None] | None = None,
    renderer: Any = None,
    stop_label: str | None = None,
    heading: str | None = None,
) -> Recording:
    """Play ``game`` between ``policies`` and write it to ``path``; returns what was written.

    Every frame is the game's own picture with the caption band under it (:class:`~.overlay.CaptionBand`): the
    players' names per seat, the running score per side, ``heading`` (e.g. ``game 2 of 3``) and the step.
    ``labels`` are the names shown per seat (default: the policies' ids by seat). ``check(result)`` may raise to
    reject the game before the file takes its name (replays use it). ``on_frame(n)`` is told of every ``n``
    frames written (a progress bar). ``renderer`` reuses one renderer across games. ``stop_label`` names the limit
    behind ``stop_when`` (e.g. ``--seconds 60``): the last frame of a game it cut says ``stopped (--seconds 60)``,
    of a game its own time limit ended ``time limit``, of a game won ``final``.
    """
    spec = get_env(env) if isinstance(env, str) else env
    settings = settings or VideoSettings()
    renderer = renderer if renderer is not None else renderer_of(spec)
    names = tuple(labels) if labels is not None else tuple(policies[s].id for s in game.seats)
    band = CaptionBand(spec, names, heading, getattr(renderer, "seat_colour", None))
    start = time.perf_counter()
    with VideoWriter(path, fps=settings.fps, size=settings.size, fmt=settings.fmt,
                     max_width=settings.width_limit) as writer:
        last: list[np.ndarray] = []  # the latest frame only
        ending = [ENDED_RESULT]

        def draw(core: BatchedCore, slot: int, index: int, ended: bool) -> None:
            step = int(core.steps[slot])
            tail = ""
            if ended:  # the last frame says how the game ended: won, its own time limit, or cut by the recording
                if core.terminated[slot]:
                    tail = " · final"
                elif core.truncated[slot]:
                    ending[0], tail = ENDED_TIME_LIMIT, " · time limit"
                else:
                    ending[0] = ENDED_STOPPED
                    tail = f" · stopped ({stop_label})" if stop_label else " · stopped"
            frame = band(renderer.draw(core, slot), core.score[:, slot], f"step {step}{tail}")
            writer.write(frame)
            if on_frame is not None:
                on_frame(1)
            if ended:
                last[:] = [frame]

        (result,) = play(spec, policies, [game], parallel=1, env_options=env_options, on_frame=draw,
                         stop_when=stop_when)
        for _ in range(settings.hold_frames):
            writer.write(last[0])
        if on_frame is not None and settings.hold_frames:
            on_frame(settings.hold_frames)
        if check is not None:
            check(result)
    height, width = writer.frame_shape[:2]  # type: ignore[index]
    return Recording(path=Path(path), result=result, frames=writer.frames, seconds=time.perf_counter() - start,
                     settings=settings, size=writer.out_size(width, height), ended=ending[0],
                     stopped_by=stop_label if ending[0] == ENDED_STOPPED else None, stored=writer.stored)


def record_replay(
    env: str | EnvSpec,
    players: Sequence[str],
    seed: int,
    actions: bytes,
    path: str | Path,
    settings: VideoSettings | None = None,
    *,
    length: int,
    scores: Sequence[float],
    env_options: dict[str, Any] | None = None,
    on_frame: Callable[[int], None] | None = None,
    heading: str | None = None,
) -> Recording:
    """Re-render a stored game from its seed and encoded actions, exactly as it was played (``heading``: the
    caption band's, e.g. ``replay of game 1234``).

    ``players`` are the names per seat; ``length`` and ``scores`` are what the ledger says the game came to: a
    replay that ends otherwise (other game options, another version of the game's rules) raises
    :class:`~selfplay_cli.play.replay.ReplayError` and leaves no file.
    """
    spec = (get_env(env) if isinstance(env, str) else env).for_options(**(env_options or {}))
    moves = decode_actions(actions, len(spec.agents), length)
    policies = replay_policies(tuple(players), spec.name, moves)

    def check(result: GameResult) -> None:
        check_replay(result, length, scores)

    return record_game(spec, policies, Game(seed, tuple(range(len(players)))), path, settings,
                       env_options=env_options, labels=players, check=check, on_frame=on_frame, heading=heading)
