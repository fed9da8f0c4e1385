"""Players: the one ``Policy`` interface, scripted bots as policies, network policies and snapshot files."""

from .base import Policy
from .bots import ScriptedPolicy, bot_names

__all__ = ["Policy", "ScriptedPolicy", "bot_names"]
