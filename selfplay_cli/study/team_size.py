"""``marl study team-size``: seed 001's method as one command.

1. **Fixed sizes.** Train a team at each size N of ``train`` (``marl train GAME --env-option SIZE=N --agents N``),
   each run ``<study>-n<N>``, for the same budget (``--steps`` or ``--minutes`` per run).
2. **Altered sizes.** Fly each trained team's final snapshot at each size M of ``eval`` against the same opponent
   (``random`` by default) on the same seeds: the mean team return per game with its 95% interval. A shared network
   flies any M; a team of networks (NoPS) by seed 001's rule (:func:`~selfplay_cli.policies.resize.resize_members`).
3. **Adaptive training.** Resume each trained team at each other trained size M from its final snapshot
   (``--init-from``; the run ``<study>-n<N>-to<M>``) for the same budget, and compare it with the team trained at
   M from scratch (step 1's run): the return each reached (on the same seeds), and the steps and minutes the adapted
   team took to reach the fresh team's final return: its snapshot moments flown in order on those seeds until one
   scores at or above it (one measure for both, the table's: not the runs' few rating games, whose noise could
   call a run "reached" that the table shows below).

Every run is trained in its own process, measured (:mod:`.measure`): wall time, CPU time (mean cores busy) and peak
memory. The study's state is ``<home>/studies/<study>/study.json`` (written to a temporary name, then renamed):
a study killed midway goes on where it stopped when the same command is typed again (a run cut short resumes with
``marl train --resume``; finished runs and evaluations are kept). Its training child dies with it (Ctrl-C and
SIGTERM are handed on and waited for; a study killed outright has the kernel stop its child), and a study typed
again while that child is still stopping waits for it (:attr:`Study.holder_wait` seconds) before resuming the run.
A study of that name with other settings is refused. The report (:func:`report`) is a table of returns by trained x
evaluated size, the adaptive-vs-fresh comparison, and each run's figures; PNGs of return against team size and of
the adapted and fresh runs' curves.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..errors import MarlError
from ..files import write_atomic
from ..league.store import League
from ..train.lock import live_trainer
from .evaluate import fly, snapshot_returns
from .measure import last_line, summed, train_process

__all__ = ["Study", "TeamSizePlan", "parse_sizes", "run_study"]

STATE_VERSION = 1


def parse_sizes(text: str, what: str) -> list[int]:
    """``2,3,4`` or ``1-6`` (or both: ``1-3,6``) as sorted distinct sizes >= 1; a one-line error otherwise."""
    out: set[int] = set()
    for part in str(text).split(","):
        part = part.strip()
        lo, dash, hi = part.partition("-")
        try:
            first, last = (int(lo), int(hi)) if dash else (int(part), int(part))
        except ValueError:
            raise MarlError(f"{what} takes team sizes like 2,3,4 or 1-6, not {text!r}") from None
        if first < 1 or last < first or last > 64:
            raise MarlError(f"{what}: team sizes run from 1 to 64, low to high, not {part!r}")
        out.update(range(first, last + 1))
    if not out:
        raise MarlError(f"{what} needs at least one team size")
    return sorted(out)


@dataclass(frozen=True)
class TeamSizePlan:
    """What a team-size study does (its settings: a study resumed must be given the same)."""

    name: str
    env: str
    size_option: str
    train: tuple[int, ...]
    eval: tuple[int, ...]
    steps: int | None = None
    minutes: float | None = None
    sharing: str = "fups"
    algo: str | None = None
    kind: str | None = None
    env_options: dict[str, Any] = field(default_factory=dict)
    eval_games: int = 50
    vs: str = "random"
    seed: int = 0
    snapshots: int = 8
    config: str | None = None
    games: int | None = None

    def __post_init__(self) -> None:
        if (self.steps is None) == (self.minutes is None):
            raise MarlError("give each run a budget: --steps N or --minutes M (one of them)")
        if self.steps is not None and self.steps < 1:
            raise MarlError(f"--steps must be at least 1, not {self.steps}")
        if self.minutes is not None and not (self.minutes > 0 and math.isfinite(self.minutes)):
            raise MarlError(f"--minutes must be a positive number, not {self.minutes}")
        if self.eval_games < 1:
            raise MarlError(f"--eval-games must be at least 1, not {self.eval_games}")
        if self.snapshots < 1:
            raise MarlError(f"--snapshots must be at least 1, not {self.snapshots}")
        if self.size_option in self.env_options:
            raise MarlError(f"--env-option {self.size_option}=... is the team size the study varies: give the sizes "
                            "with --train and --eval")

    def fresh(self, n: int) -> str:
        return f"{self.name}-n{n}"

    def adapted(self, n: int, m: int) -> str:
        return f"{self.name}-n{n}-to{m}"

    def options(self, size: int) -> dict[str, Any]:
        """The game options of a run or an evaluation at ``size``."""
        out = {**self.env_options, self.size_option: size}
        if self.kind is not None:
            out["kind"] = self.kind
        return out

    def runs(self) -> list[tuple[str, int, int | None]]:
        """Every training run in order: (name, size, the size it starts from or None), the fresh ones first."""
        out: list[tuple[str, int, int | None]] = [(self.fresh(n), n, None) for n in self.train]
        out += [(self.adapted(n, m), m, n) for n in self.train for m in self.train if m != n]
        return out

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["train"], d["eval"] = list(self.train), list(self.eval)
        return d


def _train_args(plan: TeamSizePlan, run: str, size: int, parent: str | None) -> list[str]:
    args = ["train", plan.env, "--run", run, "--agents", str(size), "--sharing", plan.sharing, "--seed",
            str(plan.seed), "--quiet", "--json"]
    for key, value in plan.options(size).items():
        if key != "kind":
            args += ["--env-option", f"{key}={_option_text(value)}"]
    if plan.kind is not None:
        args += ["--kind", plan.kind]
    if plan.algo is not None:
        args += ["--algo", plan.algo]
    if plan.config is not None:
        args += ["--config", plan.config]
    if plan.games is not None:
        args += ["--games", str(plan.games)]
    if plan.steps is not None:
        args += ["--steps", str(plan.steps), "--snapshot-steps", str(max(1, plan.steps // plan.snapshots))]
    else:
        args += ["--minutes", f"{plan.minutes:g}"]
    if parent is not None:
        args += ["--init-from", parent]
    return args


def _option_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


class Study:
    """A team-size study in a league: its plan, its state file, and the stages that fill it."""

    holder_wait = 120.0
    """Seconds a study waits for a process still training one of its runs (the child of a study killed just before,
    stopping) before it refuses to go on."""

    def __init__(self, league: League, plan: TeamSizePlan,
                 on_progress: Callable[..., None] | None = None, on_note: Callable[[str], None] | None = None) -> None:
        if league.home is None:
            raise MarlError("a study needs a league home for its runs and its files: pass --home")
        self.league, self.plan = league, plan
        self.dir = league.home_path("studies", plan.name)
        self.path = self.dir / "study.json"
        # on_progress(key, share done, detail): a run's name (its share of its budget), or "eval RUN at SIZE"
        self.on_progress = on_progress or (lambda key, done, detail="": None)
        self.on_note = on_note or (lambda line: None)  # a line for the user (stderr), e.g. what the study waits for
        self.state = self._load()
        self._curves: dict[tuple[str, int], list[tuple[int, float, float]]] = {}
        self._moments: dict[str, list[tuple[int, str]]] = {}  # a finished run's moments (read once)
        self._seconds: dict[str, dict[int, float]] = {}  # a finished run's seconds by step (read once)

    # ------------------------------------------------------------------------------------------------ state
    def _load(self) -> dict[str, Any]:
        fresh = {"version": STATE_VERSION, "plan": self.plan.to_json(), "runs": {}, "evals": {}}
        if not self.path.exists():
            return fresh
        try:
            state = json.loads(self.path.read_text())
        except (OSError, ValueError) as e:
            raise MarlError(f"{self.path}: cannot read the study's state ({e}); move it away to start again") from None
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            raise MarlError(f"{self.path} is not a study state this marl reads; move it away to start again")
        if state.get("plan") != self.plan.to_json():
            raise MarlError(f"a study named {self.plan.name!r} exists with other settings ({self.path}): give the "
                            "same ones to go on with it, or another --name")
        return state

    def _save(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        write_atomic(self.path, json.dumps(self.state, indent=1, sort_keys=True))

    # ------------------------------------------------------------------------------------------------ stages
    def child_env(self) -> dict[str, str]:
        env = dict(os.environ, MARL_HOME=str(self.league.home), SDL_VIDEODRIVER=os.environ.get("SDL_VIDEODRIVER",
                                                                                                 "dummy"))
        db = self.league
        if db.db_path is None or db.db_path.resolve() != (Path(db.home or ".") / "league.db").resolve():
            env["MARL_DB"] = db.url.render_as_string(hide_password=False)
        else:
            env.pop("MARL_DB", None)
        return env

    def train_all(self) -> None:
        for run, size, parent in self.plan.runs():
            self.train(run, size, parent)

    def train(self, run: str, size: int, parent_size: int | None) -> None:
        """Train ``run`` (or resume it, or leave it, finished), measured, its figures kept in the state."""
        entry = self.state["runs"].setdefault(run, {"size": size, "from": parent_size, "segments": []})
        if entry.get("done"):
            self.on_progress(run, 1.0, "done")
            return
        self._wait_for_holder(run)
        existing = self.league.roster.get_run(run)
        if existing is not None and existing.status == "finished":
            entry["done"], entry["steps"] = True, self._final_step(run)
            self._save()
            return
        if existing is not None:
            args = ["train", self.plan.env, "--resume", run, "--quiet", "--json"]  # the game named, as typed
        else:
            parent = None
            if parent_size is not None:
                parent = self.final_team(self.plan.fresh(parent_size))
            args = _train_args(self.plan, run, size, parent)
        metrics = self.league.home_path("runs", run) / "metrics.jsonl"
        started = time.monotonic()

        def tick() -> None:
            line = last_line(metrics)
            step, rate = int(line.get("step", 0)), line.get("steps_per_second")
            if self.plan.steps:
                done = step / self.plan.steps
            else:  # a run of --minutes: its share of the minutes (the first piece's; a resumed run starts again)
                done = (time.monotonic() - started) / (60 * float(self.plan.minutes or 1))
            self.on_progress(run, min(1.0, done), f"{step:,} steps" + (f", {rate:,} steps/s" if rate else ""))

        self.on_progress(run, 0.0)
        code, segment = train_process(args, self.child_env(), self.dir / "logs" / f"{run}.log", on_tick=tick)
        entry["segments"].append(segment.to_json())
        self._save()
        if code != 0:
            tail = _tail(self.dir / "logs" / f"{run}.log")
            raise MarlError(f"study {self.plan.name}: training {run} failed (exit {code}): {tail} (the whole log: "
                            f"{self.dir / 'logs' / (run + '.log')})")
        entry["done"] = True
        entry["steps"] = self._final_step(run)
        self._save()
        self.on_progress(run, 1.0)

    def _wait_for_holder(self, run: str) -> None:
        """A process still training ``run`` (the child of a study killed a moment ago, stopping its run since the
        kernel told it) is waited for, up to :attr:`holder_wait` seconds; one that is still at it then is not this
        study's to end: refused."""
        lock = self.league.home_path("runs", run) / "lock"
        pid = live_trainer(lock)
        if pid is None:
            return
        self.on_note(f"run {run} is still being trained by process {pid} (a study stopped a moment ago?); waiting "
                     f"up to {self.holder_wait:.0f} s for it to end")
        until = time.monotonic() + self.holder_wait
        while (pid := live_trainer(lock)) is not None and time.monotonic() < until:
            time.sleep(0.2)
        if pid is not None:
            raise MarlError(f"study {self.plan.name}: run {run} is being trained by process {pid}, not by this study: "
                            "stop it, then type the study again")

    def _snapshots(self, run: str) -> list[Any]:
        rows = [p for p in self.league.roster.players(kind="snapshot") if p.run == run and not p.removed]
        if not rows:
            raise MarlError(f"study {self.plan.name}: run {run} has no snapshots")
        return rows

    def _final_step(self, run: str) -> int:
        """The game steps a run trained: its final snapshot's."""
        return max(int(p.step or 0) for p in self._snapshots(run))

    def moments(self, run: str) -> list[tuple[int, str]]:
        """(step, ``run/<name>``) of each snapshot moment of a run in step order: its one snapshot, or its team of
        per-seat snapshots."""
        if run in self._moments:
            return self._moments[run]
        by_step: dict[int, list[str]] = {}
        for p in self._snapshots(run):
            by_step.setdefault(int(p.step or 0), []).append(p.name)
        out = []
        for step, names in sorted(by_step.items()):
            names.sort()
            out.append((step, f"{run}/{names[0] if len(names) == 1 else os.path.commonprefix(names).rstrip('-')}"))
        if self.state["runs"].get(run, {}).get("done"):
            self._moments[run] = out
        return out

    def final_team(self, run: str) -> str:
        """``run/<name>`` of a run's final moment: its one snapshot, or its team of per-seat snapshots."""
        return self.moments(run)[-1][1]

    def evaluate_all(self) -> None:
        for n in self.plan.train:
            for m in self.plan.eval:
                self.evaluate(self.plan.fresh(n), m)
        for n in self.plan.train:
            for m in self.plan.train:
                if m != n:
                    self.evaluate(self.plan.adapted(n, m), m)
        for n in self.plan.train:
            for m in self.plan.train:
                if m != n:
                    self.reach(self.plan.adapted(n, m), m)

    def evaluate(self, run: str, size: int, moment: tuple[int, str] | None = None) -> dict[str, Any]:
        """The final team of ``run`` (or its team at ``moment``: (step, name)) flown at ``size`` against the plan's
        opponent on the study's seeds (kept)."""
        final = moment is None or moment == self.moments(run)[-1]
        key = f"{run}@{size}" if final else f"{run}@{size}:{moment[0]}"  # type: ignore[index]
        if key in self.state["evals"]:
            return self.state["evals"][key]
        team = self.final_team(run) if moment is None else moment[1]
        self.on_progress(f"eval {run} at {size}" + ("" if final else f", step {moment[0]:,}"), 0.0)  # type: ignore[index]
        out = fly(self.league, team, self.plan.vs, self.plan.options(size), self.plan.eval_games,
                  seed=1_000_003 + self.plan.seed)
        self.state["evals"][key] = out
        self._save()
        return out

    def reach(self, run: str, size: int) -> dict[str, Any]:
        """When the adapted ``run`` reached the final return of the fresh run at ``size``: its snapshot moments flown
        in step order on the study's seeds (the table's measure) until one scores at or above the fresh run's final
        team; that moment's step, training seconds and return, or ``reached: False`` (kept)."""
        if run in self.state.setdefault("reach", {}):
            return self.state["reach"][run]
        target = self.evaluate(self.plan.fresh(size), size)["mean"]
        seconds = self.seconds(run)
        out: dict[str, Any] = {"reached": False, "target": target}
        for step, team in self.moments(run):
            got = self.evaluate(run, size, (step, team))["mean"]
            if target is not None and got is not None and got >= target:
                out = {"reached": True, "target": target, "step": step, "seconds": _seconds_at(seconds, step),
                       "return": got, "team": team}
                break
        self.state["reach"][run] = out
        self._save()
        return out

    # ------------------------------------------------------------------------------------------------ report
    def curve(self, run: str, size: int) -> list[tuple[int, float, float]]:
        """(step, training seconds, mean team return) of each snapshot moment of ``run`` from its rating games (read
        once per run: a fresh run's curve serves every adaptation to its size)."""
        if (run, size) not in self._curves:
            self._curves[(run, size)] = self._read_curve(run, size)
        return self._curves[(run, size)]

    def seconds(self, run: str) -> dict[int, float]:
        """A finished run's training seconds by step, from its metrics lines (read once per run)."""
        if run not in self._seconds:
            self._seconds[run] = _seconds_by_step(self.league.home_path("runs", run) / "metrics.jsonl")
        return self._seconds[run]

    def _read_curve(self, run: str, size: int) -> list[tuple[int, float, float]]:
        seconds = self.seconds(run)
        return [(step, _seconds_at(seconds, step), ret)
                for step, ret in snapshot_returns(self.league, self.plan.env, run, self.plan.options(size))]

    def report(self) -> dict[str, Any]:
        plan, runs, evals = self.plan, self.state["runs"], self.state["evals"]
        returns = [{"trained": n, "evaluated": m, **evals[f"{plan.fresh(n)}@{m}"]}
                   for n in plan.train for m in plan.eval if f"{plan.fresh(n)}@{m}" in evals]
        adaptive = []
        for n in plan.train:
            for m in plan.train:
                if m == n:
                    continue
                a_run, f_run = plan.adapted(n, m), plan.fresh(m)
                reach = self.state.get("reach", {}).get(a_run) or {}
                f_steps = runs.get(f_run, {}).get("steps")
                adaptive.append({
                    "from": n, "to": m, "run": a_run, "fresh_run": f_run,
                    "return": evals.get(f"{a_run}@{m}"), "fresh_return": evals.get(f"{f_run}@{m}"),
                    "steps_to_reach": reach.get("step"),
                    "minutes_to_reach": round(reach["seconds"] / 60, 2) if reach.get("reached") else None,
                    "reached_with": reach.get("team"), "reached_return": reach.get("return"),
                    "fresh_steps": f_steps,
                    "fresh_minutes": (round(_seconds_at(self.seconds(f_run), f_steps) / 60, 2)
                                      if f_steps is not None else None),
                    "curve": [list(p) for p in self.curve(a_run, m)],
                    "fresh_curve": [list(p) for p in self.curve(f_run, m)],
                })
        figures = [{"run": run, "size": runs[run]["size"], "from": runs[run]["from"], "steps": runs[run].get("steps"),
                    **summed(runs[run]["segments"])} for run, _, _ in plan.runs()
                   if runs.get(run, {}).get("segments")]
        return {"study": plan.name, "env": plan.env, "size_option": plan.size_option, "train": list(plan.train),
                "eval": list(plan.eval), "budget": {"steps": plan.steps, "minutes": plan.minutes},
                "sharing": plan.sharing, "algo": plan.algo, "vs": plan.vs, "eval_games": plan.eval_games,
                "returns": returns, "adaptive": adaptive, "runs": figures, "dir": str(self.dir)}


