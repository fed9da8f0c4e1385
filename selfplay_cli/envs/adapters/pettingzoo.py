"""Any PettingZoo game as a `marl` game: an :class:`EnvSpec` probed from one instance, and a batched core of N
copies, which the arena steps as it steps the built-in games' cores.

``adapt(name, factory)`` calls ``factory(**options)`` once and reads the game's declaration from it:

- seats: ``possible_agents`` (names, in order); per seat the observation space (any of a fixed size: a Box as it is,
  Discrete, MultiDiscrete, MultiBinary, Tuples and Dicts of them flattened, a top-level Dict's ``action_mask`` taken
  as the seat's mask: :mod:`selfplay_cli.envs.obs_spaces`) and the action space (Discrete, MultiDiscrete, Box);
- turns: a ``ParallelEnv`` is simultaneous, an ``AECEnv`` sequential (its ``agent_selection`` acts);
- kind: ``env.metadata["marl_kind"]`` (``"two-sides"``, ``"cooperative"`` or ``"free-for-all"``); a game whose
  metadata does not say takes it from its ``kind`` option (``--kind`` of ``marl train``, ``--env-option kind=...``
  elsewhere: a PettingZoo game's metadata is not the user's to edit), and by default a game of 2 seats is two-sides,
  of one seat cooperative, of more free-for-all. ``metadata["marl_sides"]`` (the seats, by index or agent name, of
  each of the two sides) and ``metadata["marl_tie_tolerance"]`` complete it. The kind is part of the game's
  identity: results under another kind are another variant, rated apart; ``EnvSpec.kind_from`` says where it came
  from (``metadata``, ``option`` or ``agents``, the default by their number);
- team size: options may change the agents (pursuit's ``n_pursuers``): each config is probed, and
  ``EnvSpec.for_options`` declares the game with that config's agents, kind and roles, as the lander's ``landers``
  option does (the API, parallel or AEC, must stay the same);
- roles: ``metadata["marl_roles"]``, the role of each agent (a list in ``possible_agents`` order, or a dict from
  agent name to role); by default agents whose spaces agree share a role (see
  :meth:`~selfplay_cli.envs.registry.EnvSpec.seat_roles`);
- time limit: ``metadata["marl_max_steps"]``, else the env's ``max_cycles`` (times the seats for an AEC game, a
  core step being one agent's move), else none;
- recording: when ``metadata["render_modes"]`` lists ``"rgb_array"``, every copy is made with
  ``render_mode="rgb_array"`` (PettingZoo draws such frames only when ``render()`` is called) and the game's own
  ``render()`` makes the video's frames, at ``metadata["render_fps"]`` frames a second by default.

The core (:class:`PettingZooCore`) steps N copies: ``reset(games, seeds)`` resets copies with ``reset(seed=...)``;
``step(actions)`` gives every acting agent its seat's action; ``score`` is each seat's summed rewards (a seat whose
agent left keeps its score); a game is over when no agent is left in it (``terminated``, or ``truncated`` when an
agent was cut by truncation).

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
spec declares it (:meth:`~selfplay_cli.envs.registry.EnvSpec.state_space`, read as observations are: a Box as it is,
any other fixed-size space flattened) and the core's ``state()`` gives it for every game, ``(n_games, *shape)``
float32; a game without one has ``state_space()`` None.
"""

from __future__ import annotations

import contextlib
import inspect
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv

from ..obs_spaces import SeatObs
from ..registry import KINDS, EnvError, EnvSpec, IllegalActionError, SeatSpace, SpaceError, random_bot, seat_space_of

__all__ = ["Layout", "PettingZooConfig", "PettingZooCore", "PettingZooRenderer", "adapt", "probe"]


class Layout:
    """What one instance of a game declares (for given options): the API, the seats and their spaces, and the
    global state's space (``state_space``, the env's own; None when it has none) and how it is read
    (``state``: None, or a :class:`SeatObs` whose ``box`` is what ``state()`` gives)."""

    def __init__(self, name: str, make: Callable[[], Any], api: str, agents: tuple[str, ...],
                 obs_spaces: tuple[spaces.Space, ...], act_spaces: tuple[spaces.Space, ...],
                 seats: tuple[SeatSpace, ...], metadata: Mapping[str, Any], max_steps: int | None,
                 renders: bool, state_space: spaces.Space | None = None) -> None:
        self.name, self.make, self.api, self.agents = name, make, api, agents
        self.obs_spaces, self.act_spaces, self.seats = obs_spaces, act_spaces, seats
        self.metadata, self.max_steps, self.renders = metadata, max_steps, renders
        self.state_space = state_space
        self.state = None if state_space is None else SeatObs(state_space)

    @property
    def state_box(self) -> spaces.Box | None:
        """What the core's ``state()`` gives for one game (float32), or None."""
        if self.state is None:
            return None
        box = self.state.box
        return spaces.Box(np.asarray(box.low, np.float32), np.asarray(box.high, np.float32), dtype=np.float32)


