"""What a run's settings must keep within beyond their types, checked before anything is built
(:class:`~.config.TrainConfig` calls these as it is made): where its number settings may lie (:data:`RANGES`,
:func:`check_ranges`), and what this machine's memory holds (games at once: :func:`check_games`; the learners' buffers
of observations and the teacher's labelled states: :func:`check_memory`). The networks a snapshot can hold are checked
beside the learners' set-up, in :mod:`.config`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

from ..errors import MarlError

ON_POLICY = ("ppo", "mappo", "poca")  # PPO and the learners built on it: one rollout an update, PPO's settings


@dataclass(frozen=True)
class Range:
    """Where a number setting must lie: from ``low`` (excluded when ``open_low``) to ``high``."""

    low: float
    high: float
    open_low: bool = False

    def holds(self, value: float) -> bool:
        return (value > self.low if self.open_low else value >= self.low) and value <= self.high

    def describe(self) -> str:
        low = f"more than {self.low:g}" if self.open_low else f"at least {self.low:g}"
        return f"{low} and at most {self.high:g}"


RANGES: dict[str, Range] = {
    "minutes": Range(1e-3, 1e6),  # 0.06 s to ~2 years: 1e-300 minutes is no budget at all
    **{f"{algo}.lr": Range(0.0, 1.0, open_low=True) for algo in ("ppo", "dqn", "sac", "mappo", "poca")},
    **{f"{algo}.clip_coef": Range(0.0, 1.0, open_low=True) for algo in ON_POLICY},  # a ratio clipped to [1-c, 1+c]
    **{f"{algo}.ent_coef": Range(0.0, 1e3) for algo in ON_POLICY},
    **{f"{algo}.vf_coef": Range(0.0, 1e3) for algo in ON_POLICY},
    **{f"{algo}.max_grad_norm": Range(0.0, 1e6, open_low=True) for algo in ON_POLICY},
    "dqn.max_grad_norm": Range(0.0, 1e6),  # 0: no clipping
    **{f"{algo}.reward_scale": Range(0.0, 1e6, open_low=True) for algo in ON_POLICY},
    **{f"{algo}.replay_ratio": Range(0.0, 64.0, open_low=True) for algo in ("dqn", "sac")},  # updates a transition
    **{f"{algo}.n_step": Range(1, 1_000) for algo in ("dqn", "sac")},
    "sac.alpha": Range(0.0, 1e3, open_low=True),
    "sac.target_entropy": Range(-1e6, 1e6),
}
"""The ranges of the number settings that their types and the learners' own checks leave open (a learning rate of
1e300 overflows float32 at the first update; 1e-300 minutes divides by zero; a replay ratio of 1e300 never ends an
update), checked in one pass by :func:`check_ranges` before anything is built. Past these bounds nothing is meant."""


def check_ranges(cfg: Any) -> None:
    """Refuse the first setting of :data:`RANGES` that lies outside its range (None: not set, nothing to check),
    and a replay batch larger than its buffer (a 1e12 batch is drawn as 1e12 indices)."""
    for path, bound in RANGES.items():
        value: Any = cfg
        for part in path.split("."):
            value = getattr(value, part)
        if value is not None and not bound.holds(value):
            section, _, key = path.rpartition(".")
            name = f"[{section}] {key}" if section else f"--{key.replace('_', '-')}"
            raise MarlError(f"{name} must be {bound.describe()}, not {value:g}")
    for algo in ("dqn", "sac"):
        section = getattr(cfg, algo)
        if section.batch_size > section.buffer_size:
            raise MarlError(f"[{algo}] batch_size must be at most buffer_size ({section.buffer_size:,}), not "
                            f"{section.batch_size:,}")


def _machine_memory() -> int | None:
    """Bytes of physical memory, or None where the system does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def check_games(cfg: Any, seat_spaces: Any) -> None:
    """Refuse, before the seats are laid out, more games at once than this machine holds (``games = 1e9`` in a
    config file): each step every seat's observation of every game is read, gathered, stored and kept as the final
    one (~4 float32 copies), beside the game's own state."""
    need = cfg.games * sum(16 * math.prod(s.observation.shape) + 64 for s in seat_spaces)
    have = _machine_memory()
    if have is not None and need > 0.8 * have:
        raise MarlError(f"{cfg.games:,} games at once would take {need / 2**30:,.1f} GB of observations alone; this "
                        f"machine has {have / 2**30:,.1f} GB: use fewer --games")


def check_memory(cfg: Any, obs_shape: tuple[int, ...], slots: list[int], itemsize: int = 4) -> None:
    """Refuse, before anything is built, a run whose learners' buffers of observations would not fit in this
    machine's memory (e.g. pong's 400x800 RGB frames in 256 games: ~125 GB of PPO rollout), the teacher's labelled
    states included. ``itemsize``: the bytes of one number of an observation as the learners keep it (float32's 4,
    an image's 1)."""
    per_obs = itemsize * math.prod(obs_shape)
    if cfg.algo in ON_POLICY:
        steps = getattr(cfg, cfg.algo).rollout_steps
        need = sum(per_obs * steps * n for n in slots)
        what = f"{cfg.algo.upper()}'s rollouts ({steps} steps of {sum(slots):,} seats)"
    else:
        buffer = cfg.dqn.buffer_size if cfg.algo == "dqn" else cfg.sac.buffer_size
        need = len(slots) * 2 * per_obs * buffer
        what = f"{cfg.algo.upper()}'s replay buffers ({buffer:,} transitions each)"
    if cfg.teacher.player:  # each learner keeps its teacher's labelled states (observation and action: ~2 of them)
        need += len(slots) * 2 * per_obs * cfg.teacher.states
        what += f" and the teacher's labelled states ({cfg.teacher.states:,} each)"
    have = _machine_memory()
    if have is not None and need > 0.8 * have:
        raise MarlError(f"{what} of {'x'.join(map(str, obs_shape))} observations would take {need / 2**30:,.1f} GB; "
                        f"this machine has {have / 2**30:,.1f} GB: use fewer --games, a shorter rollout or buffer, or "
                        "smaller observations")
