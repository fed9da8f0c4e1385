"""A run's settings: one dataclass with every option, validated at once, saved with the run."""

from __future__ import annotations

import json
import math
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import files
from ..algos import LEARNERS, DQNConfig, MAPPOConfig, POCAConfig, PPOConfig, SACConfig
from ..envs import EnvSpec, SeatSpace, get_env
from ..envs.obs_spaces import stacked_space
from ..errors import MarlError
from ..evaluation.executors import EVAL_MODES
from ..league.store import League
from ..play.frames import check_frame_stack
from ..play.seat_plan import SHARING, SeatPlan, league_layout, learner_spaces, parse_seats, plan_layout, plan_seats
from ..policies.joint import joint_spaces
from ..policies.network import Arch, resolve_device
from ..policies.snapshot_format import expected_tensors
from .bounds import check_games, check_memory, check_ranges
from .curriculum import Curriculum, Schedule, parse_schedule
from .league_roles import LeagueConfig
from .matchmaking import MatchmakerConfig

ALGOS = tuple(LEARNERS)  # the registered learners (selfplay_cli.algos.LEARNERS)
DICT_SETTINGS = ("env_options", "curriculum", "snapshot_meta", "init_plan")  # tables checked by the game (or their
# owner), not by the type of a field
EXECUTORS = ("local", "ray")
"""Where a run's training games are stepped (``--executor``): this process, or Ray actors
(:mod:`selfplay_cli.train.ray_rollouts`)."""


@dataclass
class TeacherConfig:
    """``[teacher]``: kickstarting (:mod:`selfplay_cli.algos.kickstart`). The learners imitate ``player`` on the
    states they visit, the imitation term weighted by ``weight`` against the run's progress (a schedule as a
    ``[curriculum]`` entry takes: a ramp, lessons or one number), so their own objective takes over as it fades."""

    player: str = ""  # a scripted player of the game (serve-bot) or a snapshot's name; "" or "none": no teacher
    weight: Any = field(default_factory=lambda: {"start": 1.0, "end": 0.0, "until": 0.5})
    states: int = 300_000  # labelled states each learner keeps to imitate (the newest)

    def __post_init__(self) -> None:
        if self.player.strip().lower() == "none":
            self.player = ""
        self.schedule()  # a bad weight is one line now
        if self.states < 1:
            raise MarlError(f"[teacher] states must be at least 1, not {self.states}")

    def schedule(self) -> Schedule:
        """The imitation term's weight against progress."""
        schedule = parse_schedule("weight", self.weight, section="teacher")
        if any(v < 0 for v in (schedule.start, schedule.end, *(v for _, v in schedule.lessons))):
            raise MarlError(f"[teacher] weight must not be negative, not {self.weight!r}")
        return schedule


