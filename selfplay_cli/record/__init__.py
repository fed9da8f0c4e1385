"""Recording: turning a game into frames and frames into mp4 or gif (imports envs and arena only)."""

from .recorder import Recording, VideoSettings, record_game, record_replay, renderer_of, stop_rule
from .video import FORMATS, VideoWriter, check_writable, parse_size

__all__ = ["FORMATS", "Recording", "VideoSettings", "VideoWriter", "check_writable", "parse_size", "record_game",
           "record_replay", "renderer_of", "stop_rule"]
