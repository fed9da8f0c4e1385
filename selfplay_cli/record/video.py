"""Frames to a video file: one ffmpeg process fed raw RGB frames through a pipe as they are rendered.

Streaming keeps memory flat however long the game, and puts the encoding in a separate process, which runs on
another core while Python draws the next frames. The ffmpeg binary is the one imageio-ffmpeg ships. Its
``write_frames`` helper is not used: it lets ffmpeg write to the terminal and never looks at ffmpeg's exit status,
so a failed encode would pass silently; here ffmpeg's messages go to a temporary file and become the error.

* mp4: H.264 (libx264), ``yuv420p`` and ``+faststart``, which every browser plays and can start before the whole
  file has arrived. Preset ``ultrafast`` at CRF 20: the frames are flat colours, which x264 compresses well even
  at its fastest, and the encoder is the slowest stage of a recording (see ``benchmarks/record_speed.py``: ffmpeg
  spends about 3 ms of CPU on a frame that Python draws in 0.25 ms).
* gif: a palette computed per frame (``palettegen=stats_mode=single`` + ``paletteuse=new=1``), so it streams too
  and keeps exact colours. GIF delays are whole hundredths of a second and browsers slow anything under 2/100 s
  down to 1/10 s, so GIFs are limited to 50 fps.

The file is written under a temporary name beside the destination (``.<name>.<pid>.part``) and renamed when ffmpeg
has finished, so the destination never holds half a video: an error, a failed check or Ctrl-C remove the temporary
file. A process killed outright (SIGKILL) cannot; the next video written into that folder removes what it left
(:func:`sweep_leftovers`, whose process is gone) and says so.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from types import TracebackType

import numpy as np

from .. import files
from ..errors import MarlError

FORMATS = ("mp4", "gif")
MAX_GIF_FPS = 50
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
    if fmt == "gif" and fps > MAX_GIF_FPS:
        raise MarlError(f"--fps {fps}: a GIF plays at most {MAX_GIF_FPS} frames per second (its delays are whole "
                        "hundredths of a second); use mp4, or --fps 50 or less")


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


def _ffmpeg() -> str:
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as e:
        raise MarlError(f"no ffmpeg to encode videos ({e}); pip install imageio-ffmpeg") from None


class VideoWriter:
    """Writes RGB frames ``(height, width, 3)`` uint8 to ``path`` as they come; use as a context manager.

    ``size`` (width, height) scales the frames in ffmpeg (None keeps the frames' size). ffmpeg starts with the
    first frame, whose size fixes the input size. Leaving the ``with`` block normally finishes the file and renames
    it into place; leaving it by an exception (or calling :meth:`abort`) removes every trace of it.
    """

    def __init__(self, path: str | Path, fps: int = 60, size: tuple[int, int] | None = None, fmt: str = "mp4",
                 crf: int = CRF, preset: str = PRESET) -> None:
        check_format(fmt, fps)
        self.path = Path(path)
        self.fps, self.size, self.fmt, self.crf, self.preset = fps, size, fmt, crf, preset
        self.frames = 0
        self.frame_shape: tuple[int, ...] | None = None
        check_writable(self.path)
        sweep_leftovers(self.path.parent)
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.part")
        self._proc: subprocess.Popen | None = None
        self._log = None
        self._done = False

    # ------------------------------------------------------------------------------------------------------------
    def _command(self, width: int, height: int) -> list[str]:
        out_w, out_h = self.size or (width, height)
        scale = ""
        if (out_w, out_h) != (width, height):
            flags = "area" if out_w <= width and out_h <= height else "bicubic"
            scale = f"scale={out_w}:{out_h}:flags={flags}"
        cmd = [_ffmpeg(), "-hide_banner", "-nostats", "-loglevel", "error", "-y",
               "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", str(self.fps), "-i", "-",
               "-an"]
        if self.fmt == "gif":
            palette = "split[a][b];[a]palettegen=stats_mode=single[p];[b][p]paletteuse=new=1"
            cmd += ["-vf", f"{scale},{palette}" if scale else palette, "-loop", "0", "-f", "gif"]
        else:
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
        """Send one frame to the encoder (no copy when it is already contiguous uint8)."""
        if self._done:
            raise ValueError("the video is already finished")
        if self._proc is None:
            self._start(frame.shape)
        elif frame.shape != self.frame_shape:
            raise ValueError(f"frame of shape {frame.shape} in a video of {self.frame_shape} frames")
        data = frame if frame.dtype == np.uint8 and frame.flags.c_contiguous else np.ascontiguousarray(frame, np.uint8)
        try:
            self._proc.stdin.write(data)  # type: ignore[union-attr]
        except (BrokenPipeError, OSError):
            self._proc.wait()  # type: ignore[union-attr]
            raise MarlError(f"ffmpeg stopped while writing {self.path}: {self._ffmpeg_says()}") from None
        self.frames += 1

    def _ffmpeg_says(self) -> str:
        if self._log is None:
            return "no output"
        self._log.seek(0)
        lines = [ln.strip() for ln in self._log.read().decode(errors="replace").splitlines() if ln.strip()]
        return lines[-1] if lines else f"exit status {self._proc.returncode if self._proc else '?'}"

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
        if code != 0:
            reason = self._ffmpeg_says()
            self.abort()
            raise MarlError(f"ffmpeg could not write {self.path}: {reason}")
        os.replace(self.tmp, self.path)
        self._cleanup()
        return self.path

    def abort(self) -> None:
        """Stop ffmpeg and remove the partial file; the destination is left as it was."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        self.tmp.unlink(missing_ok=True)
        self._cleanup()

    def _cleanup(self) -> None:
        self._done = True
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
