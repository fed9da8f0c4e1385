"""The batched game runner shared by matches, training evaluation and recording."""

from .runner import Game, GameResult, paired_schedule, play

__all__ = ["Game", "GameResult", "paired_schedule", "play"]