class PettingZooConfig:
    """The options a game is made with (passed to its factory as keyword arguments) and what they make."""

    __slots__ = ("options", "layout", "defaults", "kind", "kind_from", "sides")

    def __init__(self, options: Mapping[str, Any], layout: Layout,
                 defaults: Mapping[str, Any] | None = None, kind: str | None = None,
                 kind_from: str = "agents", sides: tuple[tuple[int, ...], ...] | None = None) -> None:
        self.options = dict(options)  # what the factory is called with (``kind`` is marl's, not the factory's)
        self.layout = layout
        self.defaults = dict(defaults or {})  # the factory's keyword defaults: an option given at its default is none
        self.kind = kind or default_kind(len(layout.agents))
        self.kind_from, self.sides = kind_from, sides

    @property
    def max_steps(self) -> int | None:
        return self.layout.max_steps

    def __repr__(self) -> str:
        return f"PettingZooConfig({self.layout.name}, {self.options})"


# --------------------------------------------------------------------------------------------------------------
def _takes_render_mode(factory: Callable[..., Any]) -> bool:
    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(p.name == "render_mode" or p.kind is inspect.Parameter.VAR_KEYWORD for p in params)


def _make(name: str, factory: Callable[..., Any], options: Mapping[str, Any], render_mode: str | None) -> Any:
    kwargs = dict(options)
    if render_mode is not None:
        kwargs["render_mode"] = render_mode
    try:
        return factory(**kwargs)
    except TypeError as e:
        if options:  # most often an option the factory does not take: a mistake in the command
            raise ValueError(f"{name} does not take the options {', '.join(sorted(options))}: {e}") from None
        raise EnvError(name, f"game {name!r}: calling its factory failed: TypeError: {e}") from None
    except (ValueError, AssertionError) as e:
        if options:
            raise ValueError(f"{name} refused the options {dict(options)}: {type(e).__name__}: {e}") from None
        raise EnvError(name, f"game {name!r}: calling its factory failed: {type(e).__name__}: {e}") from None
    except Exception as e:  # the user's code failed: say where, in one line
        raise EnvError(name, f"game {name!r}: calling its factory failed: {type(e).__name__}: {e}") from None


def _api_of(name: str, env: Any) -> str:
    if isinstance(env, ParallelEnv):
        return "parallel"
    if isinstance(env, AECEnv):
        return "aec"
    raise EnvError(name, f"game {name!r}: its factory returned a {type(env).__module__}.{type(env).__qualname__}, "
                         "not a PettingZoo env (an AECEnv or a ParallelEnv)")


def _spaces_of(name: str, env: Any, agents: tuple[str, ...]) -> tuple[tuple[spaces.Space, ...], ...]:
    try:
        obs = tuple(env.observation_space(a) for a in agents)
        act = tuple(env.action_space(a) for a in agents)
    except Exception as e:
        raise EnvError(name, f"game {name!r}: reading its spaces failed: {type(e).__name__}: {e}") from None
    return obs, act


def _state_space_of(env: Any) -> spaces.Space | None:
    """The env's ``state_space`` (PettingZoo's global state), None when it declares none, or one of no fixed size
    (a Graph, a Sequence: the game plays on without a state, as a game that gives none)."""
    try:
        space = getattr(env, "state_space", None)
    except Exception:  # a wrapper that raises for an attribute its env lacks: no state
        return None
    if space is None or not isinstance(space, spaces.Space):
        return None
    try:
        SeatObs(space)
    except ValueError:
        return None
    return space


def _max_steps(name: str, env: Any, api: str, n_agents: int, metadata: Mapping[str, Any]) -> int | None:
    limit = metadata.get("marl_max_steps")
    if limit is None:
        cycles = getattr(env, "max_cycles", None)
        if cycles is None:
            cycles = getattr(getattr(env, "unwrapped", None), "max_cycles", None)
        if isinstance(cycles, (int, np.integer)) and not isinstance(cycles, bool) and cycles > 0:
            return int(cycles) * (n_agents if api == "aec" else 1)
        return None
    if isinstance(limit, bool) or not isinstance(limit, (int, np.integer)) or limit < 1:
        raise EnvError(name, f"game {name!r}: metadata marl_max_steps must be a whole number >= 1, not {limit!r}")
    return int(limit)


