"""Where games are stepped, in batches: :func:`~.runner.play` plays rated games (matches, gauntlets, tournaments,
the gate) and recordings, N games to their end with per-game results; :class:`~.selfplay.SelfPlayGames` steps
training's games, which never stop, some seats driven by learners. Both end a game at its declared length and
refuse a number that is not finite (:func:`~.runner.first_nonfinite`). :mod:`.schedule` says who sits where on
which seed; :mod:`.replay` encodes a game's actions and replays them."""

from ..results import GameResult
from .runner import Game, play

__all__ = ["Game", "GameResult", "play"]
