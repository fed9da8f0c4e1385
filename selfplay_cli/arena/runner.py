"""The batched game runner: plays N games between policies in one batched core.

Training rollouts, evaluation matches and recordings all go through here, so a match, a training episode and a
video of it are the same game. On request it also returns each game's actions (what a replay needs, see
:mod:`selfplay_cli.arena.replay`) and shows every state a game passes through to a hook (what a recording needs).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..envs.registry import BatchedCore
from ..policies import Policy
from .replay import action_dtype, encode_actions

FrameHook = Callable[[BatchedCore, int, int, bool], None]
"""``on_frame(core, slot, game_index, ended)``: see :func:`play`."""
StopRule = Callable[[BatchedCore], np.ndarray]
"""``stop_when(core) -> (n,) bool``: games to end now, as truncated (see :func:`play`)."""


@dataclass(frozen=True)
class Game:
    """One game to play: its seed and, for each seat, the index of the policy that plays it."""

    seed: int
    seats: tuple[int, ...]


@dataclass(frozen=True)
class GameResult:
    """What a finished game leaves in the ledger. ``outcome`` is points per seat: 1 win, 0.5 draw, 0 loss."""

    env: str
    players: tuple[str, ...]
    seed: int
    scores: tuple[int, ...]
    outcome: tuple[float, ...]
    length: int
    truncated: bool
    index: int  # position of the game in the schedule
    actions: bytes | None = None  # encoded (steps, seats) actions, when play() was asked to record them

    def points_of(self, player: str) -> float:
        return sum(o for p, o in zip(self.players, self.outcome, strict=True) if p == player)


def _acting_groups(policies: Sequence[Policy]) -> list[tuple[list[int], Any]]:
    """How the policies act each step: network policies of one architecture together in one
    :class:`~selfplay_cli.policies.bank.NetworkBank` (one batched forward for all of them), any other alone."""
    if not any(getattr(p, "kind", "") == "snapshot" for p in policies):
        return [([i], None) for i in range(len(policies))]
    from ..policies.bank import NetworkBank, bank_groups  # torch, only when networks play

    return [(members, NetworkBank([policies[i] for i in members]) if len(members) > 1 else None)  # type: ignore[misc]
            for members in bank_groups(policies)]


def paired_schedule(n_games: int, first_seed: int = 0, n_policies: int = 2) -> list[Game]:
    """Game pairs: each seed is played once with policy 0 on seat 0 and once with the seats swapped."""
    if n_policies != 2:
        raise ValueError("paired schedules are for two policies")
    games = []
    for i in range(n_games):
        seed = first_seed + i // 2
        games.append(Game(seed, (0, 1) if i % 2 == 0 else (1, 0)))
    return games


class ActionLog:
    """Every step's actions of every slot, kept from the first step of the oldest running game on.

    Steps are appended to a step-major block (one contiguous row per step, a few kilobytes); every ``BLOCK`` steps
    the block is transposed once to slot-major, so a finished game's actions are a few contiguous pieces to join
    rather than a gather across the whole log (which cost a match a fifth of its speed). Blocks that no running
    game reaches back to are dropped, so the log's size follows the longest game, not the schedule.
    """

    BLOCK = 256

    def __init__(self, n_seats: int, n_slots: int, dtype: np.dtype) -> None:
        self.block = np.zeros((self.BLOCK, n_seats, n_slots), dtype=dtype)  # the current block, step-major
        self.filled = 0
        self.blocks: list[tuple[int, np.ndarray]] = []  # (first step, (slots, seats, BLOCK) slot-major)
        self.now = 0  # steps appended so far
        self.start = np.zeros(n_slots, dtype=np.int64)  # step number at which each slot's game began

    @classmethod
    def for_env(cls, spec: EnvSpec, n_slots: int, env_options: dict[str, Any] | None = None) -> ActionLog:
        """A log for ``n_slots`` games of ``spec``, in the narrowest integer type that holds its actions."""
        space = spec.action_space(spec.config(**(env_options or {})))
        return cls(len(spec.agents), n_slots, action_dtype(getattr(space, "n", None)))

    def begin(self, slots: np.ndarray) -> None:
        self.start[slots] = self.now

    def append(self, actions: np.ndarray, active: np.ndarray | None = None) -> None:
        """One step's ``(seats, slots)`` actions; ``active`` marks the slots with a game running (default: all)."""
        self.block[self.filled] = actions
        self.filled += 1
        self.now += 1
        if self.filled == self.BLOCK:
            self.blocks.append((self.now - self.BLOCK, np.ascontiguousarray(self.block.transpose(2, 1, 0))))
            self.filled = 0
            running = self.start if active is None else self.start[active]
            oldest = int(running.min()) if running.size else self.now
            self.blocks = [(first, b) for first, b in self.blocks if first + self.BLOCK > oldest]

    def take(self, slot: int) -> np.ndarray:
        """The ``(steps, seats)`` actions of the game that just ended in ``slot``."""
        begin = int(self.start[slot])
        parts = [b[slot, :, max(begin - first, 0):] for first, b in self.blocks if first + self.BLOCK > begin]
        tail = self.now - self.filled  # step number of the current block's first row
        parts.append(self.block[max(begin - tail, 0) : self.filled, :, slot].T)
        return np.concatenate(parts, axis=1).T


