"""Rollout shards: a share of a run's training games stepped away from the trainer, and their fragments put back
together (``--executor ray``: each shard is a Ray actor, :mod:`.ray_rollouts`).

A run's games are split into contiguous ranges, one per actor (:func:`plan_shards`). An actor (:class:`RolloutShard`)
steps its games with copies of the learners: each fragment it is handed the learners' acting state (weights, and
for PPO the sampling generator), the curriculum's values and the table its games' opponents are drawn from; it
plays ``steps`` steps of every game, each learner copy *deciding* (``learner.decide``: the actions and what the
learner keeps of them, log-probabilities and values for PPO) for the actor's rows of its slots, and sends back
everything the trainer's learner needs to *take* each step as if it had acted itself: observations, masks, the
decisions, rewards, ends, the slots that acted, truncations with their final observations, and the games that
finished. :class:`Fragment` puts the actors' pieces back in the learners' slot order.

Why a split run is the run: a game's seed is a function of its slot and count (:class:`~selfplay_cli.play.
training_games.SelfPlayGames`), and a learner copy draws its noise for the whole batch and keeps its own rows
(:func:`~selfplay_cli.algos.base.padded`), so every actor draws what the trainer alone would have drawn, and the
trainer's PPO adopts the generator state the actors end with. What can still differ from a local run is written in
docs/many-machines.md ("Training on many cores and machines").
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..play.seat_plan import OPPONENT
from ..play.training_games import SelfPlayGames
from ..results import GameResult
from .opponents import PolicyCache
from .win_rates import LATEST_LEARNER


@dataclass(frozen=True)
class ShardPlan:
    """How a run's games are split between ``actors``: ``games[k]`` the global game ids of actor k (a contiguous
    range); ``positions[k][i]`` where actor k's slots of learner i sit in learner i's slot order (its slots are the
    flat ``seat * games + game`` indices it holds, in order); ``totals[i]`` learner i's slot count."""

    games: list[np.ndarray]
    positions: list[list[np.ndarray]]
    totals: list[int]


def plan_shards(layout: np.ndarray, actors: int) -> ShardPlan:
    """Split the games of ``layout`` (learner per ``(seat, game)``, -1 an opponent's) between ``actors``."""
    n_seats, n_games = layout.shape
    if not 1 <= actors <= n_games:
        raise ValueError(f"{actors} actors for {n_games} games")
    n_learners = int(layout.max()) + 1
    slots = [np.flatnonzero(layout.ravel() == i) for i in range(n_learners)]
    games = np.array_split(np.arange(n_games), actors)
    positions = []
    for ids in games:
        local = layout[:, ids]
        mine = []
        for i in range(n_learners):
            seat, g = np.divmod(np.flatnonzero(local.ravel() == i), ids.size)
            mine.append(np.searchsorted(slots[i], seat * n_games + ids[g]))
        positions.append(mine)
    return ShardPlan(games, positions, [s.size for s in slots])


@dataclass
class ShardSetup:
    """What an actor is built from (sent once): the run's configuration (``TrainConfig.to_dict()``), the full
    layout, its games, the learners' ids and spaces, who holds each seat when learners hold every seat (``home``: a
    'latest' opponent's learner), each seat's role where seats differ, the league to load opponents from (its URL,
    and its home where this machine has it) and the actor's index."""

    config: dict[str, Any]
    layout: np.ndarray
    index: int
    game_ids: np.ndarray
    positions: list[np.ndarray]
    totals: list[int]
    learner_ids: list[str]
    spaces: list[Any]
    home: tuple[int, ...]
    seat_roles: tuple[str, ...] | None
    league_url: str
    league_home: str | None


