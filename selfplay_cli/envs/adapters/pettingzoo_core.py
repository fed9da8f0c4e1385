"""The batched core of a user's PettingZoo game (:class:`PettingZooCore`): N copies stepped as one core, which the
game loops step as they step the built-in games' cores, and their frames for a recording (:class:`PettingZooRenderer`).

``reset(games, seeds)`` resets copies with ``reset(seed=...)``; ``step(actions)`` gives every acting agent its seat's
action; ``score`` is each seat's summed rewards (a seat whose agent left keeps its score); a game is over when no
agent is left in it (``terminated``, or ``truncated`` when an agent was cut by truncation).

Agents come and go. An agent leaves its game when it is terminated or truncated, or when it vanishes from ``agents``
(it died, it finished): from then on it does not act, its observation stays the last it had, and rewards the game
still gives it count in its score. An agent of ``possible_agents`` that is not in the game (it was not there at the
start, or it vanished; one that was terminated or truncated is done with that game) joins when it appears in
``agents``: it acts from then on, played by its seat's policy (its seat is its index in ``possible_agents``), and
observes zeros until then. An agent that is not one of ``possible_agents`` is refused in one line (:class:`EnvError`)
naming it, the game's seed and the step. After each step ``seat_done`` says whose part in a game ended on it (it
left, or the game ended with it in; ``seat_cut``: of those, the ones cut short by truncation) and ``in_game`` who is
in each game, so that a learner stops at its seat's own end, not only at the game's. In an AEC game an agent leaves
when PettingZoo steps it out (its ``step(None)``, on its turn after it was done), so the rewards the game gives it
between its end and then still reach it; a seat's observation is refreshed when its turn comes and when it leaves
the game (zeros before its first turn). The action masks of seats that do not act are all True (their actions are
ignored).

Global state: where the env has a ``state_space`` (PettingZoo's ``state()``: what a centralised critic reads), the
spec declares it (:meth:`~selfplay_cli.envs.contract.EnvSpec.state_space`, read as observations are: a Box as it is,
any other fixed-size space flattened) and the core's ``state()`` gives it for every game, ``(n_games, *shape)``
float32; a game without one has ``state_space()`` None.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from ..contract import EnvError, IllegalActionError
from ..obs_spaces import SeatObs
from ..seat_spaces import SeatSpace
from .pettingzoo_probe import PettingZooConfig, api_of, close_env, spaces_of

__all__ = ["PettingZooCore", "PettingZooRenderer"]


class PettingZooRenderer:
    """Frames of a PettingZoo game: the copy's own ``render()`` (``rgb_array``), as the recorder asks for them."""

    def draw(self, core: PettingZooCore, game: int = 0) -> np.ndarray:
        return core.render(game)


class _Seat:
    """How one seat's actions reach its agent: converted per step from the policy's array to what the env takes."""

    def __init__(self, raw: spaces.Space, seat: SeatSpace) -> None:
        self.space = seat.action
        self.mask = seat.mask
        self.shape = seat.observation.shape
        if isinstance(raw, spaces.Discrete):
            self.kind, self.n, self.start = "discrete", int(raw.n), int(raw.start)
        elif isinstance(raw, spaces.MultiDiscrete):
            self.kind, self.nvec, self.start_vec = "multi", raw.nvec.astype(np.int64), raw.start.astype(np.int64)
        else:
            self.kind, self.dtype, self.box = "box", raw.dtype, raw.shape

    def convert(self, a: Any, n: int, acting: np.ndarray, seat: int) -> list[Any]:
        """Per game, what the env is given; an :class:`IllegalActionError` for an action outside the space."""
        if self.kind == "discrete":
            arr = np.asarray(a)
            if arr.shape != (n,):
                raise ValueError(f"seat {seat}: Discrete actions must have shape ({n},), got {arr.shape}")
            arr = arr.astype(np.int64, copy=False)
            bad = ((arr < 0) | (arr >= self.n)) & acting
            if bad.any():
                g = int(np.flatnonzero(bad)[0])
                raise IllegalActionError(seat, g, int(arr[g]), f"outside Discrete({self.n})")
            return (arr + self.start).tolist() if self.start else arr.tolist()
        if self.kind == "multi":
            arr = np.asarray(a)
            if arr.shape != (n, len(self.nvec)):
                raise ValueError(f"seat {seat}: MultiDiscrete actions must have shape ({n}, {len(self.nvec)}), "
                                 f"got {arr.shape}")
            arr = arr.astype(np.int64)
            bad = ((arr < 0) | (arr >= self.nvec)).any(axis=1) & acting
            if bad.any():
                g = int(np.flatnonzero(bad)[0])
                raise IllegalActionError(seat, g, arr[g].tolist(), f"outside MultiDiscrete({self.nvec.tolist()})")
            return list(arr + self.start_vec)
        arr = np.asarray(a, dtype=self.dtype)
        if arr.shape != (n, *self.box):
            raise ValueError(f"seat {seat}: Box actions must have shape ({n}, {', '.join(map(str, self.box))}), got "
                             f"{arr.shape}")
        return list(arr.copy())


