"""Where games are stepped, in batches, by two game loops honestly apart:

* :func:`~.matches.play` plays whole games to results: rated matches, gauntlets, tournaments, the gate and
  recordings. It takes a schedule (:mod:`.schedule`: who sits where on which seed, seats swapped between games),
  plays every game of it to its end, and returns one result per game, with its actions for a replay
  (:mod:`.replay`) and every state to a recording's hook on request.
* :class:`~.training_games.SelfPlayGames` steps training's games, which never stop: learners hold fixed slots, a
  game that ends restarts at once, and each step hands every learner the transitions of its slots; which learner
  holds which slot is :mod:`.seat_plan`'s.

Both end a game at its declared length and refuse a number that is not finite (:mod:`.limits`), and make results by
one function (:func:`~selfplay_cli.results.game_results`)."""

from ..results import GameResult
from .matches import Game, play

__all__ = ["Game", "GameResult", "play"]