def play(
    env: str | EnvSpec,
    policies: Sequence[Policy],
    games: Sequence[Game],
    parallel: int = 1024,
    env_options: dict[str, Any] | None = None,
    on_result: Callable[[GameResult], None] | None = None,
    on_step: Callable[[int], None] | None = None,
    record_actions: bool = False,
    on_frame: FrameHook | None = None,
    stop_when: StopRule | None = None,
    slots: int | None = None,
) -> list[GameResult]:
    """Play ``games`` with up to ``parallel`` of them at once; returns results in schedule order.

    ``games`` may grow while it is played: games that ``on_result`` appends to the list are played too, in the
    same batch (a sequential evaluation decides from finished games whether more are needed, without waiting for
    the slowest game of a round); ``slots`` (at most ``parallel``) sets how many games run at once when the
    schedule is expected to grow past its first length.

    Each step, every policy acts once on the batch of all (game, seat) positions it holds. ``on_result`` is
    called as each game ends (e.g. to store it at once); ``on_step`` with the number of game steps just played.

    ``record_actions`` puts each game's encoded actions in its result (for the ledger, so the game can be
    replayed exactly). ``on_frame(core, slot, game_index, ended)`` is called when a game starts and after each of
    its steps, before its slot is reused, so it sees every state the game passes through (a recording renders
    them); ``ended`` is True on a game's last call. ``stop_when(core)`` ends the games it marks after a step, as
    truncated and decided by the score at that moment (a length cap that needs no game option).
    """
    spec = get_env(env) if isinstance(env, str) else env
    if not games:
        return []

    def check(g: Game) -> Game:
        if len(g.seats) != len(spec.agents) or not all(0 <= s < len(policies) for s in g.seats):
            raise ValueError(f"game {g} does not seat {len(spec.agents)} of the {len(policies)} policies")
        return g

    for g in games:
        check(g)
    n = min(parallel, max(len(games), slots or 0))
    core = spec.core(n, **(env_options or {}))
    seats = np.zeros((len(spec.agents), n), dtype=np.int64)  # policy index per (seat, slot)
    game_of = np.full(n, -1, dtype=np.int64)  # schedule index per slot, -1 when idle
    next_game = 0
    log = ActionLog.for_env(spec, n, env_options) if record_actions else None

    def start(slots: np.ndarray) -> None:
        nonlocal next_game
        take = slots[: max(0, len(games) - next_game)]
        game_of[slots] = -1
        if take.size:
            chosen = [check(g) for g in games[next_game : next_game + take.size]]
            game_of[take] = np.arange(next_game, next_game + take.size)
            seats[:, take] = np.array([g.seats for g in chosen]).T
            core.reset(take, [g.seed for g in chosen])
            next_game += take.size
            if log is not None:
                log.begin(take)
            if on_frame is not None:
                for slot in take.tolist():
                    on_frame(core, slot, int(game_of[slot]), False)

    start(np.arange(n))
    results: dict[int, GameResult] = {}
    actions = np.zeros((len(spec.agents), n), dtype=np.int64)
    flat_actions = actions.reshape(-1)
    groups = _acting_groups(policies)
    wanted = np.arange(len(policies) + 1)

    def positions() -> tuple[np.ndarray, list[list[np.ndarray]]]:
        """Which slots have a game, and every (seat, slot) position by the policy that holds it, in position order
        (one sort, no mask per policy); they change only when games end or start."""
        active = game_of >= 0
        owner = np.where(active[None, :], seats, -1).ravel()
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], wanted)
        return active, [[order[bounds[m] : bounds[m + 1]] for m in members] for members, _ in groups]

    active, held = positions()
    playing = int(active.sum())
    while playing:
        obs = core.observe()
        flat_obs = obs.reshape(-1, *obs.shape[2:])
        actions.fill(0)
        for (members, bank), where in zip(groups, held, strict=True):
            if bank is None:
                if where[0].size:
                    flat_actions[where[0]] = policies[members[0]].act(flat_obs[where[0]])
            elif any(w.size for w in where):
                for w, a in zip(where, bank.act([flat_obs[w] for w in where]), strict=True):
                    flat_actions[w] = a
        core.step(actions)
        if log is not None:
            log.append(actions, active)
        if on_step is not None:
            on_step(playing)
        done = core.terminated | core.truncated
        stopped = None
        if stop_when is not None:
            stopped = np.asarray(stop_when(core), dtype=bool) & ~done
            done = done | stopped
        done &= active
        if on_frame is not None:
            for slot in np.flatnonzero(active).tolist():
                on_frame(core, slot, int(game_of[slot]), bool(done[slot]))
        ended = np.flatnonzero(done)
        if ended.size:
            outcome = core.outcome()
            for slot in ended:
                gi = int(game_of[slot])
                g = games[gi]
                r = GameResult(
                    env=spec.name,
                    players=tuple(policies[s].id for s in g.seats),
                    seed=g.seed,
                    scores=tuple(int(x) for x in core.score[:, slot]),
                    outcome=tuple(float(x) for x in outcome[:, slot]),
                    length=int(core.steps[slot]),
                    truncated=bool(core.truncated[slot] or (stopped is not None and stopped[slot])),
                    index=gi,
                    actions=encode_actions(log.take(slot)) if log is not None else None,
                )
                results[gi] = r
                if on_result is not None:
                    on_result(r)
            game_of[ended] = -1
            if next_game < len(games):  # into every free slot, including ones idle before the schedule grew
                start(np.flatnonzero(game_of < 0))
            active, held = positions()
            playing = int(active.sum())
    return [results[i] for i in sorted(results)]
