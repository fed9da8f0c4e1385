"""OpenSpiel games as `marl` games: ``openspiel:GAME`` or ``openspiel:GAME(param=value,...)`` (OpenSpiel's own game
string, e.g. ``openspiel:leduc_poker(players=3)``), played through marl's own batched core of N OpenSpiel states.

What marl reads from the game (``pyspiel.load_game(string)``, once per name):

- seats: OpenSpiel's players, ``player_0`` .. ``player_{n-1}``; one role when their spaces agree (they do in
  OpenSpiel's games: a player's index is part of what it observes);
- observation: the player's ``information_state_tensor`` where the game provides one, else its
  ``observation_tensor``, as a float32 Box of the tensor's shape; action: ``Discrete(num_distinct_actions)`` with the
  player's legal actions as the mask;
- turns: a simultaneous-move game (``Dynamics.SIMULTANEOUS``) is ``simultaneous`` (every player acts at a
  simultaneous node, through ``apply_actions``), every other game ``sequential`` (the current player acts);
- kind, from ``get_type().utility``: zero-sum with two players ``two-sides``; identical payoffs (or one player)
  ``cooperative``; anything else (constant-sum, general-sum, zero-sum of more players) ``free-for-all``;
- time limit: ``max_game_length()`` (a core step is one move of the players; chance nodes take none).

Chance nodes are played inside the core by the game's own ``chance_outcomes()`` distribution, drawn from marl's
counter-based generator (:mod:`selfplay_cli.envs.rng`) keyed by the game's reset seed: the same seed deals the same
cards, alone or in a batch. Scores are OpenSpiel's: a game's final score is exactly ``state.returns()``, given at the
end, or step by step where the game rewards along the way (``state.rewards()`` read once a step, after chance, as
OpenSpiel's own ``rl_environment`` reads it; the last step's reward takes the score to the returns). OpenSpiel ends
its games itself, so a game the core plays is always ``terminated``, never ``truncated``. A seat's observation is
refreshed when it is to move (zeros before its first move) and stays its last once the game is over; the masks of
seats not to move are all True (their actions are ignored). OpenSpiel games have no PettingZoo view
(``make_parallel`` says so): marl plays them through this core only.

A game marl cannot play (no tensor observations, chance it samples itself, mean-field games) and a name OpenSpiel
does not know or parameters it refuses are refused in one line naming the game and why. ``pyspiel`` comes with the
optional extra ``[openspiel]`` (``pip install "selfplay-cli[openspiel]"``); without it an ``openspiel:`` name is
refused in one line saying so. Recordings draw ``str(state)`` as text
(:class:`~selfplay_cli.envs.text_frame.TextFrame`).
"""

from __future__ import annotations

import contextlib
import difflib
import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np
from gymnasium import spaces

from ..bots import random_bot
from ..contract import EnvError, EnvSpec, IllegalActionError
from ..rng import game_key_int, uniform_int
from ..seat_spaces import SeatSpace

__all__ = ["EXTRA", "PREFIX", "OpenSpielConfig", "OpenSpielCore", "OpenSpielRenderer", "openspiel_game"]

PREFIX = "openspiel:"
EXTRA = 'pip install "selfplay-cli[openspiel]"'
_SIMULTANEOUS = -2  # pyspiel.PlayerId.SIMULTANEOUS: every player acts at this node
_OVER = -4  # pyspiel.PlayerId.TERMINAL: nobody acts
_CHANCE = -1  # pyspiel.PlayerId.CHANCE: the game draws


