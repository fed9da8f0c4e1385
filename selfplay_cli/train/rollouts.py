"""A run's rollouts: stepping its self-play games and feeding the learners what they played.

Each step, the games play under the curriculum's options at the run's progress; with a teacher (``[teacher]``,
``--teacher``: kickstarting, :mod:`selfplay_cli.algos.kickstart`) the teacher labels every learner's observations
with its own actions while the schedule's weight is above 0, and each learner adds the imitation term, so weighted,
to its policy's loss; the learners act, the games step; then each learner records its transitions and, when its
rollout is due, updates.

Global state. A learner that declares ``wants_state = True`` (a centralised critic) is handed the global state of
its slots' games (:meth:`~selfplay_cli.play.training_games.SelfPlayGames.state`: one row a slot, in its slot order)
with every observation it is handed: ``see_state(rows)`` right before it acts on a step's observations (the state
they were made in) and right before an update that takes them as the next observations. A game that gives no state
(:meth:`~selfplay_cli.envs.EnvSpec.state_space` None) is refused for such a learner in one line; when no learner
wants it, no state is read.

The team's view. A learner that declares ``centralised = True`` (MAPPO, MA-POCA: a critic of the whole team) is
handed, right before it records each step, its rows of the step as the whole team played it
(:class:`~selfplay_cli.play.team_view.TeamStep`: every seat's observations and actions, who was in each game, the
global state where the game has one, the team's reward and end): ``see_team(step)``. Nothing of it is read when no
learner is centralised.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import MarlError
from ..league.store import League
from ..league.variants import variant_key
from ..play.team_view import TeamStep, TeamView, TeamViews
from ..play.training_games import SelfPlayGames
from ..players.load import load_player
from ..policies import Policy
from ..results import GameResult
from .config import TrainConfig
from .curriculum import Curriculum, Schedule
from .team import LearnerTeam


def load_teacher(league: League, cfg: TrainConfig, spaces: list[Any], device: str = "cpu") -> Policy | None:
    """The run's teacher (``[teacher] player``) as a policy playing greedily, or None without one; one clear
    :class:`MarlError` for a name the league does not know or a player whose spaces are not the learners'."""
    name = cfg.teacher.player
    if not name:
        return None
    from ..policies.spaces import describe_space
    from ..ratings.names import resolve

    try:
        row = resolve(league, name, cfg.env, variant=variant_key(cfg.env, cfg.env_options))
    except MarlError as e:
        raise MarlError(f"--teacher: {e}") from None
    teacher = load_player(league, row, device=device, greedy=True, seed=cfg.seed)
    if callable(getattr(teacher, "configure", None)):  # a scripted player: the run's game options
        teacher.configure(cfg.env_options)
    for space in spaces:
        obs, act = getattr(teacher, "obs_space", None), getattr(teacher, "act_space", None)
        if obs is not None and tuple(obs.shape) != tuple(space.observation.shape):
            raise MarlError(f"--teacher: {row.full_name} reads observations of shape {tuple(obs.shape)}; the learners "
                            f"see {tuple(space.observation.shape)}")
        if act is not None and describe_space(act) != describe_space(space.action):
            raise MarlError(f"--teacher: {row.full_name} plays {describe_space(act)}; the learners play "
                            f"{describe_space(space.action)}")
    return teacher


@dataclass
class Step:
    """One step of every training game: the observations after it, the rewards and ends (per slot: its seat's part
    in its game ended), the games it finished, the slots that acted (turn-based games, and games whose agents come
    and go; None: all did), per learner the slots cut short on it with their final observations and masks (None:
    none was), and the global state after it for the learners that want it."""

    obs: list[np.ndarray]
    rewards: Any
    dones: Any
    finished: list[GameResult]
    acting: list[np.ndarray | None] | None
    truncated: list[np.ndarray] | None = None
    final_obs: list[np.ndarray] | None = None
    final_masks: list[np.ndarray | None] | None = None
    state: list[np.ndarray] | None = None  # each learner's rows of the global state after the step (learners that
    # want it only: None when none does)
    team: list[TeamStep] | None = None  # each learner's rows of the team's step (None when no learner is centralised)


