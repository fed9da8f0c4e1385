"""Tic-tac-toe as a PettingZoo AEC game: two seats (``x`` moves first, then ``o``), turn by turn.

Observation (per agent, egocentric): a Dict of ``observation`` (27 floats: the agent's own marks, the opponent's
marks and the empty cells, 9 each, row by row) and ``action_mask`` (9 int8: 1 where the cell is empty). Action:
Discrete(9), the cell to mark. A move on a taken cell is illegal and raises ValueError (the mask never allows it).
Rewards: +1 to the winner and -1 to the loser on the winning move; 0 for a draw. A game lasts at most 9 moves.
``render_mode="rgb_array"`` draws the board (96 x 96).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv

LINES = ((0, 1, 2), (3, 4, 5), (6, 7, 8), (0, 3, 6), (1, 4, 7), (2, 5, 8), (0, 4, 8), (2, 4, 6))
CELL = 32


class TicTacToe(AECEnv):
    metadata = {"name": "tictactoe_marl_v0", "render_modes": ["rgb_array"], "render_fps": 2,
                "is_parallelizable": False, "marl_kind": "two-sides", "marl_max_steps": 9,
                "marl_description": "tic-tac-toe, turn by turn, with action masks (tests/games)"}

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"tictactoe renders only 'rgb_array', not {render_mode!r}")
        self.render_mode = render_mode
        self.possible_agents = ["x", "o"]
        self._obs_space = spaces.Dict({
            "observation": spaces.Box(0.0, 1.0, (27,), dtype=np.float32),
            "action_mask": spaces.Box(0, 1, (9,), dtype=np.int8),
        })
        self._act_space = spaces.Discrete(9)
        self.board = np.zeros(9, dtype=np.int8)  # 0 empty, 1 x, 2 o

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        self.board = np.zeros(9, dtype=np.int8)
        self.agents = self.possible_agents[:]
        self.rewards = dict.fromkeys(self.agents, 0.0)
        self._cumulative_rewards = dict.fromkeys(self.agents, 0.0)
        self.terminations = dict.fromkeys(self.agents, False)
        self.truncations = dict.fromkeys(self.agents, False)
        self.infos = {a: {} for a in self.agents}
        self.agent_selection = "x"

    def observe(self, agent: str) -> dict[str, np.ndarray]:
        me = 1 if agent == "x" else 2
        b = self.board
        obs = np.concatenate([b == me, b == 3 - me, b == 0]).astype(np.float32)
        return {"observation": obs, "action_mask": (b == 0).astype(np.int8)}

    def _winner(self) -> int:
        b = self.board
        for i, j, k in LINES:
            if b[i] and b[i] == b[j] == b[k]:
                return int(b[i])
        return 0

    def step(self, action) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        cell = int(action)
        if not 0 <= cell < 9 or self.board[cell]:
            raise ValueError(f"illegal move {action!r} by {agent}: cell taken or off the board")
        other = "o" if agent == "x" else "x"
        self._cumulative_rewards[agent] = 0.0
        self._clear_rewards()
        self.board[cell] = 1 if agent == "x" else 2
        if self._winner():
            self.rewards[agent], self.rewards[other] = 1.0, -1.0
            self.terminations = dict.fromkeys(self.agents, True)
        elif not (self.board == 0).any():
            self.terminations = dict.fromkeys(self.agents, True)
        self.agent_selection = other
        self._accumulate_rewards()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        img = np.full((3 * CELL, 3 * CELL, 3), 255, dtype=np.uint8)
        img[CELL - 1 : CELL + 1] = img[2 * CELL - 1 : 2 * CELL + 1] = 0
        img[:, CELL - 1 : CELL + 1] = img[:, 2 * CELL - 1 : 2 * CELL + 1] = 0
        yy, xx = np.mgrid[0:CELL, 0:CELL] - (CELL - 1) / 2
        cross = (np.abs(np.abs(yy) - np.abs(xx)) < 2) & (np.abs(yy) < CELL / 3)
        ring = np.abs(np.hypot(yy, xx) - CELL / 3) < 2
        for cell, mark in enumerate(self.board.tolist()):
            if mark:
                r, c = divmod(cell, 3)
                view = img[r * CELL : (r + 1) * CELL, c * CELL : (c + 1) * CELL]
                view[cross if mark == 1 else ring] = (200, 30, 30) if mark == 1 else (30, 30, 200)
        return img

    def close(self) -> None:
        """Nothing to release: the game holds no window, file or process."""


def env(**options) -> TicTacToe:
    """A new game (``render_mode`` is its only option)."""
    return TicTacToe(**options)
