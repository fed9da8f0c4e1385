"""`marl train ENV`: self-play training into the league."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from ..errors import MarlError
from ._common import DbOpt, DeviceOpt, HomeOpt, JsonOpt, QuietOpt, open_league, parse_env_options, progress_enabled
from ._output import console, err_console, print_json


def read_toml(path: Path) -> dict[str, Any]:
    """A --config file; a missing or malformed one is a one-line error naming it."""
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


def merge_settings(settings: dict[str, Any], overrides: dict[str, Any]) -> None:
    """Merge a config file into the settings: sections ([ppo], ...) key by key, everything else replaced."""
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(settings.get(key), dict):
            settings[key] = {**settings[key], **value}
        else:
            settings[key] = value


def train(
    ctx: typer.Context,
    env: Annotated[str | None, typer.Argument(help="The game to train on (see `marl envs`).")] = None,
    config: Annotated[Path | None, typer.Option("--config", help="TOML file of settings (top-level options, "
                                                "[ppo], [dqn], [opponents], [env_options]); options typed on the "
                                                "command line win over it.")] = None,
    agents: Annotated[int, typer.Option("--agents", help="Learning agents: 2 trains both pong paddles (seed 000); 1 "
                                        "trains one learner against opponents from the league.")] = 2,
    algo: Annotated[str, typer.Option("--algo", help="Learning algorithm: ppo or dqn.")] = "ppo",
    preset: Annotated[str | None, typer.Option("--preset", help="seed000: seed 000's DQN set-up (network sizes, "
                                               "learning rate, batch, buffer, target period, epsilon).")] = None,
    sharing: Annotated[str, typer.Option("--sharing", help="nops: one network per learner; fups: one shared "
                                         "network.")] = "nops",
    steps: Annotated[int, typer.Option("--steps", help="Budget in game steps.")] = 6_000_000,
    minutes: Annotated[float | None, typer.Option("--minutes", help="Budget in minutes of wall clock instead "
                                                  "(fractions allowed).")] = None,
    run: Annotated[str | None, typer.Option("--run", help="Run name (default: <env>-<n>).")] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of networks, games and opponent choice.")] = 0,
    games: Annotated[int, typer.Option("--games", help="Games played at once.")] = 256,
    snapshot_every: Annotated[int, typer.Option("--snapshot-every", help="Episodes (finished games) between "
                                                "snapshots, named epN (0: by steps only).")] = 128,
    snapshot_steps: Annotated[int, typer.Option("--snapshot-steps", help="Game steps between snapshots, whichever "
                                                "of the two comes first (0: by episodes only).")] = 1_000_000,
    swap_every: Annotated[int, typer.Option("--swap-every", help="Game steps a game slot keeps the opponent it drew "
                                            "(ML-Agents' swap_steps); 0: a new draw for every game.")] = 0,
    tensorboard: Annotated[bool, typer.Option("--tensorboard", help="Also write the metrics for TensorBoard "
                                              "(<home>/runs/<run>/tensorboard; needs the tensorboard package).")]
    = False,
    league_games: Annotated[float, typer.Option("--league-games", help="With every seat learning (--agents 2): "
                                                "share of games in which a learner meets an opponent from the league "
                                                "(drawn by --opponents/--bots) instead of the other learner; 0 keeps "
                                                "seed 000's set-up.")] = 0.0,
    eval_games: Annotated[int, typer.Option("--eval-games", help="Rated games against each scripted player after "
                                            "every snapshot (0: none).")] = 32,
    opponents: Annotated[str, typer.Option("--opponents", help="League opponents (--agents 1, or --league-games): "
                                           "self | latest | uniform | pfsp, from the run's snapshots.")] = "pfsp",
    window: Annotated[int, typer.Option("--window", help="Opponents are drawn from the last WINDOW snapshots "
                                        "(ML-Agents' window, default 10).")] = 10,
    latest_ratio: Annotated[float, typer.Option("--latest-ratio", help="Share of league games against the "
                                                "current learner (two learners: the other one); ML-Agents' "
                                                "play_against_latest_model_ratio.")]
    = 0.5,
    bots: Annotated[str, typer.Option("--bots", help="Mix in scripted players, e.g. cpu=0.1,random=0.05.")] = "",
    lr: Annotated[float | None, typer.Option("--lr", help="Learning rate (default: the algorithm's own, PPO 2e-3, "
                                             "DQN 2.5e-4).")] = None,
    env_option: Annotated[list[str] | None, typer.Option("--env-option", help="Game option KEY=VALUE, repeatable "
                                                         "(e.g. points_to_win=5).")] = None,
    resume: Annotated[str | None, typer.Option("--resume", help="Continue a run that was stopped or killed, from "
                                               "its last snapshot (its saved configuration applies).")] = None,
    device: DeviceOpt = "auto",
    quiet: QuietOpt = False,
    home: HomeOpt = None,
    db: DbOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Train agents by self-play; every snapshot joins the league and is rated against the scripted players."""
    from ..algos.dqn import seed000_config
    from ..envs import get_env
    from ..league.matchmaking import parse_bots
    from ..train.loop import TrainConfig, Trainer, save_run_config

    league = open_league(home, db)
    try:
        if resume is not None:
            old = league.get_run(resume)
            if old is None:
                raise MarlError(f"no run named '{resume}' to resume")
            if env is not None and env != old.env:
                raise MarlError(f"run '{resume}' trains {old.env}, not {env}")
            cfg = TrainConfig.from_dict(old.config)
            if device != "auto":
                cfg.device = device
        else:
            if env is None:
                raise MarlError("name the game to train on (e.g. marl train pong), or --resume RUN")
            spec = get_env(env)
            if run is None:
                taken = {r.name for r in league.list_runs()}
                run = next(f"{env}-{i}" for i in range(1, 10_000) if f"{env}-{i}" not in taken)
            elif league.get_run(run) is not None:
                raise MarlError(f"a run named '{run}' already exists: choose another --run (or --resume it)")
            if preset not in (None, "seed000"):
                raise MarlError(f"unknown --preset '{preset}'; available: seed000")
            typed = {name for name in ctx.params  # options the user typed (not defaults), which beat --config
                     if getattr(ctx.get_parameter_source(name), "name", "") in ("COMMANDLINE", "ENVIRONMENT")}
            settings = TrainConfig(env=spec.name, run=run).to_dict()  # the defaults
            if preset == "seed000":
                settings["algo"] = "dqn"
                settings["dqn"] = seed000_config().to_dict()
            if config is not None:
                merge_settings(settings, read_toml(config))
            flags = {"agents": agents, "algo": algo, "sharing": sharing, "steps": steps, "minutes": minutes,
                     "seed": seed, "device": device, "games": games, "snapshot_every": snapshot_every,
                     "snapshot_steps": snapshot_steps, "eval_games": eval_games, "swap_every": swap_every,
                     "tensorboard": tensorboard, "league_games": league_games}
            settings.update({k: v for k, v in flags.items() if k in typed})
            matchmaking = {"opponents": ("mode", opponents), "window": ("window", window),
                           "latest_ratio": ("latest_ratio", latest_ratio)}
            settings["opponents"].update({key: value for flag, (key, value) in matchmaking.items() if flag in typed})
            if "bots" in typed:
                settings["opponents"]["bots"] = parse_bots(bots)
            if "lr" in typed:
                settings["ppo"]["lr"] = settings["dqn"]["lr"] = lr
            settings["env_options"] = {**settings["env_options"], **parse_env_options(spec.name, env_option)}
            try:
                spec.config(**settings["env_options"])
            except (TypeError, ValueError) as e:
                raise MarlError(f"[env_options]: {e}") from None
            settings["env"], settings["run"] = spec.name, run
            cfg = TrainConfig.from_dict(settings)
            algo = cfg.algo
            league.create_run(run, spec.name, cfg.to_dict(), algo=algo)
            save_run_config(league, cfg)
        show = progress_enabled(quiet or json_out)
        total = 1000
        with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[info]}"),
                      TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=err_console,
                      disable=not show, transient=True) as bar:
            task = bar.add_task(f"train {cfg.run}", total=total, info="")

            def on_progress(p: dict) -> None:
                rate = p["steps"] / max(bar.tasks[0].elapsed or 1e-9, 1e-9)
                ev = "  ".join(f"vs {k} {100 * v:.0f}%" for k, v in p["eval"].items())
                bar.update(task, completed=int(total * min(p["progress"], 1.0)),
                           info=f"{p['steps']:,} steps  {rate:,.0f}/s  {p['episodes']:,} episodes  "
                                f"elo {p['elo']:.0f}  {ev}")

            trainer = None
            try:
                trainer = Trainer(league, cfg, on_progress=on_progress)
                if resume is not None:
                    note = trainer.restore()
                    league.set_run_status(cfg.run, "running")
                    if not json_out:
                        err_console.print(note)
                report = trainer.train()
            except KeyboardInterrupt:
                league.set_run_status(cfg.run, "interrupted")
                at = f" at step {trainer.steps:,}" if trainer is not None else ""
                err_console.print(f"interrupted {cfg.run}{at}; continue it with: marl train --resume {cfg.run}")
                raise typer.Exit(130) from None
            except MarlError:
                if resume is None:  # a refused resume (e.g. another process trains it) leaves the run as it is
                    league.set_run_status(cfg.run, "failed")
                raise
            except Exception:
                league.set_run_status(cfg.run, "failed")
                raise
        league.set_run_status(cfg.run, "finished")
    finally:
        league.close()
    data = {"run": report.run, "steps": report.steps, "episodes": report.episodes,
            "seconds": round(report.seconds, 1), "steps_per_second": round(report.steps_per_second),
            "snapshots": report.snapshots, "final_eval_score": report.last_eval}
    if json_out:
        print_json(data)
        return
    console.print(f"run {report.run}: {report.steps:,} game steps in {report.seconds:.0f} s "
                  f"({report.steps_per_second:,.0f}/s), {report.episodes:,} episodes, "
                  f"{len(report.snapshots)} snapshots (latest {report.snapshots[-1]})")
    if report.last_eval:
        console.print("  latest snapshot scores " + ", ".join(f"{100 * v:.0f}% vs {k}"
                                                                for k, v in report.last_eval.items()))
