"""The docs' worked examples, run as the docs show them: each command and what it printed, kept for the pages that
quote them (their figures blocks), so no page types an example's output by hand.

Parts (one a run; each writes ``benchmarks/results/example_PART.json``):

``kuhn``
    your-own-game.md's OpenSpiel example and exploit.md's exact figures: a Kuhn poker learner against ``random``
    (``--steps 40000``), its 1,000-game match against ``random``, its exact exploitability, then a self-play run of
    one network a seat and the exact exploitability of its team.
``kuhn_br``
    exploit.md's trained best response: the same Kuhn learner, then ``marl exploit`` trains 200,000 steps against
    it (``--config`` a file holding ``games = 16``) and plays it 2,000 games; its exact figure beside it.
``kuhn_plot``
    league.md's exploitability curve: a Kuhn poker learner with a snapshot every 5,000 steps, one snapshot's exact
    figure filed by ``marl exploit``, then ``marl league plot --exploitability`` (the rest computed and filed), its
    PNG, and the ladder showing the figures; last, from the two commands' JSON, each snapshot's fitted Elo beside its
    exact exploitability, and whether the snapshot rated highest is the least exploitable.
``connect_four``
    your-own-game.md's first example: PettingZoo's connect four, 2M moves, then 200 games against ``random``.
``simple_push``
    your-own-game.md's two sides that differ: ``mpe2.simple_push_v3`` (``pip install mpe2``), one minute.
``gif``
    record.md's GIF sizes: three one-minute pong games of the ``cpu`` bot at 50 frames a second, the same at the
    default 60, and three games of the suite's tic-tac-toe: each file's size and the time it took.

Each command runs as a user types it (``marl`` in a fresh league home, output not a terminal: plain lines); the
league's folder is printed as ``league``.

Run: python benchmarks/doc_examples.py PART
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


class Shell:
    """``marl`` commands in one league home, each echoed as ``$ marl ...`` before what it printed."""

    def __init__(self, home: Path) -> None:
        self.home = home
        self.env = dict(os.environ, MARL_HOME=str(home), COLUMNS="120", SDL_VIDEODRIVER="dummy",
                        PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))

    def __call__(self, *args: str, note: str = "", show: bool = True, env: dict | None = None,
                 refused: bool = False) -> tuple[str, float]:
        """Run ``marl ARGS``; print the command (with ``note``, and its wall time) and its output; return both.
        ``refused``: the command must be refused (exit 2), and its one line on stderr is what it printed."""
        began = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env={**self.env, **(env or {})},
                             capture_output=True, text=True, cwd=ROOT)
        took = time.perf_counter() - began
        if out.returncode not in ((2,) if refused else (0, 1)):  # 1: a gate's FAIL, still an answer
            raise SystemExit(f"marl {' '.join(args)} exited {out.returncode}: {out.stderr.strip()[-2000:]}")
        text = (f"{out.stderr.strip()}\n(exit {out.returncode})" if refused else out.stdout).replace(str(self.home),
                                                                                                   "league")
        shown = " ".join(args).replace(str(self.home), "league")
        print(f"$ marl {shown}    # {took:.0f} s{f'; {note}' if note else ''}")
        if show:
            for line in text.splitlines():
                print(line.rstrip())
        return text, took


def kuhn(sh: Shell) -> None:
    sh("train", "openspiel:kuhn_poker", "--agents", "1", "--bots", "random=1", "--steps", "40000", "--games", "16")
    sh("match", "kuhn_poker-1/s40k", "random", "--games", "1000")
    sh("exploit", "kuhn_poker-1/s40k", "--exact")
    sh("train", "openspiel:kuhn_poker", "--agents", "2", "--league-games", "0.5", "--bots", "random=1", "--steps",
       "60000", "--games", "16")
    sh("exploit", "kuhn_poker-2/s60k", "--exact")


def kuhn_br(sh: Shell) -> None:
    sh("train", "openspiel:kuhn_poker", "--agents", "1", "--bots", "random=1", "--steps", "40000", "--games", "16",
       "--quiet")
    sh("exploit", "kuhn_poker-1/s40k", "--exact")
    config = sh.home / "br.toml"
    config.write_text("games = 16\n")
    print("$ cat league/br.toml")
    print(config.read_text().rstrip())
    sh("exploit", "kuhn_poker-1/s40k", "--steps", "200000", "--config", str(config), "--games", "2000")


def kuhn_plot(sh: Shell) -> None:
    import json

    sh("train", "openspiel:kuhn_poker", "--agents", "1", "--bots", "random=1", "--steps", "20000", "--snapshot-steps",
       "5000", "--games", "16")
    sh("exploit", "kuhn_poker-1/s20k", "--exact", note="one snapshot's figure, filed")
    text, _ = sh("league", "plot", "--run", "kuhn_poker-1", "--exploitability", show=False,
                 note="every snapshot's, the rest computed (its Elo chart left out here)")
    print(text[text.index("exact exploitability"):].rstrip())
    sh("league", "plot", "--run", "kuhn_poker-1", "--exploitability", "--out", str(sh.home / "kuhn.png"))
    sh("league", "ladder", "--run", "kuhn_poker-1")
    ladder, _ = sh("league", "ladder", "--run", "kuhn_poker-1", "--json", show=False)
    plot, _ = sh("league", "plot", "--run", "kuhn_poker-1", "--exploitability", "--json", show=False)
    elo = {r["policy"]: r["elo"] for r in json.loads(ladder)}
    figures = sorted(json.loads(plot)["exploitability"], key=lambda r: r["step"])
    print("snapshot by snapshot (from the two commands' JSON):")
    for r in figures:
        print(f"  {r['policy']:<18} step {r['step']:>6,}  Elo {elo[r['policy']]:6.0f}  exact exploitability "
              f"{r['exploitability']:.4f}")
    top = max(figures, key=lambda r: elo[r["policy"]])
    least = min(figures, key=lambda r: r["exploitability"])
    same = "is" if top is least else "is not"
    print(f"the snapshot rated highest ({top['policy']}, Elo {elo[top['policy']]:.0f}, exploitability "
          f"{top['exploitability']:.4f}) {same} the least exploitable ({least['policy']}, "
          f"{least['exploitability']:.4f})")


def connect_four(sh: Shell) -> None:
    game = "pettingzoo.classic.connect_four_v3"
    sh("train", game, "--sharing", "fups", "--league-games", "0.5", "--bots", "random=0.5", "--steps", "2000000")
    sh("match", "connect_four_v3-1/s2M", "random", "--games", "200", env={"MARL_GAMES": game})


def simple_push(sh: Shell) -> None:
    try:
        import mpe2  # noqa: F401
    except ImportError:
        raise SystemExit("simple_push needs mpe2: pip install mpe2") from None
    game = "mpe2.simple_push_v3"
    text, _ = sh("train", game, "--agents", "2", "--minutes", "1")
    final = next(w for line in text.splitlines() for w in line.split() if w.endswith("-agent_0:") and "/s0-" not in w)
    sh("match", final.rstrip(":"), "random", "--games", "200", env={"MARL_GAMES": game})
    sh("match", final.rstrip(":"), "simple_push_v3-1/s0-agent_0", env={"MARL_GAMES": game}, refused=True,
       note="refused: two agents cannot meet")


def gif(sh: Shell) -> None:
    def sizes(args: list[str], note: str) -> None:
        out = sh.home / "gifs" / str(len(list((sh.home / "gifs").glob("*"))) if (sh.home / "gifs").exists() else 0)
        out.mkdir(parents=True)
        _, took = sh("record", *args, "--format", "gif", "--out", str(out), note=note, show=False)
        files = sorted(out.glob("*.gif"))
        each = ", ".join(f"{f.stat().st_size / 1e6:.2f} MB" if f.stat().st_size >= 1e5
                         else f"{f.stat().st_size / 1e3:.1f} kB" for f in files)
        total = sum(f.stat().st_size for f in files)
        print(f"  {len(files)} files: {each} ({total / 1e6:.2f} MB in all; {took / max(len(files), 1):.0f} s a game)")

    sizes(["--ckpt", "cpu", "--vs", "cpu", "--env", "pong", "--games", "3", "--fps", "50"],
          "three one-minute games, 3,000 steps each")
    sizes(["--ckpt", "cpu", "--vs", "cpu", "--env", "pong", "--games", "3"], "the same at the default 60 fps")
    sizes(["--ckpt", "random", "--vs", "random", "--env", "tests.games.tictactoe:env", "--games", "3"],
          "tic-tac-toe, its own 2 moves a second")


PARTS = {"kuhn": kuhn, "kuhn_br": kuhn_br, "kuhn_plot": kuhn_plot, "connect_four": connect_four,
         "simple_push": simple_push, "gif": gif}


def main(part: str) -> None:
    sys.stdout.reconfigure(line_buffering=True)
    with tempfile.TemporaryDirectory(prefix="marl-doc-example-") as tmp:
        PARTS[part](Shell(Path(tmp) / "league"))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("part", choices=sorted(PARTS))
    part = ap.parse_args().part
    from results_file import recorded

    with recorded(f"example_{part}"):
        main(part)
