"""Reads the team's view of training games for learners with a centralised critic (the types and what they hold:
:mod:`selfplay_cli.envs.team`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..envs.team import TeamStep, TeamView, action_width, encode_actions


class TeamViews:
    """Reads the team's view of training games (a :class:`~selfplay_cli.play.training_games.SelfPlayGames`, which
    calls :meth:`stepped` on each step before its ended games restart) and hands each learner its rows."""

    def __init__(self, games: Any) -> None:
        self.games = games
        spaces_ = games.seat_spaces
        self.obs_width = max(int(np.prod(s.observation.shape)) for s in spaces_)
        self.act_widths = [action_width(s.action) for s in spaces_]
        self.act_width = max(self.act_widths)
        self.has_state = games.spec.state_space(games.spec.config(**games.options)) is not None
        self._stepped: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, TeamView | None] | None = None

    def view(self) -> TeamView:
        """The games as they stand, one row a game."""
        games = self.games
        n = games.n
        obs = np.zeros((n, games.n_seats, self.obs_width), dtype=np.float32)
        for s, o in enumerate(games.seat_observations()):
            flat = np.asarray(o, dtype=np.float32).reshape(n, -1)
            obs[:, s, :flat.shape[1]] = flat
        core = games.core
        present = (np.asarray(core.in_game, dtype=bool).T.copy() if games.comes_and_goes
                   else np.ones((n, games.n_seats), dtype=bool))
        state = np.asarray(core.state(), dtype=np.float32).reshape(n, -1) if self.has_state else None
        return TeamView(obs, present, state)

    def stepped(self, actions: Any, rewards: np.ndarray, done: np.ndarray, cut: np.ndarray, any_cut: bool) -> None:
        """The step just played (every seat's actions, per-seat rewards ``(n_seats, n)``, the games that ended and
        were cut), read before the ended games restart (``any_cut``: a seat was cut short: the view is kept as the
        final one)."""
        games = self.games
        acts = np.zeros((games.n, games.n_seats, self.act_width), dtype=np.float32)
        for s, space in enumerate(games.seat_spaces):
            acts[:, s] = encode_actions(space.action, np.asarray(actions[s]), self.act_width)
        final = self.view() if any_cut else None
        self._stepped = (acts, np.asarray(rewards, dtype=np.float32).sum(axis=0), np.asarray(done, dtype=bool).copy(),
                         np.asarray(cut, dtype=bool).copy(), final)

    def steps(self, before: TeamView, after: TeamView) -> list[TeamStep]:
        """Each learner's rows of the step :meth:`stepped` saw, between the views ``before`` and ``after``."""
        assert self._stepped is not None, "stepped() was not called on this step"
        acts, reward, done, cut, final = self._stepped
        if final is not None and self.games.comes_and_goes:  # a game that is over has nobody in it: those who
            final.present = before.present  # were in it when it was cut are its team
        out = []
        for slots in self.games.slots:
            g = slots % self.games.n
            # an absent seat acted on nothing: its action is no information
            a = acts[g] * before.present[g][:, :, None]
            out.append(TeamStep(before.rows(g), a, reward[g], done[g], cut[g], after.rows(g),
                                None if final is None else final.rows(g)))
        return out
