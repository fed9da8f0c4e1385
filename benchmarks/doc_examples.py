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
``kuhn_league``
    train.md's AlphaStar league on Kuhn poker: ``kuhn-league.toml`` (the page's ``[league]`` table) and the run, then
    the snapshot moments of each learner and the run's best, from the ladder's JSON.
``kuhn_nash``
    train.md's Nash opponents (PSRO) on Kuhn poker, run twice in two leagues: the second run's summary and whether
    the two ended with the same episodes and the same Nash mixture (a fixed seed repeats exactly).
``pong``
    the default run the pages quote (``marl train pong --agents 2``, its progress lines without a terminal: section
    ``train``); ``marl league predict`` and a 200-game ``marl match`` as league.md shows them (``predict``);
    ``marl league ladder --run pong-1`` (``ladder``); ``marl league plot`` piped (``plot``); and a fresh 200-game
    match of the run's best and the snapshot its summary names next to it, not stored (``best``).
``lander``
    league.md's lander ladder: the lander's default FuPS run (``marl train lander --agents 2 --sharing fups``), then
    ``marl league ladder --env lander``.
``envs``
    envs.md's listing: ``marl envs`` and ``marl envs tennis``.
``resume``
    train.md's resumed run: ``marl train pong --agents 2 --run long --steps 2000000`` stopped by SIGTERM once past
    its ``s1M`` moment (what it printed, its exit code), then ``marl train --resume long`` and its summary.
``checkpoint``
    checkpoint.md's removals: a run stopped by SIGTERM once past its ``s250k`` moment (``--snapshot-steps 50000``),
    then ``marl checkpoint rm`` of its first snapshot (refused while the run owes it its gauntlet: then removed
    once the run is over), of its last (refused: the run resumes from it), the same with ``--force`` (the run
    ended), and ``marl train --resume`` of it (refused): section ``rm``.
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
    """``marl`` commands in one league home, each echoed as ``$ marl ...`` before what it printed. Lines said while
    ``section`` names one are kept in ``sections`` too (the part of an example a page quotes)."""

    def __init__(self, home: Path, sections: dict[str, list[str]] | None = None) -> None:
        self.home = home
        self.env = dict(os.environ, MARL_HOME=str(home), COLUMNS="120", SDL_VIDEODRIVER="dummy",
                        PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
        self.sections = {} if sections is None else sections
        self.section = ""

    def say(self, text: str) -> None:
        """Print ``text``, and keep its lines in the current section."""
        for line in text.splitlines():
            print(line.rstrip())
            if self.section:
                self.sections.setdefault(self.section, []).append(line.rstrip())

    def __call__(self, *args: str, note: str = "", show: bool = True, env: dict | None = None,
                 refused: bool = False, stderr: bool = False) -> tuple[str, float]:
        """Run ``marl ARGS``; print the command (with ``note``, and its wall time) and its output; return both.
        ``refused``: the command must be refused (exit 2), and its one line on stderr is what it printed;
        ``stderr``: its lines on stderr (a run's progress lines, without a terminal) are printed before its output."""
        began = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "selfplay_cli", *args], env={**self.env, **(env or {})},
                             capture_output=True, text=True, cwd=ROOT)
        took = time.perf_counter() - began
        if out.returncode not in ((2,) if refused else (0, 1)):  # 1: a gate's FAIL, still an answer
            raise SystemExit(f"marl {' '.join(args)} exited {out.returncode}: {out.stderr.strip()[-2000:]}")
        text = f"{out.stderr.strip()}\n(exit {out.returncode})" if refused else out.stdout
        if stderr:
            text = out.stderr + text
        text = text.replace(str(self.home), "league")
        shown = " ".join(args).replace(str(self.home), "league")
        self.say(f"$ marl {shown}    # {took:.0f} s{f'; {note}' if note else ''}")
        if show:
            self.say(text)
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
    sh.say("$ cat league/br.toml")
    sh.say(config.read_text().rstrip())
    sh("exploit", "kuhn_poker-1/s40k", "--steps", "200000", "--config", str(config), "--games", "2000")


