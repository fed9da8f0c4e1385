"""Runs, players and names in the league: training runs, bots and snapshots, tags, and the rule a name must follow.

:class:`Roster` is a part of :class:`~selfplay_cli.league.store.League` (it runs on :class:`~selfplay_cli.league.db.
Database`'s units of work). Objects returned to callers are frozen dataclasses (:class:`RunRow`,
:class:`PlayerRow`), never ORM instances, so nothing lazy-loads after a session has closed.

A snapshot's ``sha256`` is the sha256 of its whole file (:attr:`selfplay_cli.league.models.Player.sha256`); the
weights' own checksum, where a snapshot has one, is ``meta["weights_sha256"]``. The two are never mixed: the store
hashes the file itself when it registers a snapshot (:meth:`Roster.add_snapshots`), and keeps the very bytes it hashed
as the snapshot's blob (:mod:`selfplay_cli.league.blobs`), so that any machine with the database can play it.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Collection, Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from sqlalchemy import and_, or_, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from selfplay_cli.league.blobs import store_blob
from selfplay_cli.league.bounded_json import say_unusable, unreadable
from selfplay_cli.league.db import Part
from selfplay_cli.league.failures import LeagueError, shown
from selfplay_cli.league.models import Player, Run, Tag, utcnow
from selfplay_cli.league.rows import PlayerRow, RunRow, RunStatus

__all__ = ["DEFAULT_ELO", "ENV_NAME_PATTERN", "NAME_PATTERN", "RESERVED_NAMES", "PlayerRow", "Roster", "RunRow",
           "RunStatus", "check_env_name", "check_existing_name", "check_name"]

DEFAULT_ELO = 1000.0


RESERVED_NAMES = ("latest", "best")
EXPLOITABILITY_KINDS = ("exact", "lower_bound")
"""How a filed exploitability was measured (:meth:`Roster.set_exploitability`)."""
"""Names resolved by higher-level code; no tag may take them."""

_MAX_NAME = 200


NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*")
"""What a run, snapshot, tag, bot or env name may be: ASCII letters, digits and ``. _ + -``, starting with a letter or
digit (so never ``.``, ``..``, a hidden file or something that reads as an option). A name becomes a folder or file
name under the league home and is printed on terminals, so nothing else gets in: no ``/``, no spaces, no control
characters (escape sequences)."""


def check_name(what: str, value: object) -> str:
    """Validate a run / snapshot / bot / tag / env name (:data:`NAME_PATTERN`, at most 200 characters) and return
    it; a :class:`LeagueError` saying what is allowed otherwise. The one place names are checked: the store calls it
    before every insert, and code that builds paths from names calls it before creating anything."""
    if not isinstance(value, str) or not value:
        raise LeagueError(f"invalid {what} {shown(value)}: a name must not be empty")
    if len(value) > _MAX_NAME:
        raise LeagueError(f"invalid {what} {shown(value)}: longer than {_MAX_NAME} characters")
    if not NAME_PATTERN.fullmatch(value):
        raise LeagueError(f"invalid {what} {shown(value)}: use letters, digits and . _ + - "
                          "(starting with a letter or digit)")
    return value


_check_name = check_name

ENV_NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*(:[A-Za-z_][A-Za-z0-9_.]*)?"
                              r"|openspiel:[A-Za-z0-9_]+(\([A-Za-z0-9_.=,+()-]*\))?")
"""What a game's name may be: a league name (:data:`NAME_PATTERN`), a user's PettingZoo game as ``module:factory``
(``mypkg.mygame:env``), or an OpenSpiel game with its parameters (``openspiel:leduc_poker(players=3)``). A game's
name is never a file or folder name."""


def check_env_name(value: object) -> str:
    """Validate a game's name (:data:`ENV_NAME_PATTERN`, at most 200 characters); a :class:`LeagueError` otherwise."""
    if not isinstance(value, str) or not value or len(value) > _MAX_NAME or not ENV_NAME_PATTERN.fullmatch(value):
        raise LeagueError(f"invalid env {shown(value)}: a registered game's name (letters, digits and . _ + -), a "
                          "PettingZoo game's module:factory or openspiel:GAME(param=value,...)")
    return value


def check_existing_name(what: str, value: object) -> str:
    """The looser check for a name already in a league (a run an older marl created, which :func:`check_name`
    might refuse for a space or an accent): still a plain folder name, never ``.``/``..``, no separator, nothing
    unprintable. New names always go through :func:`check_name`."""
    if (not isinstance(value, str) or not value or len(value) > _MAX_NAME or value in (".", "..")
            or any(c in value for c in "/\\") or not value.isprintable()):
        raise LeagueError(f"invalid {what} {shown(value)}: not a plain name")
    return value


