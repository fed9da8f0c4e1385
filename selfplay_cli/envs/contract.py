"""The game contract: one :class:`EnvSpec` per game, everything the rest of `marl` needs to know about it, and the
:class:`BatchedCore` protocol every game is played through.

A game declares, once: its seats (``agents``), each seat's spaces (:meth:`EnvSpec.seat_spaces`, each a
:class:`~selfplay_cli.envs.seat_spaces.SeatSpace`) and role (:meth:`EnvSpec.seat_roles`), whether seats act together
or in turns (``turns``), what a result is (``kind``, ``sides``, ``tie_tolerance``) and its scripted players
(``bots``, each a :class:`~selfplay_cli.envs.bots.BotSpec`).

Roles: seats of one role are interchangeable, so one policy may play any of them (pong's left and right paddles see
the court mirrored; a board game's two colours); a policy learned on one role plays only seats of that role. A game
may declare its roles (``roles``, a name per seat); by default seats share a role when they have the same
observation shape, action space and masks (a network that reads one can read the other).

The errors a game gives are here too: :class:`UnknownEnvError` and :class:`EnvError` (a game that cannot be found,
loaded or played) and :class:`IllegalActionError` (an action a core refuses). Registering a game and finding one by
name is :mod:`selfplay_cli.envs.loading`.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
from gymnasium import spaces

from .bots import BotSpec
from .seat_spaces import SeatSpace, SpaceError, check_seat_space, space_key

TURNS = ("simultaneous", "sequential")
KINDS = ("two-sides", "cooperative", "free-for-all")


class BatchedCore(Protocol):
    """What the game loops and the learners use: N games stepped at once, seats on the leading axis.

    A core never resets a game by itself: a finished game keeps its final score until :meth:`reset` is called for
    it. ``terminated`` / ``truncated`` say which games ended on the last step.
    """

    n: int
    n_seats: int
    terminated: np.ndarray  # (n,) bool, set by the last step
    truncated: np.ndarray  # (n,) bool
    score: np.ndarray  # (n_seats, n) float: each seat's score so far (points, summed rewards)
    steps: np.ndarray  # (n,) steps played in each game

    def reset(self, games: Any, seeds: Any) -> None: ...

    def step(self, actions: Any) -> np.ndarray:
        """``actions[seat]``: ``(n,)`` ints (Discrete), ``(n, k)`` ints (MultiDiscrete) or ``(n, d)`` float32
        (Box); entries of seats not acting are ignored. Returns the rewards ``(n_seats, n)`` float32. Raises
        :class:`IllegalActionError` for an action the seat's mask forbids."""
        ...

    def observe(self) -> Any:
        """``obs[seat]`` is ``(n, *observation.shape)`` of the seat's observation dtype (float32; an image's uint8):
        one array ``(n_seats, n, ...)`` when every seat has the same shape, else a list."""
        ...

    def action_masks(self) -> list[np.ndarray | None]:
        """Per seat: ``(n, n_actions)`` bool (a Discrete seat with masks) or None."""
        ...

    def to_act(self) -> np.ndarray:
        """``(n_seats, n)`` bool: the seats that act on the next step."""
        ...

    # A core whose agents may come and go (a PettingZoo game's) also has, set by each step, ``seat_done`` and
    # ``seat_cut`` (``(n_seats, n)`` bool: whose part in a game ended on it, and of those whose was cut short) and
    # ``in_game`` (who is in each game now); a core without them has every seat in every game from its start to its
    # end. A core of a game with a global state (:meth:`EnvSpec.state_space`) has ``state()``: ``(n, *shape)``
    # float32.


def reset_slots(games: Any, seeds: Any) -> tuple[np.ndarray, np.ndarray]:
    """A core's :meth:`BatchedCore.reset` arguments as flat int64 arrays of equal length (a ValueError otherwise)."""
    g = np.asarray(games, dtype=np.int64).reshape(-1)
    s = np.asarray(seeds, dtype=np.int64).reshape(-1)
    if g.size != s.size:
        raise ValueError(f"{g.size} games but {s.size} seeds")
    return g, s


class UnknownEnvError(KeyError):
    def __init__(self, name: str, known: list[str]) -> None:
        super().__init__(name)
        self.name = name
        self.known = known

    def __str__(self) -> str:
        return f"unknown env '{self.name}'; registered: {', '.join(self.known)}"