def _pyspiel(name: str) -> Any:
    try:
        import pyspiel
    except ImportError:
        raise EnvError(name, f"game {name!r} needs OpenSpiel, which is not installed: {EXTRA} (the extra "
                             "[openspiel])") from None
    return pyspiel


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """OpenSpiel prints every error it raises to the process's stderr (file descriptor 2) before raising it: hold
    that back, so that a bad game string is the one line marl prints."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no real stderr (a captured one): nothing to hold back
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _load(name: str, string: str) -> Any:
    """``pyspiel.load_game(string)``, or an EnvError naming the game and what OpenSpiel said was wrong."""
    pyspiel = _pyspiel(name)
    if not string:
        raise EnvError(name, f"unknown env {name!r}: name an OpenSpiel game after {PREFIX} (e.g. "
                             f"{PREFIX}kuhn_poker, {PREFIX}leduc_poker(players=3))")
    base = string.partition("(")[0].strip()
    known = pyspiel.registered_names()
    if base not in known:
        close = difflib.get_close_matches(base, known, n=3, cutoff=0.6)
        hint = f"; did you mean {', '.join(PREFIX + c for c in close)}?" if close else ""
        raise EnvError(name, f"unknown OpenSpiel game {base!r} in {name!r}{hint} ({len(known)} games: "
                             "python -c 'import pyspiel; print(pyspiel.registered_names())' lists them)")
    try:
        with _quiet_stderr():
            return pyspiel.load_game(string)
    except Exception as e:
        why = " ".join(str(e).split())
        raise EnvError(name, f"OpenSpiel game {name!r} cannot be made: {why}") from None


class OpenSpielConfig:
    """One OpenSpiel game as marl plays it: the loaded game and what marl reads from it (see the module docstring).
    An OpenSpiel game's parameters are part of its name, so a config takes no options."""

    defaults: dict[str, Any] = {}

    def __init__(self, name: str, game: Any) -> None:
        self.name, self.game = name, game
        kind = game.get_type()
        self.long_name = str(kind.long_name)
        self.n_players = int(game.num_players())
        self.n_actions = int(game.num_distinct_actions())
        self.info_state = bool(kind.provides_information_state_tensor)
        shape = game.information_state_tensor_shape() if self.info_state else game.observation_tensor_shape()
        self.shape = tuple(int(x) for x in shape)
        self.size = int(np.prod(self.shape))
        self.simultaneous = str(kind.dynamics).endswith("SIMULTANEOUS")
        self.rewarding = str(kind.reward_model).endswith("REWARDS")  # rewards along the way, not only at the end
        length = int(game.max_game_length())
        self.max_steps = length if length > 0 else None
        self.utility = str(kind.utility).rsplit(".", 1)[-1]
        self.information = str(kind.information).rsplit(".", 1)[-1]
        self.parameters = {str(k): v for k, v in game.get_parameters().items()}

    @property
    def agents(self) -> tuple[str, ...]:
        return tuple(f"player_{p}" for p in range(self.n_players))

    def seat(self) -> SeatSpace:
        box = spaces.Box(-np.inf, np.inf, self.shape, dtype=np.float32)
        return SeatSpace(box, spaces.Discrete(self.n_actions), True)

    def kind(self) -> str:
        if self.utility == "IDENTICAL" or self.n_players == 1:
            return "cooperative"
        if self.utility == "ZERO_SUM" and self.n_players == 2:
            return "two-sides"
        return "free-for-all"

    def stakes(self) -> float | None:
        """A two-player zero-sum game is played for its stakes, the most a player can win (``max_utility()``: poker's
        pot, 2 chips in Kuhn poker, 13 in Leduc; 1 in a board game, whose results are then the usual win, draw or
        loss): a result is worth what was won, so a player is rated by the chips it wins, not the hands."""
        if self.kind() != "two-sides":
            return None
        top = float(self.game.max_utility())
        return top if np.isfinite(top) and top > 0 else None

    def __repr__(self) -> str:
        return f"OpenSpielConfig({self.name})"


def _playable(name: str, game: Any) -> None:
    """Refuse, in one line naming the game and why, an OpenSpiel game marl cannot play."""
    kind = game.get_type()
    why = None
    if str(kind.dynamics).endswith("MEAN_FIELD"):
        why = "it is a mean-field game (marl plays games of players)"
    elif str(kind.chance_mode).endswith("SAMPLED_STOCHASTIC"):
        why = "OpenSpiel samples its chance events itself (marl plays chance from the game's chance_outcomes(), seeded)"
    elif not (kind.provides_information_state_tensor or kind.provides_observation_tensor):
        why = "it provides neither an information_state_tensor nor an observation_tensor (marl's players read tensors)"
    elif game.num_players() < 1:
        why = "it has no players"
    elif game.num_distinct_actions() < 1:
        why = "it has no actions"
    if why is not None:
        raise EnvError(name, f"OpenSpiel game {name!r} cannot be played by marl: {why}")


