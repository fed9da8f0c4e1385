"""A run's training games on Ray actors (``marl train --executor ray --actors N [--ray-address ADDR]``).

The learners stay in the trainer's process (on ``--device cuda`` where there is one); the games are split between N
actors (:mod:`.shards`: contiguous game ranges), each stepping its share with copies of the learners. A *fragment*
is ``steps`` steps of every game: the trainer puts the learners' acting state (weights; PPO's generator) in Ray's
object store once, every actor plays its share and sends back what the learners need, and the trainer hands the
learners each step in turn (``learner.take`` in place of ``act``), so its loop, snapshot moments, gauntlets and
ledger are the local run's.

* **PPO** is synchronous: a fragment is one rollout, collected with the weights it updates, so with the same seed the
  run is the local run (game seeds per slot, draws for the whole batch, fragments taken in actor order).
* **SAC and DQN** feed their replay from fragments of ``--fragment-steps`` (default 16) steps; the next fragment is
  under way while the trainer learns from the last, so an actor's weights are at most one fragment of updates old.
* **Faults**: an actor that dies is restarted by Ray (``max_restarts``); its fragment is collected again, from fresh
  games, and the run goes on after one line through ``note``. A task that fails (a game that gives NaN) raises its
  own error.
* **Opponents** travel by league id: an actor loads a snapshot from the league (checked against its sha256, or
  fetched by hash), keeping a bounded cache (:class:`~.opponents.PolicyCache`).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import MarlError, MarlIOError
from ..policies import Policy
from .curriculum import Curriculum, Schedule
from .opponents import Opponents
from .rollouts import Rollouts, Step
from .shards import Fragment, RolloutShard, ShardPlan, ShardSetup
from .team import LearnerTeam

MAX_RESTARTS = 4  # times Ray restarts an actor that died before the run gives up on it
ACTOR_START_SECONDS = 120.0  # how long the actors may take to be placed and built
OFF_POLICY_FRAGMENT = 16  # SAC, DQN: steps of every game per fragment (--fragment-steps 0)


def noise_seed(seed: int, learner: int, fragment: int) -> int:
    """The seed of an off-policy learner's draws in one fragment: every actor draws the same stream (its rows of the
    whole batch's draws), so the run does not depend on how the games are split."""
    return int(np.random.SeedSequence([seed, learner, fragment]).generate_state(1)[0])