class ShardOpponents:
    """The opponents of an actor's games, drawn from the trainer's table (:meth:`Opponents.shard_table`): per
    learner and role, probabilities over opponent ids, or with --swap-every the id assigned to each slot. League
    players are loaded from the league by id (a snapshot's file checked against its sha256, or its blob fetched by
    hash, as :func:`~selfplay_cli.players.load.load_player` does) and kept in a bounded cache; 'latest' is the actor's
    live copy of the learner."""

    def __init__(self, setup: ShardSetup, live: list[Any], seed: int) -> None:
        self.setup, self.live = setup, live
        self.n_games = setup.layout.shape[1]
        self.learner_of_game = setup.layout.max(axis=0)
        self.rng = np.random.default_rng([seed, setup.index])
        self._table: dict[str, Any] = {}
        self._cdfs: dict[Any, tuple[np.ndarray, np.ndarray]] = {}  # per (learner, role): opponent ids, their cdf
        self.players: dict[str, int] = {}  # policy id in game results -> league player id
        self._league: Any = None
        self._cache = PolicyCache(self._load)

    def _load(self, pid: int) -> Any:
        from ..league.store import League
        from ..players.load import load_player

        if self._league is None:
            self._league = League(self.setup.league_url, home=self.setup.league_home, readonly=True)
        policy = load_player(self._league, self._league.roster.get_player(pid), device="cpu", greedy=False, seed=pid)
        self.players[policy.id] = pid
        return policy

    @property
    def table(self) -> dict[str, Any]:
        return self._table

    @table.setter
    def table(self, table: dict[str, Any]) -> None:
        """The trainer's table of a fragment; its probabilities as cumulative sums, once."""
        self._table = table
        self._cdfs = {}
        for key, probs in table.get("draws", {}).items():
            cdf = np.cumsum(np.fromiter(probs.values(), dtype=np.float64, count=len(probs)))
            self._cdfs[key] = (np.fromiter(probs.keys(), dtype=np.int64, count=len(probs)), cdf / cdf[-1])

    def choose(self, slots: np.ndarray) -> list[Any]:
        """Policies for the opponent ``slots`` (flat ``seat * n + game`` of the actor's ``n`` games) of the games
        starting now."""
        n = self.setup.game_ids.size
        seats, games = np.divmod(slots, n)
        games = self.setup.game_ids[games]
        learners = self.learner_of_game[games]
        if "assigned" in self.table:
            ids = self.table["assigned"][seats * self.n_games + games]
        else:
            roles = self.setup.seat_roles
            ids = np.empty(slots.size, dtype=np.int64)
            for k, (learner, seat) in enumerate(zip(learners.tolist(), seats.tolist(), strict=True)):
                keys, cdf = self._cdfs[(learner, None if roles is None else roles[seat])]
                ids[k] = keys[min(int(np.searchsorted(cdf, self.rng.random(), side="right")), keys.size - 1)]
        return [self.policy(int(pid), int(seat), int(learner))
                for pid, seat, learner in zip(ids, seats, learners, strict=True)]

    def policy(self, pid: int, seat: int, learner: int) -> Any:
        if pid == LATEST_LEARNER:
            home = self.setup.home[seat]
            return self.live[home if home >= 0 else learner]
        return self._cache.get(pid)


def _numpy(x: Any) -> Any:
    """A decision's array as numpy, its own (a mask may be the game's buffer; a tensor is the learner's)."""
    if x is None:
        return None
    return np.array(x) if isinstance(x, np.ndarray) else x.detach().cpu().numpy()


def _stack(rows: list[Any]) -> np.ndarray | None:
    """Per-step arrays as one ``(steps, ...)`` array; None when every step has none. A step without one where others
    have it (a mask) is all True."""
    if all(r is None for r in rows):
        return None
    like = next(r for r in rows if r is not None)
    return np.stack([np.ones_like(like) if r is None else r for r in rows])