def _seconds_by_step(metrics: Path) -> dict[int, float]:
    out: dict[int, float] = {}
    try:
        lines = metrics.read_text().splitlines()
    except OSError:
        return out
    for line in lines:
        try:
            m = json.loads(line)
            out[int(m["step"])] = float(m["seconds"])
        except (ValueError, KeyError, TypeError):
            continue
    return out


def _seconds_at(seconds: dict[int, float], step: int) -> float:
    """The training seconds at ``step`` by the run's metrics lines (the nearest line's; 0 at step 0)."""
    if not seconds or not step:
        return 0.0
    return seconds[min(seconds, key=lambda s: abs(s - step))]


def _tail(log: Path) -> str:
    try:
        lines = [x for x in log.read_text(errors="replace").splitlines() if x.strip()]
    except OSError:
        return "(no log)"
    return lines[-1].strip() if lines else "(an empty log)"


def run_study(league: League, plan: TeamSizePlan, on_progress: Callable[..., None] | None = None,
              plots: bool = True, on_note: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Every stage of the study (each skipped where the state has it), then its report (and PNGs)."""
    study = Study(league, plan, on_progress, on_note)
    study.train_all()
    study.evaluate_all()
    out = study.report()
    if plots:
        from .plots import plot_curves, plot_returns

        out["plots"] = {"returns": str(plot_returns(out, study.dir / "returns.png")),
                        "curves": str(plot_curves(out, study.dir / "curves.png"))}
    write_atomic(study.dir / "report.json", json.dumps(out, indent=1))
    return out
