"""A run's settings as `marl train` resolves them, without the command line.

A new run's settings are built in layers, each over the last: the defaults of :class:`~.config.TrainConfig`, the
game's own training defaults (``marl envs NAME`` shows them), a preset, a ``--config`` TOML file, then the options
typed on the command line. A game's own default that makes no sense for the run as typed (a shared network for a
lone learner, a teacher for a learner that cannot imitate, league games where some seat is already the league's) is
dropped; one the user typed or wrote in the file is checked instead. A resumed run keeps the configuration saved
with it: only the device may change.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Collection, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import MarlError
from ..league.store import League, RunRow, shown
from .bounds import ON_POLICY
from .config import TrainConfig, can_teach, fups_without_partners, save_run_config, seat_plan_of
from .matchmaking import parse_bots

ALGO_SECTIONS = ("ppo", "dqn", "sac", "mappo", "poca")

PRESETS = ("seed000",)
"""The names ``--preset`` takes, each a learner's whole set-up (``seed000``: DQN's network sizes, learning rate,
batch, buffer, target period and epsilon schedule; docs/history/training.md says where it comes from)."""

FLAG_SETTINGS = ("agents", "algo", "sharing", "steps", "minutes", "seed", "device", "games", "snapshot_every",
                 "snapshot_steps", "eval_games", "eval_older", "eval", "eval_wait", "eval_actors", "eval_playoff",
                 "eval_precision",
                 "swap_every", "tensorboard", "league_games", "seats", "executor", "actors", "ray_address",
                 "fragment_steps", "frame_stack", "restart_at_snapshot", "init_from")
"""Options whose value is a top-level setting of the same name."""

OPPONENT_FLAGS = {"opponents": "mode", "window": "window", "latest_ratio": "latest_ratio", "nash_payoff": "nash_payoff"}
"""Options that set a key of ``[opponents]``: the option's name, then the key's."""

LEAGUE_FLAGS = {"league_main": "main", "league_main_exploiters": "main_exploiters",
                "league_league_exploiters": "league_exploiters"}
"""Options that set a key of ``[league]`` (AlphaStar's roles): the option's name, then the key's."""
NOT_IN_A_LEAGUE = ("agents", "opponents", "window", "latest_ratio")
"""Options a league's roles decide instead (its learners, and whom each plays), refused with ``--league``."""

EXECUTOR_OPTIONS = ("executor", "actors", "ray_address", "fragment_steps")
"""Where a run's games are stepped: a session's to say, so a resumed run may move (a cluster's new address, more
actors, back to this process)."""
RESUME_OPTIONS = frozenset({"resume", "env", "device", "eval_wait", "quiet", "json_out", "home", "db",
                            *EXECUTOR_OPTIONS})
"""What may be typed with --resume: a resumed run keeps the configuration it was started with (whether this session's
end waits for the league's workers, ``--wait/--no-wait``, and where its games are stepped are this session's to
say)."""


def read_toml(path: Path) -> dict[str, Any]:
    """A --config file; a missing or malformed one (not TOML, not UTF-8 text, nested past Python's recursion limit)
    is a one-line error naming it."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as e:
        raise MarlError(f"{path}: cannot read ({e.strerror or e})") from None
    except tomllib.TOMLDecodeError as e:
        raise MarlError(f"{path}: not valid TOML ({e})") from None
    except UnicodeDecodeError as e:  # TOML is UTF-8 text
        byte = e.object[e.start]
        raise MarlError(f"{path}: not valid TOML (not UTF-8 text: byte {e.start} is {byte:#04x})") from None
    except RecursionError:
        raise MarlError(f"{path}: not valid TOML for marl (tables or arrays nested too deeply)") from None


def merge_settings(settings: dict[str, Any], overrides: dict[str, Any]) -> None:
    """Merge a config file into the settings: sections ([ppo], ...) key by key, and an algorithm's network
    ([sac.arch], ...) key by key within its section (``hidden = [256, 256]`` alone keeps the activation); everything
    else, a curriculum's or a teacher's schedule included, replaced whole."""
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(settings.get(key), dict):
            section = {**settings[key], **value}
            arch, old = value.get("arch"), settings[key].get("arch")
            if key in ALGO_SECTIONS and isinstance(arch, dict) and isinstance(old, dict):
                section["arch"] = {**old, **arch}
            settings[key] = section
        else:
            settings[key] = value


def run_stem(env: str) -> str:
    """A default run name's stem from a game's name: ``pong``; ``tictactoe`` for ``mypkg.tictactoe:env``;
    ``kuhn_poker`` for ``openspiel:kuhn_poker`` (``leduc_poker-players-3`` for ``openspiel:leduc_poker(players=3)``)."""
    game = env.partition(":")[2] if env.startswith("openspiel:") else env.split(":")[0].rsplit(".", 1)[-1]
    stem = re.sub(r"[^A-Za-z0-9_-]+", "-", game).strip("-")
    return stem or "run"


def new_settings(env: str | None, flags: Mapping[str, Any], *, config: Path | None = None,
                 preset: str | None = None,
                 env_options: Callable[[str], dict[str, Any]] = lambda game: {}) -> dict[str, Any]:
    """A new run's settings (``TrainConfig.to_dict``'s layout, the run not named yet), every one checked: an error
    here leaves nothing behind.

    ``flags``: the options the user typed, by their parameter name (``agents``, ``opponents``, ``bots`` as typed,
    ``lr``, ``teacher``, ...), their values as the command line read them; an option left at its default is not
    among them. ``env_options``: the game's options from the command line, read for the game's registered name.
    """
    from ..envs import get_env

    if env is None:
        raise MarlError("name the game to train on (e.g. marl train pong), or --resume RUN")
    spec = get_env(env)
    if preset not in (None, *PRESETS):
        raise MarlError(f"unknown --preset '{preset}'; available: {', '.join(PRESETS)}")
    settings = TrainConfig.defaults(spec.name)  # the defaults, checked only with the layers over them (below)
    merge_settings(settings, game_defaults(spec))  # the game's own (marl envs NAME shows them)
    if preset == "seed000":
        from ..algos.dqn import seed000_config

        settings["algo"] = "dqn"
        settings["dqn"] = seed000_config().to_dict()
    from_file = read_toml(config) if config is not None else {}
    if "init_plan" in from_file:  # (what marl resolves init_from to, when the run is created)
        raise MarlError(f"{config}: init_plan is written by marl when a run is created; set init_from = \"NAME\" "
                        "(a snapshot or a team) instead")
    merge_settings(settings, from_file)
    _apply_flags(settings, flags)
    settings["env_options"] = {**settings["env_options"], **env_options(spec.name)}
    kind = flags.get("kind", settings.pop("kind", None))  # --kind, or kind = "..." at a config file's top level
    if kind is not None:
        settings["env_options"]["kind"] = check_kind(spec, kind)
    try:
        spec.config(**settings["env_options"])
    except (TypeError, ValueError) as e:
        raise MarlError(f"[env_options]: {e}") from None
    settings["env"] = spec.name
    _drop_game_defaults(settings, spec, {key for key in spec.train_defaults if key not in flags and
                                         key not in from_file})
    TrainConfig.from_dict(settings)  # every setting checked
    return settings


def game_defaults(spec: Any) -> dict[str, Any]:
    """A game's own training settings (``spec.train_defaults``), its ``[ppo]`` also the start of the learners built
    on PPO (``[mappo]``, ``[poca]``: PPO with a critic of the team, so the lander's tuned PPO, its reward scale,
    horizon and schedule, is theirs too), under what the game gives them itself."""
    out = dict(spec.train_defaults)
    if isinstance(out.get("ppo"), dict):
        for algo in ON_POLICY:
            if algo != "ppo":
                out[algo] = {**out["ppo"], **out.get(algo, {})}
    return out


def check_kind(spec: Any, kind: Any) -> str:
    """``--kind`` for ``spec``: one of the kinds, for a game that does not declare its own (a refusal otherwise)."""
    from ..envs import KINDS

    if kind not in KINDS:
        raise MarlError(f"--kind must be one of {', '.join(KINDS)}, not {kind!r}")
    if spec.make_kind is None or spec.kind_from == "metadata":
        if kind == spec.kind:
            return kind
        where = "in its metadata" if spec.kind_from == "metadata" else "itself"
        raise MarlError(f"{spec.name} declares its kind {where} ({spec.kind}): --kind is for PettingZoo games that "
                        "do not declare one")
    return kind


def _apply_flags(settings: dict[str, Any], flags: Mapping[str, Any]) -> None:
    """The typed options over the settings (the options' names are not always the settings': ``--opponents`` is
    ``[opponents] mode``, ``--lr`` every learner's ``lr``)."""
    settings.update({k: v for k, v in flags.items() if k in FLAG_SETTINGS})
    if flags.get("eval_inline"):  # --eval-inline, as earlier releases spelled --eval inline
        if flags.get("eval", "inline") != "inline":
            raise MarlError(f"--eval-inline is --eval inline: it cannot go with --eval {flags['eval']}")
        settings["eval"] = "inline"
    settings["opponents"].update({key: flags[flag] for flag, key in OPPONENT_FLAGS.items() if flag in flags})
    if "bots" in flags:
        settings["opponents"]["bots"] = parse_bots(flags["bots"])
    if "lr" in flags:
        for key in ALGO_SECTIONS:
            settings[key]["lr"] = flags["lr"]
    if "conv" in flags:  # every learner's network: [ppo.arch] conv, ...
        for key in ALGO_SECTIONS:
            settings[key]["arch"] = {**settings[key]["arch"], "conv": flags["conv"]}
    if "teacher" in flags:
        settings["teacher"]["player"] = flags["teacher"]
    _apply_league(settings, flags)


def _apply_league(settings: dict[str, Any], flags: Mapping[str, Any]) -> None:
    """``--league alphastar`` (or a ``[league]`` table) and the options that size it; what a league decides itself
    (its learners, whom each plays) refused when typed, one line each."""
    from .league_roles import LEAGUE_MODES

    if "league" in flags:
        if flags["league"] not in LEAGUE_MODES:
            raise MarlError(f"--league must be one of {', '.join(LEAGUE_MODES)}, not '{flags['league']}'")
        settings["league"] = settings.get("league") or {}
    sized = [flag for flag in LEAGUE_FLAGS if flag in flags]
    if settings.get("league") is None:
        if sized:
            raise MarlError(f"--{sized[0].replace('_', '-')} sizes a league of roles: it needs --league alphastar")
        return
    for flag in NOT_IN_A_LEAGUE:
        if flag in flags:
            raise MarlError(f"--{flag.replace('_', '-')} does not apply with --league alphastar: its learners are its "
                            "roles (--league-main, --league-main-exploiters, --league-league-exploiters), each "
                            "drawing its opponents by its role's rule")
    if not isinstance(settings["league"], dict):
        raise MarlError(f"[league] must be a table of settings, not {settings['league']!r}")
    settings["league"] = {**settings["league"], **{key: flags[flag] for flag, key in LEAGUE_FLAGS.items()
                                                   if flag in flags}}


def _drop_game_defaults(settings: dict[str, Any], spec: Any, game_set: Collection[str]) -> None:
    """The game's own defaults for learners on every seat (tennis: one shared network, a share of league games)
    are dropped with fewer learners, where every game is already against the league; typed, they are checked.
    ``game_set``: the settings that hold the game's default (neither typed nor in the config file)."""
    if settings.get("league") is not None:  # a league seats its own learners, one network each
        for key in ("sharing", "league_games", "seats"):
            if key in game_set:
                settings[key] = {"sharing": "nops", "league_games": 0.0, "seats": ""}[key]
    if "sharing" in game_set and fups_without_partners(spec, settings["agents"], settings["sharing"],
                                                       settings["seats"]):
        settings["sharing"] = "nops"
    if "teacher" in game_set and not can_teach(settings["algo"]):  # (e.g. a game's teacher, --algo dqn)
        settings["teacher"]["player"] = ""
    if settings["league_games"] and "league_games" in game_set:
        try:
            plan = seat_plan_of(spec.for_options(**settings["env_options"]), settings["agents"],
                                settings["sharing"], settings["seats"])
            if not plan.every_seat_learns:
                settings["league_games"] = 0.0
        except MarlError:
            pass  # the settings' own error follows, from TrainConfig


def start_run(league: League, settings: dict[str, Any], run: str | None) -> TrainConfig:
    """Register a new run of ``settings`` (from :func:`new_settings`) in the league under ``run`` (default:
    ``<game>-<n>``, the first free), its resolved configuration saved beside its metrics."""
    from ..policies.bots import bot_names

    if run is None:
        taken = {r.name for r in league.roster.list_runs()}
        stem = run_stem(settings["env"])
        run = next(f"{stem}-{i}" for i in range(1, 10_000) if f"{stem}-{i}" not in taken)
    elif league.roster.get_run(run) is not None:
        raise MarlError(f"a run named '{run}' already exists: choose another --run (or --resume it)")
    settings["run"] = run
    cfg = TrainConfig.from_dict(settings)
    if cfg.teacher.player and cfg.teacher.player not in bot_names(cfg.game()):  # a snapshot the league does
        from ..league.variants import variant_key
        from ..ratings.names import resolve  # not know: one line, before the run exists

        try:  # (best: the best of the run's own variant, as the trainer reads it)
            resolve(league, cfg.teacher.player, cfg.env, variant=variant_key(cfg.env, cfg.env_options))
        except MarlError as e:
            raise MarlError(f"--teacher: {e}") from None
    from .opponents import fixed_opponents

    # each --bots name is a scripted player of the game or a league player (one line, before the run exists)
    scripted = dict.fromkeys(bot_names(cfg.game()), 0)
    known = {**scripted, **fixed_opponents(league, cfg.game().name, cfg.opponents.bots, scripted)}
    missing = [name for name in cfg.opponents.bots if name not in known]
    if missing:
        raise MarlError(f"unknown bot {missing[0]!r} (known bots: {', '.join(sorted(scripted)) or 'none'}; or a "
                        "player of the league by its full name, e.g. run/s1M)")
    if cfg.init_from:  # the snapshots each learner starts from, read and fitted: one line, before the run exists
        from .init_from import plan_init

        cfg = replace(cfg, init_plan=plan_init(league, cfg))
    league.roster.create_run(run, cfg.env, cfg.to_dict(), algo=cfg.algo)
    save_run_config(league, cfg)
    return cfg


def resumed_config(league: League, old: RunRow, typed: Collection[str], device: str = "auto",
                   wait: bool | None = None, executor: Mapping[str, Any] | None = None) -> TrainConfig:
    """The configuration the stopped or killed run ``old`` was started with, to continue it (``--resume``; ``old``
    as :func:`~.needs.resumable` found it: there, readable, of the game asked for, not ended): ``typed``, the options
    the user typed, may not change it (only the device, whether this session's end ``wait``s for the league's
    workers, ``executor``: the :data:`EXECUTOR_OPTIONS` typed, and what is not a setting).

    The run's game is read from the league (its row and saved configuration, which any member of a shared league may
    have written): a game of your own is imported only when you name it again (``env``, the command's game argument,
    or ``MARL_GAMES``), never because the run's record names it (:mod:`selfplay_cli.envs.loading`)."""
    from ..envs.loading import GameNotAdmittedError, get_env

    resume = old.name
    ignored = sorted(set(typed) - RESUME_OPTIONS)
    if ignored:
        flags = ", ".join("--" + name.replace("_", "-") for name in ignored)
        raise MarlError(f"--resume continues run '{resume}' under the configuration it was started with: "
                        f"{flags} cannot change it (only --device, --wait/--no-wait, --executor, --actors, "
                        "--ray-address, --fragment-steps, --quiet, --json, --home, --db apply)")
    saved = old.config.get("env") if isinstance(old.config, dict) else old.env
    if saved != old.env:  # the game the saved configuration would load is the run's, or none
        raise MarlError(f"run '{resume}': its saved configuration names another game ({shown(saved)}) than the run "
                        f"plays ({shown(old.env)}); the league's record of it was changed: start a new run")
    try:
        get_env(old.env)
    except GameNotAdmittedError:
        raise MarlError(f"run '{resume}' trains {shown(old.env)}, a game of your own, which is imported only when you "
                        f"name it: marl train {shown(old.env)} --resume {resume} (or list it in MARL_GAMES)") from None
    cfg = TrainConfig.from_dict(old.config)
    if cfg.run != old.name:  # its folder: runs/<run> of the run's own name, never a name read elsewhere
        raise MarlError(f"run '{resume}': its saved configuration names another run ({shown(cfg.run)}); "
                        "the league's record of it was changed: start a new run")
    if device != "auto":
        cfg.device = device
    if wait is not None and wait != cfg.eval_wait:
        cfg = replace(cfg, eval_wait=wait)  # (checked: --no-wait is for --eval local or remote)
    if executor:
        cfg = replace(cfg, **{k: v for k, v in executor.items() if k in EXECUTOR_OPTIONS})  # (checked again)
    return cfg
