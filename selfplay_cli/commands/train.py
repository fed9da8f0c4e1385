"""`marl train ENV`: self-play training into the league."""

from __future__ import annotations

import re
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from ..errors import EXIT_INTERRUPTED, EXIT_TERMINATED, MarlError
from ._common import (
    MAX_PARALLEL,
    MAX_SEED,
    DbOpt,
    DeviceOpt,
    HomeOpt,
    JsonOpt,
    QuietOpt,
    open_league,
    parse_env_options,
    progress_enabled,
)
from ._output import console, err_console, print_json
from .train_view import TrainProgress, describe_record, describe_run, report_json


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


ALGO_SECTIONS = ("ppo", "dqn", "sac")


def run_stem(env: str) -> str:
    """A default run name's stem from a game's name: ``pong``; ``tictactoe`` for ``mypkg.tictactoe:env``."""
    stem = re.sub(r"[^A-Za-z0-9_-]+", "-", env.split(":")[0].rsplit(".", 1)[-1]).strip("-")
    return stem or "run"


RESUME_OPTIONS = frozenset({"resume", "env", "device", "quiet", "json_out", "home", "db"})
"""What may be typed with --resume: a resumed run keeps the configuration it was started with."""


def train(
    ctx: typer.Context,
    env: Annotated[str | None, typer.Argument(help="The game to train on (see `marl envs`).")] = None,
    config: Annotated[Path | None, typer.Option("--config", metavar="FILE", help="TOML file of settings (top-level "
                                                "options, [ppo], [dqn], [sac], [opponents], [env_options], "
                                                "[curriculum], [teacher]); options typed on the command line win over "
                                                "it.")] = None,
    agents: Annotated[int, typer.Option("--agents", min=1, max=64, help="Learning agents. Two sides: 2 is one learner "
                                        "per side (both pong paddles, seed 000), 1 one learner against opponents "
                                        "from the league; cooperative: seat s is learner s mod N; free-for-all: one "
                                        "per seat, or fewer against the league.")] = 2,
    seats: Annotated[str | None, typer.Option("--seats", metavar="L,L,...", help="Which learner holds each seat, "
                                              "in the game's seat order: 1,2 or 1,1,- (- an opponent from the "
                                              "league); overrides --agents.")] = None,
    algo: Annotated[str, typer.Option("--algo", help="Learning algorithm: ppo (any action space), dqn (Discrete "
                                      "actions) or sac (Box actions).")] = "ppo",
    preset: Annotated[str | None, typer.Option("--preset", help="seed000: seed 000's DQN set-up (network sizes, "
                                               "learning rate, batch, buffer, target period, epsilon).")] = None,
    sharing: Annotated[str, typer.Option("--sharing", help="nops: one network per learner; fups: one shared "
                                         "network.")] = "nops",
    steps: Annotated[int, typer.Option("--steps", min=1, max=10**12, help="Budget in game steps.")] = 6_000_000,
    minutes: Annotated[float | None, typer.Option("--minutes", max=10**6, help="Budget in minutes of wall clock "
                                                  "instead (fractions allowed).")] = None,
    run: Annotated[str | None, typer.Option("--run", metavar="NAME", help="Run name (default: <env>-<n>).")] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Seed of networks, games and opponent "
                                      "choice.")] = 0,
    games: Annotated[int, typer.Option("--games", min=2, max=MAX_PARALLEL, help="Games played at once.")] = 256,
    snapshot_every: Annotated[int, typer.Option("--snapshot-every", min=0, help="Also a snapshot every N episodes "
                                                "(finished games), named epN as seed 000 did (0: by steps only).")]
    = 0,
    snapshot_steps: Annotated[int, typer.Option("--snapshot-steps", min=0, help="Game steps between snapshots, "
                                                "named by the step they stand for: s0, s1M, s2M, ... and the final "
                                                "one by the budget (s6M).")] = 1_000_000,
    swap_every: Annotated[int, typer.Option("--swap-every", min=0, help="Game steps a game slot keeps the opponent "
                                            "it drew (ML-Agents' swap_steps); 0: a new draw for every game.")] = 0,
    tensorboard: Annotated[bool, typer.Option("--tensorboard", help="Also write the metrics for TensorBoard "
                                              "(<home>/runs/<run>/tensorboard; needs the tensorboard package: pip "
                                              "install -e \".[tensorboard]\").")] = False,
    league_games: Annotated[float, typer.Option("--league-games", help="With every seat learning (--agents 2): "
                                                "share of games in which a learner meets an opponent from the league "
                                                "(drawn by --opponents/--bots) instead of the other learner; 0 keeps "
                                                "seed 000's set-up.")] = 0.0,
    eval_games: Annotated[int, typer.Option("--eval-games", min=0, max=10_000, help="Games a new snapshot plays "
                                            "against each opponent of its gauntlet (its predecessor, the other "
                                            "learners, the run's best, older snapshots, the scripted players), in "
                                            "seat-swapped pairs; 2 where its predecessor's result was already "
                                            "clear. 0: no rating games.")] = 8,
    eval_older: Annotated[int, typer.Option("--eval-older", min=0, max=1_000, help="Older snapshots of the run in "
                                            "each gauntlet, besides the predecessor and the best.")] = 2,
    eval_inline: Annotated[bool, typer.Option("--eval-inline", help="Play the rating games in the training process, "
                                              "training paused (default: a worker process beside training).")]
    = False,
    eval_playoff: Annotated[int, typer.Option("--eval-playoff", min=0, max=100_000, help="After the final "
                                              "gauntlet the run's best candidates meet, up to this many games a "
                                              "pair, until the best is separated (0: no playoff).")] = 100,
    opponents: Annotated[str, typer.Option("--opponents", help="League opponents (--agents 1, or --league-games): "
                                           "self | latest | uniform | pfsp, from the run's snapshots.")] = "pfsp",
    window: Annotated[int, typer.Option("--window", min=1, max=100_000, help="Opponents are drawn from the last N "
                                        "snapshots (ML-Agents' window).")] = 10,
    latest_ratio: Annotated[float, typer.Option("--latest-ratio", help="Share of league games against the "
                                                "current learner (two learners: the other one); ML-Agents' "
                                                "play_against_latest_model_ratio.")]
    = 0.5,
    bots: Annotated[str, typer.Option("--bots", metavar="BOT=P,...", help="Mix in scripted players with these "
                                      "probabilities, e.g. cpu=0.1,random=0.05.")] = "",
    teacher: Annotated[str | None, typer.Option("--teacher", metavar="PLAYER", help="Kickstart the learners: they "
                                                "also imitate this player (a scripted player such as serve-bot, or a "
                                                "snapshot) on the states they visit, the imitation's weight fading "
                                                "by [teacher] weight (default 1 to 0 over the first half of the run); "
                                                "none: no teacher (a game's default one off).")] = None,
    lr: Annotated[float | None, typer.Option("--lr", help="Learning rate (default: the algorithm's own, PPO 2e-3, "
                                             "DQN 2.5e-4, SAC 3e-4).")] = None,
    env_option: Annotated[list[str] | None, typer.Option("--env-option", metavar="KEY=VALUE", help="Game option, "
                                                         "repeatable (e.g. points_to_win=5; marl envs NAME lists "
                                                         "a game's options, types and defaults).")] = None,
    resume: Annotated[str | None, typer.Option("--resume", metavar="RUN", help="Continue a run that was stopped or "
                                               "killed, from its last snapshot (its saved configuration applies).")]
    = None,
    device: DeviceOpt = "auto",
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Train agents by self-play (PPO, DQN or SAC); every snapshot joins the league and is rated in a gauntlet."""
    from ..algos.dqn import seed000_config
    from ..envs import get_env
    from ..league.matchmaking import parse_bots
    from ..league.store import RunStatus, check_name, shown
    from ..policies.bots import bot_names
    from ..train.config import TrainConfig, can_teach, fups_without_partners, save_run_config, seat_plan_of
    from ..train.loop import Trainer
    from ..train.needs import check_resumable

    for what, name in (("run name", run), ("run name", resume)):
        if name is not None:
            check_name(what, name)  # before anything exists: a refused name leaves no league behind
    typed = {name for name in ctx.params  # options the user typed (not defaults)
             if getattr(ctx.get_parameter_source(name), "name", "") in ("COMMANDLINE", "ENVIRONMENT")}
    settings: dict[str, Any] = {}
    if resume is None:  # the whole configuration is checked before the league is opened (or created)
        if env is None:
            raise MarlError("name the game to train on (e.g. marl train pong), or --resume RUN")
        spec = get_env(env)
        if preset not in (None, "seed000"):
            raise MarlError(f"unknown --preset '{preset}'; available: seed000")
        settings = TrainConfig(env=spec.name, run="new").to_dict()  # the defaults
        merge_settings(settings, spec.train_defaults)  # the game's own (marl envs NAME shows them)
        if preset == "seed000":
            settings["algo"] = "dqn"
            settings["dqn"] = seed000_config().to_dict()
        from_file = read_toml(config) if config is not None else {}
        merge_settings(settings, from_file)
        flags = {"agents": agents, "algo": algo, "sharing": sharing, "steps": steps, "minutes": minutes,
                 "seed": seed, "device": device, "games": games, "snapshot_every": snapshot_every,
                 "snapshot_steps": snapshot_steps, "eval_games": eval_games, "eval_older": eval_older,
                 "eval_inline": eval_inline, "eval_playoff": eval_playoff, "swap_every": swap_every,
                 "tensorboard": tensorboard, "league_games": league_games, "seats": seats}
        settings.update({k: v for k, v in flags.items() if k in typed})
        matchmaking = {"opponents": ("mode", opponents), "window": ("window", window),
                       "latest_ratio": ("latest_ratio", latest_ratio)}
        settings["opponents"].update({key: value for flag, (key, value) in matchmaking.items() if flag in typed})
        if "bots" in typed:
            settings["opponents"]["bots"] = parse_bots(bots)
        if "lr" in typed:
            settings["ppo"]["lr"] = settings["dqn"]["lr"] = settings["sac"]["lr"] = lr
        if "teacher" in typed:
            settings["teacher"]["player"] = teacher
        settings["env_options"] = {**settings["env_options"], **parse_env_options(spec.name, env_option)}
        try:
            spec.config(**settings["env_options"])
        except (TypeError, ValueError) as e:
            raise MarlError(f"[env_options]: {e}") from None
        settings["env"] = spec.name
        game_set = {key for key in spec.train_defaults if key not in typed and key not in from_file}
        # the game's own defaults for learners on every seat (tennis: one shared network, a share of league games)
        # are dropped with fewer learners, where every game is already against the league; typed, they are checked
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
        TrainConfig.from_dict(settings)  # every setting checked: an error here leaves nothing behind
    league = open_league(home, db)
    try:
        if resume is not None:
            ignored = sorted(typed - RESUME_OPTIONS)
            if ignored:
                flags = ", ".join("--" + name.replace("_", "-") for name in ignored)
                raise MarlError(f"--resume continues run '{resume}' under the configuration it was started with: "
                                f"{flags} cannot change it (only --device, --quiet, --json, --home, --db apply)")
            old = league.get_run(resume)
            if old is None:
                raise MarlError(f"no run named '{resume}' to resume")
            if env is not None and env != old.env:
                raise MarlError(f"run '{resume}' trains {old.env}, not {env}")
            check_resumable(league, old)  # a run a removed snapshot has ended: one line saying which
            cfg = TrainConfig.from_dict(old.config)
            if cfg.run != old.name:  # its folder: runs/<run> of the run's own name, never a name read elsewhere
                raise MarlError(f"run '{resume}': its saved configuration names another run ({shown(cfg.run)}); "
                                "the league's record of it was changed: start a new run")
            if device != "auto":
                cfg.device = device
        else:
            if run is None:
                taken = {r.name for r in league.list_runs()}
                stem = run_stem(settings["env"])
                run = next(f"{stem}-{i}" for i in range(1, 10_000) if f"{stem}-{i}" not in taken)
            elif league.get_run(run) is not None:
                raise MarlError(f"a run named '{run}' already exists: choose another --run (or --resume it)")
            settings["run"] = run
            cfg = TrainConfig.from_dict(settings)
            if cfg.teacher.player and cfg.teacher.player not in bot_names(cfg.game()):  # a snapshot the league does
                from ..league.variants import variant_key
                from ..rated.names import resolve  # not know: one line, before the run exists

                try:  # (best: the best of the run's own variant, as the trainer reads it)
                    resolve(league, cfg.teacher.player, cfg.env, variant=variant_key(cfg.env, cfg.env_options))
                except MarlError as e:
                    raise MarlError(f"--teacher: {e}") from None
            league.create_run(run, cfg.env, cfg.to_dict(), algo=cfg.algo)
            save_run_config(league, cfg)
        reporter = TrainProgress(cfg, bar=progress_enabled(quiet or json_out), lines=not quiet)
        with reporter, stop_on_sigterm():
            trainer = None
            claimed = resume is None  # a resumed run is this process's once restore has taken its lock
            try:
                trainer = Trainer(league, cfg, on_progress=reporter.update)
                if resume is not None:
                    note = trainer.restore()
                    claimed = True
                    league.set_run_status(cfg.run, RunStatus.RUNNING)
                    if not quiet:  # stderr: --json keeps stdout for the JSON alone
                        err_console.print(note, markup=False)
                report = trainer.train()
            except (KeyboardInterrupt, Terminated) as stop:
                league.set_run_status(cfg.run, RunStatus.STOPPED)
                at = f" at step {trainer.steps:,}" if trainer is not None else ""
                why = "SIGTERM" if isinstance(stop, Terminated) else "Ctrl-C"
                err_console.print(f"stopped {cfg.run}{at} ({why}); its last snapshot is kept: continue it with: "
                                  f"marl train --resume {cfg.run}", markup=False)
                raise typer.Exit(EXIT_TERMINATED if isinstance(stop, Terminated) else EXIT_INTERRUPTED) from None
            except MarlError:
                if claimed:  # a refused resume (e.g. another process trains it) leaves the run as it is
                    league.set_run_status(cfg.run, RunStatus.FAILED)
                raise
            except BaseException:  # whatever else ends it, the run is not left 'running'
                league.set_run_status(cfg.run, RunStatus.FAILED)
                raise
        league.set_run_status(cfg.run, RunStatus.FINISHED)
    finally:
        league.close()
    if json_out:
        print_json(report_json(report))
        return
    console.print(describe_run(report, inline=cfg.eval_inline), markup=False, highlight=False)
    for rec in report.finals:
        console.print("  " + describe_record(rec), markup=False)
    if report.best is not None:
        from ..league.ladder import verdict_lines

        for line in verdict_lines(report.side_bests or [report.best]):
            console.print("  " + line, markup=False)
    console.print(f"  all snapshots: marl league ladder --run {report.run}", markup=False)
    if report.plot is not None:
        console.print(f"  rating curves: {report.plot}", markup=False)


class Terminated(Exception):  # noqa: N818 (it is how the run learns of SIGTERM, not an error)
    """SIGTERM arrived: the run stops as it does on Ctrl-C."""


@contextmanager
def stop_on_sigterm() -> Iterator[None]:
    """While training, SIGTERM (a CI job cancelled, ``kill``, a container stopped) raises :class:`Terminated` in the
    main thread, so the run ends cleanly: the rating worker stopped, the status set, the resume hint printed."""
    def handler(signum: int, frame: Any) -> None:
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. called from a test harness thread): leave SIGTERM alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
