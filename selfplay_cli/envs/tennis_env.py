"""The tennis game's PettingZoo ``ParallelEnv`` view (one game of :class:`~selfplay_cli.envs.tennis_core.TennisCore`)
and its declaration, :data:`TENNIS` (registered as ``tennis``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .registry import BotSpec, EnvSpec
from .tennis import (
    AGENTS,
    FPS,
    LIVE_OPTIONS,
    REASON_NAMES,
    SURFACE_NAMES,
    TennisConfig,
    action_space,
    make_config,
    observation_space,
    serve_bot_for,
    serve_bot_rule,
)
from .tennis_core import TennisCore


class TennisParallelEnv(ParallelEnv):
    """Two table-tennis players, ``player_0`` (the -x end) and ``player_1``; see :mod:`selfplay_cli.envs.tennis`.

    Both act at every step (50 a second). Rewards are each seat's: the point rewards (zero-sum) and the hit
    shaping. ``reset(seed=s)`` makes the game reproducible (it is the batched core's game with seed ``s``); later
    resets without a seed draw game seeds from a generator seeded by ``s``. Infos carry the score (own first), the
    last point's reason and winner, the last hitter, the last surface, whose turn it is, and the game's seed.
    """

    metadata = {"name": "marl_tennis_v0", "render_modes": ["rgb_array"], "render_fps": FPS, "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"tennis renders only 'rgb_array' (offscreen), not {render_mode!r}")
        self.render_mode = render_mode
        self.config: TennisConfig = make_config(**options)
        self.core = TennisCore(1, self.config)
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self._obs_space = observation_space(self.config)
        self._act_space = action_space(self.config)
        self._seeds = np.random.default_rng()
        self._renderer: Any = None
        self.game_seed: int | None = None

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._seeds = np.random.default_rng(seed)
            self.game_seed = int(seed)
        else:
            self.game_seed = int(self._seeds.integers(2**62))
        self.core.reset([0], [self.game_seed])
        self.agents = self.possible_agents[:]
        obs = self.core.observe()
        return {a: obs[i, 0] for i, a in enumerate(self.agents)}, {a: self._info(i) for i, a in enumerate(self.agents)}

    def _action(self, agent: str, action: Any) -> np.ndarray:
        if self.config.discrete:
            a = np.asarray(action).reshape(-1)
            if a.shape != (3,) or not np.isin(a, (0, 1, 2)).all():
                raise ValueError(f"{agent}: a discrete tennis action is 3 of 0, 1, 2 (-1, 0, +1), not {action!r}")
            return a.astype(np.int64)
        a = np.asarray(action, dtype=np.float32).reshape(-1)
        if a.shape != (3,) or not np.isfinite(a).all():
            raise ValueError(f"{agent}: a tennis action is 3 finite numbers in [-1, 1], not {action!r}")
        return a

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("step() called on a finished game: call reset() first")
        dtype = np.int64 if self.config.discrete else np.float32
        buf = np.zeros((2, 1, 3), dtype=dtype) + (1 if self.config.discrete else 0)  # missing: stand still
        for i, agent in enumerate(self.possible_agents):
            if agent in actions:
                buf[i, 0] = self._action(agent, actions[agent])
        core = self.core
        rewards = core.step(buf)
        obs = core.observe()
        done, cut = bool(core.terminated[0]), bool(core.truncated[0])
        out = ({a: obs[i, 0] for i, a in enumerate(self.agents)},
               {a: float(rewards[i, 0]) for i, a in enumerate(self.agents)},
               dict.fromkeys(self.agents, done), dict.fromkeys(self.agents, cut),
               {a: self._info(i) for i, a in enumerate(self.agents)})
        if done or cut:
            self.agents = []
        return out

    def _info(self, seat: int) -> dict[str, Any]:
        c = self.core
        return {"score": (int(c.score[seat, 0]), int(c.score[1 - seat, 0])),
                "point_reason": REASON_NAMES[int(c.reason[0])], "point_winner": int(c.winner[0]),
                "last_hitter": int(c.hitter[0]), "last_surface": SURFACE_NAMES[int(c.surface[0])],
                "turn": int(c.turn[0]), "seed": self.game_seed}

    def render_frame(self) -> np.ndarray:
        if self._renderer is None:
            from .tennis_render import TennisRenderer

            self._renderer = TennisRenderer()
        return self._renderer.draw(self.core, 0)

    def render(self) -> np.ndarray | None:
        return self.render_frame() if self.render_mode == "rgb_array" else None

    def state(self) -> np.ndarray:
        """The global state: player_0's observation (it sees the whole world)."""
        return self.core.observe()[0, 0]

    def close(self) -> None:
        self._renderer = None


def _renderer():
    from .tennis_render import TennisRenderer

    return TennisRenderer()


TENNIS = EnvSpec(
    name="tennis",
    description="Table tennis in the plane along the table (seed 002): ball with drag, Magnus and spin-dependent "
                "bounces, two bats with continuous control, 11 points by 2",
    agents=AGENTS,
    make_config=make_config,
    make_core=TennisCore,
    make_parallel=TennisParallelEnv,
    observation_space=observation_space,
    action_space=action_space,
    make_renderer=_renderer,
    bots={
        "serve-bot": BotSpec("serve-bot", "seed 002's serve bot: serves by serve_mode (fixed, velocity, spin, mixed), "
                             "returns balls to the middle of the other half", serve_bot_rule, make_rule=serve_bot_for),
    },  # random: marl's own, uniform over the config's action space (continuous or discrete)
    turns="simultaneous",
    kind="two-sides",
    sides=((0,), (1,)),
    render_fps=FPS,
    anchor="serve-bot",  # the ratings' zero point (seed 002 rates from 1200; marl's anchor rating is its own)
    live_options=LIVE_OPTIONS,  # the rewards and bat_scale: TennisCore.set_options, for the curricula
    neutral_options=("hit_reward", "return_reward", "point_reward"),  # rewards that shape learning: the score is the
    # points won whatever they are, so results under them are one game's (bat_scale changes play: a variant)
    # SAC for tennis (benchmarks/tennis_skill.py): one network for both ends (the observation is egocentric), half
    # the games learner against learner and half against a matchmaker's opponent (3 in 4 the serve bot's randomized
    # serves, velocity or spin, 1 in 4 the league's snapshots), seed 002's curricula (a bat 3 times the size
    # shrinking to normal by 80% of the run; a hit reward decaying to 0 by 60% while the point reward grows from 0.1
    # to 1 over 30-90%) and its practice reward for a ball landed on the other half; 5-step returns; 1 gradient step
    # per 16 game steps; seed 002's 256-wide layers. Kickstarted by the serve bot (its weight 2 fading to 0.2 by half
    # the run, then held): without a teacher, runs of these settings returned 0-82% of the bot's randomized serves
    # (bimodal) and rallied ~2 hits a point against themselves, never landing a return of their own serve; with the
    # teacher faded to 0 one returned 77% and again landed none of its own serves (RL found a serve its imitated
    # receiving could not return); held at 0.2, three 30-minute runs returned 89-97% and rallied to the time limit.
    train_defaults={"algo": "sac", "sharing": "fups", "league_games": 0.5, "opponents": {"bots": {"serve-bot": 0.75}},
                    "env_options": {"serve_mode": "mixed", "return_reward": 0.5},
                    "curriculum": {"bat_scale": {"start": 3.0, "end": 1.0, "until": 0.8},
                                   "hit_reward": {"start": 0.3, "end": 0.0, "until": 0.6},
                                   "point_reward": {"start": 0.1, "end": 1.0, "from": 0.3, "until": 0.9}},
                    "teacher": {"player": "serve-bot", "weight": {"start": 2.0, "end": 0.2, "until": 0.5}},
                    "sac": {"replay_ratio": 0.0625, "n_step": 5, "arch": {"hidden": [256, 256]}},
                    "ppo": {"arch": {"hidden": [256, 256]}}},
)
"""The tennis game's declaration (registered as ``tennis``)."""