def openspiel_game(name: str) -> EnvSpec:
    """The :class:`EnvSpec` of ``openspiel:GAME(params)`` (``name``, as the user typed it), or an EnvError saying
    why not (OpenSpiel not installed, an unknown game, a parameter it refuses, a game marl cannot play)."""
    if not name.startswith(PREFIX):
        raise ValueError(f"{name!r} is not an OpenSpiel game name ({PREFIX}GAME)")
    string = name[len(PREFIX):].strip()
    game = _load(name, string)
    _playable(name, game)
    cfg = OpenSpielConfig(name, game)

    def make_config(**options: Any) -> OpenSpielConfig:
        if options:
            raise ValueError(f"{name} takes no --env-option ({', '.join(sorted(options))}): an OpenSpiel game's "
                             f"parameters are part of its name, e.g. {PREFIX}{game.get_type().short_name}"
                             "(players=3)")
        return cfg

    params = ", ".join(f"{k}={v}" for k, v in sorted(cfg.parameters.items()))
    description = (f"OpenSpiel {cfg.long_name}: {cfg.n_players} players, {cfg.utility.lower().replace('_', '-')}, "
                   f"{cfg.information.lower().replace('_', ' ')}; observes its "
                   f"{'information_state_tensor' if cfg.info_state else 'observation_tensor'}"
                   + (f"; parameters {params}" if params else ""))
    seat = cfg.seat()
    spec = EnvSpec(
        name=name,
        description=description,
        agents=cfg.agents,
        make_config=make_config,
        make_core=OpenSpielCore,
        make_parallel=_no_view(name),
        observation_space=lambda c: seat.observation,
        action_space=lambda c: seat.action,
        make_renderer=OpenSpielRenderer,
        bots={"random": random_bot(seat.action, "uniformly random legal moves")},
        turns="simultaneous" if cfg.simultaneous else "sequential",
        kind=cfg.kind(),
        stakes=cfg.stakes(),
        make_seat_spaces=lambda c: (seat,) * c.n_players,
        time_limit=lambda c: c.max_steps,
        render_fps=2,
        option_source=_no_options,
    )
    spec.seat_spaces()
    return spec


def _no_options() -> None:
    """An OpenSpiel game takes no options (``marl envs`` reads this signature): its parameters are in its name."""


def _no_view(name: str) -> Any:
    def make_parallel(**options: Any) -> Any:
        raise EnvError(name, f"game {name!r}: OpenSpiel games are played through marl's own core and have no "
                             "PettingZoo view")

    return make_parallel


# --------------------------------------------------------------------------------------------------------------
class OpenSpielRenderer:
    """A recording's frames of an OpenSpiel game: the game's name, whose move it is (or the returns at the end), and
    ``str(state)`` (OpenSpiel's own text of the state, hidden cards included: a recording is a spectator's view)."""

    def __init__(self) -> None:
        from ..text_frame import TextFrame

        self.frame = TextFrame()

    def draw(self, core: OpenSpielCore, game: int = 0) -> np.ndarray:
        return self.frame.draw(core.text(game))


