"""The training loop: learners play endless batched games, snapshot into the league, and rate as they go.

One loop for every algorithm: it steps the shared :class:`SelfPlayGames` (:mod:`.rollouts`: curricula, the teacher,
each learner's slots, its update when its rollout is due), and every ``snapshot_every`` finished games (episodes)
or ``snapshot_steps`` game steps it takes a snapshot moment (:mod:`.state`; in a league, ``--league alphastar``,
each learner takes its own when its role's rule says so, :mod:`.league_roles`):

1. saves each learner as a snapshot file and registers it in the league (``epN``; ``epN-left``/``epN-right`` when
   each seat has its own network), with its parent (the learner's previous snapshot), with the run state that
   resumes from it;
2. rates every new snapshot in a gauntlet (:mod:`selfplay_cli.evaluation.gauntlet`, played where ``--eval`` says,
:mod:`selfplay_cli.evaluation.executors`): its
   predecessor, the other learners' new snapshots, the run's best, older snapshots and the scripted players, in
   seat-swapped pairs;
3. refreshes the matchmaker's pool (:mod:`.opponents`: the run's snapshots).

Training games go to the ledger in batches (so ``marl record --game`` can replay them), filed under the learner's
latest snapshot; the learner has moved on since, so they are kept out of every fitted rating (only the online
Elo, a live view, counts them). The ratings come from the gauntlet games, which the snapshots themselves played.
"""

from __future__ import annotations

import contextlib
import copy
import json
import time
from collections.abc import Callable, Iterator
from typing import Any, TextIO

import numpy as np
import torch

from ..errors import MarlError, NonFiniteError
from ..evaluation.executors import GauntletJob, JobDone, RatingExecutor, open_executor
from ..evaluation.gauntlet_plan import ALL_OLDER
from ..league.store import League
from ..league.variants import variant_key
from ..play.seat_plan import OPPONENT, learner_roles, learner_spaces
from ..play.training_games import SelfPlayGames
from ..policies.bots import league_bots
from ..policies.network import resolve_device
from ..ratings.ladder import DEFAULT_BOOTSTRAP
from ..results import GameResult
from ..signals import clear_stop, deadline, signals_held, stoppable
from .config import TrainConfig, tensorboard_writer
from .curriculum import Curriculum
from .league_roles import LeagueRoles
from .learners import learner_names, make_learners
from .lock import claim, write_lock
from .opponents import Opponents, fixed_opponents
from .progress import BudgetEnd, Heartbeat, SnapshotRecord, Standing, TrainReport
from .ray_rollouts import OFF_POLICY_FRAGMENT, RayRollouts
from .rollouts import Rollouts, load_teacher
from .run_ratings import RunRatings
from .shards import ShardSetup, plan_shards
from .state import Job, RunState, SnapshotMoments
from .team import LearnerTeam

METRICS_STEPS = 8192  # game steps between metrics lines at least (PPO's rollouts are longer: a line an update)


