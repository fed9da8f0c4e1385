"""SA: any registered learner as one agent for a whole cooperative team (``--sharing sa``).

The trainer hands a learner its slots seat by seat: ``(N * G, obs)`` for N seats of G games. :class:`JointLearner`
regroups them into one row per game (every seat's observation side by side), lets the inner learner (PPO or DQN,
built on the joint spaces of :func:`selfplay_cli.policies.joint.joint_spaces`) choose one joint action per game, and
decodes it into each seat's action. The team's reward is the sum over its seats; a game is
over for the agent when it is over (in a game whose agents come and go, a seat that leaves does not end it: the game
ends when every seat that was in it is done); a truncated game bootstraps from the joint final observation.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..envs import SeatSpace
from ..errors import MarlError
from ..policies.joint import JointPolicy, decode, joint_spaces, regroup


class JointLearner:
    """``inner_cls`` over the joint spaces of ``n_seats`` seats like ``seat``, for ``n_games`` games."""

    def __init__(self, inner_cls: type, seat: SeatSpace, n_seats: int, n_games: int, config: Any, *, seed: int = 0,
                 device: Any = "cpu") -> None:
        if seat.mask:
            raise MarlError("--sharing sa plays games without action masks")
        obs, act = joint_spaces(seat.observation, seat.action, n_seats)
        self.seat_space, self.n, self.games = seat, int(n_seats), int(n_games)
        self.base = int(seat.action.n)
        self.inner = inner_cls(SeatSpace(obs, act, False), self.games, config, seed=seed, device=device)
        self.net = self.inner.net
        self.n_slots = self.n * self.games
        self.name = getattr(inner_cls, "name", "")

    @property
    def joint_seat(self) -> SeatSpace:
        return self.inner.seat

    def _games(self, per_seat: np.ndarray) -> np.ndarray:
        """A per-slot (seat by seat) flag or value -> per game ``(N, G)``."""
        return np.asarray(per_seat).reshape(self.n, self.games)

    @property
    def device(self) -> Any:
        return getattr(self.inner, "device", "cpu")

    @property
    def synchronous(self) -> bool:
        return bool(getattr(self.inner, "synchronous", False))

    @property
    def share(self) -> Any:
        return self.inner.share

    @share.setter
    def share(self, share: Any) -> None:
        """A rollout actor's rows of the per-seat slots (seat by seat, ``seat * games + game``) as the inner learner's
        rows, one a game: the first seat's rows are the actor's games."""
        if share is None:
            self.inner.share = None
            return
        rows, total = share
        games = total // self.n
        self.inner.share = (np.asarray(rows)[np.asarray(rows) < games], games)

    def decide(self, obs: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        joint, taken = self.inner.decide(regroup(obs, self.n))
        return decode(joint, self.n, self.base).reshape(-1), taken

    def take(self, obs: np.ndarray, taken: dict[str, Any]) -> None:
        self.inner.take(regroup(obs, self.n), taken)

    def act(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        played, taken = self.decide(obs, mask)
        self.take(obs, taken)
        return played

    def acting_state(self) -> dict[str, Any]:
        return self.inner.acting_state()

    def load_acting_state(self, state: dict[str, Any]) -> None:
        self.inner.load_acting_state(state)

    def record(self, rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray | None = None,
               acting: np.ndarray | None = None, final_obs: np.ndarray | None = None,
               final_mask: np.ndarray | None = None) -> bool:
        team = self._games(rewards).sum(axis=0)  # the team's reward: the sum over its seats
        seat_done = self._games(dones) > 0
        in_game = np.ones_like(seat_done) if acting is None else self._games(acting).astype(bool)
        done = seat_done.any(axis=0) & (seat_done | ~in_game).all(axis=0)  # everyone in the game is done
        extra: dict[str, Any] = {}
        if truncated is not None:
            extra["truncated"] = self._games(truncated).any(axis=0) & done
            if final_obs is not None:
                extra["final_obs"] = regroup(final_obs, self.n)
        return self.inner.record(team, done.astype(np.float32), **extra)

    @property
    def cut(self) -> tuple[int, int] | None:
        """The last update, when a ``--minutes`` budget cut it: (gradient steps done, due)."""
        return self.inner.cut

    def update(self, next_obs: np.ndarray, progress: float = 0.0, final_obs: np.ndarray | None = None) -> dict:
        return self.inner.update(regroup(next_obs, self.n), progress,
                                 final_obs=None if final_obs is None else regroup(final_obs, self.n))

    def policy(self, id: str, env: str, greedy: bool = False) -> JointPolicy:
        return JointPolicy(self.inner.policy(id, env, greedy=greedy), self.n, self.base,
                           self.seat_space.observation, self.seat_space.action)

    def state_dict(self) -> dict[str, Any]:
        return self.inner.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.inner.load_state_dict(state)
