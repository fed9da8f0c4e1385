"""The batched game runner: plays N games between policies in one batched core.

Training rollouts, evaluation matches and recordings all go through here, so a match, a training episode and a
video of it are the same game. On request it also returns each game's actions (what a replay needs, see
:mod:`selfplay_cli.arena.replay`) and shows every state a game passes through to a hook (what a recording needs).

Any game plays here: any number of seats, each with its own observation and action space (Discrete, MultiDiscrete
or Box), action masks (given to the policies), seats acting together or in turns (only the seats the core says act
are asked), and results by the game's kind (:class:`~selfplay_cli.results.Rules`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..envs.registry import BatchedCore, IllegalActionError
from ..errors import MarlError, NonFiniteError
from ..policies import Policy
from ..results import GameResult, Rules
from .replay import ActionLog, SeatActions, encode_actions

__all__ = ["UNDECLARED_MAX_STEPS", "ActionLog", "FrameHook", "Game", "GameLength", "GameResult", "IllegalActionError",
           "StopRule", "encode_actions", "first_nonfinite", "play"]

FrameHook = Callable[[BatchedCore, int, int, bool], None]
"""``on_frame(core, slot, game_index, ended)``: see :func:`play`."""
StopRule = Callable[[BatchedCore], np.ndarray]
"""``stop_when(core) -> (n,) bool``: games to end now, as truncated (see :func:`play`)."""


UNDECLARED_MAX_STEPS = 100_000
"""The most steps a game is played for when it declares no maximum length (a PettingZoo game without
``metadata["marl_max_steps"]`` or ``max_cycles``, pong with ``max_steps=0``): 5.5 times the longest game a built-in
game declares (pong's 18,000), so a game that can end is never cut by it, while one that never ends still does."""

_warned: set[str] = set()  # games whose cut by UNDECLARED_MAX_STEPS was already reported (once a process)


def first_nonfinite(per_seat: Any, n: int) -> tuple[int, int, str] | None:
    """``(seat, slot, "NaN" | "inf" | "-inf")`` of the first number in ``per_seat`` (per seat, ``(n, ...)`` arrays: a
    step's observations or rewards) that is not finite, None when all are. One ``np.isfinite(...).all()`` per seat
    array (one for all of them when they are one array): the search for the culprit runs only when one fails."""
    arrays = [per_seat] if isinstance(per_seat, np.ndarray) else [np.asarray(a) for a in per_seat]
    if all(a.dtype.kind not in "fc" or np.isfinite(a).all() for a in arrays):
        return None
    for s in range(len(per_seat)):
        a = np.asarray(per_seat[s]).reshape(n, -1)
        bad = ~np.isfinite(a).all(axis=1) if a.dtype.kind in "fc" else np.zeros(n, dtype=bool)
        if bad.any():
            slot = int(np.flatnonzero(bad)[0])
            value = a[slot][~np.isfinite(a[slot])][0]
            return s, slot, "NaN" if np.isnan(value) else "inf" if value > 0 else "-inf"
    return None


@dataclass(frozen=True)
class GameLength:
    """How long one game of a game (for given options) may last: the most steps it declares, else
    :data:`UNDECLARED_MAX_STEPS`. The one game loop (:func:`play`, and training's
    :class:`~selfplay_cli.arena.selfplay.SelfPlayGames`) ends a game that reaches it as truncated, so every game
    ends, whether or not the game itself keeps its declared length."""

    name: str
    limit: int
    declared: bool

    @classmethod
    def of(cls, spec: EnvSpec, cfg: Any) -> GameLength:
        declared = spec.max_steps(cfg)
        return cls(spec.name, int(declared), True) if declared else cls(spec.name, UNDECLARED_MAX_STEPS, False)

    def over(self, steps: np.ndarray, done: np.ndarray) -> np.ndarray:
        """The games not yet ``done`` that have played their length (to end now, as truncated); the first time a
        game is cut by the loop's own cap, one line on stderr says so."""
        over = (np.asarray(steps) >= self.limit) & ~done
        if not self.declared and self.name not in _warned and over.any():
            _warned.add(self.name)
            sys.stderr.write(f"marl: warning: {self.name} declares no maximum game length (metadata marl_max_steps) "
                             f"and a game reached {self.limit:,} steps: such games are cut there, as truncated\n")
            sys.stderr.flush()
        return over


@dataclass(frozen=True)
class Game:
    """One game to play: its seed and, for each seat, the index of the policy that plays it."""

    seed: int
    seats: tuple[int, ...]


def _acting_groups(policies: Sequence[Policy]) -> list[tuple[list[int], Any]]:
    """How the policies act each step: network policies of one architecture together in one
    :class:`~selfplay_cli.policies.bank.NetworkBank` (one batched forward for all of them), any other alone."""
    if not any(getattr(p, "kind", "") == "snapshot" for p in policies):
        return [([i], None) for i in range(len(policies))]
    from ..policies.bank import NetworkBank, bank_groups  # torch, only when networks play

    return [(members, NetworkBank([policies[i] for i in members]) if len(members) > 1 else None)  # type: ignore[misc]
            for members in bank_groups(policies)]


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
    slots: int | None = None,
) -> list[GameResult]:
    """Play ``games`` with up to ``parallel`` of them at once; returns results in schedule order.

    ``games`` may grow while it is played: games that ``on_result`` appends to the list are played too, in the
    same batch (a sequential evaluation decides from finished games whether more are needed, without waiting for
    the slowest game of a round); ``slots`` (at most ``parallel``) sets how many games run at once when the
    schedule is expected to grow past its first length.

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
    its declared length (:class:`GameLength`) ends there, as truncated, even if the game itself would go on. A
    policy with an ``after_step()`` method is told of every step (a replay finds each step's action by it).
    """
    spec = (get_env(env) if isinstance(env, str) else env).for_options(**(env_options or {}))
    if not games:
        return []
    n_seats = len(spec.agents)
    rules = Rules.of(spec)

    options = env_options or {}
    game_cfg = spec.config(**options)
    declared = spec.seat_spaces(game_cfg)
    seen: set[tuple[int, int]] = set()

    def check(g: Game) -> Game:
        if len(g.seats) != n_seats or not all(0 <= s < len(policies) for s in g.seats):
            raise ValueError(f"game {g} does not seat {n_seats} of the {len(policies)} policies")
        for seat, p in enumerate(g.seats):
            if (seat, p) not in seen:
                seen.add((seat, p))
                _check_seat(spec, policies[p], seat, declared[seat])
        return g

    for g in games:
        check(g)
    n = min(parallel, max(len(games), slots or 0))
    for p in policies:  # scripted players act as these options make the game (the lander's continuous engines)
        if callable(getattr(p, "configure", None)):
            p.configure(options)  # type: ignore[attr-defined]
    core = spec.core(n, **options)
    length = GameLength.of(spec, game_cfg)
    seat_groups = _seat_groups(spec, game_cfg, n)
    # A policy that acts by the seat it plays (a scripted player whose seats act differently) acts through its
    # stand-in for each group of seats.
    by_group = [[p.for_seat(sg.seats[0]) if callable(getattr(p, "for_seat", None)) else p for p in policies]
                for sg in seat_groups]
    whole = len(seat_groups) == 1  # one group of every seat, in order (Pong): its buffer is the step's actions
    step_actions: Any = seat_groups[0].actions if whole else [None] * n_seats
    if not whole:
        for sg in seat_groups:
            for k, seat in enumerate(sg.seats):
                step_actions[seat] = sg.actions[k]
    masked = any(sg.masked for sg in seat_groups)
    to_act = getattr(core, "to_act", None)
    seats = np.zeros((n_seats, n), dtype=np.int64)  # policy index per (seat, slot)
    game_of = np.full(n, -1, dtype=np.int64)  # schedule index per slot, -1 when idle
    next_game = 0
    log = ActionLog.for_env(spec, n, options) if record_actions else None
    hooks = [p.after_step for p in policies if callable(getattr(p, "after_step", None))]  # type: ignore[attr-defined]

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
    groups = _acting_groups(policies)
    wanted = np.arange(len(policies) + 1)
    # A joint (SA) policy flies its games whole: it is given every seat of them, acting or not.
    joint = {i for i, p in enumerate(policies) if getattr(p, "seats", None)}

    def owned(rows: np.ndarray, sg: _SeatGroup) -> list[list[np.ndarray]]:
        """Every (seat, slot) position of ``rows`` (seats, slots) by the policy that holds it, in position order,
        per acting group (one sort, no mask per policy)."""
        own = seats if whole else seats[sg.seats]
        picked = rows if whole else rows[sg.seats] if rows.shape[0] > 1 else rows
        owner = np.where(picked, own, -1).ravel()
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], wanted)
        return [[order[bounds[m] : bounds[m + 1]] for m in members] for members, _ in groups]

    def positions(acting: np.ndarray | None) -> tuple[np.ndarray, list[list[list[np.ndarray]]]]:
        """Which slots have a game, and, per seat group, every (seat, slot) position that acts by the policy that
        holds it; they change only when games end or start, or when the seats to act change."""
        active = game_of >= 0
        live = active[None, :] if acting is None else active[None, :] & acting
        held = []
        for sg in seat_groups:
            by_group = owned(live, sg)
            if joint:
                every = owned(np.broadcast_to(active[None, :], (n_seats, n)), sg)
                by_group = [[e if m in joint else w for m, w, e in zip(members, ws, es, strict=True)]
                            for (members, _), ws, es in zip(groups, by_group, every, strict=True)]
            held.append(by_group)
        return active, held

    acting = np.asarray(to_act(), dtype=bool) if to_act is not None else None
    active, held = positions(acting)
    playing = int(active.sum())
    while playing:
        obs = core.observe()
        bad = first_nonfinite(obs, len(game_of))
        if bad is not None and active[bad[1]]:  # a number no policy can act on, and no result can be made of
            seat, slot, kind = bad
            raise NonFiniteError(f"{spec.name}: observation of seat {seat} ({spec.agents[seat]}) in the game of seed "
                                 f"{games[int(game_of[slot])].seed} is {kind} at its step {int(core.steps[slot]):,}")
        masks = core.action_masks() if masked else None  # type: ignore[attr-defined]
        for sg, where_g, acting_as in zip(seat_groups, held, by_group, strict=True):
            if whole and isinstance(obs, np.ndarray):
                flat_obs = obs.reshape(-1, *obs.shape[2:])
            else:
                flat_obs = np.stack([np.asarray(obs[s]) for s in sg.seats]).reshape(-1, *sg.obs_shape)
            flat_mask = None
            if sg.masked and masks is not None:
                flat_mask = np.concatenate([np.ones((n, 1), dtype=bool) if masks[s] is None else np.asarray(masks[s])
                                            for s in sg.seats])
            flat_actions = sg.flat_actions
            if flat_mask is not None:  # slots nobody plays (a game stopped early, an idle slot) get a legal filler
                flat_actions[:] = flat_mask.argmax(axis=1)
            else:
                sg.actions.fill(0)
            for (members, bank), where in zip(groups, where_g, strict=True):
                if bank is None:
                    for m, w in zip(members, where, strict=True):
                        if w.size:
                            p = acting_as[m]
                            flat_actions[w] = p.act(flat_obs[w]) if flat_mask is None else p.act(flat_obs[w],
                                                                                                flat_mask[w])
                elif any(w.size for w in where):
                    acts = (bank.act([flat_obs[w] for w in where]) if flat_mask is None
                            else bank.act([flat_obs[w] for w in where], [flat_mask[w] for w in where]))
                    for w, a in zip(where, acts, strict=True):
                        flat_actions[w] = a
        try:
            core.step(step_actions)
        except IllegalActionError as e:
            raise _illegal(e, spec, policies, seats, game_of, games) from None
        if log is not None:
            log.append(step_actions, active)
        for hook in hooks:
            hook()
        if on_step is not None:
            on_step(playing)
        done = core.terminated | core.truncated
        stopped = length.over(core.steps, done | ~active)  # ended by the loop, as truncated
        if stop_when is not None:
            stopped |= np.asarray(stop_when(core), dtype=bool) & ~done
        done = (done | stopped) & active
        if on_frame is not None:
            for slot in np.flatnonzero(active).tolist():
                on_frame(core, slot, int(game_of[slot]), bool(done[slot]))
        ended = np.flatnonzero(done)
        changed = False
        if ended.size:
            scores = np.asarray(core.score[:, ended], dtype=np.float64)
            bad = first_nonfinite(scores, ended.size)
            if bad is not None:  # a result that is not a number never reaches the league
                seat, k, kind = bad
                raise NonFiniteError(f"{spec.name}: the score of seat {seat} ({spec.agents[seat]}) in the game of seed "
                                     f"{games[int(game_of[ended[k]])].seed} is {kind}")
            outcome = rules.outcome(scores)
            for k, slot in enumerate(ended.tolist()):
                gi = int(game_of[slot])
                g = games[gi]
                r = GameResult(
                    env=spec.name,
                    players=tuple(policies[s].id for s in g.seats),
                    seed=g.seed,
                    scores=tuple(float(x) for x in scores[:, k]),
                    outcome=tuple(float(x) for x in outcome[:, k]),
                    length=int(core.steps[slot]),
                    truncated=bool(core.truncated[slot] or stopped[slot]),
                    index=gi,
                    actions=encode_actions(log.take(slot)) if log is not None else None,
                )
                results[gi] = r
                if on_result is not None:
                    on_result(r)
            game_of[ended] = -1
            if next_game < len(games):  # into every free slot, including ones idle before the schedule grew
                start(np.flatnonzero(game_of < 0))
            changed = True
        if to_act is not None:
            now = np.asarray(to_act(), dtype=bool)
            if changed or not np.array_equal(now, acting):
                acting, changed = now, True
        if changed:
            active, held = positions(acting)
            playing = int(active.sum())
    return [results[i] for i in sorted(results)]


def _check_seat(spec: EnvSpec, policy: Policy, seat: int, declared: Any) -> None:
    """A network given a seat whose observations it cannot read (a seat of another role) is a :class:`MarlError`
    naming both, before any game is played (scripted players, and joint agents that fly a whole team, play any)."""
    obs = getattr(policy, "obs_space", None)
    if obs is None or getattr(policy, "kind", "") == "bot" or getattr(policy, "seats", None):
        return
    want = tuple(declared.observation.shape)
    if tuple(obs.shape) != want:
        raise MarlError(f"{policy.id} reads observations of shape {tuple(obs.shape)} but seat {spec.agents[seat]} of "
                        f"{spec.name} observes {want}: a policy plays only seats of the role it learned")


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