def probe(name: str, factory: Callable[..., Any], options: Mapping[str, Any] | None = None) -> Layout:
    """Make one instance with ``options`` and read its declaration; an :class:`EnvError` (or a ValueError for
    options the factory refuses) saying why the game cannot be played."""
    options = dict(options or {})
    env = _make(name, factory, options, None)
    try:
        api = _api_of(name, env)
        try:
            agents = tuple(env.possible_agents)
        except Exception as e:
            raise EnvError(name, f"game {name!r} has no possible_agents: {type(e).__name__}: {e}") from None
        if not agents:
            raise EnvError(name, f"game {name!r} has no agents (possible_agents is empty)")
        if not all(isinstance(a, str) and a for a in agents) or len(set(agents)) != len(agents):
            raise EnvError(name, f"game {name!r}: its agents must be distinct non-empty names (text), not "
                                 f"{list(agents)!r}")
        obs, act = _spaces_of(name, env, agents)
        seats = []
        for agent, o, a in zip(agents, obs, act, strict=True):
            try:
                seats.append(seat_space_of(o, a))
            except SpaceError as e:
                raise EnvError(name, f"game {name!r}, seat {agent!r}: {e}") from None
        metadata = dict(getattr(env, "metadata", None) or {})
        renders = "rgb_array" in (metadata.get("render_modes") or ())
        render_mode = "rgb_array" if renders and _takes_render_mode(factory) else None
        renders = renders and render_mode is not None
        max_steps = _max_steps(name, env, api, len(agents), metadata)
        state_space = _state_space_of(env)
    finally:
        _close(env)

    def make() -> Any:
        return _make(name, factory, options, render_mode)

    return Layout(name, make, api, agents, obs, act, tuple(seats), metadata, max_steps, renders, state_space)


def _close(env: Any) -> None:
    with contextlib.suppress(Exception):  # closing is a courtesy; a game that fails at it has nothing to lose
        env.close()


def _keyword_defaults(factory: Callable[..., Any]) -> dict[str, Any]:
    """The keyword arguments ``factory`` declares with a default, and their defaults (none when it cannot say)."""
    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):
        return {}
    return {p.name: p.default for p in params if p.default is not inspect.Parameter.empty
            and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)}


def _option_key(options: Mapping[str, Any]) -> Any:
    try:
        key = tuple(sorted(options.items()))
        hash(key)
        return key
    except TypeError:
        return repr(sorted(options.items(), key=lambda kv: kv[0]))


KIND_OPTION = "kind"
"""The option that gives a game whose metadata does not declare its kind one (``--kind`` of ``marl train``)."""


def default_kind(n_agents: int) -> str:
    """The kind of a game that declares none: two-sides for 2 agents, cooperative for one, free-for-all for more."""
    return "two-sides" if n_agents == 2 else ("cooperative" if n_agents == 1 else "free-for-all")


def _kind_of(name: str, layout: Layout, option: str | None = None
             ) -> tuple[str, tuple[tuple[int, ...], ...] | None, float, str]:
    """The game's kind, sides, tie tolerance and where the kind came from (``metadata``, ``option``, ``agents``)."""
    md, agents = layout.metadata, layout.agents
    kind, source = md.get("marl_kind"), "metadata"
    if kind is None and option is not None:
        kind, source = option, "option"
        if kind not in KINDS:
            raise ValueError(f"{name}: kind must be one of {', '.join(KINDS)}, not {kind!r}")
    elif kind is None:
        kind, source = default_kind(len(agents)), "agents"
    elif option is not None and option != kind:
        raise ValueError(f"{name} declares its kind in its metadata ({kind}): the kind option is for games that do "
                         "not")
    if kind not in KINDS:
        raise EnvError(name, f"game {name!r}: metadata marl_kind must be one of {', '.join(KINDS)}, not {kind!r}")
    sides = md.get("marl_sides")
    if sides is not None:
        try:
            sides = tuple(tuple(agents.index(s) if isinstance(s, str) else int(s) for s in side) for side in sides)
        except (TypeError, ValueError):
            raise EnvError(name, f"game {name!r}: metadata marl_sides must list the seats (indices or agent "
                                 f"names) of each side, not {md.get('marl_sides')!r}") from None
    elif kind == "two-sides" and len(agents) != 2:
        if source == "option":
            raise ValueError(f"{name} has {len(agents)} agents: a two-sides game of other than 2 agents needs its "
                             "sides (the game's metadata marl_sides), which it does not declare")
        raise EnvError(name, f"game {name!r} has {len(agents)} agents: a two-sides game of other than 2 agents "
                             "must declare metadata marl_sides (the agents of each side)")
    if sides is not None and kind != "two-sides":
        sides = None  # the sides of a game played, by the option, as a team or every agent for itself
    tol = md.get("marl_tie_tolerance", 0.0)
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol) or tol < 0:
        raise EnvError(name, f"game {name!r}: metadata marl_tie_tolerance must be a number >= 0, not {tol!r}")
    return kind, sides, float(tol), source