class Trainer:
    """Runs one training run against one league (see the module docstring). It composes the run's learners
    (:mod:`.learners`), state and snapshot moments (:attr:`moments`), its opponents (:attr:`opponents`), its rollouts
    (:attr:`rollouts`), what the ledger says of its ratings (:attr:`ratings`) and, while training, the rating worker
    (:attr:`evaluator`); it keeps the budget, the clock and the metrics."""

    def __init__(self, league: League, cfg: TrainConfig,
                 on_progress: Callable[[dict[str, Any]], None] | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.league, self.cfg = league, cfg
        self.on_progress = on_progress
        self.clock = clock  # seconds, for the budget, the rate and the report (tests pass their own)
        self.spec = spec = cfg.game()
        self.device = resolve_device(cfg.device)
        if self.device.type == "cpu":
            torch.set_num_threads(1)  # small networks: one thread is fastest, the other core runs the games
        if league.home is None:
            raise MarlError("training needs a league home for its snapshot files: pass --home")
        self.run_dir = league.home_path("runs", cfg.run)
        game_cfg = spec.config(**cfg.env_options)
        self.variant = variant_key(spec.name, cfg.env_options)  # where its games are rated: the run's own variant
        league.roster.ensure_bots(spec.name, league_bots(spec))
        self.bot_ids = {p.name: p.id for p in league.roster.players(env=spec.name, kind="bot")}
        self.bot_ids.update(fixed_opponents(league, spec.name, cfg.opponents.bots, self.bot_ids))
        self.time_limit = spec.max_steps(game_cfg)  # the most steps a training game lasts (None: not declared)

        plan = cfg.seat_plan()
        layout = cfg.layout(plan)
        self.names = cfg.league.names() if cfg.league else learner_names(spec.agents, plan.home, cfg.sharing)
        roles = spec.seat_roles(game_cfg)
        seat_roles = roles if len(set(roles)) > 1 else None  # each seat's role, where seats differ
        self.spaces = learner_spaces(spec, spec.seat_spaces(game_cfg), layout, seat_roles)
        learned = learner_roles(layout, seat_roles)  # the role each learner learns (None: one role)
        torch.manual_seed(cfg.seed)
        self.learners, saved = make_learners(cfg, spec, self.spaces, self.device, layout, learned)
        self.roles: LeagueRoles | None = None  # a league's roles (--league alphastar), each learner's first state
        first = None
        if cfg.league is not None:
            shares = [float((layout == i).any(axis=0).mean()) for i in range(len(self.learners))]
            self.roles = LeagueRoles(cfg.league, shares, np.random.default_rng([cfg.seed, 1]))
        if cfg.league is not None or cfg.restart_at_snapshot:  # the weights a learner restarts from
            first = [copy.deepcopy(learner.state_dict()) for learner in self.learners]
        self.state = RunState(latest=[0] * len(self.learners))
        learner_ids = [f"{cfg.run}/{n}" for n in self.names]
        # The 'latest' opponent of learner i: the next learner's live network (with one learner, itself), sampling;
        # one object per learner, so the games it plays share a batch.
        live = [learner.policy(lid, spec.name, greedy=cfg.algo == "dqn")
                for learner, lid in zip(self.learners, learner_ids, strict=True)]
        for policy in live:  # it plays as the learner reads: its seat's last frame_stack observations
            policy.frame_stack = cfg.frame_stack
        self.opponents = Opponents(league, cfg, self.bot_ids, n_seats=len(spec.agents), home=plan.home,
                                   learner_of_game=layout.max(axis=0), seat_roles=seat_roles,
                                   opponent_slots=np.flatnonzero(layout.ravel() == OPPONENT), live=live,
                                   device=str(self.device), roles=self.roles, names=self.names)
        self.learner_ids = learner_ids
        curriculum = Curriculum(cfg.curriculum, spec.name, spec.live_options)
        teacher = load_teacher(league, cfg, self.spaces, str(self.device))
        schedule = cfg.teacher.schedule() if teacher is not None else None
        if teacher is not None:
            for learner in self.learners:
                learner.imitation_capacity = cfg.teacher.states
        first_seed = cfg.seed * 1_000_003
        self.rollouts: Rollouts
        if cfg.executor == "ray":
            self.rollouts = self._ray_rollouts(layout, plan.home, seat_roles, curriculum, teacher, schedule, first_seed)
        else:
            games = SelfPlayGames(spec, cfg.games, layout, learner_ids,
                                  choose_opponents=self._choose if (layout == OPPONENT).any() else None,
                                  env_options=cfg.env_options, first_seed=first_seed, frame_stack=cfg.frame_stack)
            self.rollouts = Rollouts(games, self.learners, curriculum, teacher, schedule)
        self.match_id = league.ledger.create_match(spec.name, "training", {"run": cfg.run,
                                                                           "env_options": cfg.env_options})
        self.moments = SnapshotMoments(league, cfg, spec, self.run_dir, learners=self.learners, names=self.names,
                                       saved=saved, state=self.state, games=self.rollouts, opponents=self.opponents,
                                       device=self.device, roles=self.roles, first=first)
        self.evaluator: RatingExecutor | None = None  # set while training
        self.eval_seconds = 0.0  # time the gauntlets of this process took (beside training, unless inline)
        self._rating_games0 = 0  # the run's rating games in the ledger when this session began (ratings.rating_games())
        self.eval_events = 0  # gauntlets finished in this process
        self._t0 = 0.0  # when this process began training (its clock)
        self._start = 0.0  # when the run would have begun had it trained in this process alone (its clock)
        self._heart: Heartbeat | None = None  # tells the progress at least every second, while this process trains
        self._steps0 = 0  # the run's steps then
        self._deadline: float | None = None  # when a budget in minutes runs out (its clock)
        self._trained: float | None = None  # seconds this process trained, once its training has ended
        self._next_episodes: int | None = None  # the episodes and steps the next snapshot moment is due at
        self._next_steps: int | None = None
        self._updated_step = 0  # the step of the learners' last update (--restart-at-snapshot: its schedule)
        self._budget_end: BudgetEnd | None = None  # --minutes: how the budget ended training
        self.records: list[SnapshotRecord] = []  # the newest snapshots as the ledger rates them
        self.ratings = RunRatings(league, cfg, spec, self.variant, self.bot_ids, self.run_dir)  # (read from the ledger)

    @property
    def games(self) -> SelfPlayGames | None:
        """The training games, where this process steps them (None with ``--executor ray``)."""
        return self.rollouts.games

    def _ray_rollouts(self, layout: np.ndarray, home: tuple[int, ...], seat_roles: tuple[str, ...] | None,
                      curriculum: Curriculum, teacher: Any, schedule: Any, first_seed: int) -> RayRollouts:
        """The run's games on ``--actors`` Ray actors (:mod:`.ray_rollouts`), each built from its share."""
        cfg, league = self.cfg, self.league
        plan = plan_shards(layout, cfg.actors)
        config = cfg.to_dict()
        url = league.url.render_as_string(hide_password=False)
        setups = [ShardSetup(config, layout, k, plan.games[k], plan.positions[k], plan.totals, self.learner_ids,
                             self.spaces, home, seat_roles, url, str(league.home) if league.home else None)
                  for k in range(cfg.actors)]
        fragment = (cfg.ppo.rollout_steps if cfg.algo == "ppo"
                    else cfg.fragment_steps or OFF_POLICY_FRAGMENT)
        return RayRollouts(setups, plan, self.learners, curriculum, teacher, schedule,
                           self.opponents if (layout == OPPONENT).any() else None, seed=cfg.seed,
                           first_seed=first_seed, steps_of=lambda: self.state.steps, fragment_steps=fragment,
                           address=cfg.ray_address, note=self._note)

    def _note(self, line: str) -> None:
        """One line about the run (a rollout actor restarted) to whoever follows its progress."""
        self._tell({"event": "note", "line": line, "standing": self.standing()})

    def _tell(self, event: dict[str, Any]) -> None:
        """One progress event to ``on_progress``: through the heartbeat while it beats (one event at a time)."""
        if self._heart is not None:
            self._heart.tell(event)
        elif self.on_progress is not None:
            self.on_progress(event)

    @contextlib.contextmanager
    def _heartbeat(self) -> Iterator[None]:
        """While the block runs, ``on_progress`` hears where the run stands at least every second
        (:class:`~.progress.Heartbeat`), however long a step, an update or a gauntlet played inline takes."""
        if self.on_progress is None:
            yield
            return
        with Heartbeat(self.on_progress, self._beat) as self._heart:
            try:
                yield
            finally:
                self._heart = None

    def _beat(self) -> dict[str, Any] | None:
        """The heartbeat's event: the standing while training; then, while a local worker or this process plays the
        last gauntlets, the wait for them (a queue's is told by the wait itself: reading it takes the database)."""
        if self._trained is None:
            return {"event": "training", "standing": self.standing()}
        if self.evaluator is not None and not self.evaluator.queued and self.evaluator.left:
            return self._waiting_event()
        return None

    def _choose(self, slots: np.ndarray) -> list[Any]:
        """Opponents for the opponent ``slots`` of the games starting now (:meth:`Opponents.choose`)."""
        return self.opponents.choose(slots, self.state.steps)

    # -- snapshots -------------------------------------------------------------------------------------------
    def snapshot(self, trigger: str = "steps", which: list[int] | None = None) -> None:
        """Take a snapshot moment (:meth:`SnapshotMoments.write`: ``trigger`` is ``start``, ``steps``, ``episodes``,
        ``roles`` (a league's learners ``which`` whose role's rule says so) or ``final``, which names it), then rate
        its snapshots (the final ones against every opponent in full: the run's answer rests on them)."""
        cfg, state = self.cfg, self.state
        if state.snapshots and state.snapshot_step == state.steps:
            return  # nothing played since the last snapshot
        if cfg.opponents.mode == "nash" and state.jobs:  # the earlier moments' gauntlets in first (rarely a wait:
            # they had a whole interval): the mixture the moment solves is then the same in every run of this seed
            self._collect(self.evaluator.wait(on_wait=self._waiting))
        with signals_held():  # Ctrl-C or SIGTERM now would cut the moment: they wait until it is whole
            self.moments.write(trigger, which)
        if cfg.eval_games:
            self.evaluator.submit(self._job(state.jobs[-1]))
        self._collect(self.evaluator.poll())

    def _plan_snapshots(self) -> None:
        """The episodes and steps the next snapshot moment is due at (None: not by that count)."""
        cfg, state = self.cfg, self.state
        if self.roles is not None:  # a league: each learner's role says when it takes its snapshot
            return
        self._next_episodes = state.episodes + cfg.snapshot_every if cfg.snapshot_every else None
        if cfg.snapshot_steps:
            self._next_steps = (state.steps // cfg.snapshot_steps + 1) * cfg.snapshot_steps

    def _snapshot_due(self) -> str | None:
        """The trigger of the snapshot moment due now (``steps`` or ``episodes``), None when none is: the budget's
        end takes the final one instead."""
        state = self.state
        spent = (self.clock() >= self._deadline) if self._deadline else state.steps >= self.cfg.steps
        if spent:
            return None
        if self._next_steps is not None and state.steps >= self._next_steps:
            return "steps"
        if self._next_episodes is not None and state.episodes >= self._next_episodes:
            return "episodes"
        if self.roles is not None and self.roles.due(state.steps, self.opponents.rates):
            return "roles"
        return None

    def _job(self, job: Job) -> GauntletJob:
        """The gauntlet of a moment's snapshots (by name: the run state names them before they have ids)."""
        names, first_seed, full = job
        ids = tuple(self.moments.player_id(n) for n in names)
        # --opponents nash: every earlier snapshot, so the run's payoff matrix is whole and its mixture over them all
        nash = self.cfg.opponents.mode == "nash"
        older = ALL_OLDER if nash else self.cfg.eval_older
        return GauntletJob(ids, first_seed, self.cfg.eval_games, older, full=full,
                           playoff=self.cfg.eval_playoff if full else 0,
                           precision=0.0 if nash else self.cfg.eval_precision)

    def _collect(self, done: list[JobDone]) -> None:
        """Take note of finished gauntlets: each snapshot's record as the ledger has it now, to ``on_progress``."""
        for d in done:
            names = tuple(self.league.roster.get_player(i).full_name for i in d.job.snapshot_ids)
            self.state.jobs = [j for j in self.state.jobs if j[0] != names]
            self.eval_seconds += d.seconds
            self.eval_events += 1
            self.records = self.ratings.records([self.league.roster.get_player(i) for i in d.job.snapshot_ids])
            self._tell({"event": "snapshot", "records": self.records, "standing": self.standing()})

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

    def restore(self) -> str:
        """Continue a stopped or killed run from its latest snapshot moment (:meth:`SnapshotMoments.restore`);
        returns a line saying from where. The run's lock is taken before anything is read: a live process still
        training this run keeps it."""
        self._lock()
        return self.moments.restore()

    # -- the loop --------------------------------------------------------------------------------------------
    def _report(self, metrics: TextIO, board: Any, stats: list[dict[str, float]], elapsed: float) -> None:
        """One line of metrics (and TensorBoard scalars): counters, curriculum values, the learners' last update,
        the latest rating games' scores."""
        steps = self.state.steps
        line = {"step": steps, "episodes": self.state.episodes, "seconds": round(elapsed, 2),
                "steps_per_second": round(steps / max(elapsed, 1e-9)),
                **{f"curriculum/{k}": round(v, 5) for k, v in self.rollouts.lesson.items()},
                **{f"{self.names[i]}/{k}": round(v, 5) for i, s in enumerate(stats) for k, v in s.items()}}
        for rec in self.records:
            line.update({f"eval/{rec.learner}/{bot}": round(rec.score(bot), 4) for bot in rec.vs})
        line.update(self.opponents.nash_metrics())
        metrics.write(json.dumps(line) + "\n")
        if board is not None:
            for key, value in line.items():
                if key != "step" and isinstance(value, int | float):  # (numbers only: nash/weights is a dict)
                    board.add_scalar(key, value, global_step=steps)

    def _file_games(self, finished: list[GameResult]) -> None:
        """File finished training games in the ledger, each learner as its latest snapshot."""
        learner_players = {lid: self.state.latest[i] for i, lid in enumerate(self.learner_ids)}
        self.opponents.file_games(finished, learner_players, self.match_id)

    def train(self) -> TrainReport:
        """Train until the budget is spent (holding the run's lock), then take a final snapshot."""
        self._lock()
        cfg = self.cfg
        try:
            # (stoppable() innermost: a stop tells the learners' update threads first, so nothing waits for them)
            with LearnerTeam(self.learners) as self.team, \
                    open_executor(self.league, cfg.eval, cfg.run, str(self.device), games=cfg.eval_games,
                                  wait=cfg.eval_wait, actors=cfg.eval_actors, address=cfg.ray_address,
                                  on_worker=self._write_lock) as self.evaluator, stoppable():
                return self._train()
        finally:
            clear_stop()  # the learners' threads have ended (the team waited for them)
            self.evaluator = None
            self.rollouts.close()
            self._unlock()

    def _train(self) -> TrainReport:
        """Begin (the gauntlets a killed session asked for, the first snapshot), play until the budget is spent,
        take the final snapshot, wait for the last gauntlets, and report."""
        cfg, state = self.cfg, self.state
        t0 = self._t0 = self.clock()
        elapsed0 = state.elapsed  # the earlier sessions' time
        start = self._start = t0 - state.elapsed
        self._deadline = start + cfg.minutes * 60 if cfg.minutes is not None else None
        self._steps0 = state.steps
        # (before the gauntlets it owes: a killed session's finished one is played again, storing nothing new)
        self._rating_games0 = self.ratings.rating_games()
        with self._heartbeat():
            return self._session(start, elapsed0)

    def _session(self, start: float, elapsed0: float) -> TrainReport:
        """:meth:`_train` from its first progress event on (the run's clock started at ``start``; ``elapsed0``: the
        earlier sessions' time)."""
        cfg, state, t0 = self.cfg, self.state, self._t0
        self._tell({"event": "training", "standing": self.standing()})  # at once: a resumed run shows where it
        # stands before its first update
        for job in state.jobs:  # gauntlets a killed run had asked for (a finished one is not played again)
            self.evaluator.submit(self._job(job))
        if not state.snapshots:
            if cfg.init_plan:  # --init-from: a run starting (not a resumed one: its own state won)
                self._start_from()
            self.snapshot("start")  # s0: every learner has an identity in the league from the start
        self._plan_snapshots()
        board = tensorboard_writer(self.run_dir / "tensorboard") if cfg.tensorboard else None
        with open(self.run_dir / "metrics.jsonl", "a", buffering=1) as metrics:
            with deadline(self._deadline, self.clock):  # (an update under way at it ends at its next minibatch)
                self._play(start, metrics, board)
            if self._deadline is not None:
                self._budget_end = BudgetEnd.of(cfg.minutes * 60, self.clock() - self._deadline,
                                                dict(zip(self.names, self.learners, strict=True)),
                                                state.steps - max(self._updated_step, self._steps0))
            state.elapsed = self.clock() - start
            self._trained = self._train_seconds()
            self._check_heart()
            self.snapshot("final")
        if board is not None:
            board.close()
        t1 = self.clock()
        self._collect(self._final_wait())
        waited = self.clock() - t1
        self._check_heart()
        # the final snapshots and the best as the ledger has them now, as `marl league ladder` shows them (its default
        # intervals: one claim, one figure)
        final = self.ratings.ladder(DEFAULT_BOOTSTRAP)
        self.records = self.ratings.records([self.league.roster.get_player(i) for i in state.latest], final)
        plot = self.ratings.plot()
        session = self.clock() - t0
        rating_games = self.ratings.rating_games()
        return TrainReport(cfg.run, state.steps, state.episodes, seconds=elapsed0 + session,
                           eval_games=rating_games, snapshots=state.snapshots, finals=list(self.records),
                           sessions=state.resumes + 1, session_steps=state.steps - self._steps0,
                           session_seconds=session, train_seconds=self._train_seconds(),
                           session_eval_games=rating_games - self._rating_games0,
                           eval_seconds=self.eval_seconds, wait_seconds=waited, plot=plot,
                           rating_left=len(state.jobs), nash=self._nash(), rating=bool(cfg.eval_games),
                           budget_end=self._budget_end, same_weights=self.ratings.same_weights(),
                           **self.ratings.best(final))

    def _start_from(self) -> None:
        """``--init-from``: each learner starts from its snapshot of the run's ``init_plan`` (which is then its first
        snapshot's parent, and the weights a restart returns it to), said in the first metrics line."""
        from .init_from import load_init

        self.moments.parents = load_init(self.league, self.cfg, self.learners, self.names)
        if self.moments.first is not None:
            self.moments.first = [copy.deepcopy(learner.state_dict()) for learner in self.learners]
        self.run_dir.mkdir(parents=True, exist_ok=True)
        with open(self.run_dir / "metrics.jsonl", "a") as metrics:
            metrics.write(json.dumps({"step": self.state.steps, "init_from": self.cfg.init_plan}) + "\n")

    def _play(self, start: float, metrics: TextIO, board: Any) -> None:
        """The games and updates until the budget is spent (the run's clock started at ``start``): a metrics line
        at most every :data:`METRICS_STEPS` game steps (at an update), snapshot moments as they fall due, the
        training games filed in the ledger before each moment and at the end."""
        cfg, state = self.cfg, self.state
        try:
            obs = self.rollouts.observe()
        except NonFiniteError as e:
            raise self._stopped(e, state.steps) from None
        line_step = -METRICS_STEPS  # the step of the last metrics line (the first update writes one)
        stats: list[dict[str, float]] = []  # the learners' figures from their last update
        pending: list[GameResult] = []
        while True:
            elapsed = state.elapsed = self.clock() - start
            progress = elapsed / (self._deadline - start) if self._deadline else state.steps / cfg.steps
            if progress >= 1.0:
                break
            try:
                step = self.rollouts.step(self.team, obs, progress)
            except NonFiniteError as e:  # before any learner sees it
                raise self._stopped(e, state.steps + cfg.games) from None
            obs = step.obs
            state.steps += cfg.games
            state.episodes += len(step.finished)
            pending += step.finished
            try:  # a learner's numbers (scaled rewards, losses, gradients), before a broken network is saved
                updated = self.rollouts.learn(self.team, step, self._learning(progress))
            except NonFiniteError as e:
                raise self._stopped(e, state.steps) from None
            if updated is None:
                continue
            self._updated_step = state.steps
            stats = updated
            self._check_heart()
            if state.steps - line_step >= METRICS_STEPS:  # off-policy learners update every step: a line and a
                line_step = state.steps  # ledger write per update would be megabytes a minute
                self._file_games(pending)
                pending = []
                self._report(metrics, board, stats, elapsed)
                self._collect(self.evaluator.poll())
                self._tell({"event": "training", "standing": self.standing()})
            trigger = self._snapshot_due()
            if trigger is not None:
                self._file_games(pending)  # the games played before the snapshot are filed before it
                pending = []
                due = self.roles.due(state.steps, self.opponents.rates) if self.roles and trigger == "roles" else None
                if due != []:  # (a league's learners: still due with the games just filed)
                    self.snapshot(trigger, due)
                self._plan_snapshots()
        self._file_games(pending)
        if stats and state.steps > line_step:  # the run's last figures, whatever the spacing of the lines
            self._report(metrics, board, stats, state.elapsed)

    def _check_heart(self) -> None:
        """Raise here what the heartbeat's thread met telling the progress (a display that failed)."""
        if self._heart is not None:
            self._heart.check()

    def _learning(self, progress: float) -> float:
        """The learners' progress (their learning rate's schedule): the run's, or with ``--restart-at-snapshot`` the
        oracle's own, from its restart to its next snapshot, so each new best response learns as the first did. It is
        taken where the update's data began (the step of the learners' last update, or of the restart): an interval
        shorter than one PPO rollout still learns at the full rate, not at a rate annealed to 0."""
        cfg, state = self.cfg, self.state
        if cfg.restart_at_snapshot and cfg.snapshot_steps:
            begun = max(self._updated_step, state.snapshot_step)
            return min(1.0, (begun - state.snapshot_step) / cfg.snapshot_steps)
        return progress

    def _stopped(self, e: NonFiniteError, step: int) -> NonFiniteError:
        """The one line that stops a run at a number that is not finite: where it appeared (the game's seat, or the
        learner and its update), and the step the run stopped at. Nothing of it was saved: the last snapshot moment
        came before it."""
        if e.learner is None:
            return NonFiniteError(f"{e}; training stopped at step {step:,}")
        return NonFiniteError(f"learner {self.names[e.learner]}: {e}; training stopped at step {step:,} (the game's "
                              "numbers were finite: a smaller lr or reward_scale may help)")

    def standing(self) -> Standing:
        """Where the run stands now (see :class:`Standing`); meaningful once training has begun."""
        cfg = self.cfg
        session_steps = self.state.steps - self._steps0
        seconds = self._train_seconds()
        rate = session_steps / seconds if session_steps > 0 and seconds > 0 else None
        if cfg.minutes is not None:  # the time spent, as the clock has it now while training
            elapsed = self.clock() - self._start if self._t0 and self._trained is None else self.state.elapsed
            done = elapsed / (cfg.minutes * 60)
        else:
            done = self.state.steps / cfg.steps
        pending = sum(len(names) for names, _, _ in self.state.jobs)
        core_steps = self.rollouts.game_steps()
        return Standing(
            progress=min(max(done, 0.0), 1.0), steps=self.state.steps, episodes=self.state.episodes, playing=cfg.games,
            game_steps=float(core_steps.mean()) if core_steps.size else 0.0, time_limit=self.time_limit,
            snapshots=len(self.state.snapshots), rated=len(self.state.snapshots) - pending if cfg.eval_games else 0,
            newest=tuple(self.records) if cfg.eval_games else (), session_steps=session_steps,
            steps_per_second=rate, remaining=self._remaining(rate), ended=self._trained is not None)

    def _nash(self) -> dict[str, float] | None:
        """``--opponents nash``: the run's Nash mixture as the ledger has it at the end (full name -> weight); None
        in other modes, or without one."""
        if self.cfg.opponents.mode != "nash":
            return None
        self.opponents.resolve_nash(self.state.steps)
        return None if self.opponents.nash is None else self.opponents.nash.by_name()

    def _train_seconds(self) -> float:
        """Seconds this process has trained (all of it once training has ended), rating games played inline left
        out."""
        if self._trained is not None:
            return self._trained
        return max(self.clock() - self._t0 - (self.eval_seconds if self.cfg.eval_inline else 0.0), 0.0)

    def _final_wait(self) -> list[JobDone]:
        """Wait for the last gauntlets. Ctrl-C meanwhile stops the wait, not the run: training is over and kept, and
        the gauntlets not played go on the league's queue as ``--no-wait`` leaves them (where they cannot, inline, the
        Ctrl-C stops the run as anywhere else)."""
        try:
            return self.evaluator.wait(on_wait=self._waiting)
        except KeyboardInterrupt:
            with signals_held():  # (a second Ctrl-C while the jobs are handed over waits for them)
                done = self.evaluator.leave()
            if done is None:
                raise
            return done

    def _waiting(self, done: list[JobDone]) -> None:
        """A look during a wait for gauntlets: those ``done`` since the last are reported at once (their rated lines
        come as each finishes, not all at the end), then where the wait stands, while gauntlets are left. (The
        executor holds a Ctrl-C meanwhile: handed over, the jobs are the run's to note, no longer its to leave.)"""
        self._collect(done)
        if self.on_progress and self.evaluator is not None and self.evaluator.left:
            self._tell(self._waiting_event())

    def _waiting_event(self) -> dict[str, Any]:
        """The wait for the last gauntlets: the snapshots they rate, how many are left, the games played so far."""
        evaluator = self.evaluator
        assert evaluator is not None
        return {"event": "evaluating", "snapshots": [n for j in self.state.jobs for n in j[0]],
                "gauntlets": evaluator.left, "games": evaluator.games_played, "queue": evaluator.queue_standing(),
                "standing": self.standing()}

    def _remaining(self, rate: float | None) -> float | None:
        """Seconds left: training at the measured rate for the steps left, then the final gauntlet (at the mean time
        one took so far); inline, a gauntlet for every snapshot still to come. With --minutes: to the deadline.
        None before the rate is known, and once training has ended (what is left then is the wait for gauntlets, whose
        length is not known: the progress says how many are left)."""
        if self._trained is not None:
            return None
        if self._deadline is not None:
            return max(self._deadline - self.clock(), 0.0)
        if not rate:
            return None
        left = max(self.cfg.steps - self.state.steps, 0)
        per_event = self.eval_seconds / max(self.eval_events, 1)
        events = 1 + (left // self.cfg.snapshot_steps if self.cfg.snapshot_steps and self.cfg.eval_inline else 0)
        return left / rate + events * per_event