def kuhn_plot(sh: Shell) -> None:
    import json

    sh("train", "openspiel:kuhn_poker", "--agents", "1", "--bots", "random=1", "--steps", "20000", "--snapshot-steps",
       "5000", "--games", "16")
    sh("exploit", "kuhn_poker-1/s20k", "--exact", note="one snapshot's figure, filed")
    text, _ = sh("league", "plot", "--run", "kuhn_poker-1", "--exploitability", show=False,
                 note="every snapshot's, the rest computed (its Elo chart left out here)")
    sh.say(text[text.index("exact exploitability"):].rstrip())
    sh("league", "plot", "--run", "kuhn_poker-1", "--exploitability", "--out", str(sh.home / "kuhn.png"))
    sh("league", "ladder", "--run", "kuhn_poker-1")
    ladder, _ = sh("league", "ladder", "--run", "kuhn_poker-1", "--json", show=False)
    plot, _ = sh("league", "plot", "--run", "kuhn_poker-1", "--exploitability", "--json", show=False)
    elo = {r["policy"]: r["elo"] for r in json.loads(ladder)}
    figures = sorted(json.loads(plot)["exploitability"], key=lambda r: r["step"])
    sh.say("snapshot by snapshot (from the two commands' JSON):")
    for r in figures:
        sh.say(f"  {r['policy']:<18} step {r['step']:>6,}  Elo {elo[r['policy']]:6.0f}  exact exploitability "
               f"{r['exploitability']:.4f}")
    top = max(figures, key=lambda r: elo[r["policy"]])
    least = min(figures, key=lambda r: r["exploitability"])
    same = "is" if top is least else "is not"
    sh.say(f"the snapshot rated highest ({top['policy']}, Elo {elo[top['policy']]:.0f}, exploitability "
           f"{top['exploitability']:.4f}) {same} the least exploitable ({least['policy']}, "
           f"{least['exploitability']:.4f})")


LEAGUE_TOML = """\
[league]              # AlphaStar's defaults, but for the two step limits
main = 1
main_exploiters = 1
league_exploiters = 2
pfsp = 0.5            # main agents: share of PFSP games; verification = 0.15; the rest self-play
selfplay_rate = 0.3   # verify_exploiters = 0.3, verify_forgetting = 0.7, exploiter_rate = 0.1
snapshot_rate = 0.7
min_steps = 10_000    # a learner's own game steps between snapshots: at least...
max_steps = 20_000    # ...and at most
league_exploiter_reset = 0.25
"""


def kuhn_league(sh: Shell) -> None:
    import json

    config = sh.home / "kuhn-league.toml"
    config.parent.mkdir(parents=True, exist_ok=True)
    config.write_text(LEAGUE_TOML)
    sh.say("$ cat league/kuhn-league.toml")
    sh.say(LEAGUE_TOML.rstrip())
    sh("train", "openspiel:kuhn_poker", "--league", "alphastar", "--config", str(config), "--steps", "160000",
       "--games", "64")
    ladder, _ = sh("league", "ladder", "--run", "kuhn_poker-1", "--json", show=False)
    rows = [r for r in json.loads(ladder) if r["kind"] == "snapshot"]
    roles: dict[str, list[str]] = {}
    for r in sorted(rows, key=lambda r: int(r["step"])):
        roles.setdefault(r["policy"].rsplit("-", 1)[-1], []).append(r["policy"].split("/")[1].rsplit("-", 1)[0])
    sh.say("snapshot moments by learner (from the ladder's JSON):")
    for role, steps in roles.items():
        sh.say(f"  {role}: {', '.join(steps)}")
    best = next(r for r in rows if r.get("best"))
    sh.say(f"the run's best: {best['policy']} (Elo {best['elo']:.0f}, rank {best['rank']})")


def kuhn_nash(sh: Shell) -> None:
    import re

    args = ("train", "openspiel:kuhn_poker", "--agents", "1", "--opponents", "nash", "--nash-payoff", "score",
            "--latest-ratio", "0", "--steps", "100000", "--snapshot-steps", "20000")
    first, _ = Shell(sh.home.parent / "first")(*args, show=False, note="a first run, in a league of its own")
    second, _ = sh(*args, note="the same command again, in another league")

    def said(text: str) -> tuple[str, str]:
        mixture = next((line.split(";")[0].split(": ", 1)[1] for line in text.splitlines() if "Nash mixture" in line),
                       "-")
        return re.search(r"([\d,]+) episodes", text).group(1), mixture

    (episodes, mixture), again = said(first), said(second)
    sh.say(f"the two runs: {episodes} and {again[0]} episodes, Nash mixtures {mixture} and {again[1]}: "
           f"{'the same' if (episodes, mixture) == again else 'not the same'}")


