"""`marl train ENV`: self-play training into the league."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Annotated, Any

import typer

from ..errors import EXIT_INTERRUPTED, EXIT_TERMINATED
from ..signals import Terminated, stop_on_sigterm
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
    typed_game,
)
from ._output import console, err_console, print_json
from .train_view import TrainProgress, describe_init, describe_record, describe_run, report_json, still_coming


# Long for its signature: a Typer command whose parameters are its ~30 options (about 90 lines); the body parses
# them, runs the trainer and prints (the settings are resolved by selfplay_cli.train.settings). Its docstring is
# `marl train --help`'s text.
def train(
    ctx: typer.Context,
    env: Annotated[str | None, typer.Argument(callback=typed_game, help="The game to train on (see `marl envs`; a "
                                              "game of your own, module:factory, is imported because you name it "
                                              "here).")] = None,
    config: Annotated[Path | None, typer.Option("--config", metavar="FILE", help="TOML file of settings (top-level "
                                                "options, [ppo], [dqn], [sac], [mappo], [poca], [opponents], "
                                                "[env_options], [curriculum], [teacher], [league]); options typed on "
                                                "the command line win over it.")] = None,
    agents: Annotated[int, typer.Option("--agents", min=1, max=64, help="Learning agents. Two sides: 2 is one learner "
                                        "per side (both pong paddles, seed 000), 1 one learner against opponents "
                                        "from the league; cooperative: seat s is learner s mod N; free-for-all: one "
                                        "per seat, or fewer against the league.")] = 2,
    seats: Annotated[str | None, typer.Option("--seats", metavar="L,L,...", help="Which learner holds each seat, "
                                              "in the game's seat order: 1,2 or 1,1,- (- an opponent from the "
                                              "league); overrides --agents.")] = None,
    algo: Annotated[str, typer.Option("--algo", help="Learning algorithm: ppo (any action space), dqn (Discrete "
                                      "actions), sac (Box actions); for a cooperative team, mappo (PPO whose critic "
                                      "reads the team) or poca (MA-POCA: an attention critic over the agents "
                                      "present, credit after an agent leaves).")] = "ppo",
    preset: Annotated[str | None, typer.Option("--preset", help="seed000: seed 000's DQN set-up (network sizes, "
                                               "learning rate, batch, buffer, target period, epsilon).")] = None,
    sharing: Annotated[str, typer.Option("--sharing", help="nops: one network per learner; fups: one shared "
                                         "network; sa: one agent over a cooperative team's joint observation "
                                         "and action (not with mappo or poca).")] = "nops",
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
                                            "seat-swapped pairs (more for --eval-precision). 0: no rating "
                                            "games.")] = 8,
    eval_older: Annotated[int, typer.Option("--eval-older", min=0, max=1_000, help="Older snapshots of the run in "
                                            "each gauntlet, besides the predecessor and the best.")] = 2,
    eval: Annotated[str, typer.Option("--eval", metavar="local|inline|remote|ray", help="Who plays the rating "
                                      "games: local, a worker process beside training; inline, the training process "
                                      "(training paused); remote, the league's workers (marl worker, on any "
                                      "machine), from its work queue, this process playing what no worker takes "
                                      "at the run's end; ray, queue workers on Ray actors started for the run "
                                      "(--eval-actors; --ray-address joins a cluster).")] = "local",
    eval_actors: Annotated[int, typer.Option("--eval-actors", min=1, max=1_000, help="--eval ray: Ray actors "
                                             "playing the run's rating games (each a marl worker on the run's "
                                             "gauntlets; they stop when the run ends).")] = 1,
    eval_inline: Annotated[bool, typer.Option("--eval-inline", help="Same as --eval inline.")] = False,
    eval_wait: Annotated[bool, typer.Option("--wait/--no-wait", help="The run's end waits for its rating games "
                                            "(showing how many are left; Ctrl-C then stops the wait, not the run), "
                                            "or, with --no-wait (--eval local or remote), ends with its training and "
                                            "leaves the gauntlets not played yet on the league's queue for marl "
                                            "worker (marl queue shows them; the ladder fills in as they are "
                                            "played).")] = True,
    eval_playoff: Annotated[int, typer.Option("--eval-playoff", min=0, max=100_000, help="After the final "
                                              "gauntlet the run's best candidates meet, up to this many games a "
                                              "pair, until the best is separated (0: no playoff).")] = 100,
    eval_precision: Annotated[float, typer.Option("--eval-precision", min=0.0, max=0.99, help="A gauntlet matchup (of "
                                                  "snapshots or scripted players) plays, all at once, the games an "
                                                  "even record needs to predict a 200-game match of the two within "
                                                  "this share of the score (0.3: 30 points), up to 4 x --eval-games, "
                                                  "so the ladder's claims about the pair rest on its games; 0: "
                                                  "--eval-games exactly.")] = 0.3,
    executor: Annotated[str, typer.Option("--executor", metavar="local|ray", help="Where the training games are "
                                          "stepped: local, this process; ray, Ray actors (--actors), on this "
                                          "machine's cores or a cluster (--ray-address); the learners update here. "
                                          "Needs pip install \"selfplay-cli[ray]\".")] = "local",
    actors: Annotated[int, typer.Option("--actors", min=1, max=4096, help="--executor ray: rollout actors, one CPU "
                                        "each, each stepping a share of --games.")] = 2,
    ray_address: Annotated[str, typer.Option("--ray-address", metavar="HOST:PORT", help="--executor ray, --eval "
                                             "ray: join this running Ray cluster (ray start --head on one machine, "
                                             "ray start --address HOST:PORT on the others); default: Ray started on "
                                             "this machine.")] = "",
    fragment_steps: Annotated[int, typer.Option("--fragment-steps", min=0, max=1_000_000, help="--executor ray, SAC "
                                                "and DQN: steps of every game an actor plays between weight updates "
                                                "(the actors' weights are at most this old); 0: 16. PPO always "
                                                "collects one rollout a fragment.")] = 0,
    opponents: Annotated[str, typer.Option("--opponents", help="League opponents (--agents 1, or --league-games): "
                                           "self | latest | uniform | pfsp | nash, from the run's snapshots (nash: "
                                           "PSRO's Nash mixture of all of them, from their rated games, each new "
                                           "snapshot rated against every earlier one).")] = "pfsp",
    window: Annotated[int, typer.Option("--window", min=1, max=100_000, help="Opponents are drawn from the last N "
                                        "snapshots (ML-Agents' window; not with nash: all of them).")] = 10,
    nash_payoff: Annotated[str, typer.Option("--nash-payoff", help="--opponents nash: the meta-game's payoff, "
                                             "points (win 1, draw 0.5) or score (the game's own scores, e.g. "
                                             "poker's chips: PSRO's expected return).")] = "points",
    latest_ratio: Annotated[float, typer.Option("--latest-ratio", help="Share of league games against the "
                                                "current learner (two learners: the other one); ML-Agents' "
                                                "play_against_latest_model_ratio.")]
    = 0.5,
    bots: Annotated[str, typer.Option("--bots", metavar="BOT=P,...", help="Mix in scripted players with these "
                                      "probabilities, e.g. cpu=0.1,random=0.05.")] = "",
    restart_at_snapshot: Annotated[bool, typer.Option("--restart-at-snapshot", help="Each learner starts again from "
                                                      "its first weights, optimiser fresh, after every snapshot "
                                                      "but the final one: PSRO's oracle (with --opponents nash), a "
                                                      "new best response to the opponents of the moment.")]
    = False,
    league: Annotated[str | None, typer.Option("--league", metavar="alphastar", help="AlphaStar's league roles: "
                                               "main agents, main exploiters and league exploiters, each a learner "
                                               "of its own playing its share of the games against opponents its "
                                               "role's rule draws, snapshotting when it beats its targets or at a "
                                               "step limit ([league] table: the rules' numbers).")] = None,
    league_main: Annotated[int | None, typer.Option("--league-main", min=1, max=16, help="--league: main agents "
                                                    "(default 1).")] = None,
    league_main_exploiters: Annotated[int | None, typer.Option("--league-main-exploiters", min=0, max=16,
                                                               help="--league: main exploiters (default 1).")] = None,
    league_league_exploiters: Annotated[int | None, typer.Option("--league-league-exploiters", min=0, max=16,
                                                                 help="--league: league exploiters (default 2).")]
    = None,
    init_from: Annotated[str | None, typer.Option("--init-from", metavar="SNAPSHOT_OR_TEAM", help="Start the "
                                                  "learners from a snapshot's weights (optimiser fresh; it is their "
                                                  "first snapshots' parent), also of another variant of the game "
                                                  "(another team size): one snapshot starts every learner; a team "
                                                  "(run/s4k of s4k-lander_0, ...) gives learner i its member i, "
                                                  "extra learners copies of members from the third on (of a team "
                                                  "of 2: either member), fewer learners dropping members from the "
                                                  "third on, drawn from --seed (a shared network: the first "
                                                  "member).")] = None,
    teacher: Annotated[str | None, typer.Option("--teacher", metavar="PLAYER", help="Kickstart the learners: they "
                                                "also imitate this player (a scripted player such as serve-bot, or a "
                                                "snapshot) on the states they visit, the imitation's weight fading "
                                                "by [teacher] weight (default 1 to 0 over the first half of the run); "
                                                "none: no teacher (a game's default one off).")] = None,
    frame_stack: Annotated[int, typer.Option("--frame-stack", metavar="K", min=1, max=16, help="Each learner reads "
                                             "its seat's last K observations at once: an image's K frames on its "
                                             "channel axis, any other observation's K side by side (a game's first "
                                             "fills the stack at its start); its snapshots play the same way in "
                                             "match, ladder and record.")] = 1,
    conv: Annotated[str | None, typer.Option("--conv", metavar="LAYERS", help="The convolutional encoder of image "
                                             "seats (observations of uint8 HxWxC or CxHxW, 1 to 4 channels), as "
                                             "CHANNELSxKERNELsSTRIDE layers: e.g. 16x3s1,32x3s2; none: the pixels "
                                             "straight into the MLP. Default: 32x8s4,64x4s2,64x3s1 (the Nature-CNN) "
                                             "where the image's smaller side has 64 pixels or more, else "
                                             "16x3s1,32x3s2; then the MLP's hidden layers ([ppo.arch] hidden).")]
    = None,
    lr: Annotated[float | None, typer.Option("--lr", help="Learning rate (default: the algorithm's own, PPO 2e-3, "
                                             "DQN 2.5e-4, SAC 3e-4).")] = None,
    env_option: Annotated[list[str] | None, typer.Option("--env-option", metavar="KEY=VALUE", help="Game option, "
                                                         "repeatable (e.g. points_to_win=5; marl envs NAME lists "
                                                         "a game's options, types and defaults).")] = None,
    kind: Annotated[str | None, typer.Option("--kind", metavar="KIND", help="two-sides, cooperative or "
                                             "free-for-all: what a result is, for a PettingZoo game whose metadata "
                                             "does not say (by default 2 agents are two sides, more a free-for-all): "
                                             "pursuit's pursuers are one team (--kind cooperative). A game option "
                                             "(kind=...): the run's snapshots carry it, and its results are rated "
                                             "apart from the game's other kinds.")] = None,
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
    from ..league.store import check_name
    from ..ray_support import ray_for

    for what, name in (("run name", run), ("run name", resume)):
        if name is not None:
            check_name(what, name)  # before anything exists: a refused name leaves no league behind
    typed = {name for name in ctx.params  # options the user typed (not defaults)
             if getattr(ctx.get_parameter_source(name), "name", "") in ("COMMANDLINE", "ENVIRONMENT")}
    settings: dict[str, Any] = {}
    if resume is None:  # the whole configuration is checked before the league is opened (or created)
        from ..train.settings import new_settings

        settings = new_settings(env, {name: ctx.params[name] for name in typed}, config=config, preset=preset,
                                env_options=lambda game: parse_env_options(game, env_option))
    phase = "starting"  # where a Ctrl-C or SIGTERM outside the run's own training finds the command
    try:  # SIGTERM is this command's throughout: Ray's start sets a handler of its own (sys.exit(15)), not kept
        with stop_on_sigterm(), contextlib.ExitStack() as ray_here:
            if resume is None:  # --executor/--eval ray: joined first, so a cluster out of reach leaves nothing behind
                ray_here.enter_context(ray_for(settings))
            league = open_league(home, db)
            try:
                if resume is not None:
                    from ..train.needs import resumable

                    old = resumable(league, resume, env)  # not there, or ended: said before the trainer's imports
                    from ..train.settings import EXECUTOR_OPTIONS, resumed_config

                    cfg = resumed_config(league, old, typed, device,
                                         wait=eval_wait if "eval_wait" in typed else None,
                                         executor={k: ctx.params[k] for k in EXECUTOR_OPTIONS if k in typed})
                    ray_here.enter_context(ray_for(cfg.to_dict()))
                else:
                    from ..train.settings import start_run

                    cfg = start_run(league, settings, run)
                from ..train.session import RunStopped, run_training
                reporter = TrainProgress(cfg, bar=progress_enabled(quiet or json_out), lines=not quiet)
                with reporter, stop_on_sigterm():
                    try:
                        report = run_training(league, cfg, resumed=resume is not None, on_progress=reporter.update,
                                              on_note=None if quiet else lambda note: err_console.print(note,
                                                                                                       markup=False))
                    except RunStopped as stop:  # stderr: --json keeps stdout for the JSON alone
                        at = f" at step {stop.steps:,}" if stop.steps is not None else ""
                        err_console.print(f"stopped {cfg.run}{at} ({stop.why}); its last snapshot is kept: continue "
                                          f"it with: marl train --resume {cfg.run}", markup=False)
                        raise typer.Exit(EXIT_TERMINATED if stop.why == "SIGTERM" else EXIT_INTERRUPTED) from None
                phase = "ending"
            finally:
                league.close()
    except (Terminated, KeyboardInterrupt) as stop:  # Ray (when started here) is shut down, the league closed
        why = "SIGTERM" if isinstance(stop, Terminated) else "Ctrl-C"
        err_console.print(f"marl: stopped ({why}) while {phase}: " + ("no training was under way"
                          if phase == "starting" else "the run had finished"), markup=False)
        raise typer.Exit(EXIT_TERMINATED if isinstance(stop, Terminated) else EXIT_INTERRUPTED) from None
    if json_out:
        print_json({**report_json(report, cfg.eval, _actors(cfg)),
                    **({"init_from": cfg.init_plan} if cfg.init_plan else {})})
        return
    console.print(describe_run(report, cfg.eval, _actors(cfg)), markup=False, highlight=False)
    if cfg.init_plan:
        console.print("  " + describe_init(cfg.init_plan), markup=False, highlight=False)
    if report.budget_end is not None:
        console.print("  " + report.budget_end.describe(), markup=False, highlight=False)
    for rec in report.finals:
        console.print("  " + describe_record(rec, pending=bool(report.rating_left)), markup=False)
    if report.rating_left:
        for line in still_coming(report):
            console.print("  " + line, markup=False)
    elif report.best is not None:
        from ..ratings.verdicts import verdict_lines

        for line in verdict_lines(report.side_bests or [report.best]):
            console.print("  " + line, markup=False)
    if report.nash:
        mixture = ", ".join(f"{name.rpartition('/')[2]} {100 * w:.0f}%" for name, w in report.nash.items())
        console.print(f"  Nash mixture of the run's snapshots ({cfg.opponents.nash_payoff}): {mixture}; the matrix: "
                      f"marl league matrix --run {report.run} --min-games 1 --payoff {cfg.opponents.nash_payoff}",
                      markup=False)
    console.print(f"  all snapshots: marl league ladder --run {report.run}", markup=False)
    if report.plot is not None and (isinstance(report.plot, Path) or not report.rating_left):  # (none yet: said)
        console.print(f"  rating curves: {report.plot}", markup=False)


def _actors(cfg: Any) -> int:
    """The Ray actors that stepped the session's games (0: this process did)."""
    return cfg.actors if cfg.executor == "ray" else 0