class RolloutShard:
    """One actor's games and its copies of the learners (see the module docstring). Built from a
    :class:`ShardSetup`; :meth:`collect` plays one fragment."""

    def __init__(self, setup: ShardSetup) -> None:
        import torch

        from ..envs import admit
        from .config import TrainConfig

        torch.set_num_threads(1)  # small networks: one thread each; the actors are the parallelism
        admit(str(setup.config.get("env", "")))  # the trainer's game, which its user named (the trainer loaded it)
        self.setup = setup
        # (an actor acts on the CPU and writes no metrics, whatever device and TensorBoard the trainer has)
        self.cfg = cfg = TrainConfig.from_dict({**setup.config, "device": "cpu", "tensorboard": False})
        self.spec = cfg.game()
        self.layout = setup.layout[:, setup.game_ids]
        self.learners = self._learners()
        for learner, rows, total in zip(self.learners, setup.positions, setup.totals, strict=True):
            learner.share = (rows, total)
        self.live = [learner.policy(lid, self.spec.name, greedy=cfg.algo == "dqn")
                     for learner, lid in zip(self.learners, setup.learner_ids, strict=True)]
        for policy in self.live:
            policy.frame_stack = cfg.frame_stack
        self.opponents = ShardOpponents(setup, self.live, cfg.seed)
        self.games: SelfPlayGames | None = None  # built by the first fragment (its opponents' table comes with it)
        self.lesson: dict[str, float] = {}

    def _learners(self) -> list[Any]:
        from ..algos import get_learner
        from ..algos.joint import JointLearner
        from .config import learner_setup

        cfg, setup = self.cfg, self.setup
        learner_cls, algo_cfg = get_learner(cfg.algo), getattr(cfg, cfg.algo)
        if cfg.sharing == "sa":
            return [JointLearner(learner_cls, setup.spaces[0], self.spec.n_seats, setup.game_ids.size, algo_cfg,
                                 seed=cfg.seed, device="cpu")]
        setups = [learner_setup(cfg, space) for space in setup.spaces]
        return [learner_cls(seat, int(rows.size), section, seed=cfg.seed + i, device="cpu")
                for i, ((seat, section), rows) in enumerate(zip(setups, setup.positions, strict=True))]

    def pid(self) -> int:
        import os

        return os.getpid()

    def _start(self, seed_base: int) -> None:
        """(Re)start every game of the actor from the seeds' base ``seed_base``."""
        if self.games is not None:
            self.games.next_seed = seed_base
            self.games.restart_all()
            return
        cfg = self.cfg
        self.games = SelfPlayGames(self.spec, self.setup.game_ids.size, self.layout, self.setup.learner_ids,
                                   choose_opponents=self.opponents.choose if (self.layout == OPPONENT).any() else None,
                                   env_options=cfg.env_options, first_seed=seed_base, game_ids=self.setup.game_ids,
                                   total_games=cfg.games, frame_stack=cfg.frame_stack)
        if self.lesson:
            self.games.core.set_options(**self.lesson)

    def collect(self, states: list[dict[str, Any]], msg: dict[str, Any]) -> dict[str, Any]:
        """Play one fragment: ``states`` the learners' acting states; ``msg``: ``steps``, ``lesson`` (the curriculum's
        values), ``opponents`` (the draw table) and ``restart`` (a seeds' base to start every game afresh from, or
        None). Returns the fragment's arrays (see :class:`Fragment`)."""
        t0 = time.perf_counter()
        for learner, state in zip(self.learners, states, strict=True):
            learner.load_acting_state(state)
        if msg.get("opponents") is not None:
            self.opponents.table = msg["opponents"]
        if msg["lesson"] != self.lesson:
            self.lesson = dict(msg["lesson"])
            if self.games is not None and self.lesson:
                self.games.core.set_options(**self.lesson)
        if self.games is None or msg.get("restart") is not None:
            self._start(int(msg["restart"]))
        games = self.games
        assert games is not None
        n = len(self.learners)
        steps = int(msg["steps"])
        obs: list[list[np.ndarray]] = [[] for _ in range(n)]
        masks: list[list[Any]] = [[] for _ in range(n)]
        acting: list[list[Any]] = [[] for _ in range(n)]
        taken: list[list[dict[str, Any]]] = [[] for _ in range(n)]
        rewards: list[list[np.ndarray]] = [[] for _ in range(n)]
        dones: list[list[np.ndarray]] = [[] for _ in range(n)]
        cuts: list[tuple[int, list[Any], list[Any], list[Any]]] = []
        finished: list[tuple[int, GameResult]] = []
        for t in range(steps):
            o = games.observe()
            m = games.masks() if games.masked else [None] * n
            a = games.acting()  # (turn-based games, and games whose agents come and go; else all None)
            decided = [learner.decide(o[i], m[i]) for i, learner in enumerate(self.learners)]
            r, d, done = games.step([played for played, _ in decided])
            for i in range(n):  # copies: a game's core may hand out the same buffers step after step
                obs[i].append(np.array(o[i]))
                masks[i].append(None if m[i] is None else np.array(m[i]))
                acting[i].append(None if a[i] is None else np.array(a[i]))
                taken[i].append({k: _numpy(v) for k, v in decided[i][1].items()})
                rewards[i].append(np.array(r[i]))
                dones[i].append(np.array(d[i]))
            if games.truncated is not None:
                copied = [[None if x is None else np.array(x) for x in part or [None] * n]
                          for part in (games.truncated, games.final_obs, games.final_masks)]
                cuts.append((t, *copied))
            finished += [(t, g) for g in done]
        last = games.observe()
        out = {
            "obs": [np.stack([*obs[i], last[i]]) for i in range(n)],
            "masks": [_stack(masks[i]) for i in range(n)],
            "acting": [_stack(acting[i]) for i in range(n)],
            "taken": [{k: _stack([step[k] for step in taken[i]]) for k in taken[i][0]} for i in range(n)],
            "rewards": [np.stack(rewards[i]) for i in range(n)],
            "dones": [np.stack(dones[i]) for i in range(n)],
            "cuts": cuts, "finished": finished, "core_steps": np.asarray(games.core.steps).copy(),
            "players": dict(self.opponents.players),
            # the rows of the decisions among all of a learner's (SA: one a game, not one a seat)
            "decided": [learner.share for learner in self.learners],
            "gen": [learner.acting_state().get("gen") if getattr(learner, "synchronous", False) else None
                    for learner in self.learners],
            "seconds": time.perf_counter() - t0,
        }
        return out

    def peak_memory(self) -> int:
        """This process's peak resident memory in bytes."""
        import resource
        import sys

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return int(peak if sys.platform == "darwin" else peak * 1024)


