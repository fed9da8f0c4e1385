"""``marl serve`` in a real browser: the system's headless Chromium, driven through playwright, loads every page of a
real league (snapshots, a tournament and an SPRT match played by ``marl``, a recorded mp4) served by ``marl serve`` as
a subprocess, checks the ladder against ``marl league ladder --json``, clicks from the ladder to a player to its
replay, sees the video load, and saves a screenshot of each page in the test's folder (``MARL_SCREENSHOTS``: there
instead, as docs/images/serve/ was made)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
from cli_helpers import run_json
from serve_league import build_real_league

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _wait_for(url: str, proc: subprocess.Popen, deadline: float) -> None:
    """Poll the health page until it says the background fits are done (its first fit and nothing running)."""
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"marl serve ended with {proc.returncode}: {proc.stderr.read()}")
        try:
            with urllib.request.urlopen(url, timeout=1) as r:
                health = json.loads(r.read())
                assert not health["errors"], health["errors"]
                if r.status == 200 and health["fitted"] and health["fitting"] is None:
                    return
        except OSError:  # not listening yet: asked again until the deadline
            health = None
        time.sleep(0.05)  # (polling the health page until its deadline)
    raise AssertionError(f"marl serve's fits were not done at {url} in time")


@pytest.fixture
def served(tmp_path: Path):
    """A real league, and ``marl serve`` on a free port over it (stopped, by its pid, at the end)."""
    home = tmp_path / "league"
    build_real_league(home, tmp_path / "work")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1]), "SDL_VIDEODRIVER": "dummy"}
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", "serve", "--home", str(home), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        assert line.startswith("marl serve: http://127.0.0.1:"), (line, proc.stderr.read() if proc.poll() else "")
        base = line.split()[2].rstrip("/")
        _wait_for(base + "/health", proc, time.monotonic() + 120)
        yield home, base
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()


@pytest.mark.slow
def test_every_page_in_a_real_browser(served, tmp_path: Path, capsys) -> None:
    assert CHROMIUM, "no chromium on this machine: apt-get update && apt-get install -y chromium (as .ci/run does)"
    from playwright.sync_api import sync_playwright

    home, base = served
    shots = Path(os.environ.get("MARL_SCREENSHOTS") or tmp_path / "screenshots")
    shots.mkdir(parents=True, exist_ok=True)
    cli = run_json(capsys, "league", "ladder", "--home", str(home))
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--autoplay-policy="
                                                                                    "no-user-gesture-required"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            for name, url in [("games", "/"), ("ladder", "/ladder"), ("matrix", "/matrix"), ("curves", "/curves"),
                              ("matches", "/matches"), ("queue", "/queue"), ("replays", "/replays")]:
                response = page.goto(base + url)
                assert response is not None and response.status == 200, url
                page.screenshot(path=str(shots / f"{name}.png"), full_page=True)
            page.goto(base + "/ladder")
            rows = page.locator("#ladder tbody tr[data-policy]")
            assert rows.count() == len(cli)
            for i, want in enumerate(cli):  # the ladder's figures, as the CLI's JSON gives them, in its order
                row = rows.nth(i)
                assert row.get_attribute("data-policy") == want["policy"]
                assert row.locator("td.elo").inner_text() == f"{want['elo']:.1f}"
                assert row.locator("td.ci").inner_text() == f"{want['ci_low']:.1f} .. {want['ci_high']:.1f}"
                assert row.locator("td.wdl").inner_text() == f"{want['wins']}-{want['draws']}-{want['losses']}"
            page.locator("#ladder a.player", has_text="demo/s2").click()  # ladder -> player
            assert page.locator("#player-name").inner_text() == "demo/s2"
            page.screenshot(path=str(shots / "player.png"), full_page=True)
            page.locator("#replays a.replay").first.click()  # player -> its replay
            video = page.locator("video#video")
            video.wait_for()
            # The page's CSP (script-src 'none') refuses the string eval that wait_for_function polls with, so the
            # video's own event is awaited: one call, which resolves on loadedmetadata (or at once if it came first).
            duration = page.evaluate("""() => new Promise((resolve, reject) => {
                const v = document.querySelector('video');
                if (v.readyState >= 1) { resolve(v.duration); return; }
                v.addEventListener('loadedmetadata', () => resolve(v.duration), {once: true});
                v.addEventListener('error', () => reject(new Error('the video did not load')), {once: true});
                setTimeout(() => reject(new Error('no loadedmetadata in 20 s')), 20000);
            })""")
            assert duration > 0
            page.screenshot(path=str(shots / "replay.png"))
            assert errors == []
        finally:
            browser.close()
    assert sorted(f.name for f in shots.glob("*.png")) == sorted(
        ["games.png", "ladder.png", "matrix.png", "curves.png", "matches.png", "queue.png", "replays.png",
         "player.png", "replay.png"])
