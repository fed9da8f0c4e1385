"""Whole games to results: :func:`play` plays N games between policies in one batched core, each to its end, and
returns a :class:`~selfplay_cli.results.GameResult` per game, in schedule order.

This is one of the two game loops, the one for games that are played to an end and counted: rated matches,
gauntlets, tournaments, the gate, and recordings. It takes a schedule (who sits where on which seed, so a policy
changes seats from one game to the next and a seed is played with the seats swapped), fills its slots with the
schedule's games as earlier ones end, may grow the schedule while it plays, and on request returns each game's
actions (what a replay needs, see :mod:`selfplay_cli.play.replay`) and shows every state a game passes through to a
hook (what a recording needs). Training's games, which never end as a whole and whose learners need each step's
transitions, are the other loop (:mod:`.training_games`); both keep to the same limits (:mod:`.limits`) and make
results the same way (:func:`~selfplay_cli.results.game_results`).

Any game plays here: any number of seats, each with its own observation and action space (Discrete, MultiDiscrete
or Box), action masks (given to the policies), seats acting together or in turns (only the seats the core says act
are asked), and results by the game's kind (:class:`~selfplay_cli.results.Rules`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..envs.contract import BatchedCore, IllegalActionError
from ..errors import MarlError, NonFiniteError
from ..policies import Policy
from ..results import GameResult, Rules, game_results
from .frames import FrameStacks, stacked_space
from .limits import GameLength, first_nonfinite
from .replay import ActionLog, SeatActions, encode_actions

__all__ = ["FrameHook", "Game", "IllegalActionError", "StopRule", "play"]

FrameHook = Callable[[BatchedCore, int, int, bool], None]
"""``on_frame(core, slot, game_index, ended)``: see :func:`play`."""
StopRule = Callable[[BatchedCore], np.ndarray]
"""``stop_when(core) -> (n,) bool``: games to end now, as truncated (see :func:`play`)."""


@dataclass(frozen=True)
class Game:
    """One game to play: its seed and, for each seat, the index of the policy that plays it."""

    seed: int
    seats: tuple[int, ...]


def _acting_groups(policies: Sequence[Policy]) -> list[tuple[list[int], Any]]:
    """How the policies act each step: network policies of one architecture together in one
    :class:`~selfplay_cli.policies.bank.NetworkBank` (one batched forward for all of them; a lone network in a bank of
    its own, whose numpy path for few rows is 1.4 to 3 times its own ``act``: a snapshot against a scripted player),
    any other alone."""
    if not any(getattr(p, "kind", "") == "snapshot" for p in policies):
        return [([i], None) for i in range(len(policies))]
    from ..policies.bank import NetworkBank, bank_groups  # torch, only when networks play

    return [(members, NetworkBank([policies[i] for i in members]) if key is not None else None)  # type: ignore[misc]
            for key, members in bank_groups(policies)]


@dataclass
class _SeatGroup:
    """Seats that share one observation shape, one action space and masks (all of Pong's seats): their
    observations, masks and actions are stacked, so a policy acts once on all the positions it holds in them."""

    seats: list[int]
    obs_shape: tuple[int, ...]
    action: SeatActions
    masked: bool
    actions: np.ndarray  # (len(seats), n, *action shape), the seat's dtype
    flat_actions: np.ndarray  # (len(seats) * n, *action shape), a view of ``actions``


def _seat_groups(spec: EnvSpec, cfg: Any, n: int) -> list[_SeatGroup]:
    declared = [(tuple(s.observation.shape), SeatActions.of(s.action), bool(s.mask)) for s in spec.seat_spaces(cfg)]
    by_key: dict[tuple, list[int]] = {}
    for seat, (shape, action, masked) in enumerate(declared):
        by_key.setdefault((shape, action.kind, action.shape, masked), []).append(seat)
    groups = []
    for seats in by_key.values():
        shape, action, masked = declared[seats[0]]
        buf = np.zeros((len(seats), n, *action.shape), dtype=action.dtype)
        groups.append(_SeatGroup(seats, shape, action, masked, buf, buf.reshape(len(seats) * n, *action.shape)))
    return groups


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
) -> list[GameResult]:
    """Play ``games`` with up to ``parallel`` of them at once; returns results in schedule order.

    Each step, every policy acts once on the batch of all (game, seat) positions it holds among the seats that act
    now (the core's ``to_act()``; every seat of a running game where the core does not say), given those positions'
    action masks where the game has them (``policy.act(obs, mask)``); the actions go to the core as one array per
    seat of the seat's dtype (int64 for Discrete and MultiDiscrete, float32 for Box), and what a seat that does not
    act is given is ignored. An action the mask forbids, if the core reports one, is a :class:`MarlError` naming
    the policy and the action. Results are computed from the cores' ``score`` by the game's
    :class:`~selfplay_cli.results.Rules`. ``on_result`` is called as each game ends (e.g. to store it at once);
    ``on_step`` with the number of games that played the step just played.

    ``record_actions`` puts each game's encoded actions in its result (for the ledger, so the game can be
    replayed exactly). ``on_frame(core, slot, game_index, ended)`` is called when a game starts and after each of
    its steps, before its slot is reused, so it sees every state the game passes through (a recording renders
    them); ``ended`` is True on a game's last call. ``stop_when(core)`` ends the games it marks after a step, as
    truncated and decided by the score at that moment (a length cap that needs no game option). A game that reaches
    its declared length (:class:`~.limits.GameLength`) ends there, as truncated, even if the game itself would go
    on. A policy with an ``after_step()`` method is told of every step (a replay finds each step's action by it).
    """
    spec = (get_env(env) if isinstance(env, str) else env).for_options(**(env_options or {}))
    if not games:
        return []
    batch = _Batch(spec, policies, games, parallel, env_options or {}, record_actions, on_frame)
    return batch.run(on_result, on_step, stop_when)


class _Batch:
    """One call of :func:`play`: the batched core, which game each slot plays and who sits where in it, and the
    positions each policy acts on (worked out again only when games end or start, or the seats to act change)."""

    def __init__(self, spec: EnvSpec, policies: Sequence[Policy], games: Sequence[Game], parallel: int,
                 options: dict[str, Any], record_actions: bool, on_frame: FrameHook | None) -> None:
        self.spec, self.policies, self.games, self.on_frame = spec, policies, games, on_frame
        self.n_seats = n_seats = len(spec.agents)
        self.rules = Rules.of(spec)
        game_cfg = spec.config(**options)
        self.declared = spec.seat_spaces(game_cfg)
        self.seen: set[tuple[int, int]] = set()
        for g in games:
            self.check(g)
        self.n = n = min(parallel, len(games))
        for p in policies:  # scripted players act as these options make the game (the lander's continuous engines)
            if callable(getattr(p, "configure", None)):
                p.configure(options)  # type: ignore[attr-defined]
        self.core = spec.core(n, **options)
        self.length = GameLength.of(spec, game_cfg)
        self.seat_groups = _seat_groups(spec, game_cfg, n)
        # A policy that acts by the seat it plays (a scripted player whose seats act differently) acts through its
        # stand-in for each group of seats.
        self.by_group = [[p.for_seat(sg.seats[0]) if callable(getattr(p, "for_seat", None)) else p for p in policies]
                         for sg in self.seat_groups]
        self.whole = len(self.seat_groups) == 1  # one group of every seat, in order (Pong): its buffer is the step's
        self.step_actions: Any = self.seat_groups[0].actions if self.whole else [None] * n_seats  # actions
        if not self.whole:
            for sg in self.seat_groups:
                for k, seat in enumerate(sg.seats):
                    self.step_actions[seat] = sg.actions[k]
        self.masked = any(sg.masked for sg in self.seat_groups)
        # Policies that read their last K observations (:mod:`.frames`): every seat group's stacks of the most any of
        # them reads, moved on by the positions that act.
        self.stack_k = [frame_stack_of(p) for p in policies]
        most = max(self.stack_k, default=1)
        self.frames = ([FrameStacks(self.declared[sg.seats[0]].observation, most, len(sg.seats) * n)
                        for sg in self.seat_groups] if most > 1 else None)
        self.step_no = 0
        self.to_act = getattr(self.core, "to_act", None)
        self.seats = np.zeros((n_seats, n), dtype=np.int64)  # policy index per (seat, slot)
        self.game_of = np.full(n, -1, dtype=np.int64)  # schedule index per slot, -1 when idle
        self.next_game = 0
        self.log = ActionLog.for_env(spec, n, options) if record_actions else None
        self.hooks = [p.after_step for p in policies if callable(getattr(p, "after_step", None))]  # type: ignore
        self.start(np.arange(n))
        self.results: dict[int, GameResult] = {}
        self.groups = _acting_groups(policies)
        self.wanted = np.arange(len(policies) + 1)
        # A joint (SA) policy flies its games whole: it is given every seat of them, acting or not.
        self.joint = {i for i, p in enumerate(policies) if getattr(p, "seats", None)}

    def check(self, g: Game) -> Game:
        """``g`` seats one known policy on every seat, each of a role it may play (checked once per seat and
        policy)."""
        if len(g.seats) != self.n_seats or not all(0 <= s < len(self.policies) for s in g.seats):
            raise ValueError(f"game {g} does not seat {self.n_seats} of the {len(self.policies)} policies")
        for seat, p in enumerate(g.seats):
            if (seat, p) not in self.seen:
                self.seen.add((seat, p))
                _check_seat(self.spec, self.policies[p], seat, self.declared[seat])
        return g

    def start(self, slots: np.ndarray) -> None:
        """The next games of the schedule into ``slots`` (as many as are left; the other slots go idle)."""
        games, first = self.games, self.next_game
        take = slots[: max(0, len(games) - first)]
        self.game_of[slots] = -1
        if take.size:
            chosen = [self.check(g) for g in games[first : first + take.size]]
            self.game_of[take] = np.arange(first, first + take.size)
            self.seats[:, take] = np.array([g.seats for g in chosen]).T
            self.core.reset(take, [g.seed for g in chosen])
            if self.frames is not None:
                for sg, frames in zip(self.seat_groups, self.frames, strict=True):
                    frames.restart((np.arange(len(sg.seats))[:, None] * self.n + take[None, :]).ravel())
            self.next_game += take.size
            if self.log is not None:
                self.log.begin(take)
            if self.on_frame is not None:
                for slot in take.tolist():
                    self.on_frame(self.core, slot, int(self.game_of[slot]), False)

    def owned(self, rows: np.ndarray, sg: _SeatGroup) -> list[list[np.ndarray]]:
        """Every (seat, slot) position of ``rows`` (seats, slots) by the policy that holds it, in position order,
        per acting group (one sort, no mask per policy)."""
        own = self.seats if self.whole else self.seats[sg.seats]
        picked = rows if self.whole else rows[sg.seats] if rows.shape[0] > 1 else rows
        owner = np.where(picked, own, -1).ravel()
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], self.wanted)
        return [[order[bounds[m] : bounds[m + 1]] for m in members] for members, _ in self.groups]

    def positions(self, acting: np.ndarray | None) -> None:
        """Which slots have a game (:attr:`active`, and how many: :attr:`playing`) and, per seat group, every
        (seat, slot) position that acts by the policy that holds it (:attr:`held`)."""
        active = self.game_of >= 0
        live = active[None, :] if acting is None else active[None, :] & acting
        held = []
        for sg in self.seat_groups:
            by_group = self.owned(live, sg)
            if self.joint:
                every = self.owned(np.broadcast_to(active[None, :], (self.n_seats, self.n)), sg)
                by_group = [[e if m in self.joint else w for m, w, e in zip(members, ws, es, strict=True)]
                            for (members, _), ws, es in zip(self.groups, by_group, every, strict=True)]
            held.append(by_group)
        self.acting, self.active, self.held, self.playing = acting, active, held, int(active.sum())

    def run(self, on_result: Callable[[GameResult], None] | None, on_step: Callable[[int], None] | None,
            stop_when: StopRule | None) -> list[GameResult]:
        """Step until every game of the schedule has ended; the results in schedule order."""
        self.positions(np.asarray(self.to_act(), dtype=bool) if self.to_act is not None else None)
        while self.playing:
            self.act()
            try:
                self.core.step(self.step_actions)
            except IllegalActionError as e:
                raise _illegal(e, self.spec, self.policies, self.seats, self.game_of, self.games) from None
            self.step_no += 1
            if self.log is not None:
                self.log.append(self.step_actions, self.active)
            for hook in self.hooks:
                hook()
            if on_step is not None:
                on_step(self.playing)
            self.after_step(on_result, stop_when)
        return [self.results[i] for i in sorted(self.results)]

    def act(self) -> None:
        """This step's actions into the seat groups' buffers: every policy once on the positions it holds (a bank
        of networks once for all of its members), given their masks."""
        core, n = self.core, self.n
        obs = core.observe()
        bad = first_nonfinite(obs, len(self.game_of))
        if bad is not None and self.active[bad[1]]:  # a number no policy can act on, and no result can be made of
            seat, slot, kind = bad
            raise NonFiniteError(f"{self.spec.name}: observation of seat {seat} ({self.spec.agents[seat]}) in the game "
                                 f"of seed {self.games[int(self.game_of[slot])].seed} is {kind} at its step "
                                 f"{int(core.steps[slot]):,}")
        masks = core.action_masks() if self.masked else None  # type: ignore[attr-defined]
        for gi, (sg, where_g, acting_as) in enumerate(zip(self.seat_groups, self.held, self.by_group, strict=True)):
            if self.whole and isinstance(obs, np.ndarray):
                flat_obs = obs.reshape(-1, *obs.shape[2:])
            else:
                flat_obs = np.stack([np.asarray(obs[s]) for s in sg.seats]).reshape(-1, *sg.obs_shape)
            frames = None if self.frames is None else self.frames[gi]
            if frames is not None:  # the acting positions' stacks move on
                rows = np.concatenate([w for ws in where_g for w in ws])
                frames.see(rows, flat_obs[rows], self.step_no)

            def seen(m: int, w: np.ndarray, flat_obs: np.ndarray = flat_obs, frames: Any = frames) -> np.ndarray:
                """What policy ``m`` reads at positions ``w``: the observations, or its stacks of them."""
                k = self.stack_k[m]
                return flat_obs[w] if k == 1 or frames is None else frames.read(w, k)

            flat_mask = None
            if sg.masked and masks is not None:
                flat_mask = np.concatenate([np.ones((n, 1), dtype=bool) if masks[s] is None else np.asarray(masks[s])
                                            for s in sg.seats])
            flat_actions = sg.flat_actions
            if flat_mask is not None:  # slots nobody plays (a game stopped early, an idle slot) get a legal filler
                flat_actions[:] = flat_mask.argmax(axis=1)
            else:
                sg.actions.fill(0)
            for (members, bank), where in zip(self.groups, where_g, strict=True):
                if bank is None:
                    for m, w in zip(members, where, strict=True):
                        if w.size:
                            p = acting_as[m]
                            flat_actions[w] = p.act(seen(m, w)) if flat_mask is None else p.act(seen(m, w),
                                                                                                flat_mask[w])
                elif any(w.size for w in where):
                    x = [seen(m, w) for m, w in zip(members, where, strict=True)]
                    acts = bank.act(x) if flat_mask is None else bank.act(x, [flat_mask[w] for w in where])
                    for w, a in zip(where, acts, strict=True):
                        flat_actions[w] = a

    def after_step(self, on_result: Callable[[GameResult], None] | None, stop_when: StopRule | None) -> None:
        """End the games that ended on the step just played (by the game, its length or ``stop_when``), start the
        next ones in their slots, and work the positions out again where they changed."""
        core, active = self.core, self.active
        done = core.terminated | core.truncated
        stopped = self.length.over(core.steps, done | ~active)  # ended by the loop, as truncated
        if stop_when is not None:
            stopped |= np.asarray(stop_when(core), dtype=bool) & ~done
        done = (done | stopped) & active
        if self.on_frame is not None:
            for slot in np.flatnonzero(active).tolist():
                self.on_frame(core, slot, int(self.game_of[slot]), bool(done[slot]))
        ended = np.flatnonzero(done)
        changed = False
        if ended.size:
            for r in self.finish(ended, stopped):
                self.results[r.index] = r
                if on_result is not None:
                    on_result(r)
            self.game_of[ended] = -1
            if self.next_game < len(self.games):  # into every free slot, including ones idle before it grew
                self.start(np.flatnonzero(self.game_of < 0))
            changed = True
        acting = self.acting
        if self.to_act is not None:
            now = np.asarray(self.to_act(), dtype=bool)
            if changed or not np.array_equal(now, acting):
                acting, changed = now, True
        if changed:
            self.positions(acting)

    def finish(self, ended: np.ndarray, stopped: np.ndarray) -> list[GameResult]:
        """The results of the games in slots ``ended``; a score that is not a number never reaches the league."""
        core, spec = self.core, self.spec
        scores = np.asarray(core.score[:, ended], dtype=np.float64)
        bad = first_nonfinite(scores, ended.size)
        if bad is not None:
            seat, k, kind = bad
            raise NonFiniteError(f"{spec.name}: the score of seat {seat} ({spec.agents[seat]}) in the game of seed "
                                 f"{self.games[int(self.game_of[ended[k]])].seed} is {kind}")
        slots = ended.tolist()
        index = [int(self.game_of[slot]) for slot in slots]
        played = [self.games[gi] for gi in index]
        log = self.log
        return game_results(
            spec.name, self.rules, scores, [tuple(self.policies[s].id for s in g.seats) for g in played],
            seeds=[g.seed for g in played], lengths=core.steps[ended],
            truncated=[bool(core.truncated[slot] or stopped[slot]) for slot in slots], indices=index,
            actions=[encode_actions(log.take(slot)) for slot in slots] if log is not None else None)


def _check_seat(spec: EnvSpec, policy: Policy, seat: int, declared: Any) -> None:
    """A network given a seat whose observations it cannot read (a seat of another role) is a :class:`MarlError`
    naming both, before any game is played (scripted players, and joint agents that fly a whole team, play any)."""
    obs = getattr(policy, "obs_space", None)
    if obs is None or getattr(policy, "kind", "") == "bot" or getattr(policy, "seats", None):
        return
    want = tuple(stacked_space(declared.observation, frame_stack_of(policy)).shape)
    if tuple(obs.shape) != want:
        raise MarlError(f"{policy.id} reads observations of shape {tuple(obs.shape)} but seat {spec.agents[seat]} of "
                        f"{spec.name} observes {want}: a policy plays only seats of the role it learned")


def frame_stack_of(policy: Policy) -> int:
    """The observations a policy reads at once (its ``frame_stack``; 1 for a policy without one)."""
    k = getattr(policy, "frame_stack", 1)
    return int(k) if isinstance(k, (int, np.integer)) and k >= 1 else 1


def _illegal(e: Exception, spec: EnvSpec, policies: Sequence[Policy], seats: np.ndarray, game_of: np.ndarray,
             games: Sequence[Game]) -> MarlError:
    """One line for an action a game's mask forbids: which policy played it, where, and what it was."""
    seat = int(getattr(e, "seat", e.args[0] if e.args else 0))
    slot = int(getattr(e, "game", e.args[1] if len(e.args) > 1 else 0))
    action = getattr(e, "action", e.args[2] if len(e.args) > 2 else "?")
    action = np.asarray(action).tolist()
    who = policies[int(seats[seat, slot])].id if 0 <= seat < seats.shape[0] and 0 <= slot < seats.shape[1] else "?"
    gi = int(game_of[slot]) if 0 <= slot < game_of.size else -1
    where = f"game of seed {games[gi].seed}" if gi >= 0 else "a game"
    agent = spec.agents[seat] if 0 <= seat < len(spec.agents) else seat
    return MarlError(f"{who} played action {action} on seat {agent} of {spec.name} ({where}), which the game's action "
                     f"mask forbids: a policy must keep to the mask (a bug in {who})")
