"""The training loop: learners play endless batched games, snapshot into the league, and rate as they go.

One loop for every algorithm: it steps the shared :class:`SelfPlayGames`, gives each learner its slots, runs the
learner's update when its rollout is due, and every ``snapshot_every`` finished games (episodes) or
``snapshot_steps`` game steps it

1. saves each learner as a snapshot file and registers it in the league (``epN``; ``epN-left``/``epN-right`` when
   each seat has its own network), with its parent (the learner's previous snapshot);
2. rates every new snapshot in a gauntlet (:mod:`selfplay_cli.rated.gauntlet`): its predecessor, the other
   learners' new snapshots, the run's best, older snapshots and the scripted players, in seat-swapped pairs;
3. refreshes the matchmaker's pool (the run's snapshots).

With a teacher (``[teacher]``, ``--teacher``: kickstarting, :mod:`selfplay_cli.algos.kickstart`) the teacher
labels every learner's observations with its own actions while the schedule's weight is above 0, and each learner
adds the imitation term, so weighted, to its policy's loss.

Training games go to the ledger in batches (so ``marl record --game`` can replay them), filed under the learner's
latest snapshot; the learner has moved on since, so they are kept out of every fitted rating (only the online
Elo, a live view, counts them). The ratings come from the gauntlet games, which the snapshots themselves played.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .. import files
from ..algos import get_learner
from ..algos.joint import JointLearner
from ..arena.selfplay import OPPONENT, SelfPlayGames, learner_roles, learner_spaces, plan_layout
from ..errors import MarlError, NonFiniteError
from ..league.ledger import KIND_CODES
from ..league.store import League, PlayerRow
from ..league.variants import variant_key
from ..policies import Policy
from ..policies.bots import league_bots
from ..policies.network import resolve_device
from ..policies.snapshot import SnapshotMeta, save_snapshot
from ..rated.match import load_player
from ..rated.roles import RoleBook
from ..rated.snapshots import snapshot_relpath
from ..results import COOPERATIVE, GameResult
from ..signals import clear_stop, signals_held, stoppable
from .config import TrainConfig, tensorboard_writer
from .curriculum import Curriculum, Schedule
from .evaluator import Evaluator, GauntletJob, JobDone
from .lock import claim, write_lock
from .matchmaking import LATEST_LEARNER, Matchmaker, WinRates
from .team import LearnerTeam

METRICS_STEPS = 8192  # game steps between metrics lines at least (PPO's rollouts are longer: a line an update)
STATE_VERSION = 3  # 2: flat-buffer optimiser state (FlatAdam); 3: snapshots by name, pending gauntlets


@dataclass(frozen=True)
class SnapshotRecord:
    """What the ledger says of one snapshot right after its gauntlet: its record against each scripted player
    (``{bot: (wins, draws, losses)}``, every stored game between the two) and its fitted rating with the interval,
    None when evaluation is off."""

    name: str
    learner: str
    step: int
    vs: dict[str, tuple[int, int, int]]
    elo: float | None = None
    ci_low: float | None = None
    ci_high: float | None = None
    unit: str = "games"  # what a result against a bot is: a game, or a cooperative game's comparison of two

    @staticmethod
    def score(wdl: tuple[int, int, int]) -> float:
        w, d, lo = wdl
        return (w + 0.5 * d) / max(w + d + lo, 1)

    @staticmethod
    def interval(wdl: tuple[int, int, int]) -> tuple[float, float]:
        """The score's 95% interval (Wilson: honest with a handful of results and at 0 % or 100 %)."""
        from ..stats.match import score_interval

        return score_interval(*wdl)

    def to_json(self) -> dict[str, Any]:
        return {"snapshot": self.name, "learner": self.learner, "step": self.step,
                "elo": None if self.elo is None else round(self.elo, 1),
                "ci_low": None if self.ci_low is None else round(self.ci_low, 1),
                "ci_high": None if self.ci_high is None else round(self.ci_high, 1),
                "vs": {bot: {"score": round(self.score(wdl), 4), "score_low": round(self.interval(wdl)[0], 4),
                             "score_high": round(self.interval(wdl)[1], 4), self.unit: sum(wdl), "wins": wdl[0],
                             "draws": wdl[1], "losses": wdl[2]} for bot, wdl in self.vs.items()}}


@dataclass(frozen=True)
class Standing:
    """Where a run stands, for a progress display, in counts that hold for every game (none of them assumes a
    game's shape). Counts are of the whole run, every session of a resumed run included, unless they say
    ``session``. Games that all end together (every game of a batch cut by the same time limit) leave
    ``episodes`` at 0 for most of a run: ``playing`` and ``game_steps`` then say how far they are."""

    progress: float  # share of the budget spent: steps of the budget, or minutes of all sessions (0 to 1)
    steps: int  # game steps played: one step of each of the games played at once counts as that many
    episodes: int  # training games finished
    playing: int  # training games under way (the games played at once); once training has ended, those it left
    game_steps: float  # steps since the games under way began, averaged over them
    time_limit: int | None  # the most steps one game lasts, as the game declares it (None: it declares none)
    snapshots: int  # snapshots taken (one per learner and snapshot moment)
    rated: int  # of them, those whose gauntlet has finished (0 with rating games off)
    newest: tuple[SnapshotRecord, ...]  # the newest rated moment's snapshots, as the ledger rates them
    session_steps: int  # game steps played by this process (a resumed run: since it resumed)
    steps_per_second: float | None  # this process's training rate (rating games played inline left out); None
    # before it has played a step
    remaining: float | None  # seconds left, estimated (None before the rate is known)
    ended: bool = False  # training has ended (what remains is the wait for the last rating games)