@dataclass
class TrainConfig:
    """Everything a run is made of; saved with the run so it can be resumed and reproduced."""

    env: str  # the game (a registered name, or a module:factory of your own)
    agents: int = 2
    algo: str = "ppo"
    sharing: str = "nops"
    seats: str = ""  # which learner holds each seat, e.g. "1,2" or "1,1,-" (- an opponent); "": by the game's kind
    steps: int = 6_000_000  # game steps (one step of one game, all seats acting)
    minutes: float | None = None  # wall-clock budget instead of steps
    run: str = ""
    seed: int = 0
    device: str = "auto"
    games: int = 256  # games played at once (measured: 256 trains ~1.4x faster than 128 on 2 cores)
    snapshot_every: int = 0  # episodes (finished games) between snapshots, named epN; 0: by steps only
    snapshot_steps: int = 1_000_000  # game steps between snapshots (whichever comes first); 0: by episodes only
    tensorboard: bool = False  # also write the metrics for TensorBoard (runs/<run>/tensorboard)
    swap_every: int = 0  # game steps a game slot keeps its drawn opponent (ML-Agents' swap_steps); 0: every game
    league_games: float = 0.0  # all seats learning: share of games one learner plays a league opponent instead
    eval_games: int = 8  # games a new snapshot plays against each gauntlet opponent (more for eval_precision)
    eval_older: int = 2  # older snapshots of the run in each gauntlet, besides the predecessor and the best
    eval: str = "local"  # who plays the gauntlets: local (a worker process beside training), inline (the training
    # process, paused), remote (the league's workers, from its work queue: marl worker, on any machine), ray (queue
    # workers on Ray actors started for the run)
    eval_wait: bool = True  # the run's end waits for its gauntlets (False, --eval local or remote: leaves those not
    # played yet on the league's queue, to its workers)
    eval_actors: int = 1  # --eval ray: queue workers on Ray actors playing the run's gauntlets
    executor: str = "local"  # where the training games are stepped: local (this process) or ray (Ray actors)
    actors: int = 2  # --executor ray: rollout actors, each stepping a share of the games
    ray_address: str = ""  # --executor ray, --eval ray: a Ray cluster to join ("": Ray started on this machine)
    fragment_steps: int = 0  # --executor ray: steps of every game an actor plays between weight updates (PPO: its
    # rollout, always; SAC and DQN: 0 means 16)
    frame_stack: int = 1  # observations each learner reads at once: its seat's last K (images on the channel axis)
    eval_playoff: int = 100  # after the final gauntlet the run's best candidates meet, up to this many games a pair
    eval_precision: float = 0.3  # a gauntlet matchup (snapshots or bots) plays the games an even record needs to
    # predict a 200-game match of the two within this many score points (up to 4 x eval_games; 0: eval_games)
    opponents: MatchmakerConfig = field(default_factory=MatchmakerConfig)
    env_options: dict[str, Any] = field(default_factory=dict)
    curriculum: dict[str, Any] = field(default_factory=dict)  # live game options against progress (curriculum.py)
    teacher: TeacherConfig = field(default_factory=TeacherConfig)  # kickstarting: a player the learners imitate
    league: LeagueConfig | None = None  # AlphaStar's league roles (--league alphastar, a [league] table); None: off
    restart_at_snapshot: bool = False  # each learner starts again from its first weights (and a fresh optimiser)
    # after every snapshot but the final one: PSRO's oracle, a new best response to the opponents of the moment
    snapshot_meta: dict[str, Any] = field(default_factory=dict)  # entries of every snapshot row's meta (marl exploit's
    # best response: league_role = "exploiter", target)
    init_from: str = ""  # a snapshot or team whose weights the learners start from (--init-from; "": fresh ones)
    init_plan: dict[str, Any] = field(default_factory=dict)  # what init_from resolved to when the run was created
    # (written by marl, :mod:`.init_from`): the source, its members, and the member each learner starts from
    ppo: PPOConfig = field(default_factory=PPOConfig)
    dqn: DQNConfig = field(default_factory=DQNConfig)
    sac: SACConfig = field(default_factory=SACConfig)
    mappo: MAPPOConfig = field(default_factory=MAPPOConfig)  # --algo mappo: PPO's settings and the team critic's
    poca: POCAConfig = field(default_factory=POCAConfig)  # --algo poca: MAPPO's and the attention's heads

    def __post_init__(self) -> None:
        if self.steps < 1 and self.minutes is None:
            raise MarlError(f"--steps must be positive, not {self.steps}")
        check_ranges(self)
        if self.games < 2:
            raise MarlError(f"--games must be at least 2, not {self.games}")
        if not isinstance(self.snapshot_meta, dict):
            raise MarlError(f"snapshot_meta must be a table, not {self.snapshot_meta!r}")
        if not isinstance(self.init_plan, dict):
            raise MarlError(f"init_plan must be a table, not {self.init_plan!r}")
        self.init_from = self.init_from.strip()
        if self.init_from and self.sharing == "sa":
            raise MarlError("--init-from starts learners of one seat each (--sharing nops or fups) from a snapshot; "
                            "one agent over the whole team (--sharing sa) is not one of them")
        resolve_device(self.device)  # an unknown or unavailable device fails before anything is written
        if self.tensorboard:
            tensorboard_writer(None)  # fails now, with the install hint, rather than after the run is created
        if self.swap_every < 0:
            raise MarlError(f"--swap-every must not be negative, not {self.swap_every}")
        if self.eval_games < 0 or self.eval_games % 2:
            raise MarlError(f"--eval-games must be 0 (no rating games) or an even number (games are played in "
                            f"seat-swapped pairs), not {self.eval_games}")
        if self.eval_older < 0:
            raise MarlError(f"--eval-older must not be negative, not {self.eval_older}")
        if self.opponents.mode == "nash" and not self.eval_games:
            raise MarlError("--opponents nash draws from the Nash mixture of the run's rated games: it needs "
                            "--eval-games above 0")
        if self.eval_playoff < 0:
            raise MarlError(f"--eval-playoff must not be negative, not {self.eval_playoff}")
        if not 0.0 <= self.eval_precision < 1.0:
            raise MarlError(f"--eval-precision is a share of the score, at least 0 and below 1, not "
                            f"{self.eval_precision}")
        if self.eval not in EVAL_MODES:
            raise MarlError(f"--eval must be one of {', '.join(EVAL_MODES)}, not '{self.eval}'")
        if self.executor not in EXECUTORS:
            raise MarlError(f"--executor must be one of {', '.join(EXECUTORS)}, not '{self.executor}'")
        if self.executor == "ray" and not 1 <= self.actors <= self.games:
            raise MarlError(f"--actors must be between 1 and --games ({self.games}), not {self.actors}")
        if self.fragment_steps < 0:
            raise MarlError(f"--fragment-steps must not be negative, not {self.fragment_steps}")
        if "ray" in (self.executor, self.eval):
            from ..ray_support import ray_module

            ray_module()  # Ray not installed: one line now, before anything is written
        if self.eval_actors < 1:
            raise MarlError(f"--eval-actors must be at least 1, not {self.eval_actors}")
        if self.eval_actors != 1 and self.eval != "ray":
            raise MarlError(f"--eval-actors is for --eval ray (queue workers on Ray actors), not --eval {self.eval}")
        if not self.eval_wait and self.eval not in ("local", "remote"):
            who = "its Ray actors, which end with it, play" if self.eval == "ray" else "the training process plays"
            raise MarlError(f"--no-wait is for --eval local or remote (the run ends with its training and leaves the "
                            f"gauntlets not played yet to the league's workers, marl worker); with --eval "
                            f"{self.eval} {who} every gauntlet")
        if self.snapshot_every < 0 or self.snapshot_steps < 0 or not (self.snapshot_every or self.snapshot_steps):
            raise MarlError("--snapshot-every (episodes) or --snapshot-steps must be positive")
        if self.algo not in ALGOS:
            raise MarlError(f"unknown --algo '{self.algo}'; available: {', '.join(ALGOS)}")
        check_frame_stack(self.frame_stack)
        if self.frame_stack > 1 and self.sharing == "sa":
            raise MarlError("--frame-stack is for agents that read their own seat (--sharing nops or fups), not one "
                            "agent over the team's joint observation (--sharing sa)")
        try:
            spec = self.game()
        except (TypeError, ValueError) as e:
            raise MarlError(f"[env_options]: {e}") from None
        n_seats = spec.n_seats
        if self.sharing not in SHARING:
            raise MarlError(f"--sharing must be one of {', '.join(SHARING)}, not '{self.sharing}'")
        if getattr(LEARNERS[self.algo], "centralised", False):  # a critic of the whole team (MAPPO, MA-POCA)
            LEARNERS[self.algo].check_game(spec, self.sharing)
            if self.executor != "local":
                raise MarlError(f"--algo {self.algo} trains with --executor local only (its critic reads every "
                                "seat of a game each step)")
        if not 0.0 <= self.league_games <= 1.0:
            raise MarlError(f"--league-games must lie between 0 and 1, not {self.league_games}")
        if self.league is not None:
            _check_league(self, spec)
        if self.restart_at_snapshot and self.league is not None:
            raise MarlError("--restart-at-snapshot is for one league of learners without roles; with --league each "
                            "role's own rule says when a learner restarts")
        plan = self.seat_plan()
        if self.league_games and not plan.every_seat_learns:
            raise MarlError(f"--league-games is for --agents {n_seats} (learners on every seat); with fewer learners "
                            "every game is already against the league")
        if fups_without_partners(spec, self.agents, self.sharing, self.seats):
            raise MarlError("--sharing fups shares one network between several learners: it needs --agents 2 or more")
        try:
            game = spec.config(**self.env_options)
            core = spec.make_core(1, game)  # options the game takes but cannot train with (pong's rgb frames) fail
            seat_spaces = spec.seat_spaces(game)
        except (TypeError, ValueError) as e:
            raise MarlError(f"[env_options]: {e}") from None
        curriculum = Curriculum(self.curriculum, spec.name, spec.live_options)
        if curriculum:
            curriculum.check(core)
        check_games(self, seat_spaces)
        layout = self.layout(plan)
        roles = spec.seat_roles(game)
        if self.opponents.mode == "nash" and len(set(roles)) > 1:  # (a meta-game per pair of roles: not yet)
            raise MarlError(f"--opponents nash solves one symmetric meta-game over the run's snapshots, but the seats "
                            f"of {spec.name} hold different roles ({', '.join(dict.fromkeys(roles))}), whose "
                            "snapshots never meet: use --opponents pfsp")
        spaces = learner_spaces(spec, seat_spaces, layout, roles if len(set(roles)) > 1 else None)
        learned = {roles[s] for s in range(n_seats) if (layout[s] >= 0).any()}
        foreign = [s for s in range(n_seats) if roles[s] not in learned]
        if foreign and sum(self.opponents.bots.values()) < 1:  # its opponents: no snapshot, no live learner fits
            s = foreign[0]
            raise MarlError(f"seat {spec.agents[s]} of {spec.name} is of role {roles[s]}, which no learner learns: "
                            "only scripted players can play it; give it a learner (--seats), or let scripted "
                            "players fill it (--bots random=1)")
        if self.sharing == "sa":  # one agent over the team: its joint spaces (too many joint actions: refused)
            obs, act = joint_spaces(spaces[0].observation, spaces[0].action, spec.n_seats, spec.name)
            spaces = [type(spaces[0])(obs, act, False)]
            layout = np.zeros((1, self.games), dtype=np.int64)  # one slot a game
        for space in spaces:
            LEARNERS[self.algo].check_seat(space)  # e.g. DQN and Box actions: refused before anything is written
            _check_networks(self, space)
        if self.teacher.player:
            check_teacher(self.algo, self.sharing)
        seen = stacked_space(spaces[0].observation, self.frame_stack)
        check_memory(self, tuple(seen.shape), [int((layout == i).sum()) for i in range(len(spaces))],
                     np.dtype(seen.dtype).itemsize)

    @property
    def eval_inline(self) -> bool:
        """The gauntlets are played in the training process (``--eval inline``)."""
        return self.eval == "inline"

    def game(self) -> EnvSpec:
        """The game as the run's options make it (a lander run of 3 landers has 3 seats)."""
        return get_env(self.env).for_options(**self.env_options)

    def seat_plan(self) -> SeatPlan:
        """Which learner holds which seat of the game (``--agents``, ``--sharing``, ``--seats``); in a league
        (``--league``), the seats of a lone learner, which each of its learners takes in its own games."""
        if self.league is not None:
            return plan_seats(self.game(), 1)
        return seat_plan_of(self.game(), self.agents, self.sharing, self.seats)

    def layout(self, plan: SeatPlan) -> np.ndarray:
        """The learner of every (seat, game) slot, -1 for an opponent's (:func:`~selfplay_cli.play.seat_plan.
        plan_layout`; a league's: :func:`~selfplay_cli.play.seat_plan.league_layout`)."""
        if self.league is not None:
            return league_layout(plan, self.games, len(self.league.roles()))
        return plan_layout(plan, self.games, self.agents, self.league_games)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["ppo"] = self.ppo.to_dict()
        d["dqn"] = self.dqn.to_dict()
        d["sac"] = self.sac.to_dict()
        d["mappo"] = self.mappo.to_dict()
        d["poca"] = self.poca.to_dict()
        d["opponents"] = asdict(self.opponents)
        d["teacher"] = asdict(self.teacher)
        d["league"] = asdict(self.league) if self.league is not None else None
        return d

    @classmethod
    def defaults(cls, env: str, run: str = "new") -> dict[str, Any]:
        """Every setting at its default for a run on ``env``, in :meth:`to_dict`'s layout, unchecked: the first
        layer of a new run's settings (:func:`~selfplay_cli.train.settings.new_settings`). The defaults alone are
        no run, and are not checked as one (256 games of an image game would not fit in memory where the 4 the
        user types do): the settings are checked once every layer is applied (:meth:`from_dict`)."""
        cfg = object.__new__(cls)  # no __post_init__: nothing is checked here
        for f in fields(cls):
            if f.default is not MISSING:
                setattr(cfg, f.name, f.default)
            elif f.default_factory is not MISSING:
                setattr(cfg, f.name, f.default_factory())
        cfg.env, cfg.run = env, run
        return cfg.to_dict()

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """A configuration from ``to_dict``'s layout (a saved run, or a --config file merged over the defaults).
        Unknown keys are refused by name, so a typo in a config file is an error, not a silent default; every value
        must have its setting's type (``steps = "many"`` or ``[ppo] lr = "fast"`` is one line naming the setting
        and the type it wants; a whole float such as ``steps = 5e6`` is taken as the whole number)."""
        from ..typecheck import check_fields, field_types

        d = dict(d)
        _legacy_eval_inline(d)
        sections = {"ppo": PPOConfig, "dqn": DQNConfig, "sac": SACConfig, "mappo": MAPPOConfig, "poca": POCAConfig,
                    "opponents": MatchmakerConfig,
                    "teacher": TeacherConfig, "league": LeagueConfig}
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise MarlError(f"unknown training setting(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
        plain = check_fields(cls, {k: v for k, v in d.items() if k not in sections and k not in DICT_SETTINGS},
                             where="setting ")
        d.update(plain)
        if "seed" in d and not 0 <= d["seed"] < 2**32:
            raise MarlError(f"--seed must lie between 0 and {2**32 - 1}, not {d['seed']}")
        if "env" not in d:
            raise MarlError("the settings do not name the game (env = \"pong\", or a module:factory of your own)")
        if "env_options" in d:
            if not isinstance(d["env_options"], dict):
                raise MarlError(f"[env_options] must be a table of game options, not {d['env_options']!r}")
            game = get_env(str(d["env"]))
            d["env_options"] = check_fields(type(game.config()), d["env_options"], where="[env_options] ")
        if "curriculum" in d and not isinstance(d["curriculum"], dict):
            raise MarlError(f"[curriculum] must be a table of the game's live options, not {d['curriculum']!r}")
        for key, section in sections.items():
            if key in d and d[key] is not None and not isinstance(d[key], section):
                if not isinstance(d[key], dict):
                    raise MarlError(f"[{key}] must be a table of settings, not {d[key]!r}")
                values = dict(d[key])
                allowed = set(field_types(section)) or {f.name for f in fields(section)}
                bad = sorted(set(values) - allowed)
                if bad:
                    raise MarlError(f"unknown [{key}] setting(s) {', '.join(bad)}; known: {', '.join(sorted(allowed))}")
                values = check_fields(section, values, where=f"[{key}] ")
                try:
                    d[key] = section(**values)
                except (TypeError, ValueError) as e:
                    raise MarlError(f"[{key}]: {e}") from None
        return cls(**d)


def _check_league(cfg: TrainConfig, spec: EnvSpec) -> None:
    """A league (``--league alphastar``) lays out its own learners, one per role, each on one seat of its own games
    against opponents its role draws: what contradicts that is refused, one line each."""
    if spec.kind == "cooperative":
        raise MarlError(f"{spec.name} is cooperative: cooperative games have no exploiters (--league alphastar is for "
                        "two-sides and free-for-all games)")
    if cfg.sharing != "nops":
        raise MarlError(f"--league alphastar gives each role its own network: --sharing {cfg.sharing} does not apply")
    if cfg.seats:
        raise MarlError("--league alphastar seats each learner in its own games itself: --seats does not apply")
    if cfg.league_games:
        raise MarlError("--league alphastar plays every game against the league: --league-games does not apply")
    if cfg.opponents.bots:
        raise MarlError("--league alphastar draws every opponent by its role's rule: --bots does not apply")
    if cfg.executor != "local":
        raise MarlError("--league alphastar trains with --executor local only")
    n = len(cfg.league.roles())  # type: ignore[union-attr]
    lone = plan_seats(spec, 1)  # the seats a learner takes in turn: the two sides, or every seat of a free-for-all
    places = len(lone.sides) if lone.sides is not None else spec.n_seats
    if cfg.games < n * places:
        where = "sides" if lone.sides else "seats"
        raise MarlError(f"--games must be at least {n * places} with --league alphastar: each of its {n} learners "
                        f"plays a game in each of the game's {places} {where}, not {cfg.games}")


def _legacy_eval_inline(d: dict[str, Any]) -> None:
    """``eval_inline = true`` (a run saved by an earlier release, or a config file written for one) is ``eval =
    "inline"``; with another ``eval`` than the default it is a contradiction, refused."""
    if "eval_inline" not in d:
        return
    inline = d.pop("eval_inline")
    if not isinstance(inline, bool):
        raise MarlError(f"setting eval_inline wants true or false, not {inline!r}")
    if inline:
        if d.get("eval", "local") not in ("local", "inline"):
            raise MarlError(f"eval_inline = true is eval = \"inline\": it cannot go with eval = \"{d['eval']}\"")
        d["eval"] = "inline"


def can_teach(algo: str) -> bool:
    """Whether the algorithm's learners can imitate a teacher (kickstarting: PPO and SAC)."""
    return callable(getattr(LEARNERS.get(algo), "teach", None))


def check_teacher(algo: str, sharing: str) -> None:
    """A run that cannot have a teacher, as one line: an algorithm that cannot imitate, or one agent over the
    joint team (its actions are not a seat's). The teacher's name is resolved, and its spaces checked, against the
    league (:func:`selfplay_cli.train.rollouts.load_teacher`)."""
    if not can_teach(algo):
        learners = ", ".join(a for a in ALGOS if can_teach(a))
        raise MarlError(f"--teacher: {algo} learners cannot imitate a teacher (kickstarting is for {learners})")
    if sharing == "sa":
        raise MarlError("--teacher: one agent over the whole team (--sharing sa) acts for every seat at once; a "
                        "teacher plays one seat: use --sharing fups or nops")


def fups_without_partners(spec: EnvSpec, agents: int, sharing: str, seats: str) -> bool:
    """``--sharing fups`` with a lone learner that has nothing to share its network with (no ``--seats`` giving it
    several seats, and not a cooperative game's team)."""
    return sharing == "fups" and agents == 1 and not seats and spec.kind != "cooperative"


def seat_plan_of(spec: EnvSpec, agents: int, sharing: str, seats: str) -> SeatPlan:
    """Which learner holds which seat of ``spec`` (as :meth:`TrainConfig.seat_plan`, from the plain settings)."""
    return plan_seats(spec, agents, sharing, parse_seats(seats, spec.n_seats) if seats else None)


def _check_networks(cfg: TrainConfig, space: Any) -> None:
    """Refuse, before the run exists, networks bigger than a snapshot may be (:data:`~selfplay_cli.policies.
    snapshot_format.LIMITS`: layers, widths, parameters), so a run never grows out of memory building one, nor
    refuses its own first snapshot: the learner's network (what its snapshots save), and SAC's critics (the
    observation and the action in, one value out)."""
    section = getattr(cfg, cfg.algo, None)
    if not isinstance(getattr(section, "arch", None), Arch):
        return
    try:
        seat, section = learner_setup(cfg, space)
        arch = section.arch
        expected_tensors(tuple(seat.observation.shape), seat.action, arch)
        critics = getattr(section, "critic_hidden", None)
        if critics is not None:
            inputs = math.prod(space.observation.shape) + math.prod(space.action.shape)
            expected_tensors((inputs,), 1, Arch(hidden=critics, activation=arch.activation, value_head=False))
    except MarlError as e:
        raise MarlError(f"[{cfg.algo}] network: {e}") from None


def learner_setup(cfg: TrainConfig, space: SeatSpace) -> tuple[SeatSpace, Any]:
    """A learner of the seat ``space`` as the run makes it: the seat it reads (its last ``frame_stack``
    observations: :func:`~selfplay_cli.envs.obs_spaces.stacked_space`) and its algorithm's settings with the network
    made for the seat's observation (:meth:`~selfplay_cli.policies.network.Arch.for_obs`: an image seat's cnn, told
    from the observation before it is stacked)."""
    section = getattr(cfg, cfg.algo)
    seat = SeatSpace(stacked_space(space.observation, cfg.frame_stack), space.action, space.mask)
    return seat, replace(section, arch=section.arch.for_obs(space.observation))


def tensorboard_writer(log_dir: Path | None) -> Any:
    """A TensorBoard SummaryWriter (torch's) for ``log_dir``, or a one-line error when the tensorboard package is
    missing; with ``log_dir=None`` only the check."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        raise MarlError('--tensorboard needs the tensorboard package: pip install -e ".[tensorboard]" (or pip '
                        "install tensorboard)") from None
    return None if log_dir is None else SummaryWriter(log_dir=str(log_dir))


def save_run_config(league: League, cfg: TrainConfig) -> Path:
    """The resolved configuration, next to the run's metrics (written atomically)."""
    run_dir = league.home_path("runs", cfg.run)
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / "config.json"
    files.write_atomic(path, json.dumps(cfg.to_dict(), indent=2))
    return path