@dataclass
class Fragment:
    """The actors' pieces of one fragment in the learners' slot order: per step ``t`` (0 to ``steps - 1``) each
    learner's observations before it (:meth:`obs`; ``obs(steps)`` those after the last), masks, the slots that
    acted, the decisions, rewards, ends, truncations (with final observations and masks) and the games finished."""

    steps: int
    _obs: list[np.ndarray]
    _masks: list[np.ndarray | None]
    _acting: list[np.ndarray | None]
    _taken: list[dict[str, np.ndarray | None]]
    _rewards: list[np.ndarray]
    _dones: list[np.ndarray]
    _cuts: dict[int, tuple[list[Any], list[Any], list[Any]]] = field(default_factory=dict)
    _finished: dict[int, list[GameResult]] = field(default_factory=dict)

    @classmethod
    def merge(cls, plan: ShardPlan, pieces: list[dict[str, Any]]) -> Fragment:
        """The pieces of actors ``0 .. k-1`` (in :class:`ShardPlan` order) as one fragment."""
        n = len(plan.totals)
        steps = pieces[0]["rewards"][0].shape[0]

        def join(key: str, i: int, sub: str | None = None) -> np.ndarray | None:
            parts = [p[key][i] if sub is None else p[key][i][sub] for p in pieces]
            if all(x is None for x in parts):
                return None
            like = next(x for x in parts if x is not None)
            rows = ([p["decided"][i][0] for p in pieces], pieces[0]["decided"][i][1]) if sub is not None else \
                ([plan.positions[k][i] for k in range(len(pieces))], plan.totals[i])
            out = np.empty((like.shape[0], rows[1], *like.shape[2:]), dtype=like.dtype)
            for k, x in enumerate(parts):
                out[:, rows[0][k]] = True if x is None else x
            return out

        taken = [{key: join("taken", i, sub=key) for key in pieces[0]["taken"][i]} for i in range(n)]
        by_step: dict[int, dict[int, tuple[list[Any], list[Any], list[Any]]]] = {}
        for k, p in enumerate(pieces):
            for t, trunc, final_obs, final_masks in p["cuts"]:
                by_step.setdefault(t, {})[k] = (trunc, final_obs, final_masks)
        cuts = {t: _join_cut(plan, parts, pieces) for t, parts in by_step.items()}
        finished: dict[int, list[GameResult]] = {}
        for p in pieces:
            for t, g in p["finished"]:
                finished.setdefault(t, []).append(g)
        def per_learner(key: str) -> list[Any]:
            return [join(key, i) for i in range(n)]

        return cls(steps, per_learner("obs"), per_learner("masks"), per_learner("acting"), taken,
                   per_learner("rewards"), per_learner("dones"), cuts, finished)

    def obs(self, t: int) -> list[np.ndarray]:
        return [o[t] for o in self._obs]

    def masks(self, t: int) -> list[np.ndarray | None]:
        return [None if m is None else m[t] for m in self._masks]

    def acting(self, t: int) -> list[np.ndarray | None] | None:
        if all(a is None for a in self._acting):
            return None
        return [None if a is None else a[t] for a in self._acting]

    def taken(self, t: int) -> list[dict[str, Any]]:
        return [{k: None if v is None else v[t] for k, v in d.items()} for d in self._taken]

    def rewards(self, t: int) -> list[np.ndarray]:
        return [r[t] for r in self._rewards]

    def dones(self, t: int) -> list[np.ndarray]:
        return [d[t] for d in self._dones]

    def cut(self, t: int) -> tuple[list[Any] | None, list[Any] | None, list[Any] | None]:
        """Truncated slots, final observations and final masks per learner at step ``t`` (None, None, None: none)."""
        return self._cuts.get(t, (None, None, None))

    def finished(self, t: int) -> list[GameResult]:
        return self._finished.get(t, [])


