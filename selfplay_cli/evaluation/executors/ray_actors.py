"""A run's gauntlets on Ray actors (``marl train --eval ray``): the league's work queue as ``--eval remote`` uses it
(:class:`~.remote.RemoteEvaluator`: each snapshot moment's gauntlet a job of the run's batch ``run:<run>``, chained
to the one before, waited for at the run's end), played by ``--eval-actors`` queue workers on Ray actors started for
the run. Each actor runs ``marl worker``'s loop (:func:`selfplay_cli.evaluation.worker.run_worker`) on the run's batch
alone, against the league's database, and is listed among the league's workers (``marl queue``) as ``ray@<host>:<pid>``;
the games are those any worker, or the local rating worker, plays (one function plays a gauntlet wherever it is played).

Where the actors run: a SQLite league is a file on this machine, so they are placed on this machine's Ray node; any
other database (PostgreSQL) is reached by its URL from every node, so they are spread over the cluster, and the
snapshots they play come from the league by their sha256 where the node has no copy of the league home
(:func:`selfplay_cli.players.files.snapshot_path`), as every worker's do. They play on the CPU.

How they end: when the run's gauntlets are all done, and however the run ends (finished, Ctrl-C or SIGTERM, an
error), each actor is told to stop (:meth:`RatingActor.stop`, answered on the actor's second thread while its loop
runs on the first), which its loop reads as its ``stop()``: the job in play goes back to the queue at once and the
worker's row is marked stopped, as Ctrl-C does to ``marl worker``. (Not ``ray.cancel`` on the loop: a loop cancelled
before the actor had started it kept the actor's later calls waiting.) An actor whose
loop has not left within :data:`STOP_SECONDS` is ended with ``ray.kill`` (the last resort), and its job handed back
by this process. A driver killed with SIGKILL cannot ask: the actors are not detached (``lifetime=None``), so Ray
ends them with the driver that owns them (with Ray started by the run, Ray's own processes end with the driver and
its actors with them: ``tests/test_eval_ray.py`` kills a trainer and sees its actor's process end); the job one
held is handed back by the resumed run as it starts (or goes back to the queue when its lease lapses). That is why
the run's lock names no process for them (it names the local rating worker, which a resume must end itself), and
also why they cannot be named there: on a cluster they are processes of other machines.

An actor that dies (its process killed, its node lost) or whose loop fails is said in one line, its job goes back to
the queue at once, and another actor takes its place (up to :data:`MAX_REPLACED` in a run; then the others, or this
process at the run's end as with ``--eval remote`` when no worker takes the run's jobs, play its share). Nothing an
actor writes reaches this process's stdout (``--json`` keeps it for the JSON alone): the actors write to their
stderr, which the run does not forward either (:func:`~.ray_support.connect`: ``log_to_driver=False``).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from ...ray_support import RayConnection, check_local_actors, ray_module
from .base import JobDone
from .queue_workers import RemoteEvaluator

__all__ = ["ACTOR_ROLE", "MAX_REPLACED", "RATING_ACTOR_CPUS", "START_SECONDS", "STOP_SECONDS", "RatingActor",
           "RayEvaluator"]

RATING_ACTOR_CPUS = 0
"""The CPUs each rating actor asks Ray for: none, so that it is scheduled beside the rollout actors whatever they
take. Ray started for a run counts this machine's cores, and the rollout actors of ``--executor ray`` may ask for
all of them: a rating actor asking for even half a CPU would then wait until training ends. Rating games are a
sideline of training, as the local rating worker is a process beside the trainer that the system shares with it."""
ACTOR_ROLE = "ray"  # the actors' worker names: ray@<host>:<pid>
STOP_SECONDS = 30.0  # an actor told to stop leaves within this long (at its next game report) or is killed
MAX_REPLACED = 3  # actors started in a run in place of ones that died, before their share is left to the others
START_SECONDS = 120.0  # the run's end waits this long for its actors to join the queue (Ray starting a worker process
# and importing torch: seconds) before it plays the gauntlets itself


class RatingActor:
    """One queue worker on a Ray actor (made remote by :class:`RayEvaluator`): ``marl worker`` serving one batch."""

    def __init__(self, url: str, home: str | None, batch: str, games: tuple[str, ...] = ()) -> None:
        os.dup2(2, 1)  # nothing on stdout, even where the driver forwards its workers' output (a Ray started with
        sys.stdout = sys.stderr  # log_to_driver): a --json run's stdout is its JSON alone
        import torch

        from ...envs import admit
        from ...league.store import League
        from ..jobs import worker_name

        for game in games:  # the games of your own the trainer's user named (a job's own names are not admitted)
            admit(game)
        torch.set_num_threads(1)  # one core's worth, beside training (as the local rating worker)
        self.league = League(url, home=home)
        self.batch = batch
        self.worker = worker_name(ACTOR_ROLE)
        self.stopping = threading.Event()

    def name(self) -> str:
        """How the league lists this worker."""
        return self.worker

    def work(self) -> dict[str, Any]:
        """The worker loop on the run's batch until :meth:`stop`; what it did (as ``marl worker --json`` says)."""
        from ..worker import WorkerOptions, run_worker

        try:
            report = run_worker(self.league, WorkerOptions(batches=(self.batch,), name=self.worker),
                                say=lambda line: print(f"marl worker: {line}", file=sys.stderr, flush=True),
                                stop=self.stopping.is_set)
        finally:
            self.league.close()
        return report.to_json()

    def stop(self) -> None:
        """Tell :meth:`work` to leave (before it has begun, too: it then leaves at once)."""
        self.stopping.set()


