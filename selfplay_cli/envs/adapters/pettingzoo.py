"""Any PettingZoo game as a `marl` game: an :class:`EnvSpec` probed from one instance, and a batched core of N
copies (:mod:`.pettingzoo_core`), which marl's game loops step as they step the built-in games' cores.

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
  :meth:`~selfplay_cli.envs.contract.EnvSpec.seat_roles`);
- time limit: ``metadata["marl_max_steps"]``, else the env's ``max_cycles`` (times the seats for an AEC game, a
  core step being one agent's move), else none;
- recording: when ``metadata["render_modes"]`` lists ``"rgb_array"``, every copy is made with
  ``render_mode="rgb_array"`` (PettingZoo draws such frames only when ``render()`` is called) and the game's own
  ``render()`` makes the video's frames, at ``metadata["render_fps"]`` frames a second by default.

Reading an instance's declaration is :mod:`.pettingzoo_probe`; how the copies are stepped (agents that come and go,
AEC turns, the global state) is told in :mod:`.pettingzoo_core`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from ..bots import random_bot
from ..contract import EnvError, EnvSpec
from .pettingzoo_core import PettingZooCore, PettingZooRenderer
from .pettingzoo_probe import KIND_OPTION, Layout, PettingZooConfig, keyword_defaults, kind_of, probe, roles_of

__all__ = ["adapt"]


def _option_key(options: Mapping[str, Any]) -> Any:
    try:
        key = tuple(sorted(options.items()))
        hash(key)
        return key
    except TypeError:
        return repr(sorted(options.items(), key=lambda kv: kv[0]))


def adapt(name: str, factory: Callable[..., Any], description: str | None = None) -> EnvSpec:
    """The :class:`EnvSpec` of the PettingZoo game that ``factory(**options)`` makes, probed with no options."""
    if not callable(factory):
        raise EnvError(name, f"game {name!r}: {factory!r} is not callable (marl needs a function that returns a "
                             "PettingZoo env)")
    default = probe(name, factory)
    layouts: dict[Any, Layout] = {(): default}
    defaults = keyword_defaults(factory)
    kind, sides, tol, kind_from = kind_of(name, default)
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
        k, s, _, src = kind_of(name, layout, None if chosen is None else str(chosen))
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
            roles=roles_of(name, default),
            make_agents=lambda cfg: cfg.layout.agents,
            make_kind=lambda cfg: (cfg.kind, cfg.sides, cfg.kind_from),
            make_roles=lambda cfg: roles_of(name, cfg.layout),
            kind_from=kind_from,
        )
    except ValueError as e:
        raise EnvError(name, str(e)) from None
    spec.seat_spaces()  # declared roles must keep to the seats' spaces: refused here, in one line, if not
    return spec
