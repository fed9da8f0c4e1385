"""Turning the names users type (``17``, ``#17``, ``latest``, ``best``, ``r1/ep90``, a tag, ``random``,
``ep90``) into league players, with one-line errors that list candidates.

Resolution order (the first rule that applies decides):

1. an integer id, ``"17"`` or ``"#17"``;
2. ``latest``: the most recently added non-removed snapshot of the env;
3. ``best``: the highest fitted rating of the env among non-removed snapshots and bots
   (``ladder(league, env, bootstrap=0)``, the ladder's default prior, in the variant asked for: the game's default
   options unless ``variant`` says otherwise; players whose rating is not comparable to the anchor's, i.e. flagged
   ``disconnected``, are only considered if nobody else is rated);
4. ``run/name``;
5. a tag, a bot name or a bare snapshot name (``s6M-left``) - all matches together; more than one distinct
   player is an ambiguity error.

A **team** is the snapshots of one moment of a run that trained one network per seat: ``s6M-left`` and
``s6M-right`` are the team ``s6M`` (or ``pong-1/s6M``). :func:`resolve_or_team` returns it where a team makes
sense (``marl record`` seats it, ``marl match`` plays each member, ``marl checkpoint show`` shows each member);
:func:`resolve`, which answers with one player, refuses a team name in one line that names its members.

Removed snapshots are not resolved unless ``include_removed=True`` (for ``marl show``); naming one gives
an error saying it was removed.

It lives with rated play, not in the league, because a team is known by its game's seats (the game's registry, which
the league does not import). Imports go one way: this module uses :mod:`selfplay_cli.ratings.ladder` (for ``best``);
the ladder never resolves names itself (its ``anchor`` is a player row, an id or a full name; commands resolve
what users type here first).
"""

from __future__ import annotations

import contextlib
import difflib
import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from ..envs import UnknownEnvError, env_names, get_env
from ..league.store import League, LeagueError, PlayerRow
from ..league.variants import describe_variant
from ..stats.bradley_terry import FLAG_DISCONNECTED, FLAG_UNRATED
from .ladder import ladder
from .ladder_rows import LadderRow

__all__ = ["MAX_CANDIDATES", "LadderFn", "Team", "find_team", "resolve", "resolve_many", "resolve_or_team",
           "seat_of", "teammates"]

LadderFn = Callable[[League, "str | None"], "list[LadderRow]"]
"""``ladder_fn(league, env) -> rows``: how ``best`` gets its ratings (default: a bootstrap-free ladder)."""

MAX_CANDIDATES = 5
"""How many of the closest names, and then of the newest snapshots, an "unknown name" error lists."""

MAX_ID = 2**63 - 1
"""The largest id a player can have (a 64-bit database integer)."""


@dataclass(frozen=True)
class Team:
    """The snapshots ``<name>-<seat>`` of one run, one per seat of the game, in seat order."""

    name: str  # run/name, e.g. pong-1/s6M
    members: tuple[PlayerRow, ...]

    @property
    def env(self) -> str:
        return self.members[0].env

    @property
    def full_name(self) -> str:
        return self.name

    def describe(self) -> str:
        """``pong-1/s6M-left, pong-1/s6M-right``."""
        return ", ".join(p.full_name for p in self.members)


def seat_of(row: PlayerRow, agents: tuple[str, ...]) -> int | None:
    """The seat a per-seat learner's snapshot was trained on: its league metadata, else its ``-<seat>`` suffix."""
    learner = row.meta.get("learner")
    if learner in agents:
        return agents.index(learner)
    for i, agent in enumerate(agents):
        if row.name.endswith(f"-{agent}"):
            return i
    return None


