"""Turning the names users type (``17``, ``#17``, ``latest``, ``best``, ``r1/ep90``, a tag, ``random``,
``ep90``) into league players, with one-line errors that list candidates.

Resolution order (the first rule that applies decides):

1. an integer id, ``"17"`` or ``"#17"``;
2. ``latest``: the most recently added non-removed snapshot of the env;
3. ``best``: the highest fitted rating of the env among non-removed snapshots and bots
   (``ladder(league, env, bootstrap=0)``, the ladder's default prior; players whose rating is not comparable
   to the anchor's, i.e. flagged ``disconnected``, are only considered if nobody else is rated);
4. ``run/name``;
5. a tag, a bot name or a bare snapshot name (``ep90``) - all matches together; more than one distinct
   player is an ambiguity error.

Removed snapshots are not resolved unless ``include_removed=True`` (for ``marl show``); naming one gives
an error saying it was removed.

Imports go one way: this module uses :mod:`selfplay_cli.league.ladder` (for ``best``); the ladder never resolves
names itself (its ``anchor`` is a player row, an id or a full name; commands resolve what users type here first).
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterable

from selfplay_cli.league.ladder import LadderRow, ladder
from selfplay_cli.league.store import League, LeagueError, PlayerRow
from selfplay_cli.stats.bradley_terry import FLAG_DISCONNECTED, FLAG_UNRATED

__all__ = ["MAX_CANDIDATES", "LadderFn", "resolve", "resolve_many"]

LadderFn = Callable[[League, "str | None"], "list[LadderRow]"]
"""``ladder_fn(league, env) -> rows``: how ``best`` gets its ratings (default: a bootstrap-free ladder)."""

MAX_CANDIDATES = 10
"""How many known names an "unknown name" error lists."""


def _where(env: str | None) -> str:
    return env or "the league"


def _default_ladder(league: League, env: str | None) -> list[LadderRow]:
    return ladder(league, env, bootstrap=0)


def _label(players: list[PlayerRow]) -> str:
    """``r1/ep90, r2/ep90``; a name shared across envs gets its env: ``random (pong), random (lander)``."""
    full = [p.full_name for p in players]
    out = []
    for p in players:
        out.append(f"{p.full_name} ({p.env})" if full.count(p.full_name) > 1 else p.full_name)
    return ", ".join(dict.fromkeys(out))


def _known_names(league: League, env: str | None) -> list[str]:
    """Names a user could type in ``env``: full names of live players, bare snapshot names and tags."""
    names: list[str] = []
    for p in league.players(env=env):
        names.append(p.full_name)
        names.extend(p.tags)
    for p in league.players(env=env, kind="snapshot"):
        names.append(p.name)
    names.extend(["latest", "best"])
    return list(dict.fromkeys(names))


def _unknown(league: League, name: str, env: str | None) -> LeagueError:
    pool = _known_names(league, env)
    close = difflib.get_close_matches(name, pool, n=MAX_CANDIDATES, cutoff=0.5)
    ordered = list(dict.fromkeys(close + pool))
    shown = ", ".join(ordered[:MAX_CANDIDATES]) + (", ..." if len(ordered) > MAX_CANDIDATES else "")
    return LeagueError(f"no policy named '{name}' in {_where(env)}; known: {shown}")


def _removed(name: str, players: list[PlayerRow]) -> LeagueError:
    what = ", ".join(f"{p.full_name} (#{p.id})" for p in players)
    return LeagueError(f"'{name}' was removed: {what}; its games still count in the ratings")


def _by_id(league: League, name: str, pid: int, env: str | None, include_removed: bool) -> PlayerRow:
    try:
        p = league.get_player(pid)
    except LeagueError:
        raise LeagueError(f"no player with id {pid} in {_where(env)}") from None
    if env is not None and p.env != env:
        raise LeagueError(f"player {pid} ({p.full_name}) belongs to env {p.env}, not {env}")
    if p.removed and not include_removed:
        raise LeagueError(f"player {pid} ({p.full_name}) was removed; its games still count in the ratings")
    return p


def _best(league: League, env: str | None, ladder_fn: LadderFn) -> PlayerRow:
    rows = [r for r in ladder_fn(league, env) if r.player_id is not None and r.kind in ("bot", "snapshot")]
    comparable = [r for r in rows if r.flag not in (FLAG_DISCONNECTED, FLAG_UNRATED)]
    for r in sorted(comparable or rows, key=lambda r: (-r.elo, r.player_id)):
        p = league.get_player(int(r.player_id))  # type: ignore[arg-type]
        if not p.removed:
            return p
    raise LeagueError(f"no rated policy in {_where(env)} yet: 'best' needs games (marl match / tournament)")


def resolve(
    league: League,
    name: str,
    env: str | None = None,
    ladder_fn: LadderFn | None = None,
    include_removed: bool = False,
) -> PlayerRow:
    """The player ``name`` means in ``env`` (any env if None); see the module docstring for the rules.

    Raises:
        LeagueError: unknown name (with up to :data:`MAX_CANDIDATES` known names, closest first), an
            ambiguous name (listing the matches), a removed snapshot, ``latest`` / ``best`` without any
            snapshot / rated player.
    """
    text = str(name).strip()
    if not text:
        raise LeagueError("empty policy name")
    digits = text[1:] if text.startswith("#") else text
    if digits.isdigit():
        return _by_id(league, text, int(digits), env, include_removed)
    if text == "latest":
        p = league.latest(env=env)
        if p is None:
            raise LeagueError(f"no snapshot in {_where(env)} yet: 'latest' needs one")
        return p
    if text == "best":
        return _best(league, env, ladder_fn or _default_ladder)
    found = league.find_players(text, env=env, include_removed=True)
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
    raise _unknown(league, text, env)


def resolve_many(
    league: League,
    names: Iterable[str],
    env: str | None = None,
    ladder_fn: LadderFn | None = None,
    include_removed: bool = False,
) -> list[PlayerRow]:
    """:func:`resolve` each name in order (the ladder behind ``best`` is fitted at most once)."""
    base = ladder_fn or _default_ladder
    cache: dict[str | None, list[LadderRow]] = {}

    def cached(lg: League, e: str | None) -> list[LadderRow]:
        if e not in cache:
            cache[e] = base(lg, e)
        return cache[e]

    return [resolve(league, n, env, ladder_fn=cached, include_removed=include_removed) for n in names]