class EnvError(UnknownEnvError):
    """A game that cannot be loaded or does not keep the contract: one line that names the game and says why.

    A subclass of :class:`UnknownEnvError`, so everything that refuses an unknown game (the CLI: exit code 2)
    refuses this one the same way."""

    def __init__(self, name: str, message: str) -> None:
        super().__init__(name, [])
        self.message = message

    def __str__(self) -> str:
        return self.message


class IllegalActionError(ValueError):
    """A core was given an action that the seat's mask forbids (or that is outside its action space)."""

    def __init__(self, seat: int, game: int, action: Any, reason: str = "forbidden by its action mask") -> None:
        self.seat, self.game, self.action = int(seat), int(game), action
        super().__init__(f"illegal action {action!r} for seat {seat} in game slot {game}: {reason}")


@dataclass(frozen=True)
class EnvSpec:
    """A game: its seats, spaces, turns and kind, and how to make its batched core.

    ``turns``: ``"simultaneous"`` (all seats act at every step) or ``"sequential"`` (some act at each step: the
    core's ``to_act()`` says which). ``kind``: what a result is: ``"two-sides"`` (zero-sum, win/draw/loss by the
    sides' total score; ``sides`` lists the seats of each side, default seat i is side i for 2 seats),
    ``"cooperative"`` (all seats one team; two policies compared by team return on the same seeds, a difference
    within ``tie_tolerance`` a draw) or ``"free-for-all"`` (pairwise results from the final order of scores).
    ``stakes``: a two-sides game played for stakes (poker's chips), the most a side can win: a result is then worth
    what was won (:class:`~selfplay_cli.results.Rules`), not only who won.

    ``make_parallel(**options)`` makes the game's PettingZoo env (a ParallelEnv for pong). ``make_seat_spaces``
    gives each seat's :class:`SeatSpace` for a config; without it every seat has ``observation_space(cfg)`` and
    ``action_space(cfg)`` and no masks. ``time_limit(cfg)``: the most steps a game lasts (None: no declared
    limit); by default the config's ``max_steps`` if it has one. ``make_agents(cfg)``: the seats of a config for a
    game whose options change its seats (``agents`` are the default config's); see :meth:`for_options`.
    ``render_fps``: a recording's default frame rate
    (a board game's moves at 2 a second; None: 60, one frame per step). ``make_renderer()``: an object whose
    ``draw(core, game)`` returns game ``game``'s picture as an RGB array; it may offer ``seat_colour(seat)``, the
    colour a seat is drawn in (the recording's caption band, which names the players, shows it beside each name).

    ``roles``: the role of each seat (see the module docstring), where the game says it; None infers them from the
    seats' spaces (:meth:`seat_roles`).

    ``live_options``: the options the core's ``set_options(**values)`` changes between steps of running games (what
    a training curriculum may drive: tennis's reward weights and bat size).

    ``neutral_options``: options that leave the game a result belongs to unchanged, so that ratings do not split over
    them (:meth:`variant_options`): how it is drawn, what a policy observes, rewards that only shape learning while
    the scores stay the game's. Every other option makes a *variant*: another game for ratings, with a ladder of its
    own, because a result under it means something else (a game to 3 points, four landers, a serve bot serving
    otherwise). An option that changes how a scripted player plays is never neutral: the bots anchor every ladder.
    Observation options (pong's frame stack) are neutral although two networks made for different ones cannot meet
    (:func:`~selfplay_cli.players.load.env_options_of` refuses the match): the game and its bots are the same, so
    ratings through the bots compare them, which is what a user who tries 4 frames against 8 asks of the ladder.

    ``make_state_space(cfg)``: the space of the game's global state for a config (a float32 Box), where the game
    gives one: its core's ``state()`` is then every game's state, ``(n_games, *shape)`` float32, what a centralised
    critic reads (:meth:`state_space`; None, the default: the game gives no state).

    ``train_defaults``: the game's own training settings, laid out as a run's TOML (``{"ppo": {"gamma": 0.999},
    "games": 64}``), applied over marl's defaults and under a ``--config`` file and the flags typed (the lander wants
    a longer horizon than pong).
    """

    name: str
    description: str
    agents: tuple[str, ...]
    make_config: Callable[..., Any]
    make_core: Callable[[int, Any], BatchedCore]
    make_parallel: Callable[..., Any]
    observation_space: Callable[[Any], spaces.Space]
    action_space: Callable[[Any], spaces.Space]
    make_renderer: Callable[[], Any] | None = None
    bots: dict[str, BotSpec] = field(default_factory=dict)
    turns: str = "simultaneous"
    kind: str = "two-sides"
    sides: tuple[tuple[int, ...], ...] | None = None
    tie_tolerance: float = 0.0
    stakes: float | None = None  # a two-sides game played for stakes: the most a side can win (results by margin)
    make_seat_spaces: Callable[[Any], tuple[SeatSpace, ...]] | None = None
    time_limit: Callable[[Any], int | None] | None = None
    render_fps: int | None = None  # frames per second a recording of it plays at by default (None: one per step at 60)
    make_agents: Callable[[Any], tuple[str, ...]] | None = None  # the seats of a config, where options change them
    anchor: str = "random"  # the scripted player whose rating is fixed (1000 by default): the ladder's zero point
    live_options: tuple[str, ...] = ()  # options the core's set_options() changes while games run (curricula)
    train_defaults: dict[str, Any] = field(default_factory=dict)  # the game's training settings (a run's TOML layout)
    neutral_options: tuple[str, ...] = ()  # options that split no rating: the same game drawn, seen or shaped otherwise
    option_source: Callable[..., Any] | None = None  # a function whose keyword arguments are the options, for a game
    # whose config is no dataclass (a PettingZoo game's factory): `marl envs NAME` reads them from its signature
    roles: tuple[str, ...] | None = None  # each seat's role, where the game declares them (None: by their spaces)
    make_state_space: Callable[[Any], spaces.Box | None] | None = None  # the global state's space for a config
    make_kind: Callable[[Any], tuple[str, tuple[tuple[int, ...], ...] | None, str]] | None = None  # a config's
    # (kind, sides, kind_from), for a game whose options choose them (a PettingZoo game that does not declare its
    # kind: its ``kind`` option; one whose agents change with its options: its default kind for their number)
    make_roles: Callable[[Any], tuple[str, ...] | None] | None = None  # a config's declared roles (None: inferred)
    sized_config: Any = field(default=None, compare=False)  # the config :meth:`for_options` declared these seats
    # for (None: the default config's): what the methods taking ``cfg=None`` read
    size_option: str | None = None  # the option that sets the team size (the lander's ``landers``), where the game
    # names one: what ``marl study team-size`` varies (a PettingZoo game: ``--size-option n_pursuers``)
    kind_from: str = "declared"  # where the kind comes from: declared (by marl's game), metadata (a PettingZoo
    # game's), option (the ``kind`` option), agents (none said: by the number of agents)

    def __post_init__(self) -> None:
        n = len(self.agents)
        if n < 1:
            raise ValueError(f"game {self.name!r} has no seats")
        if len(set(self.agents)) != n:
            raise ValueError(f"game {self.name!r} names a seat twice: {list(self.agents)}")
        if self.turns not in TURNS:
            raise ValueError(f"game {self.name!r}: turns must be one of {', '.join(TURNS)}, not {self.turns!r}")
        if self.kind not in KINDS:
            raise ValueError(f"game {self.name!r}: kind must be one of {', '.join(KINDS)}, not {self.kind!r}")
        if not (isinstance(self.tie_tolerance, (int, float)) and math.isfinite(self.tie_tolerance)
                and self.tie_tolerance >= 0):
            raise ValueError(f"game {self.name!r}: tie_tolerance must be a finite number >= 0, "
                             f"not {self.tie_tolerance!r}")
        if self.stakes is not None and not (self.kind == "two-sides" and math.isfinite(self.stakes)
                                            and self.stakes > 0):
            raise ValueError(f"game {self.name!r}: stakes are for two-sides games, a finite number > 0, not "
                             f"{self.stakes!r} ({self.kind})")
        if self.sides is not None:
            if self.kind != "two-sides":
                raise ValueError(f"game {self.name!r}: sides are for two-sides games, not {self.kind}")
            seats = [s for side in self.sides for s in side]
            if len(self.sides) != 2 or any(not side for side in self.sides) or sorted(seats) != list(range(n)):
                raise ValueError(f"game {self.name!r}: sides must split the seats 0..{n - 1} into two non-empty "
                                 f"sides, not {self.sides!r}")
        elif self.kind == "two-sides" and n != 2:
            raise ValueError(f"game {self.name!r} has {n} seats: a two-sides game with other than 2 seats must "
                             "declare its sides")
        if self.roles is not None and (len(self.roles) != n or not all(isinstance(r, str) and r
                                                                        for r in self.roles)):
            raise ValueError(f"game {self.name!r}: roles must name one role (a non-empty text) per seat, "
                             f"{n} in all, not {self.roles!r}")

    def config(self, **options: Any) -> Any:
        return self.make_config(**options)

    def for_options(self, **options: Any) -> EnvSpec:
        """The game as these options make it: itself, or, for a game whose seats follow its options
        (``make_agents``: the lander's ``landers=M``, pursuit's ``n_pursuers``), the same game declared with that
        config's seats; for a game whose options choose its kind (``make_kind``), with that kind."""
        if (self.make_agents is None and self.make_kind is None) or not options:
            return self
        return self.for_config(self.make_config(**options))

    def for_config(self, cfg: Any) -> EnvSpec:
        """:meth:`for_options` for a config already made."""
        changes: dict[str, Any] = {}
        if self.make_kind is not None:
            kind, sides, kind_from = self.make_kind(cfg)
            if (kind, sides, kind_from) != (self.kind, self.sides, self.kind_from):
                changes.update(kind=kind, sides=sides, kind_from=kind_from)
        agents = tuple(self.make_agents(cfg)) if self.make_agents is not None else self.agents
        if agents != self.agents:
            changes.update(agents=agents, roles=self.make_roles(cfg) if self.make_roles is not None else None)
        if not changes:
            return self
        out = replace(self, **changes, sized_config=cfg)
        if agents != self.agents and out.roles is None:
            out = replace(out, roles=out.seat_roles(cfg))  # the roles of that config's seats, stated
        return out

    def variant_options(self, options: Mapping[str, Any] | None) -> dict[str, Any]:
        """The options among ``options`` that make a variant of this game (see ``neutral_options``), by name, in
        canonical form (:func:`canonical_option`): each one not neutral whose value differs from the game's default.
        Empty for the game as declared, whichever way it was asked for (no options, or options at their defaults)."""
        defaults = option_defaults(self.make_config())
        out: dict[str, Any] = {}
        for key in sorted(options or {}):
            if key in self.neutral_options:
                continue
            value = canonical_option(options[key])  # type: ignore[index]
            if key in defaults and canonical_option(defaults[key]) == value:
                continue
            out[str(key)] = value
        return out

    def core(self, n_games: int, **options: Any) -> BatchedCore:
        return self.make_core(n_games, self.make_config(**options))

    @property
    def n_seats(self) -> int:
        return len(self.agents)

    def side_seats(self) -> tuple[tuple[int, ...], ...]:
        """The seats of each side: ``sides`` or seat i alone for two-sides games, one team of all seats for
        cooperative games, every seat alone for free-for-all."""
        if self.sides is not None:
            return self.sides
        if self.kind == "cooperative":
            return (tuple(range(self.n_seats)),)
        return tuple((s,) for s in range(self.n_seats))

    def seat_spaces(self, cfg: Any = None) -> tuple[SeatSpace, ...]:
        """One :class:`SeatSpace` per seat for the config ``cfg`` (default options when None), checked: an
        unsupported space, or two seats of one declared role whose spaces differ, is an :class:`EnvError` naming
        the game, the seats and why."""
        cfg = self._config(cfg)
        agents = self._agents_of(cfg)
        if self.make_seat_spaces is not None:
            seats = tuple(self.make_seat_spaces(cfg))
        else:
            obs, act = self.observation_space(cfg), self.action_space(cfg)
            seats = tuple(SeatSpace(obs, act, False) for _ in agents)
        if len(seats) != len(agents):
            raise EnvError(self.name, f"game {self.name!r} declares {len(agents)} seats but {len(seats)} seat "
                                      "spaces")
        for agent, seat in zip(agents, seats, strict=True):
            try:
                check_seat_space(seat)
            except SpaceError as e:
                raise EnvError(self.name, f"game {self.name!r}, seat {agent!r}: {e}") from None
        first: dict[str, int] = {}
        for s, role in enumerate((self.roles or ()) if agents == self.agents else ()):
            k = first.setdefault(role, s)
            if space_key(seats[k]) != space_key(seats[s]):
                raise EnvError(self.name, f"game {self.name!r}: seats {self.agents[k]!r} and {self.agents[s]!r} are "
                                          f"both of role {role!r} but their spaces differ (a role's seats must be "
                                          "interchangeable)")
        return seats

    def _config(self, cfg: Any) -> Any:
        """``cfg``, or when None the config this declaration is of (``sized_config``, else the default's)."""
        if cfg is not None:
            return cfg
        return self.sized_config if self.sized_config is not None else self.make_config()

    def _agents_of(self, cfg: Any) -> tuple[str, ...]:
        """The seats of the config ``cfg``: ``agents``, or, for a game whose options change them, that config's."""
        return self.agents if self.make_agents is None else tuple(self.make_agents(cfg))

    def state_space(self, cfg: Any = None) -> spaces.Box | None:
        """The space of the game's global state for the config ``cfg`` (default options when None), None when the
        game gives none (see ``make_state_space``)."""
        if self.make_state_space is None:
            return None
        return self.make_state_space(self._config(cfg))

    def seat_roles(self, cfg: Any = None) -> tuple[str, ...]:
        """The role of each seat for the config ``cfg`` (default options when None): the declared ``roles`` (which
        :meth:`seat_spaces` checks), else inferred from the seats' spaces (:func:`infer_roles`)."""
        cfg = self._config(cfg)
        agents = self._agents_of(cfg)
        if agents != self.agents:  # a config of other seats (pursuit's n_pursuers=3 asked of the default game)
            return self.for_config(cfg).seat_roles(cfg)
        if self.roles is not None:
            return self.roles
        return infer_roles(self.agents, self.seat_spaces(cfg))

    def max_steps(self, cfg: Any = None) -> int | None:
        """The most steps one game of this config lasts, if the game declares it."""
        cfg = self._config(cfg)
        if self.time_limit is not None:
            return self.time_limit(cfg)
        limit = getattr(cfg, "max_steps", None)
        return int(limit) if isinstance(limit, (int, np.integer)) and limit > 0 else None