class RayRollouts(Rollouts):
    """The training games of one run on Ray actors (see the module docstring); the calls of :class:`Rollouts`."""

    def __init__(self, setups: list[ShardSetup], plan: ShardPlan, learners: list[Any], curriculum: Curriculum,
                 teacher: Policy | None, teacher_schedule: Schedule | None, opponents: Opponents | None, *,
                 seed: int, first_seed: int, steps_of: Callable[[], int], fragment_steps: int,
                 address: str = "", note: Callable[[str], None] | None = None) -> None:
        from ..ray_support import check_local_actors, connect, machine_cores, ray_module

        super().__init__(None, learners, curriculum, teacher, teacher_schedule)
        check_local_actors(len(setups), "--actors", address)
        self._started = connect(address, num_cpus=max(machine_cores(), len(setups) + 1))
        self.ray = ray = ray_module()
        self.plan, self.opponents, self.seed = plan, opponents, seed
        self.steps_of = steps_of  # the run's steps now (--swap-every draws by them)
        self.note = note or (lambda line: None)
        self.synchronous = all(getattr(learner, "synchronous", False) for learner in learners)
        # bit for bit the local run: learners on the CPU, as the actors are (a CUDA generator and CUDA's floats
        # cannot be repeated there: the actors then draw streams of their own, seeded per fragment)
        self.exact = self.synchronous and all(str(getattr(learner, "device", "cpu")).startswith("cpu")
                                              for learner in learners)
        self.fragment_steps = fragment_steps
        actor = ray.remote(num_cpus=1, max_restarts=MAX_RESTARTS, max_task_retries=0)(RolloutShard)
        self.actors = []
        try:  # whatever stops the start (Ctrl-C, SIGTERM while the actors are placed), the actors end with it
            for setup in setups:
                self.actors.append(actor.remote(setup))
            self._ready(address)
        except BaseException:
            self.close()
            raise
        self._next_seed = first_seed
        self._restart: list[int | None] = [first_seed] * len(self.actors)  # each actor's next (re)start, if due
        self._restarts = 0
        self._fragments = 0
        self._fragment: Fragment | None = None
        self._t = 0
        self._inflight: list[tuple[Any, Any, dict[str, Any]]] | None = None
        self._core_steps = np.zeros(sum(s.game_ids.size for s in setups), dtype=np.int64)
        # where the time goes (benchmarks/ray_rollouts.py): actors' own stepping, and the rest of waiting for them
        self.actor_seconds = 0.0  # per fragment, the slowest actor's
        self.wait_seconds = 0.0
        self.merge_seconds = 0.0
        self.actor_peaks: list[int] = []  # each actor's peak memory (bytes), read as the run ends

    # -- what the run reads of its games ----------------------------------------------------------------------
    @property
    def next_seed(self) -> int:
        return self._next_seed

    @next_seed.setter
    def next_seed(self, value: int) -> None:
        self._next_seed = value

    def restart_all(self) -> None:
        self._restart = [self._next_seed] * len(self.actors)
        self._fragment = None
        self._inflight = None

    def game_steps(self) -> np.ndarray:
        return self._core_steps

    def observe(self) -> None:
        return None

    def _ready(self, address: str) -> None:
        """Wait until every actor is built (Ray places each on a core of its own); one line when the cluster has no
        room for them, or an actor cannot be built there (marl not installed on a node)."""
        from ray.exceptions import GetTimeoutError, RayActorError, RayTaskError

        try:
            self.ray.get([a.pid.remote() for a in self.actors], timeout=ACTOR_START_SECONDS)
        except GetTimeoutError:
            free = self.ray.available_resources().get("CPU", 0)
            self.close()
            raise MarlIOError(f"Ray{' at ' + address if address else ''} has no room for {len(self.plan.games)} "
                              f"rollout actors of one CPU each ({free:g} CPUs free after "
                              f"{ACTOR_START_SECONDS:.0f} s): fewer --actors, or more machines") from None
        except (RayActorError, RayTaskError) as e:
            self.close()
            raise MarlError(f"a rollout actor could not start: {str(e).strip().splitlines()[-1][:300]} (is marl "
                            "installed on every machine of the cluster?)") from None

    def close(self) -> None:
        """End the actors (and Ray, when this run started it), their peak memory read first."""
        if self.actors:
            with contextlib.suppress(Exception):  # (an actor that cannot answer, or not yet placed, has no figure)
                self.actor_peaks = self.peak_memory(timeout=10.0)
        for actor in self.actors:
            self.ray.kill(actor)
        self.actors = []
        if self._started:
            from ..ray_support import shutdown

            shutdown()
            self._started = False

    def actor_pids(self) -> list[int]:
        return [int(pid) for pid in self.ray.get([a.pid.remote() for a in self.actors])]

    def peak_memory(self, timeout: float | None = None) -> list[int]:
        """Each actor's peak resident memory in bytes (Ray's ``GetTimeoutError`` past ``timeout`` seconds)."""
        return [int(m) for m in self.ray.get([a.peak_memory.remote() for a in self.actors], timeout=timeout)]

    def _await_restart(self, k: int) -> None:
        """Wait until Ray has restarted actor ``k`` (a new process: it imports marl and torch again); one line when
        it is not back within :data:`ACTOR_START_SECONDS` (its restarts used up, or no room for it)."""
        from ray.exceptions import GetTimeoutError, RayActorError

        deadline = time.perf_counter() + ACTOR_START_SECONDS
        while True:
            try:
                self.ray.get(self.actors[k].pid.remote(), timeout=max(deadline - time.perf_counter(), 0.1))
                return
            except (GetTimeoutError, RayActorError):  # (ActorUnavailableError among them: it is restarting)
                if time.perf_counter() > deadline:
                    raise MarlIOError(f"rollout actor {k + 1} was not restarted within {ACTOR_START_SECONDS:.0f} s; "
                                      "the run stops (resume it with marl train --resume)") from None
                time.sleep(0.2)

    # -- a step ---------------------------------------------------------------------------------------------
    def step(self, team: LearnerTeam, obs: Any, progress: float) -> Step:
        """The next step of every game, from the current fragment (a new one when it is used up): the learners take
        the actors' decisions as their own."""
        if self._fragment is None or self._t == self._fragment.steps:
            self._fragment = self._fetch(progress)
            self._t = 0
        f, t = self._fragment, self._t
        self._t += 1
        seen, masks, acting = f.obs(t), f.masks(t), f.acting(t)
        if self.teacher is not None:
            self._teach(seen, masks, acting, progress)
        team.take(seen, f.taken(t))
        truncated, final_obs, final_masks = f.cut(t)
        return Step(f.obs(t + 1), f.rewards(t), f.dones(t), f.finished(t), acting, truncated, final_obs,
                    final_masks)

    def _fetch(self, progress: float) -> Fragment:
        """The next fragment: the one under way (off-policy), or one asked for now with the learners as they are;
        off-policy, the one after it is asked for before this one is handed over."""
        if self.curriculum:
            self.lesson = self.curriculum.values(progress)
        if self._inflight is None:
            self._inflight = self._submit()
        pieces = self._gather(self._inflight)
        self._inflight = None if self.synchronous else self._submit()
        t0 = time.perf_counter()
        fragment = Fragment.merge(self.plan, pieces)
        for k, piece in enumerate(pieces):
            self._core_steps[self.plan.games[k]] = piece["core_steps"]
            if self.opponents is not None and piece["players"]:
                self.opponents.know_players(piece["players"])
        if self.exact:  # the actors drew the whole batch's noise: the learner's generator is where theirs are
            for learner, state in zip(self.learners, pieces[0]["gen"], strict=True):
                if state is not None:
                    learner.load_acting_state({"gen": state})
        self.merge_seconds += time.perf_counter() - t0
        return fragment

    def _submit(self) -> list[tuple[Any, Any, dict[str, Any]]]:
        """Ask every actor for its share of the next fragment."""
        steps = self.fragment_steps
        states = [learner.acting_state() for learner in self.learners]
        if not self.exact:
            for i, state in enumerate(states):
                state.pop("gen", None)
                state["noise_seed"] = noise_seed(self.seed, i, self._fragments)
        self._fragments += 1
        ref = self.ray.put(states)
        table = self.opponents.shard_table(self.steps_of()) if self.opponents is not None else None
        out = []
        for k, actor in enumerate(self.actors):
            msg = {"steps": steps, "lesson": dict(self.lesson), "opponents": table, "restart": self._restart[k]}
            self._restart[k] = None
            out.append((actor.collect.remote(ref, msg), ref, msg))
        return out

    def _gather(self, inflight: list[tuple[Any, Any, dict[str, Any]]]) -> list[dict[str, Any]]:
        """Every actor's piece, in actor order. An actor that died is restarted by Ray and asked again (its games
        afresh, from a seed range of their own), said in one line; a failure inside a fragment is raised as the
        error it is."""
        from ray.exceptions import RayActorError, RayTaskError

        t0 = time.perf_counter()
        pieces = []
        for k, (ref, states, msg) in enumerate(inflight):
            tries = 0
            while True:
                try:
                    piece = self.ray.get(ref)
                    break
                except RayTaskError as e:
                    cause = getattr(e, "cause", None)
                    if isinstance(cause, MarlError):
                        raise cause from None
                    raise MarlError(f"rollout actor {k + 1}: {cause or e}") from None
                except RayActorError as e:
                    tries += 1
                    if tries > MAX_RESTARTS:
                        raise MarlIOError(f"rollout actor {k + 1} of {len(self.actors)} died {tries} times in one "
                                          "fragment; the run stops (resume it with marl train --resume)") from None
                    self._restarts += 1
                    reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                    self.note(f"rollout actor {k + 1} of {len(self.actors)} died ({reason[:100]}); Ray restarts it "
                              "and its share of the fragment is collected again from fresh games")
                    self._await_restart(k)
                    msg = dict(msg, restart=self._next_seed + (self._restarts << 36))
                    ref = self.actors[k].collect.remote(states, msg)
            pieces.append(piece)
        self.actor_seconds += max(float(p["seconds"]) for p in pieces)
        self.wait_seconds += time.perf_counter() - t0
        return pieces
