"""Table tennis in the vertical plane along the table, a physics game registered as ``tennis``: its declaration
(:data:`TENNIS`) and its modules.

``config`` the constants, the options (:class:`~.config.TennisConfig`), the seats and their spaces; ``physics`` the
ball's flight and contacts and the scoring rules, shared by the core and the scripted player, who plans with them;
``core`` the batched core (N games in numpy arrays); ``scalar`` one game in Python floats, the core's numbers bit for
bit (the view plays it: numpy's overhead per operation makes a batch of one slow); ``view`` the PettingZoo view;
``render`` the offscreen renderer; ``bots`` the scripted player (on arrays, or a few observations one at a time in
Python floats: the same actions).

The world (SI units; x along the table, y up; seat 0 plays from the -x end, seat 1 from the +x end)
    Table 2.74 m long, surface at y = 0, x from -1.37 to +1.37; net at x = 0, 0.1525 m high; floor at y = -0.76.
    Ball: radius 20 mm, mass 2.7 g, a thin shell (moment of inertia 2/3 m r^2), with a scalar spin ``w`` about the
    axis perpendicular to the plane (counter-clockwise positive: for a ball moving to +x, topspin is w < 0).

Flight (:func:`.physics.accel`, integrated with semi-implicit Euler)
    Gravity 9.81; quadratic air drag ``-k_d |v| v`` (k_d from rho = 1.2 kg/m3, C_d = 0.40 and the ball's cross
    section); Magnus force ``k_m w x v`` (k_m = rho A r C_m / 2m with C_m = 1.0: at 150 rad/s and 10 m/s about 8 m/s2,
    so topspin dips and backspin floats); spin decays slowly in the air (0.2 /s). ``drag`` and ``magnus`` scale the
    two forces (0 switches them off).

Contacts (:func:`.physics.contact`, one model for table and bats)
    An impulse at the contact point: the normal relative velocity is reversed with a restitution (table 0.90, bat
    0.85); friction acts on the contact point's slip ``u = v_t - r w`` (the surface's tangential speed of the ball
    relative to the surface): it takes out the impulse that brings the slip to zero (the ball leaves rolling),
    ``0.4 m |u|`` for a thin shell, unless that exceeds Coulomb's ``mu J_n`` (table 0.40, bat rubber 1.0), when the
    ball keeps sliding. The same impulse changes the speed along the surface and the spin, so topspin (which slips
    less) bounces off the table lower and faster than a ball without spin, and backspin (which slips more) higher
    and slower; a bat's angle and velocity decide the return (the ball's velocity relative to the bat's contact point
    is reflected about the bat's normal, friction on the rubber imparts spin), and a brushing stroke makes spin.
    A ball without spin reaches rolling (grips) at the usual landing angles (steeper than ~28 degrees); the table's
    0.40 is at the grippy end of measured values and is chosen for that.

Substeps and tunnelling
    50 decisions a second; each step is 4 physics substeps of 5 ms. Every substep tests the ball's whole path
    against each bat (a swept test: the ball's signed distance to the bat's line at the start and end of the substep,
    the bat moving and turning with it, and where along the face the crossing happens), against the net (the ball
    crossing the net's plane below its top plus a radius, or touching it) and against the table (crossing the
    surface from above), so a ball at any speed cannot pass through a bat, the net or the table.

Bats
    Each a thin segment 0.15 m long (``bat_scale`` times), with position, velocity, tilt and tilt rate. The tilt
    ``angle`` is egocentric: 0 is the face upright facing the net, positive opens the face (turns it upward),
    limits +-pi/2. Either side of the segment hits. A bat stays in its own reachable box: from 1.5 m behind its end
    of the table up to the net (no part of it may cross the net's plane), 0.4 m below to 1.6 m above the table's
    surface. Bats do not collide with the table, the net or each other.

Actions (per seat)
    ``Box(-1, 1, (3,))``: the bat's velocity toward the net and upward (times 6 m/s each) and its tilt rate (times
    10 rad/s), held for the step, or with ``discrete=true`` ``MultiDiscrete([3, 3, 3])`` (0, 1, 2 meaning -1, 0, +1
    on each axis). A bat pushed against its box stops there, and observes the velocity it really had.

Rules
    * Serve: at the start of a point the ball is tossed straight up (2.6 m/s, from 0.15 m above the table's height,
      0.18 m behind the server's end, +-``toss_jitter`` m along the table at random), in front of the server's bat.
      The server must strike it within ``serve_time`` seconds and before it touches anything else (the floor,
      typically); otherwise the receiver wins the point. By default the struck ball must land on the receiver's half
      first, a simplification of the real serve; with ``serve_bounce=true`` it is table tennis's serve: it bounces
      on the server's own half first (reason ``serve_no_bounce`` if it does not; a second bounce there is
      ``own_half``), then on the receiver's half. No lets.
    * After each legal hit the ball must land on the opponent's half before anything else. The point goes to the
      opponent of the player who hits into the net (any net contact before the landing: no net cords), hits out
      (the ball reaches the floor, leaves the room (4.5 m from the net) or goes below the table's surface without
      landing on the opponent's half), lands it on their own half, hits it twice (a second contact with the same
      bat, after 40 ms: contacts within 40 ms are one stroke) or volleys (hits a ball the opponent sent before it
      bounced on the hitter's half).
    * Once the ball has landed on the opponent's half, the opponent must return it before it bounces again: any
      other event (a second bounce, the floor, the net, the hitter's own half or bat) gives the point to the hitter.
    * Serves alternate every 2 points, every point from 10-10 (``points_to_win - 1`` all); the first server is drawn
      from the game's seed. A game is won at 11 (``points_to_win``) by 2 (terminated); after ``max_steps`` steps it
      is truncated and decided by the points at that moment.
    * The game tracks the last hitter (:attr:`TennisCore.hitter`), the last surface the ball
      touched (:attr:`TennisCore.surface`) and whose turn it is (:attr:`TennisCore.turn`), and why each point
      ended (:attr:`TennisCore.reason`).

Rewards and score
    ``point_reward`` to the winner of a point and its negative to the loser (zero-sum); ``hit_reward`` to a player for
    each legal stroke (a serve of the own toss, or a return of a ball that bounced on the own half), a shaping reward
    for a curriculum to decay while the point reward grows; and ``return_reward`` to a player whose stroke (serve or
    return) lands on the opponent's half: the ball not only across the net but onto the opponent's table. A foul's
    touch earns no hit reward: paid, learners learn to volley the serve. ``score`` is the points each seat won, so
    results and ratings go by points.
    :meth:`TennisCore.set_options` changes ``hit_reward``, ``return_reward``, ``point_reward`` and ``bat_scale``
    of running games between steps (the curricula's hook).

Observation (per seat, egocentric: x points from the seat's own end toward the net and the opponent, spins and
velocities mirrored with it, so one policy plays either end; mirroring the world swaps the two seats' observations
exactly). 25 float32 values, clipped to the declared bounds (which the ball leaves only far from play):

    0-5    own bat: x, y (m), vx, vy (m/s / 10), angle (rad), tilt rate (/ 10 rad/s)
    6-11   the opponent's bat, the same in my frame (its angle is its own tilt)
    12-16  ball: x, y (m), vx, vy (m/s / 10), spin (rad/s / 100; topspin toward the opponent is negative)
    17     the opponent hit last and the ball has not yet bounced on my half (I may not touch it)
    18     the opponent hit last and the ball bounced on my half (my turn: return it before it bounces again)
    19     I hit last and the ball has not yet landed on the opponent's half
    20     I hit last and the ball landed on the opponent's half (their turn)
    21     I am to serve (the toss is in the air)
    22     the opponent is to serve
    23     serve clock: the fraction of ``serve_time`` left while a toss is in the air, else 0
    24     the bats' length (m), which ``bat_scale`` sets

Scripted players: ``serve-bot`` (the ratings' anchor) plans with the game's physics (:mod:`.physics`): it serves
by ``serve_mode`` (``fixed``: one serve; ``velocity``: random speed, arc and placement; ``spin``: random top- or
backspin; ``mixed``, marl's own: a ``velocity`` or a ``spin`` serve, drawn per serve, so one practice run meets both),
solving the contact model backwards for the bat's tilt and velocity, and returns balls to the middle of the
other half (in the randomized modes at the pace they came); it misjudges spin (see
:func:`.bots.serve_bot_rule_for`), so spin beats it. ``random`` is marl's own (uniform actions). Randomness: the
first server and each toss's place come from the game's seed (counter-based).

Not modelled: the third dimension (sidespin, the table's width, the ball going wide), lets (the real serve's first
bounce on the server's half is an option, ``serve_bounce``, off by default), net cords (a net touch ends the point), the
bounce of the ball off the net or the floor, the bat's edge and handle (a bat is a segment with no thickness, struck on
either face, its ends included within half a ball radius), bat inertia (the velocity commanded is the velocity), rubber
types, the ball's deformation (the bat's friction is an impulse limited only by Coulomb friction), and speed-dependent
restitution.
"""

