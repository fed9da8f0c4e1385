"""What a user's PettingZoo game declares, read from the game itself: one instance made with given options and
read (:func:`probe`: the API, the agents and their spaces, the metadata, the time limit, whether it renders, the
global state's space, as a :class:`Layout`), what its metadata says of its kind, sides, tie tolerance and roles
(:func:`kind_of`, :func:`roles_of`), the options its factory takes (:func:`keyword_defaults`) and the config a game
is made with (:class:`PettingZooConfig`). :mod:`selfplay_cli.envs.adapters.pettingzoo` lists the rules and makes the
game's :class:`~selfplay_cli.envs.contract.EnvSpec` from these.
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

from ..contract import KINDS, EnvError
from ..obs_spaces import SeatObs
from ..seat_spaces import SeatSpace, SpaceError, seat_space_of

__all__ = ["KIND_OPTION", "Layout", "PettingZooConfig", "api_of", "close_env", "default_kind", "keyword_defaults",
           "kind_of", "probe", "roles_of", "spaces_of"]


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


def api_of(name: str, env: Any) -> str:
    """``"parallel"`` or ``"aec"``: the API of the env a factory made, or an :class:`EnvError` for no PettingZoo env."""
    if isinstance(env, ParallelEnv):
        return "parallel"
    if isinstance(env, AECEnv):
        return "aec"
    raise EnvError(name, f"game {name!r}: its factory returned a {type(env).__module__}.{type(env).__qualname__}, "
                         "not a PettingZoo env (an AECEnv or a ParallelEnv)")


def spaces_of(name: str, env: Any, agents: tuple[str, ...]) -> tuple[tuple[spaces.Space, ...], ...]:
    """The observation spaces and the action spaces of ``agents``, as ``env`` gives them."""
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
        api = api_of(name, env)
        try:
            agents = tuple(env.possible_agents)
        except Exception as e:
            raise EnvError(name, f"game {name!r} has no possible_agents: {type(e).__name__}: {e}") from None
        if not agents:
            raise EnvError(name, f"game {name!r} has no agents (possible_agents is empty)")
        if not all(isinstance(a, str) and a for a in agents) or len(set(agents)) != len(agents):
            raise EnvError(name, f"game {name!r}: its agents must be distinct non-empty names (text), not "
                                 f"{list(agents)!r}")
        obs, act = spaces_of(name, env, agents)
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
        close_env(env)

    def make() -> Any:
        return _make(name, factory, options, render_mode)

    return Layout(name, make, api, agents, obs, act, tuple(seats), metadata, max_steps, renders, state_space)


def close_env(env: Any) -> None:
    """Close ``env``, whatever its ``close()`` raises."""
    with contextlib.suppress(Exception):  # closing is a courtesy; a game that fails at it has nothing to lose
        env.close()


def keyword_defaults(factory: Callable[..., Any]) -> dict[str, Any]:
    """The keyword arguments ``factory`` declares with a default, and their defaults (none when it cannot say)."""
    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):
        return {}
    return {p.name: p.default for p in params if p.default is not inspect.Parameter.empty
            and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)}


KIND_OPTION = "kind"
"""The option that gives a game whose metadata does not declare its kind one (``--kind`` of ``marl train``)."""


def default_kind(n_agents: int) -> str:
    """The kind of a game that declares none: two-sides for 2 agents, cooperative for one, free-for-all for more."""
    return "two-sides" if n_agents == 2 else ("cooperative" if n_agents == 1 else "free-for-all")


def kind_of(name: str, layout: Layout, option: str | None = None
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


def roles_of(name: str, layout: Layout) -> tuple[str, ...] | None:
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
