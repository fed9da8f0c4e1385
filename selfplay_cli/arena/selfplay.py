"""Self-play rollouts: N games in one batched core that never stop, some seats driven by learners.

This is the training side of the arena. Each (seat, game) slot is either a learner's (learner index >= 0, fixed
for the whole run) or an opponent's (-1), filled at every game start by ``choose_opponents`` (the matchmaker:
a pool snapshot, a scripted bot, or a frozen copy of a learner). A learner sees only its own slots, in a fixed
order, as a vectorised environment: ``observe()`` -> observations, ``step(actions)`` -> rewards and dones.
A finished game restarts at once with a fresh seed (auto-reset: the observation after a done is the new game's
first) and comes back as a :class:`GameResult`, so the ledger gets every training game.

Seat layouts for two-seat games, by ``--agents`` and ``--sharing``:

* two learners, one network each (seed 000's set-up): learner 0 on the left of every game, learner 1 on the right;
* one shared network for both seats: learner 0 on both seats of every game;
* one learner against the league: learner 0 on the left of even games and the right of odd ones (it plays both
  sides, which egocentric observations allow), opponents on the other seat;
* every seat a learner, with ``league_games`` > 0: that share of the games seats one learner (on its own seat,
  the learners taking turns game by game) against an opponent from the league; the other games are as above.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..envs import EnvSpec, get_env
from ..policies import Policy
from .replay import encode_actions
from .runner import ActionLog, GameResult

OPPONENT = -1


def _as_slice(index: np.ndarray) -> np.ndarray | slice:
    """Increasing ``index`` as the equal slice when it is a run of consecutive integers (indexing with a slice gives a
    view, with an index array a copy)."""
    if index.size and index[-1] - index[0] + 1 == index.size:
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def seat_layout(n_seats: int, n_games: int, agents: int, sharing: str, league_games: float = 0.0) -> np.ndarray:
    """The learner index of every (seat, game) slot, -1 for opponent seats (see the module docstring)."""
    if not 0.0 <= league_games <= 1.0:
        raise ValueError(f"league_games must lie in [0, 1], not {league_games}")
    if sharing not in ("nops", "fups"):
        raise ValueError(f"sharing must be 'nops' or 'fups', not {sharing!r}")
    if not 1 <= agents <= n_seats:
        raise ValueError(f"this game has {n_seats} seats: --agents must be between 1 and {n_seats}, not {agents}")
    layout = np.full((n_seats, n_games), OPPONENT, dtype=np.int64)
    if agents == n_seats:
        for seat in range(n_seats):
            layout[seat] = 0 if sharing == "fups" else seat
        k = round(league_games * n_games)  # the first k games: one learner against the league
        seat_of = np.arange(k) % n_seats
        layout[:, :k] = OPPONENT
        layout[seat_of, np.arange(k)] = 0 if sharing == "fups" else seat_of
    elif agents == 1:
        layout[np.arange(n_games) % n_seats, np.arange(n_games)] = 0
    else:
        for seat in range(agents):  # learners on the first seats, rotating with the game index
            layout[(np.arange(n_games) + seat) % n_seats, np.arange(n_games)] = 0 if sharing == "fups" else seat
    return layout


class SelfPlayGames:
    """Endless batched games where learners drive fixed slots and opponents the rest.

    ``learner_ids`` names each learner in game results (e.g. ``"run/left"``); ``choose_opponents(slots)``
    returns one policy for each game slot starting a game now (a game with several opponent seats uses that
    policy on all of them). Seeds of successive games are ``first_seed``,
    ``first_seed + 1``, ... in the order games start, so a run is reproducible.
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
    ) -> None:
        self.spec = get_env(env) if isinstance(env, str) else env
        self.core = self.spec.core(n_games, **(env_options or {}))
        self.n = n_games
        self.layout = np.asarray(layout, dtype=np.int64)
        if self.layout.shape != (len(self.spec.agents), n_games):
            raise ValueError(f"layout must have shape ({len(self.spec.agents)}, {n_games})")
        self.learner_ids = list(learner_ids)
        self.n_learners = int(self.layout.max()) + 1
        if len(self.learner_ids) != self.n_learners:
            raise ValueError(f"{self.n_learners} learners in the layout but {len(self.learner_ids)} ids")
        self.needs_opponents = bool((self.layout == OPPONENT).any())
        if self.needs_opponents and choose_opponents is None:
            raise ValueError("opponent seats need a choose_opponents callback")
        self.choose_opponents = choose_opponents
        # Slots of each learner, in a fixed order: flat indices into (seat, game); as a slice where they are a run of
        # consecutive slots (one learner per seat), so its observations and rewards are views, not gathered copies.
        self.slots = [np.flatnonzero(self.layout.ravel() == i) for i in range(self.n_learners)]
        self._index = [_as_slice(s) for s in self.slots]
        self.opponent_slots = np.flatnonzero(self.layout.ravel() == OPPONENT)
        self.policies: list[Policy] = []  # distinct opponent policies seen so far
        self.opponent_of = np.full(n_games, -1, dtype=np.int64)  # index into self.policies per game
        self._obs: np.ndarray | None = None
        self.next_seed = first_seed
        self.seeds = np.zeros(n_games, dtype=np.int64)
        self.games_started = 0
        # Every game's actions, so the ledger can replay training games too (`marl record --game ID`).
        self._log = ActionLog.for_env(self.spec, n_games, env_options)
        self._start(np.arange(n_games))

    def _start(self, games: np.ndarray) -> None:
        seeds = np.arange(self.next_seed, self.next_seed + games.size)
        self.next_seed += games.size
        self.games_started += games.size
        self.seeds[games] = seeds
        self.core.reset(games, seeds)
        self._log.begin(games)
        if self.needs_opponents:
            chosen = list(self.choose_opponents(games))  # type: ignore[misc]
            if len(chosen) != games.size:
                raise ValueError("choose_opponents returned the wrong number of policies")
            index = {id(p): i for i, p in enumerate(self.policies)}
            for g, p in zip(games.tolist(), chosen, strict=True):
                if id(p) not in index:
                    index[id(p)] = len(self.policies)
                    self.policies.append(p)
                self.opponent_of[g] = index[id(p)]

    def restart_all(self) -> None:
        """Abandon the games in progress and start fresh ones (from ``next_seed``), e.g. after a resume."""
        self.games_started -= self.n
        self._start(np.arange(self.n))
        self._obs = None

    def observe(self) -> list[np.ndarray]:
        """Each learner's observations, ``(len(slots), *obs_shape)`` in its fixed slot order."""
        obs = self.core.observe()
        flat = obs.reshape(-1, *obs.shape[2:])
        self._obs = flat
        return [flat[s] for s in self._index]

    def step(self, actions: Sequence[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray], list[GameResult]]:
        """Apply each learner's actions (opponents act by themselves); returns per learner the rewards and
        dones of its slots, and the games that ended on this step (already restarted)."""
        n_seats = len(self.spec.agents)
        all_actions = np.zeros(n_seats * self.n, dtype=np.int64)
        for s, a in zip(self._index, actions, strict=True):
            all_actions[s] = a
        if self.needs_opponents:
            self._opponents_act(all_actions)
        rewards = self.core.step(all_actions.reshape(n_seats, self.n))
        self._log.append(all_actions.reshape(n_seats, self.n))  # every slot always has a game running
        self._obs = None
        done_games = self.core.terminated | self.core.truncated
        flat_rewards = rewards.ravel()
        flat_done = np.tile(done_games, n_seats)
        out_r = [flat_rewards[s] for s in self._index]
        out_d = [flat_done[s] for s in self._index]
        finished: list[GameResult] = []
        ended = np.flatnonzero(done_games)
        if ended.size:
            outcome = self.core.outcome()
            for g in ended.tolist():
                players = tuple(self._player_id(seat, g) for seat in range(n_seats))
                finished.append(GameResult(
                    env=self.spec.name, players=players, seed=int(self.seeds[g]),
                    scores=tuple(int(x) for x in self.core.score[:, g]),
                    outcome=tuple(float(x) for x in outcome[:, g]), length=int(self.core.steps[g]),
                    truncated=bool(self.core.truncated[g]), index=g, actions=encode_actions(self._log.take(g))))
            self._start(ended)
        return out_r, out_d, finished

    def _player_id(self, seat: int, game: int) -> str:
        who = self.layout[seat, game]
        if who == OPPONENT:
            return self.policies[self.opponent_of[game]].id
        return self.learner_ids[who]

    def _opponents_act(self, all_actions: np.ndarray) -> None:
        if self._obs is None:
            self.observe()
        slots = self.opponent_slots
        which = self.opponent_of[slots % self.n]
        for k in np.unique(which).tolist():
            idx = slots[which == k]
            all_actions[idx] = self.policies[k].act(self._obs[idx])  # type: ignore[index]