from __future__ import annotations

from ..bots import BotSpec
from ..contract import EnvSpec
from .bots import serve_bot_for, serve_bot_rule
from .config import AGENTS, FPS, LIVE_OPTIONS, action_space, make_config, observation_space
from .core import TennisCore
from .render import TennisRenderer
from .view import TennisParallelEnv

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
    make_renderer=TennisRenderer,
    bots={
        "serve-bot": BotSpec("serve-bot", "seed 002's serve bot: serves by serve_mode (fixed, velocity, spin, mixed), "
                             "returns balls to the middle of the other half", serve_bot_rule, make_rule=serve_bot_for),
    },  # random: marl's own, uniform over the config's action space (continuous or discrete)
    turns="simultaneous",
    kind="two-sides",
    sides=((0,), (1,)),
    render_fps=FPS,
    anchor="serve-bot",  # the ratings' zero point (marl's anchor rating, 1000 by default)
    live_options=LIVE_OPTIONS,  # the rewards and bat_scale: TennisCore.set_options, for the curricula
    neutral_options=("hit_reward", "return_reward", "point_reward"),  # rewards that shape learning: the score is the
    # points won whatever they are, so results under them are one game's (bat_scale changes play: a variant)
    # SAC for tennis (benchmarks/tennis_skill.py; docs/history/games.md has the runs that chose these settings): one
    # network for both ends (the observation is egocentric); half the games learner against learner and half against
    # a matchmaker's opponent (3 in 4 the serve bot's randomized serves, velocity or spin, 1 in 4 the league's
    # snapshots); curricula: a bat 3 times the size shrinking to normal by 80% of the run, a hit reward decaying to 0
    # by 60% while the point reward grows from 0.1 to 1 over 30-90%; the practice reward for a ball landed on the
    # other half; 5-step returns; 1 gradient step per 16 game steps; 256-wide layers. Kickstarted by the serve bot,
    # its weight 2 fading to 0.2 by half the run and then held: without a teacher, or with one faded to 0, learners
    # do not learn to return their own serves.
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