class PettingZooCore:
    """N copies of a PettingZoo game stepped as one batched core (see the module's docstring for the rules)."""

    def __init__(self, n_games: int, config: PettingZooConfig) -> None:
        if n_games < 1:
            raise ValueError(f"n_games must be at least 1, not {n_games}")
        layout = config.layout
        self.config, self.layout, self.n = config, layout, n_games
        self.agents = layout.agents
        self.n_seats = S = len(layout.agents)
        self._seat_of = {a: i for i, a in enumerate(layout.agents)}
        self._aec = layout.api == "aec"
        self._seats = [_Seat(raw, seat) for raw, seat in zip(layout.act_spaces, layout.seats, strict=True)]
        self._masked = any(s.mask for s in self._seats)
        self._reads = [SeatObs(o) for o in layout.obs_spaces]  # each seat's observation as a policy reads it
        self._plain = all(r.raw is r.box for r in self._reads)  # every seat's a Box, read as it is
        shapes = {(s.observation.shape, s.observation.dtype) for s in layout.seats}
        self._stacked = len(shapes) == 1
        self.envs: list[Any] = []
        for i in range(n_games):
            env = layout.make()
            self._check_copy(i, env)
            self.envs.append(env)
        n = n_games
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        self.score = np.zeros((S, n))
        self.steps = np.zeros(n, dtype=np.int64)
        self._zero_obs = [np.zeros(s.observation.shape, dtype=s.observation.dtype) for s in layout.seats]
        self._obs: list[list[Any]] = [[z] * n for z in self._zero_obs]
        self._mask: list[list[Any]] = [[None] * n for _ in range(S)]
        self._live = np.zeros((S, n), dtype=bool)  # the seats whose agents are in each game
        self._live_agents: list[list[tuple[int, str]]] = [[] for _ in range(n)]  # parallel: (seat, agent), in order
        self._live_names: list[list[str]] = [[] for _ in range(n)]  # ... and their names alone (compared per step)
        self._listed: list[list[str] | None] = [None] * n  # AEC: each game's agents when last seen
        self._done_agents: list[set[str]] = [set() for _ in range(n)]  # parallel: agents done in each game (no return)
        self.seat_done = np.zeros((S, n), dtype=bool)  # set by step(): whose part in a game ended on it
        self.seat_cut = np.zeros((S, n), dtype=bool)  # ... of those, the ones cut short (truncated)
        self._seeds = [0] * n  # each game's seed (to name the game in an error)
        self._turn = [-1] * n  # AEC: the seat whose turn it is in each game, -1 when it is over
        self._acting: np.ndarray | None = None  # to_act() until the next step or reset
        self._ones = [np.ones(seat.action.n, dtype=bool) if seat.mask else None for seat in layout.seats]
        self._running = np.zeros(n, dtype=bool)
        self._cut = np.zeros(n, dtype=bool)  # an agent of the game left by truncation
        self.reset(np.arange(n), np.arange(n))

    def _check_copy(self, i: int, env: Any) -> None:
        name, lay = self.layout.name, self.layout
        api = api_of(name, env)
        if api != lay.api or tuple(env.possible_agents) != lay.agents:
            raise EnvError(name, f"game {name!r}: copy {i} is a {api} env with agents {list(env.possible_agents)}, "
                                 f"the first was a {lay.api} env with {list(lay.agents)}: marl needs every copy "
                                 "of a game to be alike")
        obs, act = spaces_of(name, env, lay.agents)
        for agent, o, a, o0, a0 in zip(lay.agents, obs, act, lay.obs_spaces, lay.act_spaces, strict=True):
            for what, got, first in (("observation", o, o0), ("action", a, a0)):
                if got is not first and got != first:
                    raise EnvError(name, f"game {name!r}: copy {i} has {what} space {got} for seat {agent!r}, the "
                                         f"first copy {first}: marl needs every copy of a game to have the same "
                                         "spaces")

    # ----------------------------------------------------------------------------------------------------
    def _store(self, seat: int, g: int, o: Any) -> None:
        read = self._reads[seat]
        self._obs[seat][g], mask = read.split(o)
        if read.mask_space is not None:
            self._mask[seat][g] = mask

    def reset(self, games: Any, seeds: Any) -> None:
        """Start new games in the slots ``games``, copy g with ``reset(seed=seeds[i])``."""
        g_list = np.asarray(games, dtype=np.int64).reshape(-1).tolist()
        s_list = np.asarray(seeds).reshape(-1).tolist()
        if len(g_list) != len(s_list):
            raise ValueError(f"reset got {len(g_list)} games but {len(s_list)} seeds")
        self._acting = None
        for g, seed in zip(g_list, s_list, strict=True):
            env = self.envs[g]
            self._seeds[g] = int(seed)
            self.score[:, g] = 0.0
            self.steps[g] = 0
            self.terminated[g] = self.truncated[g] = self._cut[g] = False
            for s in range(self.n_seats):
                self._obs[s][g] = self._zero_obs[s]
                self._mask[s][g] = None
            self._live[:, g] = self.seat_done[:, g] = self.seat_cut[:, g] = False
            if self._aec:  # each seat observes when its turn comes (zeros until then)
                env.reset(seed=int(seed))
                self._running[g] = True
                self._listed[g] = agents = list(env.agents)
                for agent in agents:
                    s = self._seat_of.get(agent)
                    self._live[self._seat(g, agent) if s is None else s, g] = True
                self._settle(g)
            else:
                obs, _ = env.reset(seed=int(seed))
                self._done_agents[g] = set()
                live = []
                for agent in env.agents:
                    s = self._seat(g, agent)
                    live.append((s, agent))
                    self._live[s, g] = True
                    self._store(s, g, obs[agent])
                self._live_agents[g] = live
                self._live_names[g] = [a for _, a in live]
                self._running[g] = bool(live)

    @property
    def in_game(self) -> np.ndarray:
        """``(n_seats, n)`` bool: the seats whose agents are in each game now (none in a game that is over)."""
        return self._live.copy()

    def _seat(self, g: int, agent: Any) -> int:
        """The seat of ``agent``, which is in game g; an :class:`EnvError` for one not among ``possible_agents``."""
        s = self._seat_of.get(agent)
        if s is None:
            name = self.layout.name
            raise EnvError(name, f"game {name!r}: agent {agent!r} is in the game of seed {self._seeds[g]} at its step "
                                 f"{int(self.steps[g])} but is not one of its possible_agents "
                                 f"({', '.join(self.agents)}): marl plays a seat for each of possible_agents only")
        return s

    def _leaves(self, s: int, g: int, cut: bool = False) -> None:
        """Seat s's agent left game g on this step (``cut``: by truncation)."""
        self._live[s, g] = False
        self.seat_done[s, g] = True
        if cut:
            self.seat_cut[s, g] = True
            self._cut[g] = True

    def _settle(self, g: int) -> None:
        """AEC: step the agents that are done out of the game (PettingZoo's ``step(None)``), keeping their final
        observation, until a live agent has the turn or nobody is left; then see who else left or joined."""
        env, seat_of = self.envs[g], self._seat_of
        while agents := env.agents:
            agent = env.agent_selection
            s = seat_of.get(agent)
            if s is None:
                s = self._seat(g, agent)  # (refused)
            term, trunc = env.terminations.get(agent, False), env.truncations.get(agent, False)
            self._store(s, g, env.observe(agent))
            if not (term or trunc):
                self._turn[g] = s
                if agents != self._listed[g]:
                    self._present(g, agents)
                return
            env.step(None)
            if self._live[s, g]:
                self._leaves(s, g, cut=bool(trunc and not term))
        self._turn[g] = -1
        if self._running[g]:
            self._over(g)

    def _present(self, g: int, agents: list[str]) -> None:
        """AEC: the seats in game g as its ``agents`` now are (they changed since last seen): one that vanished left
        it, one that appeared joined."""
        live = self._live[:, g]
        self._listed[g] = list(agents)
        now = np.zeros(self.n_seats, dtype=bool)
        for a in agents:
            now[self._seat(g, a)] = True
        for s in np.flatnonzero(live & ~now).tolist():
            self._leaves(s, g)
        live[now] = True

    # ----------------------------------------------------------------------------------------------------
    def to_act(self) -> np.ndarray:
        """``(n_seats, n)`` bool: the seats that act on the next step."""
        if self._acting is None:
            if self._aec:
                acting = np.zeros((self.n_seats, self.n), dtype=bool)
                turn = np.array(self._turn)
                g = np.flatnonzero((turn >= 0) & self._running)  # a finished game's seats wait for its reset
                acting[turn[g], g] = True
            else:
                acting = self._live & self._running
            self._acting = acting
        return self._acting.copy()

    def observe(self) -> Any:
        """Per seat ``(n, *shape)`` of the seat's dtype (float32; an image's uint8): one array ``(n_seats, n, ...)``
        if all seats have one shape and dtype, else a list."""
        n = self.n
        if self._stacked:
            out = np.empty((self.n_seats, n, *self._zero_obs[0].shape), dtype=self._zero_obs[0].dtype)
            for s in range(self.n_seats):
                self._stack(s, out[s])
            return out
        outs = []
        for s in range(self.n_seats):
            buf = np.empty((n, *self._zero_obs[s].shape), dtype=self._zero_obs[s].dtype)
            self._stack(s, buf)
            outs.append(buf)
        return outs

    def _stack(self, s: int, out: np.ndarray) -> None:
        try:
            np.stack(self._obs[s], out=out, casting="unsafe")
        except ValueError:
            for g, o in enumerate(self._obs[s]):
                got = np.shape(o)
                if got != out.shape[1:]:
                    raise EnvError(self.layout.name, f"game {self.layout.name!r}: seat {self.agents[s]!r} observed "
                                                     f"shape {got} in game slot {g}, its space declares "
                                                     f"{out.shape[1:]}") from None
            raise

    def action_masks(self) -> list[np.ndarray | None]:
        """Per seat ``(n, n_actions)`` bool for seats with masks (all True where the seat does not act), else
        None."""
        out: list[np.ndarray | None] = []
        acting = self.to_act().tolist() if self._masked else None
        for s, seat in enumerate(self._seats):
            if not seat.mask:
                out.append(None)
                continue
            ones, masks = self._ones[s], self._mask[s]
            rows = [ones] * self.n
            for g, a in enumerate(acting[s]):
                if a and masks[g] is not None:
                    rows[g] = masks[g]
            m = np.empty((self.n, seat.space.n), dtype=bool)
            try:
                np.stack(rows, out=m, casting="unsafe")
            except ValueError:
                raise EnvError(self.layout.name, f"game {self.layout.name!r}: seat {self.agents[s]!r} gave an "
                                                 f"action_mask of another shape than ({seat.space.n},)") from None
            out.append(m)
        return out

    def _check_masks(self, cols: list[list[Any]], acting: np.ndarray) -> None:
        for s, seat in enumerate(self._seats):
            if not seat.mask:
                continue
            masks, col, start = self._mask[s], cols[s], seat.start
            for g, a in enumerate(acting[s].tolist()):
                if a:
                    m = masks[g]
                    if m is not None and not m[col[g] - start]:
                        raise IllegalActionError(s, g, col[g] - start)

    def step(self, actions: Any) -> np.ndarray:
        """Advance every running game one step; returns the rewards ``(n_seats, n)`` float32."""
        S, n = self.n_seats, self.n
        if len(actions) != S:
            raise ValueError(f"actions must have one entry per seat ({S}), got {len(actions)}")
        acting = self.to_act()
        cols = [seat.convert(actions[s], n, acting[s], s) for s, seat in enumerate(self._seats)]
        if self._masked:
            self._check_masks(cols, acting)
        rewards = np.zeros((S, n), dtype=np.float32)
        self._acting = None
        self.terminated.fill(False)
        self.truncated.fill(False)
        self.seat_done.fill(False)
        self.seat_cut.fill(False)
        running = np.flatnonzero(self._running)
        self.steps[running] += 1  # (first: an error on this step names it)
        if self._aec:
            self._step_aec(running.tolist(), cols, rewards)
        else:
            self._step_parallel(running.tolist(), cols, rewards)
        self.score += rewards
        return rewards

    def _step_parallel(self, games: list[int], cols: list[list[Any]], rewards: np.ndarray) -> None:
        seat_of, envs, live_agents, obs_of = self._seat_of, self.envs, self._live_agents, self._obs
        live_names = self._live_names
        plain, splits, masks_of = self._plain, [r.split for r in self._reads], self._mask
        masked = [r.mask_space is not None for r in self._reads]
        for g in games:  # the hot loop: plain loops, no comprehensions (each would build a function in 3.11)
            live = live_agents[g]
            act = {}
            for s, agent in live:
                act[agent] = cols[s][g]
            env = envs[g]
            obs, rew, term, trunc, _ = env.step(act)
            for agent, r in rew.items():
                if r:
                    s = seat_of.get(agent)
                    if s is not None:
                        rewards[s, g] = r
            for s, agent in live:
                o = obs.get(agent)
                if o is not None:
                    if plain:
                        obs_of[s][g] = o
                    else:  # _store, inlined
                        obs_of[s][g], m = splits[s](o)
                        if masked[s]:
                            masks_of[s][g] = m
            if True in term.values() or True in trunc.values() or env.agents != live_names[g]:
                self._come_and_go(g, obs, term, trunc)

    def _come_and_go(self, g: int, obs: Mapping[str, Any], term: Mapping[str, Any], trunc: Mapping[str, Any]) -> None:
        """Parallel game g after a step where its agents changed: those done (terminated or truncated) or gone from
        ``agents`` leave it, those of ``possible_agents`` that appeared join it (their first observation stored);
        the game is over when none is left."""
        present = self.envs[g].agents
        was = {a: s for s, a in self._live_agents[g]}
        listed, done = set(present), self._done_agents[g]
        for a, s in was.items():
            ended, cut = term.get(a), trunc.get(a)
            if ended or cut:
                done.add(a)
            if ended or cut or a not in listed:
                self._leaves(s, g, cut=bool(cut and not ended))
        stay = []
        for a in present:
            if a in done:  # (an agent done in this game that the env still lists has left all the same)
                continue
            s = was.get(a)
            if s is None:  # one of possible_agents that was not in the game: it joins
                s = self._seat(g, a)
                self._live[s, g] = True
                o = obs.get(a)
                if o is not None:
                    self._store(s, g, o)
            stay.append((s, a))
        self._live_agents[g] = stay
        self._live_names[g] = [a for _, a in stay]
        if not stay:
            self._over(g)

    def _over(self, g: int) -> None:
        self.seat_done[:, g] |= self._live[:, g]  # the seats still in it: their part ends with the game
        self._live[:, g] = False
        self._live_agents[g] = []
        self._live_names[g] = []
        self._running[g] = False
        self.truncated[g] = bool(self._cut[g])
        self.terminated[g] = not self._cut[g]

    def _step_aec(self, games: list[int], cols: list[list[Any]], rewards: np.ndarray) -> None:
        seat_of, envs, turn = self._seat_of, self.envs, self._turn
        for g in games:
            env = envs[g]
            env.step(cols[turn[g]][g])
            for agent, r in env.rewards.items():
                if r:
                    s = seat_of.get(agent)
                    if s is not None:
                        rewards[s, g] += r
            self._settle(g)

    def state(self) -> np.ndarray:
        """Every game's global state as its env's ``state()`` gives it, ``(n, *shape)`` float32 (games that are over
        and not yet reset: their final state). An :class:`EnvError` for a game that gives none, or one of another
        shape than its ``state_space``."""
        name, read = self.layout.name, self.layout.state
        if read is None:
            raise EnvError(name, f"game {name!r} gives no global state (its env has no state_space)")
        shape = self.layout.state_box.shape  # type: ignore[union-attr]
        out = np.empty((self.n, *shape), dtype=np.float32)
        for g, env in enumerate(self.envs):
            try:
                x, _ = read.split(env.state())
                out[g] = x
            except ValueError as e:
                raise EnvError(name, f"game {name!r}: state() in game slot {g} does not fit its state_space "
                                     f"{self.layout.state_space}: {e}") from None
        return out

    # ----------------------------------------------------------------------------------------------------
    def render(self, game: int = 0) -> np.ndarray:
        """The frame of copy ``game`` as its own ``render()`` draws it: ``(height, width, 3)`` uint8."""
        name = self.layout.name
        if not self.layout.renders:
            raise EnvError(name, f"game {name!r} cannot be recorded: its metadata render_modes has no 'rgb_array'")
        frame = self.envs[game].render()
        arr = np.asarray(frame) if frame is not None else None
        if arr is None or arr.ndim != 3 or arr.shape[2] != 3:
            got = "None" if arr is None else f"an array of shape {arr.shape}"
            raise EnvError(name, f"game {name!r}: render() returned {got}, not an RGB frame (height, width, 3)")
        return arr if arr.dtype == np.uint8 else np.clip(arr, 0, 255).astype(np.uint8)

    def close(self) -> None:
        for env in self.envs:
            close_env(env)