def find_team(league: League, name: str, env: str | None) -> list[PlayerRow] | None:
    """The snapshots ``<name>-<seat>`` for every seat of the game as their run played it (a run whose options change
    the seats, ``landers=3``, ``n_pursuers=3``: those seats), all from one run, in seat order; None if there are
    none. Raises LeagueError if several runs have such a team (``run/name`` chooses)."""
    teams: dict[tuple[str, str], list[PlayerRow]] = {}
    runs = league.roster.list_runs(env)
    # the registered games, and the users' games the league's runs play (mpe2.simple_push_v3, a module:factory)
    for e in [env] if env else dict.fromkeys([*env_names(), *(r.env for r in runs)]):
        try:
            spec = get_env(e)
        except UnknownEnvError:  # a game this process cannot load: its names are found one by one, not as teams
            continue
        seatings = {spec.agents: None}  # the seats of the game, and those its runs' options made
        for r in runs:
            if r.env == e and (options := (r.config or {}).get("env_options")):
                with contextlib.suppress(TypeError, ValueError, UnknownEnvError):
                    seatings.setdefault(spec.for_options(**options).agents)
        seatings = {agents: None for agents in seatings if len(agents) > 1}  # in order: the game's own first
        found: dict[str, list[PlayerRow]] = {}  # each seat's snapshots, asked for once whatever seatings share it
        for agent in dict.fromkeys(a for agents in seatings for a in agents):
            found[agent] = [p for p in league.roster.find_players(f"{name}-{agent}", env=e)
                            if p.kind == "snapshot" and p.run is not None
                            and ("/" not in name or p.full_name == f"{name}-{agent}")]
        for agents in seatings:
            by_run: dict[str, list[PlayerRow | None]] = {}
            for seat, agent in enumerate(agents):
                for p in found[agent]:
                    by_run.setdefault(p.run, [None] * len(agents))[seat] = p  # type: ignore[arg-type]
            for run, members in by_run.items():
                whole = all(m is not None for m in members)
                if whole and len(members) > len(teams.get((e, run), ())):  # the run's whole team, not a part
                    teams[(e, run)] = members  # type: ignore[assignment]
    if len(teams) > 1:
        listed = ", ".join(f"{run}/{name}" for _, run in sorted(teams))
        raise LeagueError(f"'{name}' is a team in several runs: {listed}; use run/name")
    return next(iter(teams.values()), None)


def teammates(league: League, row: PlayerRow, agents: tuple[str, ...]) -> list[PlayerRow] | None:
    """The whole team (seat order) of a per-seat learner's snapshot, from its run and name; None if it has none."""
    seat = seat_of(row, agents)
    suffix = f"-{agents[seat]}" if seat is not None else ""
    if seat is None or row.run is None or not row.name.endswith(suffix):
        return None
    base = row.name[: -len(suffix)]
    team = find_team(league, f"{row.run}/{base}", row.env)
    return team if team is not None and row.id in {p.id for p in team} else None


def _team(league: League, text: str, env: str | None) -> Team | None:
    members = find_team(league, text, env)
    if members is None:
        return None
    base = text.rsplit("/", 1)[-1]
    return Team(f"{members[0].run}/{base}", tuple(members))


def _where(env: str | None) -> str:
    return env or "the league"


def _default_ladder(league: League, env: str | None, variant: str = "") -> list[LadderRow]:
    return ladder(league, env, bootstrap=0, variant=variant)


def _label(players: list[PlayerRow]) -> str:
    """``r1/ep90, r2/ep90``; a name shared across envs gets its env: ``random (pong), random (lander)``."""
    full = [p.full_name for p in players]
    out = []
    for p in players:
        out.append(f"{p.full_name} ({p.env})" if full.count(p.full_name) > 1 else p.full_name)
    return ", ".join(dict.fromkeys(out))


def _team_names(players: list[PlayerRow]) -> list[str]:
    """``s6M`` and ``pong-1/s6M`` for every team among ``players`` (per-seat snapshots of one moment)."""
    out: list[str] = []
    for p in players:
        if p.kind != "snapshot" or p.run is None:
            continue
        agents = get_env(p.env).agents if p.env in env_names() else ()
        seat = seat_of(p, agents) if len(agents) > 1 else None
        if seat is not None and p.name.endswith(f"-{agents[seat]}"):
            base = p.name[: -len(agents[seat]) - 1]
            out += [base, f"{p.run}/{base}"]
    return out


