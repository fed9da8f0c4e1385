"""Recording: a game played (or replayed from the ledger) through the whole-game loop (:mod:`selfplay_cli.play`)
(:func:`selfplay_cli.play.play`), each state turned into a frame (the game's picture and the caption band under it,
:mod:`.overlay`), and the frames into mp4 or gif (:mod:`.video`). Imports envs, play and results only."""

from .overlay import CaptionBand
from .recorder import Recording, VideoSettings, record_game, record_replay, renderer_of, stop_rule
from .video import FORMATS, GIF_FPS, GIF_MAX_WIDTH, VideoWriter, check_writable, gif_frames, parse_size

__all__ = ["FORMATS", "GIF_FPS", "GIF_MAX_WIDTH", "CaptionBand", "Recording", "VideoSettings", "VideoWriter",
           "check_writable", "gif_frames", "parse_size", "record_game", "record_replay", "renderer_of", "stop_rule"]