def _roles_of(name: str, layout: Layout) -> tuple[str, ...] | None:
    """``metadata["marl_roles"]`` as one role per seat, or None when the game does not declare them."""
    roles, agents = layout.metadata.get("marl_roles"), layout.agents
    if roles is None:
        return None
    if isinstance(roles, dict) and set(roles) == set(agents):
        roles = [roles[a] for a in agents]
    if (not isinstance(roles, (list, tuple)) or len(roles) != len(agents)
            or not all(isinstance(r, str) and r for r in roles)):
        raise EnvError(name, f"game {name!r}: metadata marl_roles must give each agent ({', '.join(agents)}) a role "
                             f"name, as a list in that order or a dict by agent, not {roles!r}")
    return tuple(roles)


def adapt(name: str, factory: Callable[..., Any], description: str | None = None) -> EnvSpec:
    """The :class:`EnvSpec` of the PettingZoo game that ``factory(**options)`` makes, probed with no options."""
    if not callable(factory):
        raise EnvError(name, f"game {name!r}: {factory!r} is not callable (marl needs a function that returns a "
                             "PettingZoo env)")
    default = probe(name, factory)
    layouts: dict[Any, Layout] = {(): default}
    defaults = _keyword_defaults(factory)
    kind, sides, tol, kind_from = _kind_of(name, default)
    # A game that does not declare its kind takes the kind option, unless its factory has an option of that name.
    kind_option = kind_from != "metadata" and KIND_OPTION not in defaults
    if kind_option:
        defaults[KIND_OPTION] = kind

    def make_config(**options: Any) -> PettingZooConfig:
        chosen = options.pop(KIND_OPTION, None) if kind_option else None
        if not kind_option and KIND_OPTION in options and KIND_OPTION not in defaults:
            given = options.pop(KIND_OPTION)  # the kind the game declares, given again: nothing to choose
            if given != kind:
                raise ValueError(f"{name} declares its kind in its metadata ({kind}): the kind option is for games "
                                 "that do not")
        key = _option_key(options)
        layout = layouts.get(key)
        if layout is None:
            layout = probe(name, factory, options)
            if layout.api != default.api:
                raise ValueError(f"{name} with options {options} is a {layout.api} game, not {default.api}: options "
                                 "that change a game's API are not supported (register each as its own game)")
            if len(layouts) < 64:
                layouts[key] = layout
        k, s, _, src = _kind_of(name, layout, None if chosen is None else str(chosen))
        return PettingZooConfig(options, layout, defaults, k, src, s)

    fps = default.metadata.get("render_fps")
    fps = int(fps) if isinstance(fps, (int, float)) and not isinstance(fps, bool) and 1 <= fps <= 240 else None
    first = default.seats[0].action
    same = all(s.action == first for s in default.seats)
    bots = {"random": random_bot(first)} if same else {}
    text = description or default.metadata.get("marl_description") or (
        f"PettingZoo {'AEC' if default.api == 'aec' else 'parallel'} game "
        f"{default.metadata.get('name') or getattr(factory, '__qualname__', name)}")
    try:
        spec = EnvSpec(
            name=name,
            description=str(text),
            agents=default.agents,
            make_config=make_config,
            make_core=PettingZooCore,
            make_parallel=lambda **options: factory(**options),
            observation_space=lambda cfg: cfg.layout.seats[0].observation,
            action_space=lambda cfg: cfg.layout.seats[0].action,
            make_renderer=PettingZooRenderer if default.renders else None,
            bots=bots,
            turns="sequential" if default.api == "aec" else "simultaneous",
            kind=kind,
            sides=sides,
            tie_tolerance=tol,
            make_seat_spaces=lambda cfg: cfg.layout.seats,
            make_state_space=lambda cfg: cfg.layout.state_box,
            time_limit=lambda cfg: cfg.layout.max_steps,
            render_fps=fps if default.renders else None,
            neutral_options=("render_mode",),  # how it is drawn: marl sets it itself to record
            option_source=factory,
            roles=_roles_of(name, default),
            make_agents=lambda cfg: cfg.layout.agents,
            make_kind=lambda cfg: (cfg.kind, cfg.sides, cfg.kind_from),
            make_roles=lambda cfg: _roles_of(name, cfg.layout),
            kind_from=kind_from,
        )
    except ValueError as e:
        raise EnvError(name, str(e)) from None
    spec.seat_spaces()  # declared roles must keep to the seats' spaces: refused here, in one line, if not
    return spec


# --------------------------------------------------------------------------------------------------------------
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
        api = _api_of(name, env)
        if api != lay.api or tuple(env.possible_agents) != lay.agents:
            raise EnvError(name, f"game {name!r}: copy {i} is a {api} env with agents {list(env.possible_agents)}, "
                                 f"the first was a {lay.api} env with {list(lay.agents)}: marl needs every copy "
                                 "of a game to be alike")
        obs, act = _spaces_of(name, env, lay.agents)
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
            _close(env)
