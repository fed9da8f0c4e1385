"""Who plays which seat when a user names one policy (``marl record --ckpt s6M [--vs POLICY]``).

A run that trains one network per seat files its snapshots as ``<name>-<seat>`` (``s6M-left``, ``s6M-right``),
the seat's learner in the snapshot's league metadata. So a name can mean a *team* (see
:mod:`selfplay_cli.ratings.names`, where names are resolved the same way for every command):

* ``s6M`` (or ``run/s6M``), when no single snapshot has that name but ``s6M-<seat>`` exists for every seat in
  one run, is that team, each on its own seat: left s6M against right s6M;
* ``s6M-left`` alone plays its own seat; without ``--vs`` its teammates from the same snapshot take the other
  seats, so naming either half of a team records the same game;
* any other player (a one-network snapshot, a tag, ``latest``, a bot) takes the first seat and, without ``--vs``,
  meets the game's default opponent (:func:`default_opponent`: its first scripted player that is not ``random``)
  in the others.

How many seats a player fills follows the game's kind: in a two-sides game a player fills every seat of its side
(the opponent the other side's); in a cooperative game a player named alone flies every seat (there is no opponent
to name), and with ``--vs`` the opponent fills the seats but the player's own; in a free-for-all game the player
takes its seat and the opponent every other.

``--vs`` names the opponent the same way; a team given to ``--vs`` contributes its players for the other seats. A
team given to ``--ckpt`` with ``--vs`` records each member against it (:func:`lineups`), as ``marl match`` plays
each member.
"""

from __future__ import annotations

import contextlib
import re
from dataclasses import dataclass
from typing import Any

from ..envs import EnvSpec, UnknownEnvError, env_names, get_env
from ..errors import MarlError
from ..league.store import League, PlayerRow
from ..players.snapshots import player_options
from ..policies.bots import league_bots
from ..policies.resize import describe_resize, resize_members
from ..ratings.names import Team, find_team, resolve_or_team, seat_of, teammates
from ..results import COOPERATIVE, TWO_SIDES, Rules
from .roles import RoleBook, cannot_meet_message, roles_text

__all__ = ["Lineup", "default_opponent", "find_team", "lineup", "lineups", "safe_filename", "seat_of", "teammates"]


def default_opponent(spec: EnvSpec) -> str:
    """The scripted player a policy meets when the user names none: the game's first that is not ``random`` (the
    stronger anchor), else ``random`` (which every game has, whether it registers it or not)."""
    bots = league_bots(spec)  # random too, which every game has
    return next((b for b in bots if b != "random"), bots[-1])


@dataclass(frozen=True)
class Lineup:
    """One league player per seat, in seat order, and ``focus``: the seat of the player the user named."""

    env: str
    players: tuple[PlayerRow, ...]
    focus: int

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.full_name for p in self.players)

    def file_stem(self, seed: int) -> str:
        """``<run>-<name>-vs-<opponent>-s<seed>``; an opponent from the same run goes by its bare name."""
        me = self.players[self.focus]
        others = [p for i, p in enumerate(self.players) if i != self.focus]
        them = "-".join(p.name if p.run is not None and p.run == me.run else p.full_name for p in others)
        return safe_filename(f"{me.full_name}-vs-{them}-s{seed}")


def refit(lu: Lineup, n_seats: int, seed: int = 0) -> Lineup:
    """The lineup for a game of ``n_seats`` seats when options change the number (a lander team trained with N
    landers flown as M), by seed 001's rule (:func:`~selfplay_cli.policies.resize.resize_members`, a fixed draw from
    ``seed``): the first members keep their places, extra seats copy members from the third on (a team of 1 or 2:
    any member), fewer seats drop members from the third on."""
    if n_seats == len(lu.players):
        return lu
    players = tuple(lu.players[i] for i in resize_members(len(lu.players), n_seats, seed))
    return Lineup(lu.env, players, focus=min(lu.focus, n_seats - 1))


def safe_filename(text: str) -> str:
    """A name made of letters, digits and ``._-`` (``/`` of ``run/name`` becomes ``-``)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text.replace("/", "-")).strip("._") or "video"


def _player_or_team(league: League, name: str, env: str | None) -> PlayerRow | list[PlayerRow]:
    """A single player if ``name`` resolves to one, else the team it names; the resolver's error otherwise."""
    found = resolve_or_team(league, name, env)
    return list(found.members) if isinstance(found, Team) else found


def _bots_ready(league: League, env: str | None) -> None:
    """Scripted players are league players once a game has used them: make sure they exist for ``env``."""
    for e in [env] if env else env_names():
        league.roster.ensure_bots(e, league_bots(get_env(e)))