def canonical_option(value: Any) -> Any:
    """An option's value as a variant records it, one form per value: numbers as JSON numbers (a whole number
    without a fraction, so ``3``, ``3.0`` and ``numpy.int64(3)`` are one value), sequences as lists, mappings sorted
    by key; anything else as its text."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        x = float(value)
        return int(x) if x.is_integer() and abs(x) < 2**53 else x
    if isinstance(value, (list, tuple)):
        return [canonical_option(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): canonical_option(value[k]) for k in sorted(value, key=str)}
    return str(value)


def option_defaults(cfg: Any) -> dict[str, Any]:
    """The default value of each option a game's config declares: a dataclass's fields, or a config's own
    ``defaults`` mapping (a PettingZoo game: its factory's keyword defaults)."""
    if dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)}
    return dict(getattr(cfg, "defaults", None) or {})


def infer_roles(agents: Sequence[str], seats: Sequence[SeatSpace]) -> tuple[str, ...]:
    """Each seat's role when a game does not declare them: seats whose observation shape, action space and masks
    agree share a role. A role is named after its seats: their name less a trailing ``_<number>`` where that is
    one name (``adversary_0`` and ``adversary_1``: ``adversary``), else their names joined by ``/`` (pong's
    ``left/right``); two roles never share a name (their seats' names then, ``player_0``, ``player_1``)."""
    members: dict[tuple[Any, ...], list[str]] = {}
    for agent, seat in zip(agents, seats, strict=True):
        members.setdefault(space_key(seat), []).append(agent)

    def name(group: list[str]) -> str:
        short = {re.sub(r"_\d+$", "", agent) or agent for agent in group}
        return short.pop() if len(short) == 1 else "/".join(group)

    names = {key: name(group) for key, group in members.items()}
    if len(set(names.values())) < len(names):
        names = {key: "/".join(group) for key, group in members.items()}
    return tuple(names[space_key(seat)] for seat in seats)


def check_spaces(spec: EnvSpec, cfg: Any = None) -> tuple[SeatSpace, ...]:
    """``spec.seat_spaces(cfg)``: each seat's spaces, or an :class:`EnvError` naming the seat and why."""
    return spec.seat_spaces(cfg)
