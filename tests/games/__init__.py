"""Games written for the test suite, each a small PettingZoo env that marl plays through its adapter.

- ``tests.games.tictactoe:env``: turn-based (AEC), 2 seats, two sides, Discrete(9) with action masks.
- ``tests.games.rendezvous:parallel_env``: simultaneous (parallel), 3 seats, cooperative, Box(-1, 1, (2,)) actions.
- ``tests.games.tug:parallel_env``: simultaneous, 2 seats, two sides, Discrete(3); its observations or rewards turn
  NaN after a while (a user's buggy game).
- ``tests.games.duet:parallel_env``: simultaneous, 2 seats (``agents``), cooperative, Discrete(3); reward only when
  every agent names its own target, plus luck each agent alone sees: a team critic's game (MAPPO, MA-POCA).
- ``tests.games.relay:parallel_env``: simultaneous, 2 seats, cooperative, Discrete(2); the scout answers and leaves,
  the runner is paid for its answer later: credit after leaving (MA-POCA).
- ``tests.games.slow:parallel_env``: simultaneous, 2 seats, cooperative, Discrete(2); every step moves the test's
  clock (``tests.games.slow.CLOCK``) on, so a trainer on that clock meets a slow game without waiting for one.
"""
