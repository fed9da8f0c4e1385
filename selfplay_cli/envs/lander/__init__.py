"""Multi-agent Lunar Lander, registered as ``lander``: gymnasium's LunarLander rules for 1 to 8 landers; its
declaration (:data:`LANDER`) and its modules.

``config`` gymnasium's constants, the options (:class:`~.config.LanderConfig`), the seats and their spaces; ``core``
the batched core (one Box2D world per game, N games stepped at once); ``scalar`` one game of the core in Python
floats (the views' game); ``view`` the PettingZoo views (parallel and AEC); ``render`` the offscreen renderer;
``bots`` the scripted player's rules.

Rules, per game:

* One Box2D world: gymnasium's moon (11 chunks of random height, a flat helipad in the middle between the flags),
  gravity ``gravity``, and ``landers`` landers spread evenly across the top (lander ``i`` of ``N`` starts at
  ``x = (i + 1) / (N + 1)`` of the width; one lander starts where gymnasium's does), each pushed by its own random
  initial force. Each lander is gymnasium's: a body and two spring-loaded legs.
* Collisions: a lander collides with the moon and with the other landers (gymnasium's lone lander collides with the
  moon only). Anything touching a lander's BODY (the moon, another lander's body or legs) crashes it; legs touching
  legs do not. A leg's ground contact (observation and reward) is a contact with the moon only, and lasts while
  the leg touches any part of it. gymnasium keeps a flag that any contact's end clears, so a leg standing across
  two terrain edges reads "off the ground" when it leaves one of them (measured: 14 of 30 heuristic landings meet
  it); ``gym_leg_contact=True`` keeps gymnasium's flag, for exact comparisons.
* Actions per lander: ``Discrete(4)`` (0 no-op, 1 left engine, 2 main engine, 3 right engine), or with
  ``continuous=True`` a ``Box(-1, 1, (2,))``: main throttle (off at <= 0, else 50% to 100% power) and lateral
  (-1..-0.5 left engine, 0.5..1 right, off between), as gymnasium.
* Observation per lander, gymnasium's 8 values: x and y relative to the helipad, x and y velocity, angle, angular
  velocity, leg 0 and leg 1 contact (clipped to the declared bounds, which a lander meets only far outside play).
* Reward per lander, gymnasium's: the change of the shaping ``-100 |position| - 100 |velocity| - 100 |angle| + 10
  per leg on the ground``, minus 0.3 per frame of main engine and 0.03 per frame of side engine (scaled by the
  throttle); a crash or leaving the screen sideways (``|x| >= 1``) makes the step's reward -100, coming to rest
  (the body asleep) +100.
* Each lander ends on its own (crash, out of bounds, at rest) and from then on does not act and earns nothing; a
  crashed lander is a wreck that stays where it crashed and touches no lander again, a lost one leaves the world, a
  landed one stays on the ground for the others to avoid. The game ends when every lander has ended (terminated)
  or after ``max_steps`` steps (truncated). All seats are one team: the team's return is the sum of the landers'
  returns.
* Wind and turbulence (``enable_wind``): gymnasium's, ``tanh(sin(2 k t) + sin(pi k t))`` times ``wind_power``
  (force) and ``turbulence_power`` (torque), on each lander whose legs do not touch the ground.
* ``engine_scale`` multiplies each engine's impulse and its fuel cost (1: gymnasium's); the AEC view, where a
  lander acts once every N physics steps, sets it to N so that the landers can still fly (without it the AEC game
  cannot be solved from 3 landers on).

With ``landers=1`` the game is gymnasium's ``LunarLander-v3``: the same random draws in the same order from a
generator seeded alike, the same impulses, observations and rewards; with ``gym_leg_contact=True`` too, step for
step and bit for bit (tests/test_lander.py compares them).
"""

from __future__ import annotations

from ..bots import BotSpec
from ..contract import EnvSpec
from .bots import heuristic_continuous_rule, heuristic_rule
from .config import AGENTS, FPS, action_space, agents, make_config, observation_space
from .core import LanderCore
from .render import LanderRenderer
from .view import LanderParallelEnv

LANDER = EnvSpec(
    name="lander",
    description="Multi-agent Lunar Lander (seed 001): gymnasium's lander for 1-8 landers in one Box2D world, one team",
    agents=AGENTS,
    make_config=make_config,
    make_core=LanderCore,
    make_parallel=LanderParallelEnv,
    observation_space=observation_space,
    action_space=action_space,
    make_renderer=LanderRenderer,
    bots={
        "heuristic": BotSpec("heuristic", "gymnasium's heuristic lander controller, each lander on its own "
                             "observation (its continuous form with continuous=true)", heuristic_rule,
                             make_rule=lambda cfg: heuristic_continuous_rule if cfg.continuous else heuristic_rule),
    },  # random: marl's own, uniform over the config's action space (discrete or continuous)
    turns="simultaneous",
    kind="cooperative",
    render_fps=FPS,
    make_agents=lambda cfg: agents(cfg.landers),  # landers=M: M seats (a team trained with N flies M)
    size_option="landers",
    anchor="heuristic",  # the ratings' zero point: gymnasium's heuristic
    # No neutral options: each changes the flight, the score (the summed rewards) or how the heuristic flies.
    # PPO's settings for the lander (benchmarks/lander_modes.py; docs/history/games.md has the runs that chose them):
    # rewards of +-100 scaled to order 1 (unscaled, the value loss swamps the policy's gradient in the shared trunk),
    # 10 epochs of 8 minibatches, the long horizon gymnasium's lander wants (gamma 0.999), 64 games, and a step of
    # 1e-3 annealed to 0 over the run: at a constant 5e-4 the final snapshot fell where the last update left it
    # (FuPS: 142.7 a lander, its best 224.5); annealed, the last updates are small and the final is the best's.
    train_defaults={"games": 64, "ppo": {"lr": 1e-3, "anneal_lr": True, "gamma": 0.999, "rollout_steps": 256,
                                         "update_epochs": 10, "minibatches": 8, "reward_scale": 0.01}},
)
"""The lander game's declaration (registered as ``lander``)."""
