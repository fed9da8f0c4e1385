"""Multi-run studies: :mod:`.team_size` (seed 001's method: train teams of several sizes, fly each at others, adapt
each to another size from its snapshot against training afresh), its runs measured in their own processes
(:mod:`.measure`), its evaluations (:mod:`.evaluate`) and PNGs (:mod:`.plots`)."""

from .team_size import Study, TeamSizePlan, parse_sizes, run_study

__all__ = ["Study", "TeamSizePlan", "parse_sizes", "run_study"]