class OpenSpielCore:
    """N OpenSpiel states stepped as one batched core (see the module's docstring for the rules).

    The hot loop stays in plain Python (each game's turn in a list; the tensors and legal-action masks OpenSpiel
    gives, as lists, queued): the arrays the game loop reads take the queued rows in one assignment a step, on
    demand."""

    def __init__(self, n_games: int, config: OpenSpielConfig) -> None:
        if n_games < 1:
            raise ValueError(f"n_games must be at least 1, not {n_games}")
        self.config, self.game, self.n = config, config.game, n_games
        self.agents = config.agents
        self.n_seats = S = config.n_players
        n = n_games
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        self.score = np.zeros((S, n))
        self.steps = np.zeros(n, dtype=np.int64)
        self.states: list[Any] = [None] * n
        self._obs = np.zeros((S, n, config.size), dtype=np.float32)  # each seat's latest tensor in each game
        self._legal = np.ones((S, n, config.n_actions), dtype=bool)  # ... and its latest legal-action mask
        self._new_obs: list[tuple[int, int, list[float]]] = []  # (seat, game, tensor) not yet in self._obs
        self._new_legal: list[tuple[int, int, list[int]]] = []  # (seat, game, mask) not yet in self._legal
        self._turn = [_OVER] * n  # who acts next in each game: a player, _SIMULTANEOUS, or _OVER
        self._acting: np.ndarray | None = None  # to_act() until the next step or reset
        self._masks: np.ndarray | None = None  # action_masks() until the next step or reset
        self._running = np.zeros(n, dtype=bool)
        self._keys = [0] * n  # each game's random key (from its seed) and the chance draws made so far
        self._draws = [0] * n
        self._last: list[tuple[int, list[int]] | None] = [None] * n  # each game's last move: (player, actions)
        state_type = type(config.game.new_initial_state())
        self._tensor = state_type.information_state_tensor if config.info_state else state_type.observation_tensor
        self._all_seats = list(range(S))
        self.reset(np.arange(n), np.arange(n))

    # ----------------------------------------------------------------------------------------------------
    def reset(self, games: Any, seeds: Any) -> None:
        """Start new games in the slots ``games``, game g dealt from ``seeds[i]``."""
        g_list = np.asarray(games, dtype=np.int64).reshape(-1).tolist()
        s_list = np.asarray(seeds, dtype=np.int64).reshape(-1).tolist()
        if len(g_list) != len(s_list):
            raise ValueError(f"reset got {len(g_list)} games but {len(s_list)} seeds")
        self._acting = self._masks = None
        self._flush()
        self._obs[:, g_list] = 0.0
        rewards = np.zeros((self.n_seats, self.n), dtype=np.float32)
        self.score[:, g_list] = 0.0
        self.steps[g_list] = 0
        self.terminated[g_list] = self.truncated[g_list] = False
        self._running[g_list] = True
        ended: list[tuple[int, list[float]]] = []
        for g, seed in zip(g_list, s_list, strict=True):
            self.states[g] = self.game.new_initial_state()
            self._keys[g], self._draws[g] = game_key_int(seed), 0
            self._last[g] = None
            self._settle(g, self.states[g], ended)
        self._end(ended, rewards)  # a game that chance alone decided

    def _settle(self, g: int, st: Any, ended: list[tuple[int, list[float]]]) -> None:
        """Play game g's chance nodes (state ``st``) by its seeded draws, then either note that it ended (with its
        returns, for :meth:`_end`) or say who acts next and keep what they see and may do."""
        p = st.current_player()
        if p == _CHANCE:
            p = self._chance(g, st)
        if p >= 0:
            self._turn[g] = p
            self._new_obs.append((p, g, self._tensor(st, p)))
            self._new_legal.append((p, g, st.legal_actions_mask(p)))
        elif p == _SIMULTANEOUS:
            self._turn[g] = p
            for q in self._all_seats:
                self._new_obs.append((q, g, self._tensor(st, q)))
                self._new_legal.append((q, g, st.legal_actions_mask(q)))
        else:  # over: each seat's observation stays that of its last move (nothing reads a finished game's)
            self._turn[g] = _OVER
            ended.append((g, st.returns()))

    def _chance(self, g: int, st: Any) -> int:
        """Play game g's chance nodes from their ``chance_outcomes()`` by the game's next draws; the player to act
        after them."""
        p = _CHANCE
        while p == _CHANCE:
            outcomes = st.chance_outcomes()
            u = uniform_int(self._keys[g], self._draws[g])
            self._draws[g] += 1
            action = outcomes[-1][0]
            for a, prob in outcomes:
                u -= prob
                if u < 0.0:
                    action = a
                    break
            st.apply_action(action)
            p = st.current_player()
        return p

    def _flush(self) -> None:
        """Put the queued tensors and masks in their arrays (one assignment each)."""
        if self._new_obs:
            seats, games, rows = zip(*self._new_obs, strict=True)
            self._obs[seats, games] = np.array(rows, dtype=np.float32)
            self._new_obs.clear()
        if self._new_legal:
            seats, games, rows = zip(*self._new_legal, strict=True)
            self._legal[seats, games] = np.array(rows, dtype=bool)
            self._new_legal.clear()

    def _end(self, ended: list[tuple[int, list[float]]], rewards: np.ndarray) -> None:
        """The games that ended: their final score is exactly OpenSpiel's returns (whatever the rewards summed to),
        their last step's reward what takes the score there."""
        if not ended:
            return
        idx = [g for g, _ in ended]
        returns = np.array([r for _, r in ended], dtype=np.float64).T
        rewards[:, idx] = returns - self.score[:, idx]
        self.score[:, idx] = returns
        self._running[idx] = False
        self.terminated[idx] = True

    # ----------------------------------------------------------------------------------------------------
    def to_act(self) -> np.ndarray:
        """``(n_seats, n)`` bool: the seats that act on the next step."""
        if self._acting is None:
            turn = np.array(self._turn)
            acting = np.zeros((self.n_seats, self.n), dtype=bool)
            one = np.flatnonzero(turn >= 0)
            acting[turn[one], one] = True
            acting[:, turn == _SIMULTANEOUS] = True
            self._acting = acting
        return self._acting.copy()

    def observe(self) -> np.ndarray:
        """``(n_seats, n, *shape)`` float32: each seat's latest tensor (zeros before its first move)."""
        self._flush()
        return self._obs.reshape(self.n_seats, self.n, *self.config.shape).copy()

    def action_masks(self) -> list[np.ndarray | None]:
        """Per seat ``(n, n_actions)`` bool: the legal actions of an acting seat, all True for the others."""
        if self._masks is None:
            self.to_act()
            self._flush()
            masks = self._legal.copy()
            masks[~self._acting] = True  # type: ignore[operator]
            self._masks = masks
        return list(self._masks.copy())

    def step(self, actions: Any) -> np.ndarray:
        """Each acting seat's action applied to its game (a simultaneous node's all at once), chance played; returns
        the rewards ``(n_seats, n)`` float32."""
        S, n = self.n_seats, self.n
        if len(actions) != S:
            raise ValueError(f"actions must have one entry per seat ({S}), got {len(actions)}")
        cols = np.empty((S, n), dtype=np.int64)
        for s in range(S):
            a = np.asarray(actions[s])
            if a.shape != (n,):
                raise ValueError(f"seat {s}: Discrete actions must have shape ({n},), got {a.shape}")
            cols[s] = a
        self._check(cols)
        rewards = np.zeros((S, n), dtype=np.float32)
        self.terminated.fill(False)
        self.truncated.fill(False)
        running = np.flatnonzero(self._running)
        by_game = cols.T.tolist()
        rewarding, states, turn, last = self.config.rewarding, self.states, self._turn, self._last
        ended: list[tuple[int, list[float]]] = []
        for g in running.tolist():  # the hot loop
            st, p = states[g], turn[g]
            if p == _SIMULTANEOUS:
                st.apply_actions(by_game[g])
            else:
                st.apply_action(by_game[g][p])
            last[g] = (p, by_game[g])
            self._settle(g, st, ended)
            if rewarding and turn[g] != _OVER:  # read once a step, after chance, as OpenSpiel's rl_environment does
                rewards[:, g] = st.rewards()
        self._acting = self._masks = None
        self.steps[running] += 1
        self._end(ended, rewards)
        live = running[self._running[running]]
        self.score[:, live] += rewards[:, live]
        return rewards

    def _check(self, cols: np.ndarray) -> None:
        """An :class:`IllegalActionError` for an acting seat's action outside its space or not legal now."""
        self.action_masks()
        seat, game = np.nonzero(self._acting)  # type: ignore[arg-type]
        if not seat.size:
            return
        a = cols[seat, game]
        n_actions = self.config.n_actions
        outside = (a < 0) | (a >= n_actions)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            raise IllegalActionError(int(seat[i]), int(game[i]), int(a[i]), f"outside Discrete({n_actions})")
        bad = ~self._masks[seat, game, a]  # type: ignore[index]
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise IllegalActionError(int(seat[i]), int(game[i]), int(a[i]))

    # ----------------------------------------------------------------------------------------------------
    def text(self, game: int = 0) -> list[str]:
        """Game ``game`` as lines of text: the game's name and move, the last move, whose move it is (or the
        returns), and ``str(state)``."""
        st = self.states[game]
        lines = [f"{self.config.long_name} · move {int(self.steps[game])}"]
        last = self._last[game]
        if last is not None:
            p, moves = last
            players = self._all_seats if p == _SIMULTANEOUS else [p]
            lines.append("last: " + ", ".join(f"{self.agents[q]} {st.action_to_string(q, moves[q])}" for q in players))
        if st.is_terminal():
            lines.append("over: " + ", ".join(f"{a} {r:+g}" for a, r in zip(self.agents, st.returns(), strict=True)))
        else:
            p = st.current_player()
            lines.append("all players move" if p == _SIMULTANEOUS else f"{self.agents[p]} to move")
        return [*lines, "", *str(st).splitlines()]

    def render(self, game: int = 0) -> np.ndarray:
        """Game ``game``'s text frame, ``(height, width, 3)`` uint8."""
        return OpenSpielRenderer().draw(self, game)