class RayEvaluator(RemoteEvaluator):
    """``--eval ray``: :class:`RemoteEvaluator`'s queueing and waiting, with ``actors`` queue workers on Ray actors
    started now (Ray joined at ``address``, or started on this machine, or the one already running in this process,
    which is then left running); see the module docstring."""

    def __init__(self, league: Any, run: str, device: str, *, actors: int = 1, address: str = "",
                 note: Callable[[str], None] | None = None, stop_seconds: float = STOP_SECONDS,
                 start_seconds: float = START_SECONDS, **kwargs: Any) -> None:
        super().__init__(league, run, device, wait=True, note=note, **kwargs)
        self.stop_seconds, self.start_seconds = stop_seconds, start_seconds
        self.replaced = 0  # actors started in place of one that died
        self._actors: list[Any] = []
        self._names: list[Any] = []  # each actor's worker name (an object ref, answered at once)
        self._loops: list[Any] = []  # each actor's worker loop (an object ref, ready once the loop has ended)
        check_local_actors(actors, "--eval-actors", address)
        self._take_back()
        self._ray = RayConnection(address)
        self._ray.__enter__()
        try:
            ray = ray_module()
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            if league.is_sqlite:  # the league is a file of this machine
                where: Any = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
            else:
                where = "SPREAD"
            # not detached (lifetime None): owned by this process, the actors end with it however it ends; not
            # restarted by Ray (a restarted actor would be a new worker while its old row still held the job); two
            # threads, so that stop() is answered while work() runs
            self._cls = ray.remote(RatingActor).options(num_cpus=RATING_ACTOR_CPUS, lifetime=None,
                                                        scheduling_strategy=where, max_restarts=0,
                                                        max_concurrency=2)
            for _ in range(actors):
                self._spawn()
        except BaseException:
            self.close()
            raise

    def _take_back(self) -> None:
        """The jobs that the actors of an earlier session of this run still hold, back to the queue now rather than
        when their leases lapse (minutes): those actors ended with their driver (killed), since the run's lock lets
        one process train it at a time, and a run's actors take jobs of its batch alone."""
        for w in self.league.queue.workers(taking=self.batch):
            if w.stopped_at is None and w.serves == (self.batch,) and w.name.startswith(f"{ACTOR_ROLE}@"):
                self.league.queue.stop_worker(w.id, give_back=True)

    def _spawn(self) -> None:
        """Start one actor and its worker loop."""
        home = None if self.league.home is None else str(self.league.home)
        from ...envs.loading import admitted

        actor = self._cls.remote(self.league.url.render_as_string(hide_password=False), home, self.batch, admitted())
        self._actors.append(actor)
        self._names.append(actor.name.remote())
        self._loops.append(actor.work.remote())

    def poll(self) -> list[JobDone]:
        self._check_actors()
        return super().poll()

    def wait(self, on_wait: Callable[[list[JobDone]], None] | None = None) -> list[JobDone]:
        """:meth:`RemoteEvaluator.wait`, once the actors have joined the queue (so the run does not play its
        gauntlets itself merely because they were still starting); then the actors are stopped."""
        since = time.monotonic()
        self._check_actors()  # (a dead actor's worker row would pass for one that serves)
        while self.pending and self._loops and not self.serving() and time.monotonic() - since < self.start_seconds:
            self._tick(on_wait, force=True)
            time.sleep(self.poll_seconds)
            self._check_actors()
        done = super().wait(on_wait)
        if not self.pending:
            self._stop_actors()
        return done

    def _check_actors(self) -> None:
        """An actor whose loop ended (it died, or its loop failed): said in one line, its job back in the queue at
        once, and another actor started in its place, up to :data:`MAX_REPLACED` in a run (then the others, or this
        process at the run's end, play its share)."""
        if not self._loops:
            return
        ray = ray_module()
        ended, _ = ray.wait(self._loops, num_returns=len(self._loops), timeout=0)
        for ref in ended:
            i = self._loops.index(ref)
            try:
                ray.get(ref)
                why = "its loop returned"
            except Exception as e:  # (RayActorError, RayTaskError: the first line says which and why)
                why = (str(e).strip().splitlines() or [type(e).__name__])[0]
            ray.kill(self._actors[i])
            self._release([self._names[i]])
            del self._actors[i], self._names[i], self._loops[i]
            if self.replaced < MAX_REPLACED:
                self.replaced += 1
                self._spawn()
                then = "another is started"
            else:
                then = (f"{MAX_REPLACED} were replaced already, so its share is played by the others, or by this "
                        "process at the run's end")
            self._note(f"a rating actor of this run ended ({why}); its gauntlet went back to the queue and {then}")

    def _stop_actors(self) -> None:
        """Tell every actor's loop to stop (the job in play back to the queue), wait up to :attr:`stop_seconds` for
        the loops to leave, end the actors (``ray.kill``: what is left of an actor whose loop has left is an idle
        process), and hand back the jobs of those whose loops were still in play."""
        if not self._actors:
            return
        ray = ray_module()
        for actor in self._actors:
            actor.stop.remote()
        ready, _ = ray.wait(self._loops, num_returns=len(self._loops), timeout=self.stop_seconds)
        stuck = [name for name, ref in zip(self._names, self._loops, strict=True) if ref not in ready]
        for actor in self._actors:
            ray.kill(actor)  # (an actor whose loop has left holds nothing; one that is stuck: the last resort)
        self._actors, self._names, self._loops = [], [], []
        if stuck:
            self._release(stuck)
            self._note(f"{len(stuck)} rating actor(s) did not stop within {self.stop_seconds:.0f} s and were killed; "
                       "their gauntlets went back to the queue")

    def _release(self, names: list[Any]) -> None:
        """The workers of ended actors (their names' refs) marked stopped, and their jobs back to the queue now (not
        when their leases lapse)."""
        ray = ray_module()
        ready, _ = ray.wait(names, num_returns=len(names), timeout=0)
        gone = set()
        for ref in ready:  # (an actor that never answered never joined the queue)
            with contextlib.suppress(Exception):
                gone.add(ray.get(ref))
        for w in self.league.queue.workers(taking=self.batch):
            if w.name in gone and w.stopped_at is None:
                self.league.queue.stop_worker(w.id, give_back=True)

    def close(self) -> None:
        """Stop the actors (if the wait has not), then leave Ray as it was found."""
        try:
            self._stop_actors()
        finally:
            self._ray.__exit__()

    def __enter__(self) -> RayEvaluator:
        return self