def _unknown(league: League, name: str, env: str | None) -> LeagueError:
    """An unknown name: the closest names first, then the newest snapshots, then what else can be typed."""
    players = league.roster.players(env=env)
    snapshots = sorted((p for p in players if p.kind == "snapshot"), key=lambda p: -p.id)
    pool = [p.full_name for p in players] + [t for p in players for t in p.tags]
    pool += [p.name for p in snapshots] + _team_names(snapshots) + ["latest", "best"]
    pool = list(dict.fromkeys(pool))
    close = difflib.get_close_matches(name, pool, n=MAX_CANDIDATES, cutoff=0.5)
    if not close:  # a different case, or a prefix: s6m, pong-1/s6
        folded = name.casefold()
        close = [n for n in pool if n.casefold() == folded or n.casefold().startswith(folded)][:MAX_CANDIDATES]
    newest = [p.full_name for p in snapshots if p.full_name not in close][:MAX_CANDIDATES]
    bots = list(dict.fromkeys(p.name for p in players if p.kind == "bot"))  # random is every game's: named once
    parts = [f"no policy named '{name}' in {_where(env)}"]
    shared = _seatless(snapshots, name)
    if shared is not None:
        parts.append(f"{shared.full_name} is one network for every seat (its run shares one), so its name has no "
                     f"seat: name it {shared.full_name if '/' in name else shared.name}")
    if close:
        parts.append(f"closest: {', '.join(close)}")
    if newest:
        more = len(snapshots) - len(newest) - sum(1 for p in snapshots if p.full_name in close)
        parts.append(f"newest: {', '.join(newest)}" + (f" (and {more} older: marl checkpoint list)" if more > 0
                                                          else ""))
    parts.append(", ".join(["latest", "best", *bots]) + " or an id also work")
    return LeagueError("; ".join(parts))


def _seatless(snapshots: list[PlayerRow], name: str) -> PlayerRow | None:
    """The snapshot ``name`` would be without a ``-<seat>`` suffix of its game's seats (``tennis-1/s0-player_0`` for
    ``tennis-1/s0`` of a run that shares one network), if there is exactly one."""
    found = {}
    for p in snapshots:
        agents = get_env(p.env).agents if p.env in env_names() else ()
        if any(name in (f"{p.full_name}-{a}", f"{p.name}-{a}") for a in agents):
            found[p.id] = p
    return next(iter(found.values())) if len(found) == 1 else None


def _removed(name: str, players: list[PlayerRow]) -> LeagueError:
    what = ", ".join(f"{p.full_name} (#{p.id})" for p in players)
    return LeagueError(f"'{name}' was removed: {what}; its games still count in the ratings")


def _by_id(league: League, name: str, pid: int, env: str | None, include_removed: bool) -> PlayerRow:
    try:
        if pid > MAX_ID:
            raise LeagueError(str(pid))
        p = league.roster.get_player(pid)
    except LeagueError:
        raise LeagueError(f"no player with id {pid} in {_where(env)}") from None
    if env is not None and p.env != env:
        raise LeagueError(f"player {pid} ({p.full_name}) belongs to env {p.env}, not {env}")
    if p.removed and not include_removed:
        raise LeagueError(f"player {pid} ({p.full_name}) was removed; its games still count in the ratings")
    return p


