"""Frames to a video file: one ffmpeg process fed raw RGB frames through a pipe as they are rendered.

Streaming keeps memory flat however long the game, and puts the encoding in a separate process, which runs on
another core while Python draws the next frames. The ffmpeg binary is the one imageio-ffmpeg ships. Its
``write_frames`` helper is not used: it lets ffmpeg write to the terminal and never looks at ffmpeg's exit status,
so a failed encode would pass silently; here ffmpeg's messages go to a temporary file and become the error.

* mp4: H.264 (libx264), ``yuv420p`` and ``+faststart``, which every browser plays and can start before the whole
  file has arrived. Preset ``ultrafast`` at CRF 20: the frames are flat colours, which x264 compresses well even
  at its fastest, and the encoder is the slowest stage of a recording (see ``benchmarks/record_speed.py``: ffmpeg
  spends about 3 ms of CPU on a frame that Python draws in 0.25 ms).
* gif: two passes, so that the file is small (a minute of pong, 3,000 steps: 12.3 MB stored a frame per step with a
  palette each, 1.36 MB so; see docs/commands/record.md):

  - at most :data:`GIF_FPS` frames a second: frames are one per game step (60 a second for pong), and those that
    fall between two stored ones are dropped, so the game still plays at its own speed;
  - each picture stored once: a frame equal to the last stored one (a board between moves, the held final frame)
    is not stored again, the one before it stays on screen longer;
  - frames wider than :data:`GIF_MAX_WIDTH` scaled down (``max_width``; ``--size`` sets a size of its own);
  - one palette for the whole file, computed from every stored frame, so that ffmpeg's encoder only stores what
    changed between frames (a palette per frame stores each frame whole).

  The first pass streams like the mp4: the stored frames go losslessly (FFV1) to a temporary file beside the
  destination while ffmpeg counts their colours; the second maps them to the palette and writes the GIF, whose
  frame delays (whole hundredths of a second) are then set to the time each frame stays on screen.

The file is written under a temporary name beside the destination (``.<name>.<pid>.part``) and renamed when ffmpeg
has finished, so the destination never holds half a video: an error, a failed check or Ctrl-C remove the temporary
file. A process killed outright (SIGKILL) cannot; the next video written into that folder removes what it left
(:func:`sweep_leftovers`, whose process is gone) and says so.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import struct
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import numpy as np

from .. import files
from ..errors import MarlError, MarlIOError

FORMATS = ("mp4", "gif")
GIF_FPS = 20
"""A GIF stores at most this many frames a second (delays of 5/100 s: every third frame of a 60 fps game); the
others are dropped, the pace kept."""
GIF_MAX_WIDTH = 640
"""A GIF's frames wider than this are scaled down to it by default (``--max-width``)."""
MAX_FPS = 240
MIN_SIDE, MAX_SIDE = 16, 4096
CRF = 20
PRESET = "ultrafast"


