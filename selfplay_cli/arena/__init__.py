"""The batched game runner shared by matches, training evaluation and recording."""

from ..results import GameResult
from .runner import Game, play

__all__ = ["Game", "GameResult", "play"]