class Rollouts:
    """The training games of one run, stepped in this process (``--executor local``), and what its learners take
    from them. :class:`~selfplay_cli.train.ray_rollouts.RayRollouts` steps them on Ray actors instead, behind the
    same calls."""

    def __init__(self, games: SelfPlayGames | None, learners: list[Any], curriculum: Curriculum,
                 teacher: Policy | None, teacher_schedule: Schedule | None) -> None:
        self.games, self.learners, self.curriculum = games, learners, curriculum
        self.teacher, self.teacher_schedule = teacher, teacher_schedule
        self.lesson: dict[str, float] = {}  # the curriculum's values the training games play under now
        self.wants_state = [bool(getattr(learner, "wants_state", False)) for learner in learners]
        self._state: list[np.ndarray] | None = None  # the state the games stand in, while it is known
        self.centralised = [bool(getattr(learner, "centralised", False)) for learner in learners]
        self._team_view: TeamView | None = None  # the team's view of the games as they stand, while it is known
        if any(self.centralised):
            if games is None:
                raise MarlError("a learner with a critic of the whole team trains with --executor local only")
            games.team = TeamViews(games)
        if any(self.wants_state):
            if games is None:
                raise MarlError("a learner that reads the game's global state trains with --executor local only")
            if games.spec.state_space(games.spec.config(**games.options)) is None:
                raise MarlError(f"a learner that reads the game's global state cannot train on {games.spec.name}: "
                                "the game gives none (its env has no state_space)")

    # -- what the run reads of its games (its snapshot moments save the seeds' base, a resume restarts them) ----
    @property
    def next_seed(self) -> int:
        assert self.games is not None
        return self.games.next_seed

    @next_seed.setter
    def next_seed(self, value: int) -> None:
        assert self.games is not None
        self.games.next_seed = value

    def restart_all(self) -> None:
        assert self.games is not None
        self.games.restart_all()
        self._state = None
        self._team_view = None

    def game_steps(self) -> np.ndarray:
        """Steps played so far in each game in progress."""
        assert self.games is not None
        return np.asarray(self.games.core.steps)

    def observe(self) -> list[np.ndarray] | None:
        """Each learner's observations of the games as they stand (None where they are stepped elsewhere)."""
        assert self.games is not None
        return self.games.observe()

    def close(self) -> None:
        """Let go of what stepping the games holds (nothing, in this process)."""

    # -- a step ---------------------------------------------------------------------------------------------
    def step(self, team: LearnerTeam, obs: list[np.ndarray], progress: float) -> Step:
        """Play one step of every game at ``progress`` (0 to 1 of the budget) from observations ``obs``."""
        if self.curriculum:
            self._follow_curriculum(progress)
        games = self.games
        assert games is not None
        acting = games.acting() if games.sequential or games.comes_and_goes else None
        masks = games.masks() if games.masked else None
        if self.teacher is not None:
            self._teach(obs, masks, acting, progress)
        if any(self.wants_state):
            self._hand_state(self._state if self._state is not None else games.state())
        before = None
        if games.team is not None:
            before = self._team_view if self._team_view is not None else games.team.view()
        rewards, dones, finished = games.step(team.act(obs, masks))
        self._state = games.state() if any(self.wants_state) else None
        team_steps = None
        if before is not None:
            self._team_view = games.team.view()
            team_steps = games.team.steps(before, self._team_view)
        return Step(games.observe(), rewards, dones, finished, acting, games.truncated, games.final_obs,
                    games.final_masks, self._state, team_steps)

    def learn(self, team: LearnerTeam, step: Step, progress: float) -> list[dict[str, float]] | None:
        """The learners record ``step``; those whose rollout is due update. Their figures from the update, None
        when none was due."""
        if step.team is not None:
            for learner, centralised, rows in zip(self.learners, self.centralised, step.team, strict=True):
                if centralised:
                    learner.see_team(rows)
        if not team.record(step.rewards, step.dones, step.truncated, step.acting, step.final_obs, step.final_masks):
            return None
        if step.state is not None:
            self._hand_state(step.state)
        return team.update(step.obs, progress)

    def _hand_state(self, state: list[np.ndarray]) -> None:
        """Each learner that wants it its rows of the global state (see the module docstring)."""
        for learner, wants, rows in zip(self.learners, self.wants_state, state, strict=True):
            if wants:
                learner.see_state(rows)

    def _follow_curriculum(self, progress: float) -> None:
        """The training games' live options as the curriculum has them at this progress (changed only when they
        change: a ramp moves them a little each step, lessons at their thresholds)."""
        values = self.curriculum.values(progress)
        if values != self.lesson:
            assert self.games is not None
            self.games.core.set_options(**values)
            self.lesson = values

    def _teach(self, obs: list[np.ndarray], masks: list[np.ndarray | None] | None,
               acting: list[np.ndarray | None] | None, progress: float) -> None:
        """The teacher's actions for every learner's observations of this step (in turn-based games, the slots
        that act), while the teacher's weight is above 0; each learner's weight for its next update."""
        assert self.teacher is not None and self.teacher_schedule is not None
        weight = self.teacher_schedule.value(progress)
        if weight > 0:
            masks = masks if masks is not None else [None] * len(self.learners)
            for i, learner in enumerate(self.learners):
                o, m = obs[i], masks[i]
                rows = acting[i] if acting is not None else None
                if rows is not None:
                    o, m = o[rows], None if m is None else m[rows]
                if len(o):
                    learner.teach(o, self.teacher.act(o) if m is None else self.teacher.act(o, m), m)
        for learner in self.learners:
            learner.teacher_weight = weight