def pong(sh: Shell) -> None:
    import re

    sh.section = "train"
    text, _ = sh("train", "pong", "--agents", "2", stderr=True, note="the default run; no terminal: plain lines")
    sh.section = "predict"
    sh("league", "predict", "pong-1/s6M-left", "pong-1/s2M-left")
    sh("match", "pong-1/s6M-left", "pong-1/s6M-right", "--games", "200")
    sh.section = "ladder"
    sh("league", "ladder", "--run", "pong-1")
    sh.section = "plot"
    sh("league", "plot", "--run", "pong-1")
    sh.section = "best"
    line = next(x for x in text.splitlines() if x.lstrip().startswith("best of pong-1:"))
    best, other = re.search(r"best of pong-1: (\S+) .*? over (\S+) \(", line).groups()
    sh.say(f"the run's summary: {line.strip()}")
    sh("match", best, other, "--games", "200", "--no-store", note="a fresh match of the two, not stored")


def lander(sh: Shell) -> None:
    sh("train", "lander", "--agents", "2", "--sharing", "fups")
    sh("league", "ladder", "--env", "lander")


def envs(sh: Shell) -> None:
    sh("envs")
    sh("envs", "tennis")


def _stopped(sh: Shell, args: list[str], run: str, past: int) -> None:
    """``marl ARGS`` (a training run named ``run``) stopped by SIGTERM once its metrics are past step ``past``: its
    command, wall time, the step it was signalled at and its exit code, then what it printed."""
    import json
    import signal

    metrics = sh.home / "runs" / run / "metrics.jsonl"
    began = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "selfplay_cli", *args], env=sh.env, cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    step = 0
    while proc.poll() is None and step < past:
        time.sleep(0.5)
        if metrics.exists():
            lines = metrics.read_text().splitlines()
            step = max((json.loads(x)["step"] for x in lines if x.endswith("}")), default=0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate()
    sh.say(f"$ marl {' '.join(args)}    # {time.perf_counter() - began:.0f} s; SIGTERM once past step {step:,}: "
           f"exit {proc.returncode}")
    sh.say((out + err).replace(str(sh.home), "league"))


def resume(sh: Shell) -> None:
    _stopped(sh, ["train", "pong", "--agents", "2", "--run", "long", "--steps", "2000000"], "long",
             1_100_000)  # past the s1M moment (a snapshot every million steps)
    sh("train", "--resume", "long")


def checkpoint(sh: Shell) -> None:
    import json

    sh.section = "rm"
    _stopped(sh, ["train", "pong", "--agents", "2", "--run", "long", "--steps", "1000000", "--snapshot-steps",
                  "50000"], "long", 260_000)  # past its s250k moment
    sh.section = ""
    rows, _ = sh("checkpoint", "list", "--run", "long", "--json", show=False)
    left = [r for r in json.loads(rows) if r["name"].endswith("-left")]
    first, last = left[0]["policy"], left[-1]["policy"]
    owed = not left[0]["games"]  # its rating gauntlet not played yet when the run stopped: the run needs it too
    sh.section = "rm"
    if owed:
        sh("checkpoint", "rm", first, refused=True, note="refused: the run owes it its rating gauntlet")
    else:
        sh("checkpoint", "rm", first, note="an old snapshot, rated: its pool goes on without it")
    sh("checkpoint", "rm", last, refused=True, note="refused: the run resumes from it")
    sh("checkpoint", "rm", "--force", last)
    sh("train", "--resume", "long", refused=True, note="refused, for good")
    if owed:
        sh("checkpoint", "rm", first, note="the run is over: nothing needs it now")


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


PARTS = {"kuhn": kuhn, "kuhn_br": kuhn_br, "kuhn_plot": kuhn_plot, "kuhn_league": kuhn_league, "kuhn_nash": kuhn_nash,
         "pong": pong, "lander": lander, "envs": envs, "resume": resume, "checkpoint": checkpoint,
         "connect_four": connect_four, "simple_push": simple_push, "gif": gif}


def main(part: str, data: dict) -> None:
    sys.stdout.reconfigure(line_buffering=True)
    sections: dict[str, list[str]] = {}
    with tempfile.TemporaryDirectory(prefix="marl-doc-example-") as tmp:
        PARTS[part](Shell(Path(tmp) / "league", sections))
    if sections:
        data["sections"] = sections


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("part", choices=sorted(PARTS))
    part = ap.parse_args().part
    from results_file import recorded

    with recorded(f"example_{part}") as figures:
        main(part, figures)