def _run_status(status: RunStatus | str) -> str:
    """The word stored for ``status``; a :class:`LeagueError` for one that is not a :class:`RunStatus`."""
    try:
        return RunStatus(status).value
    except ValueError:
        raise LeagueError(f"unknown run status {shown(status)}: one of "
                          f"{', '.join(s.value for s in RunStatus)}") from None


def _player_row(p: Player) -> PlayerRow:
    """Copy an ORM player (with its run and tags loaded) into a :class:`PlayerRow`; a row whose ``meta`` cannot be
    read is unusable, said once on stderr."""
    run = p.run.name if p.run is not None else None
    bad = unreadable(p.meta)
    if bad is not None:
        say_unusable(f"player {p.id} ({shown(f'{run}/{p.name}' if run else p.name)} of {shown(p.env)})", "meta",
                     bad, "it is listed, never played")
    return PlayerRow(
        id=p.id, env=p.env, kind=p.kind, name=p.name, run=run,
        step=int(p.step or 0), episode=int(p.episode or 0), algo=p.algo, path=p.path, sha256=p.sha256,
        parent_id=p.parent_id, tags=tuple(t.tag for t in p.tags), elo=float(p.elo), games=int(p.games),
        removed=bool(p.removed), created_at=p.created_at, meta=dict(p.meta or {}), unusable=bad,
    )


def _bound_of(record: dict[str, Any]) -> float:
    """The figure a lower bound stands on: its interval's low end, else its value."""
    low = record.get("low")
    return float(low if low is not None else record["value"])


def _run_row(r: Run) -> RunRow:
    """Copy an ORM run into a :class:`RunRow`; a run whose ``config`` cannot be read is unusable, said once on
    stderr."""
    bad = unreadable(r.config)
    if bad is not None:
        say_unusable(f"run {r.id} ({shown(r.name)})", "config", bad, "it is listed, never resumed")
    return RunRow(id=r.id, name=r.name, env=r.env, algo=r.algo, config=dict(r.config or {}), status=r.status,
                  created_at=r.created_at, unusable=bad)


