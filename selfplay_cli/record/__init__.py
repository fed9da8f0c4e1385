"""Recording: turning a game into frames (the game's picture and the caption band under it) and frames into mp4 or
gif (imports envs and arena only)."""

from .overlay import CaptionBand
from .recorder import Recording, VideoSettings, record_game, record_replay, renderer_of, stop_rule
from .video import FORMATS, GIF_FPS, GIF_MAX_WIDTH, VideoWriter, check_writable, gif_frames, parse_size

__all__ = ["FORMATS", "GIF_FPS", "GIF_MAX_WIDTH", "CaptionBand", "Recording", "VideoSettings", "VideoWriter",
           "check_writable", "gif_frames", "parse_size", "record_game", "record_replay", "renderer_of", "stop_rule"]