def lineup(league: League, ckpt: str, vs: str | None = None, env: str | None = None) -> Lineup:
    """Seat the player (or team) ``ckpt`` names, against ``vs`` or its teammates or the default opponent."""
    if env is not None:
        get_env(env)
    _bots_ready(league, env)
    me = _player_or_team(league, ckpt, env)
    if isinstance(me, list):
        if vs is not None:
            names = " or ".join(p.full_name for p in me)
            raise MarlError(f"'{ckpt}' is a team of {len(me)} snapshots, one per seat: to play one of them against "
                            f"--vs {vs}, name it ({names})")
        return Lineup(me[0].env, tuple(me), focus=0)
    return _seat(league, me, vs)


def lineups(league: League, ckpt: str, vs: str | None = None, env: str | None = None) -> list[Lineup]:
    """The games ``marl record --ckpt CKPT [--vs VS]`` records: one lineup, or, for a team with ``--vs``, one per
    member, each on its own seat against ``vs`` (as ``marl match TEAM VS`` plays each member)."""
    if vs is None:
        return [lineup(league, ckpt, vs, env)]
    if env is not None:
        get_env(env)
    _bots_ready(league, env)
    me = _player_or_team(league, ckpt, env)
    if isinstance(me, list):
        return [_seat(league, member, vs) for member in me]
    return [_seat(league, me, vs)]


def _seat(league: League, me: PlayerRow, vs: str | None) -> Lineup:
    """``me`` on its own seat (a per-seat learner's, else the first) and the seats the game's kind gives it, against
    ``vs``, its teammates or the default opponent (see the module docstring)."""
    spec = get_env(me.env)
    if not me.is_bot and (spec.make_kind is not None or spec.make_agents is not None):
        with contextlib.suppress(MarlError, OSError, TypeError, ValueError):  # unreadable: refused when loaded
            spec = spec.for_options(**player_options(league, me))  # the game as it trained (its kind, its seats)
    rules = Rules.of(spec)
    agents = spec.agents
    book = RoleBook(league, me.env)
    seat = seat_of(me, agents)
    if seat is None and book.roles(me) is not None:  # a snapshot of one role: the first seat of that role
        seat = next((s for s, role in enumerate(rules.roles or ()) if role in book.roles(me)), None)
    focus = seat if seat is not None else 0
    if vs is None:
        team = teammates(league, me, agents)
        if team is not None:
            return Lineup(me.env, tuple(team), focus=focus)
        if rules.kind == COOPERATIVE:
            return Lineup(me.env, (me,) * len(agents), focus=focus)
        vs = default_opponent(spec)
    them = _player_or_team(league, vs, me.env)
    players = list(them) if isinstance(them, list) else [them] * len(agents)
    mine = [focus]
    if rules.kind == TWO_SIDES and not isinstance(them, list):
        assert rules.sides is not None
        mine = list(next(side for side in rules.sides if focus in side))
    for s in mine:
        players[s] = me
    misfit = [(s, p) for s, p in enumerate(players)  # a game whose seats differ: everyone on a seat of its role
              if rules.roles is not None and book.roles(p) is not None and rules.roles[s] not in book.roles(p)]
    if misfit:
        s, p = misfit[0]
        if not isinstance(them, list):
            raise MarlError(cannot_meet_message(spec.name, rules, me.full_name, book.roles(me), them.full_name,
                                                book.roles(them)))
        raise MarlError(f"{p.full_name} ({roles_text(book.roles(p))}) cannot play seat {agents[s]} of {spec.name} "
                        f"(role {rules.roles[s]})")  # type: ignore[index]
    return Lineup(me.env, tuple(players), focus=focus)


def resized_in_variant(league: League, env: str, rows: Any, variant: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """The snapshots among ladder ``rows`` that the variant ``variant`` (its options) flies with another number of
    seats than they trained with, by player id: ``trained_seats``, ``seats``, their ``team`` (``run/name`` of a team
    of per-seat networks; None for one network, which plays every seat) and the ``rule`` that seats the team (seed
    001's, in words). A snapshot whose file cannot be read is left out (its row says nothing more)."""
    try:
        spec = get_env(env)
        if spec.make_agents is None:
            return {}
        seats = spec.for_options(**variant).n_seats
    except (TypeError, ValueError, UnknownEnvError):  # a game not loadable here, options it no longer takes
        return {}
    out: dict[int, dict[str, Any]] = {}
    for r in rows:
        if r.kind != "snapshot" or r.player_id is None:
            continue
        try:
            row = league.roster.get_player(int(r.player_id))
            trained = spec.for_options(**player_options(league, row))
        except (MarlError, OSError, TypeError, ValueError):
            continue
        if trained.n_seats == seats:
            continue
        team = teammates(league, row, trained.agents)
        members = len(team) if team is not None else 1
        out[int(r.player_id)] = {
            "trained_seats": trained.n_seats, "seats": seats,
            "team": f"{row.run}/{row.name.rsplit('-', 1)[0]}" if team is not None else None,
            "rule": (describe_resize(members, seats, "each match's first seed") if team is not None
                     else "one network on every seat")}
    return out