def parse_size(text: str | None) -> tuple[int, int] | None:
    """``"800x400"`` -> ``(800, 400)``; None stays None (the renderer's own size)."""
    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
    if not m:
        raise MarlError(f"--size must look like WIDTHxHEIGHT, e.g. 800x400, not {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (MIN_SIDE <= w <= MAX_SIDE and MIN_SIDE <= h <= MAX_SIDE):
        raise MarlError(f"--size {w}x{h}: width and height must lie between {MIN_SIDE} and {MAX_SIDE}")
    if w % 2 or h % 2:
        raise MarlError(f"--size {w}x{h}: width and height must be even (H.264 in yuv420p halves the colour planes)")
    return w, h


def check_format(fmt: str, fps: int) -> None:
    """A clear error for a format or frame rate the file cannot hold."""
    if fmt not in FORMATS:
        raise MarlError(f"--format must be one of {', '.join(FORMATS)}, not {fmt!r}")
    if not 1 <= fps <= MAX_FPS:
        raise MarlError(f"--fps must lie between 1 and {MAX_FPS}, not {fps}")


def check_writable(path: Path) -> None:
    """Fail now, before any game is played, if ``path`` cannot be written (creating its folder if needed)."""
    path = Path(path)
    if path.is_dir():
        raise MarlError(f"cannot write {path}: it is a directory")
    blocker = next((p for p in path.parents if p.exists()), None)
    if blocker is not None and not blocker.is_dir():
        raise MarlError(f"cannot write {path}: {blocker} is a file, not a folder")
    probe = path.parent / f".{path.name}.{os.getpid()}.check"  # a name files.sweep knows, should we be killed here
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        probe.unlink(missing_ok=True)
        with open(probe, "xb"):
            pass
        probe.unlink()
    except OSError as e:
        raise MarlError(f"cannot write {path}: {e.strerror or e}") from None


def sweep_leftovers(folder: Path) -> list[Path]:
    """Remove the hidden partial videos (``.<name>.<pid>.part``) and probes that killed processes left in
    ``folder``, saying so in one line on stderr; returns them."""
    removed = files.sweep(folder)
    if removed:
        sys.stderr.write(files.describe_removed(removed) + "\n")
    return removed


class _GifTiming:
    """Which frames a GIF stores and how long each stays on screen. Frame ``i`` of a recording at ``fps`` starts at
    ``i / fps`` seconds; a frame is due when it opens a new 1/:data:`GIF_FPS`-second slot (every frame, at
    ``fps <= GIF_FPS``), and stored when due and not equal to the last stored one (the writer checks that)."""

    def __init__(self, fps: int) -> None:
        self.fps, self.rate = fps, min(fps, GIF_FPS)
        self.starts: list[int] = []  # the frame index of each stored frame
        self._slot = -1

    @property
    def stored(self) -> int:
        return len(self.starts)

    def due(self, i: int) -> bool:
        return i * self.rate // self.fps != self._slot

    def store(self, i: int) -> None:
        self.starts.append(i)
        self._slot = i * self.rate // self.fps

    def delays(self, frames: int) -> list[int]:
        """Each stored frame's delay in hundredths of a second, until the next one (the last: until the end of the
        ``frames`` written); rounded at the frames' start times, so the delays add up to the whole length."""
        cs = [round(100 * i / self.fps) for i in [*self.starts, frames]]
        return [min(b - a, 0xFFFF) for a, b in zip(cs, cs[1:], strict=False)]


@dataclass(frozen=True)
class GifFrame:
    """One frame of a GIF file as stored: its delay (hundredths of a second), whether it brings a palette of its
    own, and where its delay is in the file (the Graphic Control Extension before it; None if it has none)."""

    delay: int
    local_palette: bool
    delay_at: int | None


def gif_frames(data: bytes) -> tuple[bool, list[GifFrame]]:
    """Read a GIF's block structure: (whether it has a global palette, its frames). Raises MarlError if ``data``
    is not a whole GIF."""

    def blocks(pos: int) -> int:  # past a run of data sub-blocks and its terminator
        while data[pos]:
            pos += data[pos] + 1
        return pos + 1

    def colour_table(flags: int) -> int:
        return 3 * (2 << (flags & 7)) if flags & 0x80 else 0

    if data[:6] not in (b"GIF87a", b"GIF89a"):
        raise MarlError("not a GIF file")
    frames: list[GifFrame] = []
    pos, control = 13 + colour_table(data[10]), None
    try:
        while data[pos] != 0x3B:  # the trailer
            if data[pos] == 0x21:  # an extension: 0x21, label, sub-blocks; 0xF9 is the frame's control
                if data[pos + 1] == 0xF9:
                    control = pos + 4
                pos = blocks(pos + 2)
            elif data[pos] == 0x2C:  # an image: descriptor, its colour table, LZW code size, sub-blocks
                delay = struct.unpack_from("<H", data, control)[0] if control is not None else 0
                frames.append(GifFrame(delay, bool(data[pos + 9] & 0x80), control))
                pos, control = blocks(pos + 10 + colour_table(data[pos + 9]) + 1), None
            else:
                raise IndexError(pos)
    except IndexError:
        raise MarlError("a GIF file that ends early or holds an unknown block") from None
    return bool(data[10] & 0x80), frames


def set_gif_delays(path: Path, delays: list[int]) -> None:
    """Set the delay of each frame of the GIF ``path``, in order (ffmpeg writes a control block before every
    frame). Raises MarlError if the file does not hold one such frame per delay."""
    data = bytearray(path.read_bytes())
    try:
        _, frames = gif_frames(data)
    except MarlError as e:
        raise MarlError(f"ffmpeg wrote {path}, but: {e}") from None
    if len(frames) != len(delays) or any(f.delay_at is None for f in frames):
        raise MarlError(f"the GIF holds {len(frames)} frames where {len(delays)} were stored ({path})")
    for frame, delay in zip(frames, delays, strict=True):
        struct.pack_into("<H", data, frame.delay_at, delay)  # type: ignore[arg-type]
    with open(path, "r+b") as fh:
        fh.write(data)


_IO_CAUSES = {  # what ffmpeg says when the disk, not the video, is at fault -> what to do about it
    "no space left on device": "free some space on that disk and run it again",
    "disk quota exceeded": "the disk quota is used up: free some space",
    "file too large": "a file size limit stops the write (ulimit -f): raise it",
    "read-only file system": "the file system is read-only: write the video elsewhere (--out)",
    "permission denied": "check the permissions of that folder, or write the video elsewhere (--out)",
    "input/output error": "the device reported an error: check the disk",
}


def ffmpeg_failure(path: Path, what: str, said: str, code: int | None) -> MarlError:
    """The error for an ffmpeg that failed writing ``path``: a :class:`MarlIOError` (exit 4) naming the path and
    the cause when the disk is at fault (full, a quota, a file size limit: ffmpeg killed by SIGXFSZ, read-only,
    permissions), else a :class:`MarlError` with what ffmpeg said."""
    if code == -signal.SIGXFSZ:
        return MarlIOError(f"{what} {path}: File too large (EFBIG): ffmpeg was stopped by the file size limit; "
                           f"{_IO_CAUSES['file too large']}")
    hint = next((h for words, h in _IO_CAUSES.items() if words in said.lower()), None)
    if hint is not None:
        return MarlIOError(f"{what} {path}: {said}; {hint}")
    return MarlError(f"{what} {path}: {said}")


def _ffmpeg() -> str:
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as e:
        raise MarlError(f"no ffmpeg to encode videos ({e}); pip install imageio-ffmpeg") from None


class VideoWriter:
    """Writes RGB frames ``(height, width, 3)`` uint8 to ``path`` as they come; use as a context manager.

    ``size`` (width, height) scales the frames in ffmpeg (None keeps the frames' size); ``max_width`` (0: none)
    scales frames wider than that down, keeping their aspect. ffmpeg starts with the first frame, whose size fixes
    the input size. Leaving the ``with`` block normally finishes the file and renames it into place; leaving it by
    an exception (or calling :meth:`abort`) removes every trace of it.

    A GIF keeps at most :data:`GIF_FPS` frames a second and each picture once (see the module docstring):
    ``frames`` counts the frames written, ``stored`` those the file holds.
    """

    def __init__(self, path: str | Path, fps: int = 60, size: tuple[int, int] | None = None, fmt: str = "mp4",
                 crf: int = CRF, preset: str = PRESET, max_width: int = 0) -> None:
        check_format(fmt, fps)
        self.path = Path(path)
        self.fps, self.size, self.fmt, self.crf, self.preset = fps, size, fmt, crf, preset
        self.max_width = max_width
        self.frames = 0
        self.frame_shape: tuple[int, ...] | None = None
        check_writable(self.path)
        sweep_leftovers(self.path.parent)
        self.tmp = self._part("")
        self._proc: subprocess.Popen | None = None
        self._log = None
        self._done = False
        self._gif = _GifTiming(fps) if fmt == "gif" else None
        self._last: np.ndarray | None = None  # a GIF's latest stored frame, to store each picture once

    @property
    def stored(self) -> int:
        """Frames the file holds: every frame written (mp4), or each picture once at most GIF_FPS a second (gif)."""
        return self._gif.stored if self._gif is not None else self.frames

    def _part(self, what: str) -> Path:
        """A temporary file beside the destination, named so that :func:`sweep_leftovers` knows it."""
        return self.path.with_name(f".{self.path.name}{what}.{os.getpid()}.part")

    # ------------------------------------------------------------------------------------------------------------
    def out_size(self, width: int, height: int) -> tuple[int, int]:
        """The file's (width, height) for frames of this size: --size, else a width above max_width brought down to
        it (the height in proportion, even), else the frames' own."""
        if self.size is not None:
            return self.size
        if self.max_width and width > self.max_width:
            return self.max_width, max(2, round(height * self.max_width / width / 2) * 2)
        return width, height

    def _scale(self, width: int, height: int) -> str:
        """The scale filter that :meth:`out_size` needs ('' for none)."""
        out_w, out_h = self.out_size(width, height)
        if (out_w, out_h) == (width, height):
            return ""
        flags = "area" if out_w <= width and out_h <= height else "bicubic"
        return f"scale={out_w}:{out_h}:flags={flags}"

    def _command(self, width: int, height: int) -> list[str]:
        scale = self._scale(width, height)
        cmd = [_ffmpeg(), "-hide_banner", "-nostats", "-loglevel", "error", "-y",
               "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", str(self.fps), "-i", "-",
               "-an"]
        if self.fmt == "gif":
            # the first pass: the stored frames, losslessly, and the palette of all of them (a histogram, not frames)
            graph = f"{scale + ',' if scale else ''}split[v][s];[s]palettegen=stats_mode=full[p]"
            return [*cmd, "-filter_complex", graph, "-map", "[v]", "-c:v", "ffv1", "-f", "matroska",
                    str(self._part("-frames")), "-map", "[p]", "-update", "1", "-f", "image2",
                    str(self._part("-palette"))]
        if not scale and (width % 2 or height % 2):  # yuv420p wants even sides: one black row or column more
            scale = "pad=ceil(iw/2)*2:ceil(ih/2)*2"
        if scale:
            cmd += ["-vf", scale]
        # Without a resize, the only scaling is halving the colour planes for yuv420p; sampling them instead of
        # filtering costs half as much (0.8 against 1.5 ms a frame at 800x400: the dearest step of the encode)
        # and changes nothing on flat-colour graphics. A resize keeps its own filter (area or bicubic).
        cmd += ["-sws_flags", "neighbor", "-c:v", "libx264", "-preset", self.preset, "-crf", str(self.crf),
                "-pix_fmt", "yuv420p", "-movflags", "+faststart", "-f", "mp4"]
        return [*cmd, str(self.tmp)]

    def _start(self, shape: tuple[int, ...]) -> None:
        if len(shape) != 3 or shape[2] != 3:
            raise ValueError(f"frames must be (height, width, 3) RGB, got shape {shape}")
        self.frame_shape = shape
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as ffmpeg; closed in _cleanup
        try:
            # its own session: Ctrl-C reaches Python only, which then removes the partial file (see abort)
            self._proc = subprocess.Popen(self._command(shape[1], shape[0]), stdin=subprocess.PIPE,
                                          stdout=subprocess.DEVNULL, stderr=self._log, start_new_session=True)
        except OSError as e:
            raise MarlError(f"cannot start ffmpeg: {e.strerror or e}") from None

    def write(self, frame: np.ndarray) -> None:
        """Send one frame to the encoder (no copy when it is already contiguous uint8); a GIF's frames that fall
        between its stored ones, or repeat the last stored picture, are counted and not sent."""
        if self._done:
            raise ValueError("the video is already finished")
        if self._proc is None:
            self._start(frame.shape)
        elif frame.shape != self.frame_shape:
            raise ValueError(f"frame of shape {frame.shape} in a video of {self.frame_shape} frames")
        data = frame if frame.dtype == np.uint8 and frame.flags.c_contiguous else np.ascontiguousarray(frame, np.uint8)
        self.frames += 1
        if self._gif is not None:
            if not self._gif.due(self.frames - 1) or (self._last is not None and np.array_equal(data, self._last)):
                return
            self._gif.store(self.frames - 1)
            self._last = data.copy()
        try:
            self._proc.stdin.write(data)  # type: ignore[union-attr]
        except (BrokenPipeError, OSError):
            code = self._proc.wait()  # type: ignore[union-attr]
            raise ffmpeg_failure(self.path, "ffmpeg stopped while writing", self._ffmpeg_says(), code) from None

    def _ffmpeg_says(self) -> str:
        if self._log is None:
            return "no output"
        self._log.seek(0)
        lines = [ln.strip() for ln in self._log.read().decode(errors="replace").splitlines() if ln.strip()]
        if not lines:
            return f"exit status {self._proc.returncode if self._proc else '?'}"
        return re.sub(r"^\[[^\]]*@ 0x[0-9a-f]+\]\s*", "", lines[-1])  # "[out#0/mp4 @ 0x55b7...] " says nothing

    def close(self) -> Path:
        """Finish the file and move it to its final name; returns the path."""
        if self._done:
            return self.path
        if self._proc is None:
            self.abort()
            raise MarlError(f"no frames to write to {self.path}")
        with contextlib.suppress(OSError):  # ffmpeg may already have gone; its exit status tells why
            self._proc.stdin.close()  # type: ignore[union-attr]
        code = self._proc.wait()
        if code == 0 and self._gif is not None:
            try:
                code = self._encode_gif()
            except BaseException:  # an unreadable GIF, Ctrl-C during the second pass: no file left, partial or whole
                self.abort()
                raise
        if code != 0:
            reason = self._ffmpeg_says()
            self.abort()
            raise ffmpeg_failure(self.path, "ffmpeg could not write", reason, code)
        files.publish(self.tmp, self.path)
        self._cleanup()
        return self.path

    def _encode_gif(self) -> int:
        """The second pass of a GIF: the stored frames mapped to the palette of all of them, then each frame's
        delay set to how long it stays on screen. Returns ffmpeg's exit status."""
        assert self._gif is not None and self._log is not None
        dither = "paletteuse=dither=bayer:bayer_scale=5:diff_mode=rectangle"
        cmd = [_ffmpeg(), "-hide_banner", "-nostats", "-loglevel", "error", "-y", "-i", str(self._part("-frames")),
               "-i", str(self._part("-palette")), "-lavfi", f"[0:v][1:v]{dither}", "-loop", "0", "-f", "gif",
               str(self.tmp)]
        try:
            code = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._log,
                                  start_new_session=True, check=False).returncode
        except OSError as e:
            raise MarlError(f"cannot start ffmpeg: {e.strerror or e}") from None
        if code == 0:
            set_gif_delays(self.tmp, self._gif.delays(self.frames))
        return code

    def abort(self) -> None:
        """Stop ffmpeg and remove the partial files; the destination is left as it was."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        self.tmp.unlink(missing_ok=True)
        self._cleanup()

    def _cleanup(self) -> None:
        self._done = True
        for what in ("-frames", "-palette"):  # a GIF's first pass
            self._part(what).unlink(missing_ok=True)
        if self._proc is not None and self._proc.stdin is not None and not self._proc.stdin.closed:
            with contextlib.suppress(OSError):
                self._proc.stdin.close()
        if self._log is not None:
            self._log.close()
            self._log = None

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