@dataclass
class TrainReport:
    """What a finished run says of itself: the whole run (every session of a resumed run), and this session's part
    where a field says so."""

    run: str
    steps: int  # game steps of the whole run
    episodes: int  # training games finished in the whole run
    seconds: float  # wall time of the whole run: each earlier session's up to its last snapshot moment (what the
    # next one continued from: a killed session's later work was done again), then all of this session's
    eval_games: int  # games the run's gauntlets played, every session (as the ledger holds them)
    snapshots: list[str]  # the whole run's snapshots, oldest first
    finals: list[SnapshotRecord]  # each learner's final snapshot, as the ledger rates it
    sessions: int  # processes that trained the run: the first, then one per resume from a snapshot moment
    session_steps: int  # game steps this session played
    session_seconds: float  # wall time of this session, rating games and the wait for the last ones included
    train_seconds: float  # of it, training: the loop of games and updates (rating games played inline left out)
    session_eval_games: int  # games this session's gauntlets played
    eval_seconds: float  # this session: time the gauntlets took (beside training, unless inline)
    wait_seconds: float  # this session: time spent after training waiting for the last gauntlets
    plot: Path | str | None = None  # the rating curves' PNG, or why there is none
    best: Any = None  # the run's best snapshot as the ladder has it at the end (a LadderRow), None unrated
    side_bests: list[Any] = field(default_factory=list)  # a game rated per side: the run's best of each side

    @property
    def steps_per_second(self) -> float:
        """This session's training rate: its game steps over its training time."""
        return self.session_steps / self.train_seconds if self.train_seconds > 0 else 0.0


def step_label(steps: int) -> str:
    """A step count as a short name, to three significant figures: ``0``, ``500``, ``250k``, ``1M``, ``1.5M``,
    ``4.92M``."""
    rounded = float(f"{int(steps):.3g}")
    for scale, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if rounded >= scale:
            return f"{rounded / scale:g}{unit}"
    return f"{rounded:g}"


def load_teacher(league: League, cfg: TrainConfig, spaces: list[Any], device: str = "cpu") -> Policy | None:
    """The run's teacher (``[teacher] player``) as a policy playing greedily, or None without one; one clear
    :class:`MarlError` for a name the league does not know or a player whose spaces are not the learners'."""
    name = cfg.teacher.player
    if not name:
        return None
    from ..league.names import resolve
    from ..policies.spaces import describe_space

    try:
        row = resolve(league, name, cfg.env, variant=variant_key(cfg.env, cfg.env_options))
    except MarlError as e:
        raise MarlError(f"--teacher: {e}") from None
    teacher = load_player(league, row, device=device, greedy=True, seed=cfg.seed)
    if callable(getattr(teacher, "configure", None)):  # a scripted player: the run's game options
        teacher.configure(cfg.env_options)
    for space in spaces:
        obs, act = getattr(teacher, "obs_space", None), getattr(teacher, "act_space", None)
        if obs is not None and tuple(obs.shape) != tuple(space.observation.shape):
            raise MarlError(f"--teacher: {row.full_name} reads observations of shape {tuple(obs.shape)}; the learners "
                            f"see {tuple(space.observation.shape)}")
        if act is not None and describe_space(act) != describe_space(space.action):
            raise MarlError(f"--teacher: {row.full_name} plays {describe_space(act)}; the learners play "
                            f"{describe_space(space.action)}")
    return teacher


def _learner_names(agents: tuple[str, ...], home: tuple[int, ...], sharing: str) -> list[str]:
    """Each learner's name: with one network per learner, the seat (agent) it holds first (``left``, ``right``);
    with one network for all, ``learner``."""
    n = max(home) + 1
    if sharing == "fups" or n == 1:
        return ["learner"]
    return [agents[home.index(i)] for i in range(n)]


