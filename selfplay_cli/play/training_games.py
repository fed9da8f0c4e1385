"""Training's games: N games in one batched core that never stop, some seats driven by learners.

This is one of the two game loops, the one training steps. Rated play needs whole games (a schedule of
seeds and seat swaps, each game played to its end and counted, replays, recordings: :mod:`.matches`); training
needs slots that never stop (a game that ends restarts at once) and, every step, each learner's transitions
(observations, rewards, dones, what a cut game bootstraps from) for the slots it holds. Both keep to the same
limits (:mod:`.limits`: a game's length, numbers that are not finite) and make results the same way
(:func:`~selfplay_cli.results.game_results`). Each (seat, game) slot is either a learner's (learner index >= 0, fixed
for the whole run) or an opponent's (-1), filled at every game start by ``choose_opponents`` (the matchmaker draws
for every opponent slot on its own: a pool snapshot, a scripted bot, or a live learner). A learner sees only its own
slots, in a fixed order, as a vectorised environment: ``observe()`` -> observations (and ``masks()``, ``acting()``,
``state()``), ``step(actions)`` -> rewards, dones and what a truncated game's learner needs to bootstrap. A slot's
done is its seat's own end in its game: the game's, or, where agents come and go (a PettingZoo game whose agents die
or finish), the step its agent left; a seat out of its game does not act (``acting()``). A finished game restarts
at once with a fresh seed (auto-reset: the observation after a done is the new game's first) and comes back as a
:class:`GameResult`, so the ledger gets every training game.

Which learner holds which seat, and so which slots are opponents', is :mod:`.seat_plan`'s
(:func:`~.seat_plan.plan_seats`, :func:`~.seat_plan.plan_layout`).

An opponent slot's "latest" opponent is the live network of the learner that holds that seat when every seat is a
learner's (the learner itself where it would hold it): self-play against the current policies.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..envs import EnvSpec, SeatSpace, get_env
from ..errors import NonFiniteError
from ..policies import Policy
from ..results import GameResult, Rules, game_results
from .frames import FrameStacks, stacked_space
from .limits import GameLength, first_nonfinite
from .matches import frame_stack_of
from .replay import ActionLog, SeatActions, encode_actions
from .seat_plan import OPPONENT, learner_spaces


def _as_slice(index: np.ndarray) -> np.ndarray | slice:
    """Increasing ``index`` as the equal slice when it is a run of consecutive integers (indexing with a slice gives a
    view, with an index array a copy)."""
    if index.size and index[-1] - index[0] + 1 == index.size:
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


class SelfPlayGames:
    """Endless batched games where learners drive fixed slots and opponents the rest.

    ``learner_ids`` names each learner in game results (e.g. ``"run/left"``); ``choose_opponents(slots)`` returns
    one policy for each opponent slot of the games starting now (``slots``: flat ``seat * n_games + game``
    indices, game by game). The k-th game played in game slot g has the seed ``first_seed + k * total + g``: a
    function of the slot and its count, not of the order games end in, so a run is reproducible and plays the same
    games when its slots are split between rollout actors. An actor's share is ``game_ids`` (the global slots of
    its ``n_games``) of ``total_games`` (default: the whole run, ``arange(n_games)`` of ``n_games``).

    Each step: ``observe()`` (and, where the game has them, ``masks()``; in turn-based games ``acting()``) for each
    learner's slots, then ``step(actions)``. Opponents act by themselves, given their masks, and only the seats that
    act are asked. With ``frame_stack`` K > 1 the learners read their seats' last K observations
    (:mod:`.frames`; :attr:`spaces` are then the stacked ones), and an opponent its own ``frame_stack``.
    """

    def __init__(
        self,
        env: str | EnvSpec,
        n_games: int,
        layout: np.ndarray,
        learner_ids: Sequence[str],
        choose_opponents: Callable[[np.ndarray], Sequence[Policy]] | None = None,
        env_options: dict[str, Any] | None = None,
        first_seed: int = 0,
        game_ids: Sequence[int] | None = None,
        total_games: int | None = None,
        frame_stack: int = 1,
    ) -> None:
        options = env_options or {}
        self.spec = spec = (get_env(env) if isinstance(env, str) else env).for_options(**options)
        self.options = dict(options)
        self.core = spec.core(n_games, **options)
        self.n = n_games
        self.n_seats = n_seats = spec.n_seats
        self.rules = Rules.of(spec)
        self.layout = np.asarray(layout, dtype=np.int64)
        if self.layout.shape != (n_seats, n_games):
            raise ValueError(f"layout must have shape ({n_seats}, {n_games})")
        self.learner_ids = list(learner_ids)
        self.n_learners = int(self.layout.max()) + 1
        if len(self.learner_ids) != self.n_learners:
            raise ValueError(f"{self.n_learners} learners in the layout but {len(self.learner_ids)} ids")
        game_cfg = spec.config(**options)
        self.seat_spaces = spec.seat_spaces(game_cfg)
        self.length = GameLength.of(spec, game_cfg)  # a game that reaches it ends there, as truncated
        self.frame_stack = int(frame_stack)
        self.spaces = [SeatSpace(stacked_space(s.observation, self.frame_stack), s.action, s.mask)
                       for s in learner_spaces(spec, self.seat_spaces, self.layout)]
        self._frames: list[FrameStacks] | None = None  # each seat's stacks, where anyone reads more than one
        self._raw: Any = None  # this step's observations as the game gives them, where stacks are kept
        self._steps = 0  # steps played (a stack moves on once a step)
        if self.frame_stack > 1:
            self._stack_frames(self.frame_stack)
        self.needs_opponents = bool((self.layout == OPPONENT).any())
        if self.needs_opponents and choose_opponents is None:
            raise ValueError("opponent seats need a choose_opponents callback")
        self.choose_opponents = choose_opponents
        # One array for every seat's observations and actions where all seats are alike (pong): learners' slots are
        # then flat indices into (seat, game), as slices where consecutive (views, not copies).
        first = self.seat_spaces[0]
        self.uniform = all(s.observation.shape == first.observation.shape and s.action == first.action
                           and s.mask == first.mask for s in self.seat_spaces)
        self.masked = any(s.mask for s in self.seat_spaces)
        self.sequential = spec.turns == "sequential"
        # A core whose agents may come and go (a PettingZoo game's) says whose part in a game ended on each step
        # (seat_done): a seat ends there, not only with its game, and while it is out of a game it does not act.
        self.comes_and_goes = hasattr(self.core, "seat_done")
        self.acts = [SeatActions.of(s.action) for s in self.seat_spaces]
        self.slots = [np.flatnonzero(self.layout.ravel() == i) for i in range(self.n_learners)]
        self._index = [_as_slice(s) for s in self.slots]
        # Games with seats unlike each other: each learner's slots seat by seat, as (seat, rows of the learner's
        # slots, their games), so per-seat arrays are gathered and scattered without working the split out per step.
        self._by_seat = [[(s, rows, slots[rows] % n_games) for s in np.unique(slots // n_games).tolist()
                          for rows in [np.flatnonzero(slots // n_games == s)]] for slots in self.slots]
        self.opponent_slots = np.flatnonzero(self.layout.ravel() == OPPONENT)
        self.policies: list[Policy] = []  # distinct opponent policies seen so far
        self.opponent_of = np.full(n_seats * n_games, -1, dtype=np.int64)  # index into self.policies per slot
        if self.uniform:
            self._actions: Any = np.zeros((n_seats * n_games, *self.acts[0].shape), dtype=self.acts[0].dtype)
        else:
            self._actions = [np.zeros((n_games, *a.shape), dtype=a.dtype) for a in self.acts]
        self._flat: np.ndarray | None = None  # this step's observations, flat (uniform games)
        self._seat_obs: Any = None  # this step's observations, per seat
        self._masks: Any = None
        self._acting: np.ndarray | None = None
        self.truncated: list[np.ndarray] | None = None  # set by step(): per learner, its slots' games cut short
        self.final_obs: list[np.ndarray] | None = None  # ... and their final observations (before the restart)
        self.final_masks: list[np.ndarray | None] | None = None
        self.next_seed = first_seed  # the seeds' base (a resumed run moves it to a range of its own)
        self.team: Any = None  # a TeamViews (.team_view) when a learner's critic reads the whole team: told each step
        self.game_ids = np.arange(n_games, dtype=np.int64) if game_ids is None else np.asarray(game_ids, np.int64)
        self.total_games = n_games if total_games is None else int(total_games)
        if self.game_ids.shape != (n_games,) or n_games > self.total_games:
            raise ValueError(f"game_ids must name {n_games} of the {self.total_games} games")
        self.starts = np.zeros(n_games, dtype=np.int64)  # games started in each slot since the seeds' base was set
        self.seeds = np.zeros(n_games, dtype=np.int64)
        self.games_started = 0
        # Every game's actions, so the ledger can replay training games too (`marl record --game ID`).
        self._log = ActionLog.for_env(spec, n_games, options)
        self._start(np.arange(n_games))

    # -- games ---------------------------------------------------------------------------------------------------
    def _start(self, games: np.ndarray) -> None:
        seeds = self.next_seed + self.starts[games] * self.total_games + self.game_ids[games]
        self.starts[games] += 1
        self.games_started += games.size
        self.seeds[games] = seeds
        self.core.reset(games, seeds)
        if self._frames is not None:
            for frames in self._frames:
                frames.restart(games)
        self._log.begin(games)
        if self.needs_opponents:
            is_opp = self.layout[:, games] == OPPONENT  # (seats, games)
            seat_idx, game_idx = np.nonzero(is_opp.T)[::-1]  # game by game, seats in order
            slots = seat_idx * self.n + games[game_idx]
            if slots.size:
                chosen = list(self.choose_opponents(slots))  # type: ignore[misc]
                if len(chosen) != slots.size:
                    raise ValueError("choose_opponents returned the wrong number of policies")
                index = {id(p): i for i, p in enumerate(self.policies)}
                for slot, p in zip(slots.tolist(), chosen, strict=True):
                    if id(p) not in index:
                        index[id(p)] = len(self.policies)
                        self.policies.append(p)
                        if callable(getattr(p, "configure", None)):  # a scripted player: the run's game options
                            p.configure(self.options)
                        if frame_stack_of(p) > 1:  # a snapshot that reads its last observations
                            self._stack_frames(frame_stack_of(p))
                    self.opponent_of[slot] = index[id(p)]
            self._forget_idle()
        self._stale()

    def _forget_idle(self) -> None:
        """Let go of opponent policies no game plays any more (kept, they would hold every snapshot a long run ever
        drew), once they outnumber those in play."""
        used = np.unique(self.opponent_of[self.opponent_slots])
        if len(self.policies) <= max(16, 2 * used.size):
            return
        remap = np.full(len(self.policies), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        self.policies = [self.policies[i] for i in used.tolist()]
        self.opponent_of[self.opponent_slots] = remap[self.opponent_of[self.opponent_slots]]

    def _stale(self) -> None:
        self._flat = self._seat_obs = self._masks = self._acting = None

    def restart_all(self) -> None:
        """Abandon the games in progress and start fresh ones from the seeds' base ``next_seed`` (a resume gives it a
        range of its own first)."""
        self.games_started -= self.n
        self.starts[:] = 0
        self._start(np.arange(self.n))

    # -- what the learners see -------------------------------------------------------------------------------------
    def _stack_frames(self, k: int) -> None:
        """Keep each seat's last ``k`` observations from now on (at least)."""
        if self._frames is None:
            self._frames = [FrameStacks(seat.observation, k, self.n) for seat in self.seat_spaces]
        for frames in self._frames:
            frames.grow(k)

    def _read(self) -> None:
        if self._seat_obs is None:
            obs = self.core.observe()
            self._check_finite(obs, "observation")
            if self._frames is not None:  # the stacks of the seats that act move on; the learners read theirs
                self._raw = obs
                acting = self._to_act().reshape(self.n_seats, self.n) if self.sequential else None
                for s, frames in enumerate(self._frames):
                    rows = np.arange(self.n) if acting is None else np.flatnonzero(acting[s])
                    frames.see(rows, np.asarray(obs[s])[rows], self._steps)
                if self.frame_stack > 1:
                    seen = [frames.read(slice(None), self.frame_stack) for frames in self._frames]
                    obs = np.stack(seen) if isinstance(obs, np.ndarray) else seen
            self._seat_obs = obs
            if self.uniform and isinstance(obs, np.ndarray):
                self._flat = obs.reshape(-1, *obs.shape[2:])
            elif self.uniform:
                self._flat = np.concatenate([np.asarray(obs[s]) for s in range(self.n_seats)])

    def _gather(self, per_seat: Sequence[Any], flat: np.ndarray | None, i: int, width: tuple[int, ...]) -> np.ndarray:
        """Learner ``i``'s rows of a per-seat quantity (observations, masks), in its slot order."""
        if flat is not None:
            return flat[self._index[i]]
        parts = self._by_seat[i]
        out = np.empty((self.slots[i].size, *width), dtype=np.asarray(per_seat[parts[0][0]]).dtype)
        for s, rows, games in parts:
            out[rows] = np.asarray(per_seat[s])[games]
        return out

    def seat_observations(self) -> Any:
        """This step's observations seat by seat (each ``(n_games, *shape)``, as the learners read them)."""
        self._read()
        return self._seat_obs

    def observe(self) -> list[np.ndarray]:
        """Each learner's observations, ``(len(slots), *obs_shape)`` in its fixed slot order."""
        self._read()
        return [self._gather(self._seat_obs, self._flat, i, tuple(self.spaces[i].observation.shape))
                for i in range(self.n_learners)]

    def _all_masks(self) -> Any:
        """This step's masks per seat (all True for a seat without masks), and, where every seat is alike, all of
        them in one flat array as the observations are."""
        if self._masks is None:
            masks = self.core.action_masks()  # type: ignore[attr-defined]
            width = [int(s.action.n) if s.mask else 0 for s in self.seat_spaces]  # type: ignore[attr-defined]
            per_seat = [np.ones((self.n, w or 1), dtype=bool) if m is None else np.asarray(m, dtype=bool)
                        for m, w in zip(masks, width, strict=True)]
            self._masks = (per_seat, np.concatenate(per_seat) if self.uniform else None)
        return self._masks

    def masks(self) -> list[np.ndarray | None]:
        """Each learner's action masks, ``(len(slots), n_actions)`` bool (None for a learner without masks)."""
        if not self.masked:
            return [None] * self.n_learners
        masks, flat = self._all_masks()
        return [self._gather(masks, flat, i, (int(self.spaces[i].action.n),)) if self.spaces[i].mask else None
                for i in range(self.n_learners)]

    def _to_act(self) -> np.ndarray:
        if self._acting is None:
            self._acting = np.asarray(self.core.to_act(), dtype=bool).reshape(-1)  # type: ignore[attr-defined]
        return self._acting

    def acting(self) -> list[np.ndarray | None]:
        """Each learner's slots whose seat acts on this step: in turn-based games, and in games whose agents come and
        go (a seat out of its game does not act); None for a learner all of whose slots act."""
        if not (self.sequential or self.comes_and_goes):
            return [None] * self.n_learners
        flat = self._to_act()
        if self.sequential:
            return [flat[s] for s in self._index]
        return [None if a.all() else a for a in (flat[s] for s in self._index)]

    def state(self) -> list[np.ndarray]:
        """Each learner's rows of the games' global state (the game's :meth:`~selfplay_cli.envs.EnvSpec.state_space`),
        ``(len(slots), *state_shape)``: each slot's game's state, in the learner's slot order."""
        state = self.core.state()  # type: ignore[attr-defined]
        return [state[slots % self.n] for slots in self.slots]

    # -- a step ---------------------------------------------------------------------------------------------------
    def step(self, actions: Sequence[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray], list[GameResult]]:
        """Apply each learner's actions (opponents act by themselves); returns per learner the rewards and dones of
        its slots, and the games that ended on this step (already restarted). A slot is done when its seat's part in
        its game ended: with the game, or, in a game whose agents come and go, when its agent left (then it does not
        act until its game restarts: :meth:`acting`). Slots cut short on this step are :attr:`truncated` (per
        learner), their final observations :attr:`final_obs` (and :attr:`final_masks`)."""
        n, n_seats = self.n, self.n_seats
        if self.uniform:
            flat_actions = self._actions
            for s, a in zip(self._index, actions, strict=True):
                flat_actions[s] = a
            if self.needs_opponents:
                self._opponents_act(flat_actions)
            step_actions = flat_actions.reshape(n_seats, n, *flat_actions.shape[1:])
        else:
            for parts, a in zip(self._by_seat, actions, strict=True):
                a = np.asarray(a)
                for s, rows, games in parts:
                    self._actions[s][games] = a[rows]
            if self.needs_opponents:
                self._opponents_act(None)
            step_actions = self._actions
        rewards = np.asarray(self.core.step(step_actions), dtype=np.float32)
        self._steps += 1
        self._check_finite(rewards, "reward")
        self._log.append(step_actions)  # every slot always has a game running
        self._stale()
        stopped = self.length.over(self.core.steps, self.core.terminated | self.core.truncated)
        cut = self.core.truncated | stopped
        done_games = self.core.terminated | cut
        flat_rewards = rewards.reshape(-1)
        if self.comes_and_goes:  # each seat's own end: when its agent left, or with its game
            in_game = self.core.in_game & stopped  # type: ignore[attr-defined]  # games the loop cuts: who was in
            flat_done = (self.core.seat_done | in_game).reshape(-1)  # type: ignore[attr-defined]
            flat_cut = (self.core.seat_cut | in_game).reshape(-1)  # type: ignore[attr-defined]
        else:
            flat_done, flat_cut = np.tile(done_games, n_seats), np.tile(cut, n_seats)
        out_r = [flat_rewards[s] for s in self._index]
        out_d = [flat_done[s] for s in self._index]
        self.truncated = self.final_obs = self.final_masks = None
        if flat_cut.any():  # what a learner bootstraps a cut seat from: its final observation, before the restart
            self.truncated = [flat_cut[s] for s in self._index]
            self.final_obs = self.observe()
            self.final_masks = self.masks()
        if self.team is not None:  # the step as the whole team played it, before its ended games restart
            self.team.stepped(step_actions, rewards, done_games, cut, bool(flat_cut.any()))
        finished: list[GameResult] = []
        ended = np.flatnonzero(done_games)
        if ended.size:
            games = ended.tolist()
            finished = game_results(
                self.spec.name, self.rules, self.core.score[:, ended],
                [tuple(self._player_id(seat, g) for seat in range(n_seats)) for g in games], seeds=self.seeds[ended],
                lengths=self.core.steps[ended], truncated=cut[ended], indices=self.game_ids[ended].tolist(),
                actions=[encode_actions(self._log.take(g)) for g in games])
            self._start(ended)
        return out_r, out_d, finished

    def _check_finite(self, per_seat: Any, what: str) -> None:
        """Refuse a NaN or infinite ``what`` (``observation``, ``reward``) from the game
        (:func:`~selfplay_cli.play.limits.first_nonfinite`): the first seat and game at fault, named in a
        :class:`NonFiniteError` with the game's seed and how many steps it had played (enough to replay it). A
        learner must never learn from such a number."""
        bad = first_nonfinite(per_seat, self.n)
        if bad is not None:
            s, g, kind = bad
            raise NonFiniteError(f"{what} of seat {s} ({self.spec.agents[s]}) in game {g} (seed "
                                 f"{int(self.seeds[g])}) is {kind} at that game's step {int(self.core.steps[g]):,}")

    def _player_id(self, seat: int, game: int) -> str:
        who = self.layout[seat, game]
        if who == OPPONENT:
            return self.policies[self.opponent_of[seat * self.n + game]].id
        return self.learner_ids[who]

    def _opponents_act(self, flat_actions: np.ndarray | None) -> None:
        """The opponents' actions for this step, into the flat action array (uniform games) or the per-seat ones;
        in turn-based games only opponents whose seat acts are asked."""
        self._read()
        slots = self.opponent_slots
        if self.sequential or self.comes_and_goes:
            slots = slots[self._to_act()[slots]]
        if not slots.size:
            return
        masks, flat_masks = self._all_masks() if self.masked else (None, None)
        which = self.opponent_of[slots]
        for k in np.unique(which).tolist():
            idx = slots[which == k]
            if flat_actions is not None and frame_stack_of(self.policies[k]) == self.frame_stack:
                obs = self._flat[idx]  # type: ignore[index]
                mask = None if flat_masks is None else flat_masks[idx]
                flat_actions[idx] = self._act(self.policies[k], obs, mask)
                continue
            policy = self.policies[k]
            for s in np.unique(idx // self.n).tolist():
                rows = idx[idx // self.n == s] % self.n
                obs = self._seen(policy, s, rows)
                mask = None if masks is None or not self.seat_spaces[s].mask else masks[s][rows]
                # a scripted player acts as the seat's own (random: its action space)
                player = policy.for_seat(s) if callable(getattr(policy, "for_seat", None)) else policy
                played = self._act(player, obs, mask)
                if flat_actions is not None:
                    flat_actions[s * self.n + rows] = played
                else:
                    self._actions[s][rows] = played

    def _seen(self, policy: Policy, seat: int, rows: np.ndarray) -> np.ndarray:
        """What ``policy`` reads on ``seat`` in the games ``rows``: its own number of the seat's last observations."""
        k = frame_stack_of(policy)
        if k == self.frame_stack:
            return np.asarray(self._seat_obs[seat])[rows]
        if k == 1 or self._frames is None:
            return np.asarray(self._raw[seat])[rows]
        return self._frames[seat].read(rows, k)

    @staticmethod
    def _act(policy: Policy, obs: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
        return policy.act(obs) if mask is None else policy.act(obs, mask)
