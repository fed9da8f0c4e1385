"""Games: the game contract, the built-in games, and what makes a user's game one.

- :mod:`.contract`: the game contract (:class:`EnvSpec`: seats, spaces, turns, kind, options; the
  :class:`BatchedCore` protocol every game is stepped through; the errors a game gives).
- :mod:`.seat_spaces`: what a seat is to a policy (:class:`SeatSpace`) and which spaces `marl` plays;
  :mod:`.bots`: scripted players (:class:`BotSpec`) and the random player any game can have.
- :mod:`.loading`: the registry (``register``) and finding a game by name (``get_env``): the registered games,
  games of installed packages (entry-point group ``selfplay_cli.envs``), a user's PettingZoo game named
  ``module:factory`` or ``module``, which is imported only once the user of this machine names it (``admit``,
  ``MARL_GAMES``), never because a league row or a file names it.
- :mod:`.options`: a game's options as a user sets them (``--env-option``), read from its declaration.
- The built-in games, one package each, registered when this package is imported: :mod:`.pong`, :mod:`.lander`,
  :mod:`.tennis`. Each holds its declaration (the ``EnvSpec``) in its ``__init__`` and modules by concern: ``config``
  (constants, options, spaces), ``core`` (the batched core), ``view`` (its PettingZoo view), ``render`` (the
  offscreen renderer), ``bots`` (the scripted players' rules), and what else the game needs.
- :mod:`.view`: the one-game PettingZoo view the built-in games share; :mod:`.rng`: their counter-based randomness;
  :mod:`.canvas`: the offscreen surface their renderers draw on.
- :mod:`.adapters`: users' games as `marl` games (:mod:`.adapters.pettingzoo`).
- :mod:`.pong_v0`, :mod:`.lander_v0`, :mod:`.tennis_v0`: the built-in games offered the way PettingZoo offers its
  own (``parallel_env``, ``env``, ``raw_env``, ``metadata``; :mod:`.zoo`), for other libraries' learners.

marl's game loops (``selfplay_cli.play``) step every game, built in or adapted, through its batched core.
"""

from __future__ import annotations

from .bots import BotSpec, random_bot, random_rule
from .contract import KINDS, TURNS, BatchedCore, EnvError, EnvSpec, IllegalActionError, UnknownEnvError, check_spaces
from .lander import LANDER
from .loading import GameNotAdmittedError, admit, env_names, get_env, known_env, register
from .options import GameOption, GameOptions, game_options
from .pong import PONG
from .seat_spaces import SeatSpace, describe_space
from .tennis import TENNIS

register(PONG)
register(LANDER)
register(TENNIS)

__all__ = ["KINDS", "TURNS", "BatchedCore", "BotSpec", "EnvError", "EnvSpec", "GameNotAdmittedError", "GameOption",
           "GameOptions", "IllegalActionError", "SeatSpace", "UnknownEnvError", "admit", "check_spaces",
           "describe_space", "env_names", "game_options", "get_env", "known_env", "random_bot", "random_rule",
           "register"]