def _join_cut(plan: ShardPlan, parts: dict[int, tuple[list[Any], list[Any], list[Any]]],
              pieces: list[dict[str, Any]]) -> tuple[list[Any], list[Any], list[Any]]:
    """One step's truncations from the actors that had any: per learner, truncated flags over all its slots (False
    where an actor had none), final observations (rows only read where truncated) and final masks."""
    n = len(plan.totals)
    trunc, final_obs, final_masks = [], [], []
    for i in range(n):
        flags = np.zeros(plan.totals[i], dtype=bool)
        obs_rows: np.ndarray | None = None
        mask_rows: np.ndarray | None = None
        for k, (t_k, o_k, m_k) in parts.items():
            pos = plan.positions[k][i]
            flags[pos] = t_k[i]
            if o_k[i] is not None:
                o = np.asarray(o_k[i])
                if obs_rows is None:
                    obs_rows = np.zeros((plan.totals[i], *o.shape[1:]), dtype=o.dtype)
                obs_rows[pos] = o
            if m_k[i] is not None:
                m = np.asarray(m_k[i])
                if mask_rows is None:
                    mask_rows = np.ones((plan.totals[i], *m.shape[1:]), dtype=m.dtype)
                mask_rows[pos] = m
        if obs_rows is None:  # no actor's rows: the observations of another step stand in (never read)
            obs_rows = np.zeros((plan.totals[i], *np.asarray(pieces[0]["obs"][i]).shape[2:]),
                                dtype=np.asarray(pieces[0]["obs"][i]).dtype)
        trunc.append(flags)
        final_obs.append(obs_rows)
        final_masks.append(mask_rows)
    return trunc, final_obs, final_masks