class Roster(Part):
    """Runs, players (bots and snapshots) and tags."""

    # ---------------------------------------------------------------- runs

    def create_run(self, name: str, env: str, config: dict[str, Any], algo: str | None = None,
                   status: RunStatus = RunStatus.RUNNING) -> RunRow:
        """Register a new training run. Raises LeagueError if the name is taken."""
        _check_name("run name", name)
        check_env_name(env)
        status = _run_status(status)

        def work(s: Session) -> RunRow:
            if s.execute(select(Run.id).where(Run.name == name)).first() is not None:
                raise LeagueError(f"run {name!r} already exists")
            run = Run(name=name, env=env, algo=algo, config=dict(config or {}), status=status)
            s.add(run)
            s.flush()
            return _run_row(run)

        try:
            return self._unit(work)
        except IntegrityError as exc:  # lost a race against another process
            raise LeagueError(f"run {name!r} already exists") from exc

    def get_run(self, name: str) -> RunRow | None:
        """The run called ``name``, or None."""

        def work(s: Session) -> RunRow | None:
            run = s.execute(select(Run).where(Run.name == name)).scalar_one_or_none()
            return _run_row(run) if run is not None else None

        return self._read(work)

    def set_run_status(self, name: str, status: RunStatus | str) -> None:
        """Set a run's status (a :class:`RunStatus`, or its word). Raises LeagueError for an unknown run or a word
        that is not a status."""
        status = _run_status(status)

        def work(s: Session) -> None:
            run = s.execute(select(Run).where(Run.name == name)).scalar_one_or_none()
            if run is None:
                raise LeagueError(f"no run named {name!r}")
            run.status = status

        self._unit(work)

    def list_runs(self, env: str | None = None) -> list[RunRow]:
        """All runs (of ``env``), oldest first."""

        def work(s: Session) -> list[RunRow]:
            q = select(Run).order_by(Run.id)
            if env is not None:
                q = q.where(Run.env == env)
            return [_run_row(r) for r in s.execute(q).scalars()]

        return self._read(work)

    # ---------------------------------------------------------------- players

    def ensure_bots(self, env: str, names: Iterable[str]) -> None:
        """Make sure a bot player exists for each name in ``env`` (idempotent)."""
        check_env_name(env)
        wanted = [_check_name("bot name", n) for n in dict.fromkeys(names)]
        if not wanted:
            return

        def have(s: Session) -> set[str]:
            q = select(Player.name).where(Player.env == env, Player.run_id.is_(None), Player.name.in_(wanted))
            return set(s.execute(q).scalars())

        if set(wanted) <= self._read(have):  # the common case: nothing to write, no write lock
            return

        def work(s: Session) -> None:
            rows = s.execute(select(Player).where(Player.env == env, Player.run_id.is_(None),
                                                  Player.name.in_(wanted))).scalars().all()
            existing = {p.name: p for p in rows}
            for n in wanted:
                p = existing.get(n)
                if p is None:
                    s.add(Player(env=env, kind="bot", name=n))
                elif p.kind != "bot":
                    raise LeagueError(f"bot name {n!r} is taken by a snapshot without run in env {env!r}")

        try:
            self._unit(work)
        except IntegrityError:  # another process added the same bots first (non-SQLite backends)
            self._unit(work)

    def add_snapshot(self, *, env: str, run: str | None, name: str, path: str, sha256: str | None = None,
                     step: int = 0, episode: int = 0, algo: str | None = None, parent_id: int | None = None,
                     meta: dict[str, Any] | None = None, run_config: dict[str, Any] | None = None) -> PlayerRow:
        """Register a policy snapshot. Raises LeagueError if ``(env, run, name)`` exists or run/parent is unknown.

        ``path`` is the file, relative to the home (or absolute); ``sha256`` the sha256 of the whole file (see
        :attr:`Player.sha256 <selfplay_cli.league.models.Player.sha256>`). With the file in place the store hashes it
        itself: ``sha256`` may be left out, and one given must be the file's or, as callers passed before it meant
        the file, the weights' checksum of ``meta["weights_sha256"]`` (the file's hash is stored then). Without the
        file (kept elsewhere) the given ``sha256`` is stored as it is.

        ``run_config``: a ``run`` that does not exist yet is created with it (status ``finished``), in the same
        transaction as the snapshot (an import that fails leaves no empty run behind).
        """
        return self.add_snapshots([dict(env=env, run=run, name=name, path=path, sha256=sha256, step=step,
                                        episode=episode, algo=algo, parent_id=parent_id, meta=meta)],
                                  run_config=run_config)[0]

    def add_snapshots(self, items: Sequence[dict[str, Any]], run_config: dict[str, Any] | None = None
                      ) -> list[PlayerRow]:
        """Register several snapshots (the keyword arguments of :meth:`add_snapshot`, one dict each) in ONE
        transaction: all of them or none (a training run's snapshots of one moment are one unit). ``run_config``
        as in :meth:`add_snapshot`.

        The bytes of each file are stored in the league as its blob (:mod:`selfplay_cli.league.blobs`) in the same
        transaction as its row: the very bytes that were hashed, so any machine with the database can play it. A
        row registered without its file (kept elsewhere) has no blob."""
        for item in items:
            check_env_name(item["env"])
            _check_name("snapshot name", item["name"])
            if item.get("run") is not None:  # a new run is checked like any new name; an existing one stays usable
                (check_name if run_config is not None else check_existing_name)("run name", item["run"])
        files = [self._file_bytes(item) for item in items]
        items = [{**item, "sha256": sha} for item, (sha, _) in zip(items, files, strict=True)]

        def insert(s: Session, env: str, run: str | None, name: str, path: str, sha256: str, step: int = 0,
                   episode: int = 0, algo: str | None = None, parent_id: int | None = None,
                   meta: dict[str, Any] | None = None) -> Player:
            where = f"{run}/{name}" if run else name
            run_row: Run | None = None
            if run is not None:
                run_row = s.execute(select(Run).where(Run.name == run)).scalar_one_or_none()
                if run_row is None and run_config is not None:
                    run_row = Run(name=run, env=env, algo=algo, config=dict(run_config),
                                  status=RunStatus.FINISHED.value)
                    s.add(run_row)
                    s.flush()
                if run_row is None:
                    raise LeagueError(f"no run named {run!r}")
                if run_row.env != env:
                    raise LeagueError(f"run {run!r} trains env {run_row.env!r}, not {env!r}")
            dup = select(Player.id).where(Player.env == env, Player.name == name)
            dup = dup.where(Player.run_id == run_row.id) if run_row is not None else dup.where(Player.run_id.is_(None))
            if s.execute(dup).first() is not None:
                raise LeagueError(f"snapshot {where!r} already exists in env {env!r}")
            if parent_id is not None:
                parent = s.get(Player, parent_id)
                if parent is None:
                    raise LeagueError(f"no player with id {parent_id} (parent of {where!r})")
            p = Player(env=env, kind="snapshot", name=name, run=run_row, step=int(step), episode=int(episode),
                       algo=algo, path=str(path), sha256=sha256, parent_id=parent_id, meta=dict(meta or {}),
                       elo=DEFAULT_ELO, games=0, removed=False)
            s.add(p)
            s.flush()
            return p

        def work(s: Session) -> list[PlayerRow]:
            players = [insert(s, **item) for item in items]
            for sha, data in files:
                if data is not None:
                    store_blob(s, sha, data)
            for p in players:
                s.refresh(p, ["tags"])
            return [_player_row(p) for p in players]

        try:
            return self._unit(work)
        except IntegrityError as exc:
            names = ", ".join(f"{i['run']}/{i['name']}" if i["run"] else i["name"] for i in items)
            raise LeagueError(f"snapshot {names} already exists") from exc

    def _file_bytes(self, item: dict[str, Any]) -> tuple[str, bytes | None]:
        """The sha256 a snapshot row gets, its file's (see :meth:`add_snapshot`), and the file's bytes that hash to
        it (None for a row registered without its file)."""
        given, where = item.get("sha256"), item["path"]
        file = Path(where)
        if not file.is_absolute():
            if self.db.home is None:
                file = None  # type: ignore[assignment]
            else:
                file = self.db.home_path(*Path(where).parts)
        if file is not None and file.is_file():
            try:
                data = file.read_bytes()
            except OSError as exc:
                raise LeagueError(f"{file}: cannot read ({exc.strerror or exc})") from exc
            actual = hashlib.sha256(data).hexdigest()
            legacy = (item.get("meta") or {}).get("weights_sha256")
            if given is not None and given != actual and given != legacy:
                raise LeagueError(f"{file}: the file's sha256 is not the {given[:12]}... given for it (changed while "
                                  "it was being registered?)")
            return actual, data
        if not given:
            raise LeagueError(f"no snapshot file at {file or where} to register")
        return str(given), None

    def get_player(self, player_id: int) -> PlayerRow:
        """The player with this id (removed ones included). Raises LeagueError if there is none."""

        def work(s: Session) -> PlayerRow:
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            return _player_row(p)

        return self._read(work)

    def players(self, env: str | None = None, kind: str | None = None,
                include_removed: bool = False) -> list[PlayerRow]:
        """Players (of ``env``, of ``kind`` "bot" / "snapshot") in id order."""

        def work(s: Session) -> list[PlayerRow]:
            q = select(Player).order_by(Player.id)
            if env is not None:
                q = q.where(Player.env == env)
            if kind is not None:
                q = q.where(Player.kind == kind)
            if not include_removed:
                q = q.where(Player.removed.is_(False))
            return [_player_row(p) for p in s.execute(q).unique().scalars()]

        return self._read(work)

    def find_players(self, name: str, env: str | None = None, include_removed: bool = False) -> list[PlayerRow]:
        """Every player that ``name`` could mean, in id order (empty if none; several if ambiguous).

        ``name`` is matched as: an integer id (``"12"``), a bot name, a snapshot name in any run
        (``"ep90"``), ``"run/name"``, or a tag. The special names ``latest`` / ``best`` are left to the
        caller (see :meth:`latest`). Removed snapshots are skipped unless ``include_removed``.
        """
        name = name.strip()
        if not name:
            return []

        def work(s: Session) -> list[PlayerRow]:
            conds = [Player.name == name]  # bot or snapshot name
            if name.isdigit():
                conds.append(Player.id == int(name))
            if "/" in name:
                run_name, _, snap = name.partition("/")
                run_ids = select(Run.id).where(Run.name == run_name).scalar_subquery()
                conds.append(and_(Player.name == snap, Player.run_id == run_ids))
            tag_q = select(Tag.player_id).where(Tag.tag == name)
            if env is not None:
                tag_q = tag_q.where(Tag.env == env)
            conds.append(Player.id.in_(tag_q))
            q = select(Player).where(or_(*conds)).order_by(Player.id)
            if env is not None:
                q = q.where(Player.env == env)
            if not include_removed:
                q = q.where(Player.removed.is_(False))
            return [_player_row(p) for p in s.execute(q).unique().scalars()]

        return self._read(work)

    def latest(self, env: str | None = None, run: str | None = None) -> PlayerRow | None:
        """The most recently created (not removed) snapshot, of ``env`` / ``run`` if given."""

        def work(s: Session) -> PlayerRow | None:
            q = select(Player).where(Player.kind == "snapshot", Player.removed.is_(False))
            if env is not None:
                q = q.where(Player.env == env)
            if run is not None:
                q = q.join(Run, Run.id == Player.run_id).where(Run.name == run)
            p = s.execute(q.order_by(Player.id.desc()).limit(1)).unique().scalar_one_or_none()
            return _player_row(p) if p is not None else None

        return self._read(work)

    def tag(self, player_id: int, tag: str) -> None:
        """Tag a player; a tag already on another player of the env moves to this one.

        Raises LeagueError for an unknown or removed player, a tag equal to a bot name of the env, a
        reserved name (``latest``, ``best``) or an all-digit tag (it would read as an id).
        """
        _check_name("tag", tag)
        if tag in RESERVED_NAMES:
            raise LeagueError(f"tag {tag!r} is reserved")
        if tag.isdigit():
            raise LeagueError(f"tag {tag!r} would be read as a player id")

        def work(s: Session) -> None:
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            if p.removed:
                raise LeagueError(f"player {p.id} ({p.name}) has been removed")
            bot = select(Player.id).where(Player.env == p.env, Player.kind == "bot", Player.name == tag)
            if s.execute(bot).first() is not None:
                raise LeagueError(f"tag {tag!r} would shadow the bot of that name in env {p.env!r}")
            old = s.execute(select(Tag).where(Tag.env == p.env, Tag.tag == tag)).scalar_one_or_none()
            if old is not None:
                if old.player_id == p.id:
                    return
                s.delete(old)
                s.flush()
            s.add(Tag(env=p.env, tag=tag, player_id=p.id))

        self._unit(work)

    def set_exploitability(self, player_id: int, record: dict[str, Any]) -> PlayerRow:
        """File a measured exploitability of a player in its row (``meta["exploitability"][kind]``), in one
        transaction; returns the row as it is now.

        ``record["kind"]`` is ``exact`` (OpenSpiel's best-response computation: it replaces any older exact figure)
        or ``lower_bound`` (a trained best response's mean return against the player, ``low``/``high`` its 95%
        interval: it replaces an older lower bound only when its ``low`` is higher, since each is a bound and the
        tightest one stands). ``record["value"]`` is in the game's return units. Raises LeagueError for an unknown
        player, a kind that is neither, or a value that is not a finite number."""
        kind = record.get("kind")
        if kind not in EXPLOITABILITY_KINDS:
            raise LeagueError(f"exploitability kind must be one of {', '.join(EXPLOITABILITY_KINDS)}, not {kind!r}")
        value = record.get("value")
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            raise LeagueError(f"exploitability value must be a finite number, not {value!r}")
        new = {**record, "at": utcnow().isoformat(timespec="seconds")}

        def work(s: Session) -> PlayerRow:
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            meta = dict(p.meta or {})
            book = dict(meta.get("exploitability") or {})
            old = book.get(kind)
            if kind == "lower_bound" and old is not None and _bound_of(old) >= _bound_of(new):
                return _player_row(p)
            book[kind] = new
            meta["exploitability"] = book
            p.meta = meta  # (a new dict: the JSON column sees the change)
            s.flush()
            return _player_row(p)

        return self._unit(work)

    def remove_snapshot(self, player_id: int, end_runs: Collection[str] = (),
                        status: RunStatus = RunStatus.ENDED) -> PlayerRow:
        """Mark a snapshot removed (soft delete) and drop its tags; its games stay in the ledger. The runs named in
        ``end_runs`` (runs that needed it, removed anyway) get ``status`` in the same transaction.

        Returns the player row as it was just before removal (with its path, so the caller can delete
        the file, and its former tags). Raises LeagueError for bots, unknown or already removed players.
        """

        status = _run_status(status)

        def work(s: Session) -> PlayerRow:
            for run in s.execute(select(Run).where(Run.name.in_(list(end_runs)))).scalars():
                run.status = status
            p = s.get(Player, int(player_id))
            if p is None:
                raise LeagueError(f"no player with id {player_id}")
            if p.kind != "snapshot":
                raise LeagueError(f"player {p.id} ({p.name}) is a bot; only snapshots can be removed")
            if p.removed:
                raise LeagueError(f"snapshot {p.id} ({p.name}) is already removed")
            before = _player_row(p)
            for t in list(p.tags):
                s.delete(t)
            p.removed = True
            p.removed_at = utcnow()
            return replace(before, removed=True)

        return self._unit(work)

