"""Which seats a league player may take, and who can meet whom, in a game whose seats hold different roles.

A snapshot belongs to the role it learned (:func:`~selfplay_cli.policies.snapshot_format.snapshot_roles`): in
``mpe2.simple_push_v3`` an ``adversary`` snapshot reads 8 values and plays only the adversary's seat, an ``agent``
snapshot reads 19 and plays only the agent's. Scripted players play any seat. Every rated game is seated by these
roles (:mod:`selfplay_cli.play.schedule`), and two players that no seating fits (two adversaries, in a game of one
adversary against one agent) cannot meet: a match between them is refused, a gauntlet or a tournament does not pair
them.

A player's roles come from its league row (training records the role of each per-role learner's snapshot there),
else from its file's metadata (header only: older snapshots, imported ones), and are kept per row for the life of
one :class:`RoleBook`.
"""

from __future__ import annotations

from collections.abc import Collection

from ..envs import get_env
from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..play.schedule import can_meet
from ..policies import Policy
from ..results import Rules

__all__ = ["RoleBook", "cannot_meet_message", "policy_roles", "roles_text"]


def policy_roles(policy: Policy, spec: object) -> frozenset[str] | None:
    """The roles a loaded policy may play (None: any seat): a snapshot's, from its metadata; a scripted player's
    or any other policy's: every seat."""
    from ..policies.snapshot_format import snapshot_roles

    meta = getattr(policy, "meta", None)
    if meta is None or getattr(policy, "kind", "") == "bot":
        return None
    return snapshot_roles(meta, spec)


def roles_text(roles: Collection[str] | None) -> str:
    """``adversary``, ``adversary or agent``, ``any``."""
    return "any" if roles is None else " or ".join(sorted(roles))


class RoleBook:
    """The roles of a game's league players, read once each (see the module docstring)."""

    def __init__(self, league: League, env: str) -> None:
        self.league = league
        self.spec = get_env(env)
        self.rules = Rules.of(self.spec)
        self._roles: dict[int, frozenset[str] | None] = {}

    @property
    def differ(self) -> bool:
        """Whether the game's seats hold more than one role (else anyone meets anyone)."""
        return self.rules.roles is not None

    def roles(self, row: PlayerRow) -> frozenset[str] | None:
        """The roles ``row`` may play (None: any seat)."""
        if not self.differ or row.is_bot:
            return None
        if row.id not in self._roles:
            self._roles[row.id] = self._read(row)
        return self._roles[row.id]

    def _read(self, row: PlayerRow) -> frozenset[str] | None:
        role = row.meta.get("role")
        if isinstance(role, str) and role in self.rules.roles:  # type: ignore[operator]
            return frozenset((role,))
        from ..players.files import snapshot_path
        from ..policies.snapshot_format import snapshot_roles
        from ..policies.snapshot_reader import read_meta

        try:
            meta = read_meta(snapshot_path(self.league, row))
        except (MarlError, OSError):  # a file that is gone or bad is refused when it is loaded to play
            return None
        return snapshot_roles(meta, self.spec)

    def meets(self, a: PlayerRow, b: PlayerRow) -> bool:
        """Whether ``a`` and ``b`` can play each other (some seating gives each only seats of its roles)."""
        return not self.differ or can_meet(self.rules, self.roles(a), self.roles(b))


def cannot_meet_message(game: str, rules: Rules, a: str, a_roles: Collection[str] | None, b: str,
                        b_roles: Collection[str] | None) -> str:
    """The one line that refuses a match two players cannot play: what each plays, and who could play them."""
    sides = ""
    if rules.sides is not None:
        sides = " (" + "; ".join(f"side {i + 1}: {name}" for i, name in enumerate(rules.side_roles())) + ")"
    return (f"{a} ({roles_text(a_roles)}) and {b} ({roles_text(b_roles)}) cannot meet in {game}: a snapshot plays "
            f"only seats of the role it learned, and no seating of the game{sides} gives each its own; match each "
            "against a player of another role, or a scripted player (random plays any seat)")