class Trainer:
    """Runs one training run against one league (see the module docstring)."""

    def __init__(self, league: League, cfg: TrainConfig,
                 on_progress: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.league, self.cfg = league, cfg
        self.on_progress = on_progress
        self.spec = spec = cfg.game()
        self.device = resolve_device(cfg.device)
        if self.device.type == "cpu":
            torch.set_num_threads(1)  # small networks: one thread is fastest, the other core runs the games
        if league.home is None:
            raise MarlError("training needs a league home for its snapshot files: pass --home")
        self.run_dir = league.home_path("runs", cfg.run)
        game_cfg = spec.config(**cfg.env_options)
        self.variant = variant_key(spec.name, cfg.env_options)  # where its games are rated: the run's own variant
        league.ensure_bots(spec.name, league_bots(spec))
        self.bot_ids = {p.name: p.id for p in league.players(env=spec.name, kind="bot")}
        self.time_limit = spec.max_steps(game_cfg)  # the most steps a training game lasts (None: not declared)

        plan = cfg.seat_plan()
        layout = plan_layout(plan, cfg.games, cfg.agents, cfg.league_games)
        self.home = plan.home  # the learner of each seat when learners hold every seat (its 'latest' opponent)
        self.learner_of_game = layout.max(axis=0)  # the learner in each game (opponent slots: the one it faces)
        self.names = _learner_names(spec.agents, plan.home, cfg.sharing)
        roles = spec.seat_roles(game_cfg)
        self.seat_roles = roles if len(set(roles)) > 1 else None  # each seat's role, where seats differ
        self.spaces = learner_spaces(spec, spec.seat_spaces(game_cfg), layout, self.seat_roles)
        self.roles = learner_roles(layout, self.seat_roles)  # the role each learner learns (None: one role)
        self._can_play: dict[str, set[int]] = {}  # per role, the pool's snapshots that can play it
        torch.manual_seed(cfg.seed)
        learner_cls, algo_cfg = get_learner(cfg.algo), getattr(cfg, cfg.algo)
        self.arch = algo_cfg.arch
        if cfg.sharing == "sa":  # one agent over the team's joint observation and action (seed 001's SA)
            sa = JointLearner(learner_cls, self.spaces[0], spec.n_seats, cfg.games, algo_cfg, seed=cfg.seed,
                              device=self.device)
            self.learners: list[Any] = [sa]
            self.saved_spaces = [sa.joint_seat]  # what its snapshots read and play
            self.joint = {"seats": spec.n_seats, "base": sa.base}
        else:
            self.learners = [
                learner_cls(self.spaces[i], int((layout == i).sum()), algo_cfg, seed=cfg.seed + i, device=self.device)
                for i in range(len(self.names))
            ]
            self.saved_spaces = self.spaces
            self.joint = None
        self.latest: list[int] = [0] * len(self.learners)  # player id of each learner's latest snapshot
        self.snapshots: list[str] = []
        self._snapshot_episode = self._snapshot_step = -1
        self.matchmaker = Matchmaker(cfg.opponents, np.random.default_rng(cfg.seed), self.bot_ids)
        self.rates = WinRates(decay=cfg.opponents.decay, prior=cfg.opponents.prior)
        self._policies: dict[int, Policy] = {}
        self._player_of: dict[str, int] = dict(self.bot_ids)  # policy id in game results -> league player id
        self._assigned: np.ndarray | None = None  # opponent id per game slot, with --swap-every
        self._opponent_slots = np.flatnonzero(layout.ravel() == OPPONENT)  # flat (seat, game) slots of opponents
        self._next_swap = 0
        self.steps = 0
        learner_ids = [f"{cfg.run}/{n}" for n in self.names]
        # The 'latest' opponent of learner i: the next learner's live network (with one learner, itself), sampling;
        # one object per learner, so the games it plays share a batch.
        self.live = [learner.policy(lid, spec.name, greedy=cfg.algo == "dqn")
                     for learner, lid in zip(self.learners, learner_ids, strict=True)]
        self.games = SelfPlayGames(spec, cfg.games, layout, learner_ids,
                                   choose_opponents=self._choose if (layout == OPPONENT).any() else None,
                                   env_options=cfg.env_options, first_seed=cfg.seed * 1_000_003)
        self.curriculum = Curriculum(cfg.curriculum, spec.name, spec.live_options)
        self.teacher = load_teacher(league, cfg, self.spaces, str(self.device))
        self.teacher_schedule: Schedule | None = cfg.teacher.schedule() if self.teacher is not None else None
        if self.teacher is not None:
            for learner in self.learners:
                learner.imitation_capacity = cfg.teacher.states
        self.lesson: dict[str, float] = {}  # the curriculum's values the training games play under now
        self.match_id = league.create_match(spec.name, "training", {"run": cfg.run, "env_options": cfg.env_options})
        self.episodes = 0
        self.elapsed = 0.0  # seconds trained before this process (resumed runs)
        self.resumes = 0
        self.jobs: list[tuple[tuple[str, ...], int, bool]] = []  # gauntlets asked for, not known to be done:
        # (snapshot names, first seed, full)
        self.evaluator: Evaluator | None = None  # set while training
        self.eval_seconds = 0.0  # time the gauntlets of this process took (beside training, unless inline)
        self.eval_games = 0  # games they played
        self.eval_events = 0  # gauntlets finished in this process
        self._t0 = 0.0  # when this process began training (perf_counter)
        self._steps0 = 0  # the run's steps then
        self._deadline: float | None = None  # when a budget in minutes runs out (perf_counter)
        self._trained: float | None = None  # seconds this process trained, once its training has ended
        self.records: list[SnapshotRecord] = []  # the newest snapshots as the ledger rates them

    # -- opponents -------------------------------------------------------------------------------------------
    def _opponent_policy(self, pid: int, seat: int, learner: int) -> Policy:
        if pid == LATEST_LEARNER:  # ML-Agents' "latest model": the learner that holds this seat when learners hold
            home = self.home[seat]  # every seat, as it is now (pong: the other learner; one learner: itself)
            return self.live[home if home >= 0 else learner]
        if pid not in self._policies:
            self._policies[pid] = load_player(self.league, self.league.get_player(pid), device=str(self.device),
                                              greedy=False, seed=pid)
            self._player_of[self._policies[pid].id] = pid
        return self._policies[pid]

    def _draw(self, slots: np.ndarray) -> np.ndarray:
        """Opponent ids for the opponent ``slots`` (flat ``seat * games + game``), each drawn by the matchmaker for
        the learner that plays that game."""
        ids = np.empty(len(slots), dtype=np.int64)
        learners = self.learner_of_game[slots % self.cfg.games]
        if self.seat_roles is None:
            for i in np.unique(learners).tolist():
                mine = learners == i
                ids[mine] = self.matchmaker.sample(i, int(mine.sum()), self.rates)
            return ids
        roles = np.asarray(self.seat_roles, dtype=object)[slots // self.cfg.games]
        for i in np.unique(learners).tolist():  # a seat's opponents: the run's snapshots of the seat's role
            for role in dict.fromkeys(roles[learners == i].tolist()):
                mine = (learners == i) & (roles == role)
                ids[mine] = self.matchmaker.sample(i, int(mine.sum()), self.rates, among=self._can_play.get(role, ()))
        return ids

    def _choose(self, slots: np.ndarray) -> list[Policy]:
        """Opponents for the opponent ``slots`` of the games starting now, one each: drawn afresh for every game, or
        with --swap-every kept per slot until the next swap (ML-Agents' swap_steps, counted in game steps)."""
        if not self.cfg.swap_every:
            ids = self._draw(slots)
        else:
            due = self.steps >= self._next_swap
            if due or self._assigned is None:
                self._assigned = np.zeros(len(self.spec.agents) * self.cfg.games, dtype=np.int64)
                self._assigned[self._opponent_slots] = self._draw(self._opponent_slots)
                self._next_swap = self.steps + self.cfg.swap_every
            ids = self._assigned[slots]
        n = self.cfg.games
        return [self._opponent_policy(int(i), int(slot) // n, int(self.learner_of_game[slot % n]))
                for i, slot in zip(ids, slots, strict=True)]

    # -- snapshots -------------------------------------------------------------------------------------------
    def _base_name(self, trigger: str) -> str:
        """The name of this snapshot moment (``-<learner>`` is added per learner): by the training step it stands
        for (``s0``, ``s1M``, ``s2M``, ... ``s6M``: every ``--snapshot-steps``, named by the schedule, and the final
        one by the budget), or, taken every ``--snapshot-every`` episodes, by the episodes finished (``ep90``, as
        seed 000 named its checkpoints)."""
        cfg = self.cfg
        if trigger == "episodes":
            base = f"ep{self.episodes}"
        elif trigger == "steps":
            base = "s" + step_label(self.steps // cfg.snapshot_steps * cfg.snapshot_steps)
        elif trigger == "final" and cfg.minutes is None:
            base = "s" + step_label(cfg.steps)
        else:  # the start, or the end of a budget in minutes
            base = "s" + step_label(self.steps)
        first = base if len(self.names) == 1 else f"{base}-{self.names[0]}"
        if f"{cfg.run}/{first}" in self.snapshots:  # two moments that round to one label: the exact count decides
            base = f"s{self.steps}" if not base.startswith("ep") else f"{base}.{self.steps}"
        return base

    def snapshot(self, trigger: str = "steps") -> None:
        """Save and register every learner's snapshot, then rate them (the final ones against every opponent in full:
        the run's answer rests on them). ``trigger``: ``start``, ``steps``, ``episodes`` or ``final``, which names
        the moment (:meth:`_base_name`).

        One moment is one unit, whatever instant a kill comes at: the files are written first (each to a temporary
        name, then renamed), then the run state as it will be once they are registered (``state.pt.pending``),
        then all the rows in one transaction, which is the moment the snapshots exist; then the pending state
        becomes ``state.pt``. Killed before the transaction, the moment never happened (:meth:`restore` removes its
        files and pending state); killed after it, the pending state is the moment's, complete.
        """
        cfg = self.cfg
        if self.snapshots and self._snapshot_step == self.steps:
            return  # nothing played since the last snapshot
        with signals_held():  # Ctrl-C or SIGTERM now would cut the moment: they wait until it is whole
            self._write_moment(trigger)
        if cfg.eval_games:
            self.evaluator.submit(self._job(self.jobs[-1]))  # type: ignore[union-attr]
        self._collect(self.evaluator.poll())  # type: ignore[union-attr]

    def _write_moment(self, trigger: str) -> None:
        cfg = self.cfg
        base = self._base_name(trigger)
        names = [base if len(self.names) == 1 else f"{base}-{n}" for n in self.names]
        rows = []
        for i, (learner, name) in enumerate(zip(self.learners, names, strict=True)):
            rel = snapshot_relpath(cfg.run, name)
            parent = self.league.get_player(self.latest[i]).full_name if self.latest[i] else None
            meta = SnapshotMeta(env=self.spec.name, env_options=cfg.env_options,
                                obs_space=self.saved_spaces[i].observation, act_space=self.saved_spaces[i].action,
                                arch=self.arch,
                                algo=cfg.algo, step=self.steps,
                                episode=self.episodes, run=cfg.run, name=name, parent=parent,
                                seat=self.names[i] if len(self.names) > 1 else None, role=self.roles[i],
                                extra={"learner": self.names[i], **({"joint": self.joint} if self.joint else {})})
            meta = save_snapshot(self.league.home / rel, learner.net, meta)  # type: ignore[operator]
            row_meta = {"weights_sha256": meta.weights_sha256, "learner": self.names[i]}
            if self.roles[i] is not None:  # the seats it plays (a game whose seats hold several roles)
                row_meta["role"] = self.roles[i]
            rows.append(dict(env=self.spec.name, run=cfg.run, name=name, path=rel,  # the store hashes the file
                             step=self.steps, episode=self.episodes, algo=cfg.algo, parent_id=self.latest[i] or None,
                             meta=row_meta))
        full = [f"{cfg.run}/{n}" for n in names]
        jobs = list(self.jobs)
        if cfg.eval_games:
            jobs.append((tuple(full), 10_000_000 + 10_000 * len(self.snapshots), trigger == "final"))
        self._write_state(self.pending_path, latest=full, snapshots=self.snapshots + full, jobs=jobs,
                          snapshot_step=self.steps, snapshot_episode=self.episodes)
        registered = self.league.add_snapshots(rows)  # the moment exists from here on
        files.publish(self.pending_path, self.state_path)
        self._snapshot_episode, self._snapshot_step = self.episodes, self.steps
        self.latest = [r.id for r in registered]
        self.snapshots += full
        self.jobs = jobs
        self._set_pool()

    def _set_pool(self) -> None:
        """The matchmaker's pool: the run's snapshots, oldest first; in a game whose seats hold different roles,
        also which of them can play each role (a snapshot only its own)."""
        pool = [p for p in self.league.players(env=self.spec.name, kind="snapshot") if p.run == self.cfg.run]
        self.matchmaker.set_pool([p.id for p in pool])
        if self.seat_roles is not None:
            book = RoleBook(self.league, self.spec.name)
            self._can_play = {role: {p.id for p in pool if book.roles(p) is None or role in book.roles(p)}
                              for role in set(self.seat_roles)}

    def _job(self, job: tuple[tuple[str, ...], int, bool]) -> GauntletJob:
        """The gauntlet of a moment's snapshots (by name: the run state names them before they have ids)."""
        names, first_seed, full = job
        ids = tuple(self._player_id(n) for n in names)
        return GauntletJob(ids, first_seed, self.cfg.eval_games, self.cfg.eval_older, full=full,
                           playoff=self.cfg.eval_playoff if full else 0)

    def _player_id(self, full_name: str) -> int:
        run, _, name = full_name.partition("/")
        found = [p for p in self.league.find_players(full_name, env=self.spec.name) if p.run == run and p.name == name]
        if not found:
            raise MarlError(f"run '{self.cfg.run}': snapshot {full_name} of its resume state is not in the league")
        return found[0].id

    def _collect(self, done: list[JobDone]) -> None:
        """Take note of finished gauntlets: each snapshot's record as the ledger has it now, to ``on_progress``."""
        for d in done:
            names = tuple(self.league.get_player(i).full_name for i in d.job.snapshot_ids)
            self.jobs = [j for j in self.jobs if j[0] != names]
            self.eval_seconds += d.seconds
            self.eval_games += d.games
            self.eval_events += 1
            self.records = self._records([self.league.get_player(i) for i in d.job.snapshot_ids])
            if self.on_progress:
                self.on_progress({"event": "snapshot", "records": self.records, "standing": self.standing()})

    def _records(self, new: list[PlayerRow]) -> list[SnapshotRecord]:
        """Each new snapshot's record against the scripted players and its fitted rating, from the ledger."""
        from ..league.ladder import ladder
        from ..league.pairs import head_to_head

        rated = {}
        if self.cfg.eval_games:
            rated = {r.player_id: r for r in ladder(self.league, self.spec.name, bootstrap=0, variant=self.variant)}
        out = []
        for p in new:
            vs = {}
            for bot, bot_id in self.bot_ids.items():
                h = head_to_head(self.league, p.id, bot_id, variant=self.variant)
                if h["games"]:
                    vs[bot] = (h["wins"], h["draws"], h["losses"])
            r = rated.get(p.id)
            out.append(SnapshotRecord(p.full_name, p.meta.get("learner", ""), p.step, vs,
                                      r.elo if r else None, r.ci_low if r else None, r.ci_high if r else None,
                                      "comparisons" if self.spec.kind == COOPERATIVE else "games"))
        return out

    # -- one process per run ---------------------------------------------------------------------------------
    def _lock(self) -> None:
        """Claim the run for this process (:func:`~selfplay_cli.train.lock.claim`: refused while another live
        process trains it; a rating worker of a killed session still alive is ended first)."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        claim(self.run_dir / "lock", self.cfg.run)

    def _write_lock(self, worker: int | None) -> None:
        """The run's lock naming this process and, once one is started (and each time it is replaced), its rating
        worker."""
        write_lock(self.run_dir / "lock", worker)

    def _unlock(self) -> None:
        (self.run_dir / "lock").unlink(missing_ok=True)

    # -- resuming -------------------------------------------------------------------------------------------
    @property
    def state_path(self) -> Path:
        return self.run_dir / "state.pt"

    @property
    def pending_path(self) -> Path:
        return self.run_dir / "state.pt.pending"

    def _write_state(self, path: Path, *, latest: list[str], snapshots: list[str],
                     jobs: list[tuple[tuple[str, ...], int, bool]], snapshot_step: int, snapshot_episode: int) -> None:
        """Everything to continue exactly from a snapshot moment, written to a temporary name, flushed to disk and
        renamed to ``path``. Snapshots are named, not numbered: the state of a moment is written before its rows
        (and their ids) exist."""
        state = {
            "version": STATE_VERSION,
            "learners": [learner.state_dict() for learner in self.learners],
            "latest": latest, "snapshots": snapshots, "steps": self.steps, "episodes": self.episodes,
            "snapshot_episode": snapshot_episode, "snapshot_step": snapshot_step,
            "next_seed": self.games.next_seed, "elapsed": self.elapsed, "resumes": self.resumes,
            "matchmaker": json.dumps(self.matchmaker.state_dict()), "rates": json.dumps(self.rates.to_dict()),
            "jobs": [[list(names), seed, full] for names, seed, full in jobs],
        }
        self.run_dir.mkdir(parents=True, exist_ok=True)
        with files.atomic_write(path) as f:
            torch.save(state, f)

    def _read_state(self, path: Path) -> dict[str, Any]:
        try:
            state = torch.load(path, map_location=self.device, weights_only=True)
        except Exception as e:  # a torn or foreign file: say which, never a traceback
            raise MarlError(f"{path}: cannot read the resume state ({e})") from None
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            raise MarlError(f"{path}: resume state written by another marl version; start a new run")
        return state

    def restore(self) -> str:
        """Continue a stopped or killed run from its latest snapshot moment; returns a line saying from where.

        The league is the authority (see :meth:`snapshot`): a pending state whose snapshots are registered is the
        newest moment's (the run was killed between the rows and the rename); one whose snapshots are not is a
        moment that never happened, and goes, with the files written for it. Files under the run's snapshot folder
        that no row names (a moment cut short, a temporary file of a killed process) go too.
        """
        self._lock()  # before reading anything: a live process still training this run keeps it
        notes = []
        for torn in self.run_dir.glob("*.tmp-*"):  # half-written by a killed process (the lock is ours now)
            torn.unlink()
        if self.pending_path.exists():
            pending = self._read_state(self.pending_path)
            if all(self._registered(n) for n in pending["latest"]):
                files.publish(self.pending_path, self.state_path)
                notes.append(f"the snapshots {', '.join(pending['latest'])} were registered as it was killed")
            else:
                self.pending_path.unlink()
        if not self.state_path.exists():
            if any(p.run == self.cfg.run for p in self.league.players(env=self.spec.name, kind="snapshot")):
                raise MarlError(f"run '{self.cfg.run}' has snapshots but no resume state ({self.state_path})")
            self._remove_strays()  # killed before its first snapshot: nothing to continue, start it again
            return f"restarted {self.cfg.run} from the beginning (it was stopped before its first snapshot)"
        state = self._read_state(self.state_path)
        try:
            for learner, ls in zip(self.learners, state["learners"], strict=True):
                learner.load_state_dict(ls)
        except (KeyError, ValueError, RuntimeError) as e:
            raise MarlError(f"{self.state_path}: cannot resume from this state ({e})") from None
        self.snapshots = list(state["snapshots"])
        self.latest = [self._player_id(n) for n in state["latest"]]
        self.steps, self.episodes = int(state["steps"]), int(state["episodes"])
        self._snapshot_episode, self._snapshot_step = int(state["snapshot_episode"]), int(state["snapshot_step"])
        self.elapsed = float(state["elapsed"])
        self.matchmaker.load_state_dict(json.loads(state["matchmaker"]))
        self._set_pool()
        self.rates = WinRates.from_dict(json.loads(state["rates"]))
        self.jobs = [(tuple(names), int(seed), bool(full)) for names, seed, full in state["jobs"]]
        removed = self._remove_strays()
        if removed:
            notes.append(f"removed {removed} file(s) of a snapshot moment that never completed")
        self.resumes = int(state["resumes"]) + 1
        self.games.next_seed = int(state["next_seed"]) + (self.resumes << 40)  # a seed range of its own
        self.games.restart_all()
        return f"resumed {self.cfg.run} at step {self.steps:,} (snapshot {self.snapshots[-1]})" + "".join(
            f"; {n}" for n in notes)

    def _registered(self, full_name: str) -> bool:
        try:
            self._player_id(full_name)
        except MarlError:
            return False
        return True

    def _remove_strays(self) -> int:
        """Remove the files under ``snapshots/<run>/`` that no row of the league names."""
        folder = self.league.home / snapshot_relpath(self.cfg.run, "x").rsplit("/", 1)[0]  # type: ignore[operator]
        if not folder.is_dir():
            return 0
        known = set()
        for p in self.league.players(env=self.spec.name, kind="snapshot", include_removed=True):
            if p.run == self.cfg.run:
                with contextlib.suppress(MarlError):  # a row whose path leaves the league names no file here
                    known.add(self.league.snapshot_file(p))
        removed = 0
        for f in folder.iterdir():
            if f.is_file() and f not in known:
                f.unlink()
                removed += 1
        return removed

    # -- the ledger ------------------------------------------------------------------------------------------
    def _record(self, finished: list[GameResult]) -> None:
        learner_player = {lid: self.latest[i] for i, lid in enumerate(self.games.learner_ids)}
        records = []
        for r in finished:
            ids = [learner_player[p] if p in learner_player else self._player_of.get(p, 0) for p in r.players]
            if 0 in ids or len(set(ids)) < 2:
                continue  # the learners among themselves (or a live copy) carry no rating information
            records.append(r.with_players(dict(zip(r.players, ids, strict=True))))
            learners = {self.games.learner_ids.index(p) for p in r.players if p in self.games.learner_ids}
            if len(learners) == 1:  # a learner against the league: its win rate against each opponent (PFSP)
                (i,) = learners
                mine = self.games.learner_ids[i]
                points = r.points_of(mine)
                for opponent in dict.fromkeys(q for p, q in zip(r.players, ids, strict=True) if p != mine):
                    self.rates.update(i, opponent, points)
        if records:
            self.league.record_games(self.match_id, records)

    # -- the loop --------------------------------------------------------------------------------------------
    def _report(self, metrics: Any, board: Any, stats: list[dict[str, float]], elapsed: float) -> None:
        """One line of metrics (and TensorBoard scalars): counters, curriculum values, the learners' last update,
        the latest rating games' scores."""
        line = {"step": self.steps, "episodes": self.episodes, "seconds": round(elapsed, 2),
                "steps_per_second": round(self.steps / max(elapsed, 1e-9)),
                **{f"curriculum/{k}": round(v, 5) for k, v in self.lesson.items()},
                **{f"{self.names[i]}/{k}": round(v, 5) for i, s in enumerate(stats) for k, v in s.items()}}
        for rec in self.records:
            line.update({f"eval/{rec.learner}/{bot}": round(rec.score(wdl), 4) for bot, wdl in rec.vs.items()})
        metrics.write(json.dumps(line) + "\n")
        if board is not None:
            for key, value in line.items():
                if key != "step":
                    board.add_scalar(key, value, global_step=self.steps)

    def _follow_curriculum(self, progress: float) -> None:
        """The training games' live options as the curriculum has them at this progress (changed only when they
        change: a ramp moves them a little each step, lessons at their thresholds)."""
        values = self.curriculum.values(progress)
        if values != self.lesson:
            self.games.core.set_options(**values)
            self.lesson = values

    def _teach(self, obs: list[np.ndarray], acting: list[np.ndarray | None] | None, progress: float) -> None:
        """The teacher's actions for every learner's observations of this step (in turn-based games, the slots
        that act), while the teacher's weight is above 0; each learner's weight for its next update."""
        assert self.teacher is not None and self.teacher_schedule is not None
        weight = self.teacher_schedule.value(progress)
        if weight > 0:
            masks = self.games.masks() if self.games.masked else [None] * len(self.learners)
            for i, learner in enumerate(self.learners):
                o, m = obs[i], masks[i]
                rows = acting[i] if acting is not None else None
                if rows is not None:
                    o, m = o[rows], None if m is None else m[rows]
                if len(o):
                    learner.teach(o, self.teacher.act(o) if m is None else self.teacher.act(o, m), m)
        for learner in self.learners:
            learner.teacher_weight = weight

    def train(self) -> TrainReport:
        """Train until the budget is spent (holding the run's lock), then take a final snapshot."""
        self._lock()
        try:
            background = bool(self.cfg.eval_games) and not self.cfg.eval_inline
            # (stoppable() innermost: a stop tells the learners' update threads first, so nothing waits for them)
            with LearnerTeam(self.learners) as self.team, \
                    Evaluator(self.league, str(self.device), background=background,
                              on_worker=self._write_lock) as self.evaluator, stoppable():
                return self._train()
        finally:
            clear_stop()  # the learners' threads have ended (the team waited for them)
            self.evaluator = None
            self._unlock()

    def _train(self) -> TrainReport:
        cfg = self.cfg
        t0 = self._t0 = time.perf_counter()
        elapsed0 = self.elapsed  # the earlier sessions' time
        start = t0 - self.elapsed
        deadline = self._deadline = start + cfg.minutes * 60 if cfg.minutes is not None else None
        self._steps0 = self.steps
        if self.on_progress:  # at once: a resumed run shows where it stands before its first update
            self.on_progress({"event": "training", "standing": self.standing()})
        for job in self.jobs:  # gauntlets a killed run had asked for (a finished one is not played again)
            self.evaluator.submit(self._job(job))  # type: ignore[union-attr]
        if not self.snapshots:
            self.snapshot("start")  # s0: every learner has an identity in the league from the start
        next_episodes = self.episodes + cfg.snapshot_every if cfg.snapshot_every else None
        next_steps = (self.steps // cfg.snapshot_steps + 1) * cfg.snapshot_steps if cfg.snapshot_steps else None
        try:
            obs = self.games.observe()
        except NonFiniteError as e:
            raise self._stopped(e, self.steps) from None
        line_step = -METRICS_STEPS  # the step of the last metrics line (the first update writes one)
        stats: list[dict[str, float]] = []  # the learners' figures from their last update
        pending: list[GameResult] = []
        board = tensorboard_writer(self.run_dir / "tensorboard") if cfg.tensorboard else None
        with open(self.run_dir / "metrics.jsonl", "a", buffering=1) as metrics:
            while True:
                elapsed = self.elapsed = time.perf_counter() - start
                progress = elapsed / (deadline - start) if deadline else self.steps / cfg.steps
                if progress >= 1.0:
                    break
                if self.curriculum:
                    self._follow_curriculum(progress)
                games = self.games
                acting = games.acting() if games.sequential else None
                if self.teacher is not None:
                    self._teach(obs, acting, progress)
                try:
                    rewards, dones, finished = games.step(self.team.act(obs, games.masks() if games.masked else None))
                    obs = games.observe()
                except NonFiniteError as e:  # before any learner sees it
                    raise self._stopped(e, self.steps + cfg.games) from None
                self.steps += cfg.games
                self.episodes += len(finished)
                pending += finished
                try:  # a learner's numbers (scaled rewards, losses, gradients), before a broken network is saved
                    due = self.team.record(rewards, dones, games.truncated, acting, games.final_obs, games.final_masks)
                    if due:
                        stats = self.team.update(obs, progress)
                except NonFiniteError as e:
                    raise self._stopped(e, self.steps) from None
                if due:
                    if self.steps - line_step >= METRICS_STEPS:  # off-policy learners update every step: a line
                        line_step = self.steps  # and a ledger write per update would be megabytes a minute
                        self._record(pending)
                        pending = []
                        self._report(metrics, board, stats, elapsed)
                        self._collect(self.evaluator.poll())  # type: ignore[union-attr]
                        if self.on_progress:
                            self.on_progress({"event": "training", "standing": self.standing()})
                    spent = (time.perf_counter() >= deadline) if deadline else self.steps >= cfg.steps
                    by_steps = next_steps is not None and self.steps >= next_steps
                    if not spent and (by_steps or (next_episodes is not None and self.episodes >= next_episodes)):
                        self._record(pending)  # the games played before the snapshot are filed before it
                        pending = []
                        self.snapshot("steps" if by_steps else "episodes")  # (the budget's end takes the final)
                        next_episodes = self.episodes + cfg.snapshot_every if cfg.snapshot_every else None
                        if cfg.snapshot_steps:
                            next_steps = (self.steps // cfg.snapshot_steps + 1) * cfg.snapshot_steps
            self._record(pending)
            if stats and self.steps > line_step:  # the run's last figures, whatever the spacing of the lines
                self._report(metrics, board, stats, self.elapsed)
            self._trained = self._train_seconds()
            self.snapshot("final")
        if board is not None:
            board.close()
        t1 = time.perf_counter()
        self._collect(self.evaluator.wait(on_wait=self._waiting))  # type: ignore[union-attr]
        waited = time.perf_counter() - t1
        if not self.records:  # no rating games: name the final snapshots all the same
            self.records = self._records([self.league.get_player(i) for i in self.latest])
        plot = self._plot()
        session = time.perf_counter() - t0
        return TrainReport(cfg.run, self.steps, self.episodes, seconds=elapsed0 + session,
                           eval_games=self.rating_games(), snapshots=self.snapshots, finals=list(self.records),
                           sessions=self.resumes + 1, session_steps=self.steps - self._steps0,
                           session_seconds=session, train_seconds=self._train_seconds(),
                           session_eval_games=self.eval_games,
                           eval_seconds=self.eval_seconds, wait_seconds=waited, plot=plot, **self._best())

    def _stopped(self, e: NonFiniteError, step: int) -> NonFiniteError:
        """The one line that stops a run at a number that is not finite: where it appeared (the game's seat, or the
        learner and its update), and the step the run stopped at. Nothing of it was saved: the last snapshot moment
        came before it."""
        if e.learner is None:
            return NonFiniteError(f"{e}; training stopped at step {step:,}")
        return NonFiniteError(f"learner {self.names[e.learner]}: {e}; training stopped at step {step:,} (the game's "
                              "numbers were finite: a smaller lr or reward_scale may help)")

    def rating_games(self) -> int:
        """Games the run's gauntlets have stored in the ledger, every session's: the ledger, not a count kept in
        the run state, because a gauntlet that finished after the last snapshot moment of a killed session (or was
        cut short in it: its finished matchups are stored, and not played again on resume) is in the ledger only.
        A game counts once, a cooperative comparison as its two episodes."""
        if not self.cfg.eval_games:
            return 0
        run = self.cfg.run
        ids = [p.id for p in self.league.players(env=self.spec.name, kind="snapshot", include_removed=True)
               if p.run == run]
        table = self.league.games(self.spec.name, players=ids, any_seat=True, variant=self.variant, pooled=False)
        gauntlets = []
        for match_id in np.unique(table.match_id).tolist():
            kind, params = self.league.match_info(match_id)
            if kind == "eval" and params.get("gauntlet"):
                gauntlets.append(match_id)
        mine = table.select(np.isin(table.match_id, gauntlets))
        coop = mine.kind == KIND_CODES[COOPERATIVE]
        return int(np.unique(mine.game_id[~coop]).size + 2 * np.unique(mine.game_id[coop]).size)

    def standing(self) -> Standing:
        """Where the run stands now (see :class:`Standing`); meaningful once training has begun."""
        cfg = self.cfg
        session_steps = self.steps - self._steps0
        seconds = self._train_seconds()
        rate = session_steps / seconds if session_steps > 0 and seconds > 0 else None
        done = self.elapsed / (cfg.minutes * 60) if cfg.minutes is not None else self.steps / cfg.steps
        pending = sum(len(names) for names, _, _ in self.jobs)
        core_steps = np.asarray(self.games.core.steps)
        return Standing(
            progress=min(max(done, 0.0), 1.0), steps=self.steps, episodes=self.episodes, playing=cfg.games,
            game_steps=float(core_steps.mean()) if core_steps.size else 0.0, time_limit=self.time_limit,
            snapshots=len(self.snapshots), rated=len(self.snapshots) - pending if cfg.eval_games else 0,
            newest=tuple(self.records) if cfg.eval_games else (), session_steps=session_steps,
            steps_per_second=rate, remaining=self._remaining(rate), ended=self._trained is not None)

    def _train_seconds(self) -> float:
        """Seconds this process has trained (all of it once training has ended), rating games played inline left
        out."""
        if self._trained is not None:
            return self._trained
        return max(time.perf_counter() - self._t0 - (self.eval_seconds if self.cfg.eval_inline else 0.0), 0.0)

    def _best(self) -> dict[str, Any]:
        """The report's ``best``: the run's best snapshot in the ladder fitted now (its margin over the run's next,
        or the snapshots it is tied with), and ``side_bests``: in a game rated per side, the best of each side. None
        of them without rating games."""
        from ..league.ladder import ladder

        if not self.cfg.eval_games:
            return {}
        bests = [r for r in ladder(self.league, self.spec.name, bootstrap=0, variant=self.variant)
                 if r.best and r.run == self.cfg.run]
        return {"best": bests[0] if bests else None, "side_bests": [r for r in bests if r.side is not None]}

    def _plot(self) -> Path | str | None:
        """The run's rating curves as ``runs/<run>/ratings.png`` (as ``marl league plot --run`` draws them); None
        without rating games. A plot that cannot be written does not fail a finished run: the reason is returned."""
        from ..report.plots import write_run_plot

        if not self.cfg.eval_games:
            return None
        try:
            return write_run_plot(self.league, self.cfg.run, self.run_dir / "ratings.png")
        except (MarlError, OSError) as e:
            return f"no plot written ({e})"

    def _waiting(self) -> None:
        if self.on_progress:
            self.on_progress({"event": "evaluating", "snapshots": [n for j in self.jobs for n in j[0]],
                              "games": self.evaluator.games_played,  # type: ignore[union-attr]
                              "standing": self.standing()})

    def _remaining(self, rate: float | None) -> float | None:
        """Seconds left: training at the measured rate for the steps left, then the final gauntlet (at the mean time
        one took so far); inline, a gauntlet for every snapshot still to come. With --minutes: to the deadline.
        None before the rate is known."""
        if self._deadline is not None:
            return max(self._deadline - time.perf_counter(), 0.0)
        if not rate:
            return None
        left = max(self.cfg.steps - self.steps, 0)
        per_event = self.eval_seconds / max(self.eval_events, 1)
        events = 1 + (left // self.cfg.snapshot_steps if self.cfg.snapshot_steps and self.cfg.eval_inline else 0)
        return left / rate + events * per_event