def _best(league: League, env: str | None, ladder_fn: LadderFn, variant: str = "") -> PlayerRow:
    rows = [r for r in ladder_fn(league, env) if r.player_id is not None and r.kind in ("bot", "snapshot")]
    comparable = [r for r in rows if r.flag not in (FLAG_DISCONNECTED, FLAG_UNRATED)]
    sides = list(dict.fromkeys(r.side for r in rows))
    if len(sides) > 1:  # a game rated per side: ratings of two sides do not compare
        tops = [max([r for r in comparable if r.side == side] or [r for r in rows if r.side == side],
                    key=lambda r: r.elo).policy for side in sides]
        raise LeagueError(f"'best' is per side in {_where(env)}, whose sides differ: name one ("
                          + "; ".join(f"{side} side: {top}" for side, top in zip(sides, tops, strict=True)) + ")")
    for r in sorted(comparable or rows, key=lambda r: (-r.elo, r.player_id)):
        p = league.roster.get_player(int(r.player_id))  # type: ignore[arg-type]
        if not p.removed:
            return p
    where = _where(env) + (f" with {describe_variant(variant)}" if variant else "")
    raise LeagueError(f"no rated policy in {where} yet: 'best' needs games (marl match / tournament)")


def resolve(
    league: League,
    name: str,
    env: str | None = None,
    ladder_fn: LadderFn | None = None,
    include_removed: bool = False,
    variant: str = "",
) -> PlayerRow:
    """The player ``name`` means in ``env`` (any env if None); see the module docstring for the rules. ``variant``:
    the variant whose ladder ``best`` is read from (its key; the default variant unless given), where no
    ``ladder_fn`` is.

    Raises:
        LeagueError: unknown name (with up to :data:`MAX_CANDIDATES` known names, closest first), an
            ambiguous name (listing the matches), a removed snapshot, ``latest`` / ``best`` without any
            snapshot / rated player.
    """
    text = str(name).strip()
    if not text:
        raise LeagueError("empty policy name")
    digits = text[1:] if text.startswith("#") else text
    if digits.isascii() and digits.isdigit():
        return _by_id(league, text, int(digits), env, include_removed)
    if text == "latest":
        p = league.roster.latest(env=env)
        if p is None:
            raise LeagueError(f"no snapshot in {_where(env)} yet: 'latest' needs one")
        return p
    if text == "best":
        return _best(league, env, ladder_fn or functools.partial(_default_ladder, variant=variant), variant)
    found = league.roster.find_players(text, env=env, include_removed=True)
    if "/" in text:  # only run/name matches can contain a slash; keep exactly those
        run, _, snap = text.partition("/")
        found = [p for p in found if p.run == run and p.name == snap]
    live = [p for p in found if include_removed or not p.removed]
    if len(live) == 1:
        return live[0]
    if len(live) > 1:
        raise LeagueError(f"'{text}' is ambiguous: {_label(live)} — use run/name or an id")
    if found:
        raise _removed(text, found)
    team = _team(league, text, env)
    if team is not None:
        raise LeagueError(f"'{text}' names a team of {len(team.members)} snapshots, one per seat ({team.describe()})"
                          f": name one of them, e.g. {team.members[0].full_name}")
    raise _unknown(league, text, env)


def resolve_or_team(
    league: League,
    name: str,
    env: str | None = None,
    ladder_fn: LadderFn | None = None,
    include_removed: bool = False,
    variant: str = "",
) -> PlayerRow | Team:
    """What ``name`` means where a team makes sense: the one player :func:`resolve` finds, else the team of
    per-seat snapshots it names (``s6M``, ``pong-1/s6M``); the resolver's error otherwise."""
    try:
        return resolve(league, name, env, ladder_fn=ladder_fn, include_removed=include_removed, variant=variant)
    except LeagueError:
        team = _team(league, str(name).strip(), env)
        if team is None:
            raise
        return team


def resolve_many(
    league: League,
    names: Iterable[str],
    env: str | None = None,
    ladder_fn: LadderFn | None = None,
    include_removed: bool = False,
    variant: str = "",
) -> list[PlayerRow]:
    """:func:`resolve` each name in order (the ladder behind ``best`` is fitted at most once)."""
    base = ladder_fn or functools.partial(_default_ladder, variant=variant)
    cache: dict[str | None, list[LadderRow]] = {}

    def cached(lg: League, e: str | None) -> list[LadderRow]:
        if e not in cache:
            cache[e] = base(lg, e)
        return cache[e]

    return [resolve(league, n, env, ladder_fn=cached, include_removed=include_removed, variant=variant)
            for n in names]
