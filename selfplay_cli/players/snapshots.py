"""Snapshot files and their league rows: importing one, the game options a snapshot was made for, putting snapshots
in the league for other machines. Where this machine reads a snapshot from, and whether a file is the one its row
registered, is :mod:`selfplay_cli.players.files`'s.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ..errors import MarlError
from ..files import write_atomic
from ..league.store import League, LeagueIOError, PlayerRow, check_name
from ..league.variants import describe_variant, variant_key
from .files import check_legacy_file, snapshot_path, snapshot_relpath


def player_options(league: League, row: PlayerRow) -> dict[str, Any]:
    """The game options a player was made for, which its games are played under: a snapshot's, as its file's
    metadata records them (the header alone is read); none for a scripted player, which plays under any."""
    if row.is_bot:
        return {}
    from ..policies.snapshot_reader import read_meta

    return dict(read_meta(snapshot_path(league, row)).env_options or {})


def players_variant(league: League, env: str, rows: Iterable[PlayerRow], override: dict[str, Any] | None = None
                    ) -> str:
    """The variant (its key) the games among ``rows`` are filed in: the one each snapshot's options make, with
    ``override`` (a command's ``--env-option``) over them. Snapshots made for options that differ only in neutral
    ones (pong's frame stack) share a variant, though two of them cannot meet; snapshots of different variants are
    a :class:`MarlError` naming two of them. Scripted players play in any."""
    found: tuple[str, str] | None = None
    for row in rows:
        if row.is_bot:
            continue
        key = variant_key(env, {**player_options(league, row), **(override or {})})
        if found is not None and key != found[0]:
            raise MarlError(f"{found[1]} and {row.full_name} play different variants of {env} "
                            f"({describe_variant(found[0])}; {describe_variant(key)}): they are rated apart")
        found = (key, row.full_name)
    return found[0] if found is not None else variant_key(env, override)


def run_options(league: League, run: str) -> dict[str, Any]:
    """The game options a run's snapshots were made for: a trained run's ``[env_options]`` (its config), else (a run
    of imported files) its newest readable snapshot's metadata; none when neither says."""
    info = league.roster.get_run(run)
    if info is None:
        raise MarlError(f"no run named '{run}'")
    if isinstance((info.config or {}).get("env_options"), dict):
        return dict(info.config["env_options"])
    for p in reversed(league.roster.players(env=info.env, kind="snapshot")):
        if p.run == run:
            with contextlib.suppress(MarlError, OSError):
                return player_options(league, p)
    return {}


def import_snapshot(league: League, file: Path, run: str | None = None, name: str | None = None,
                    env: str | None = None) -> PlayerRow:
    """Validate ``file`` (format, game, spaces, weights against the network it describes, checksum), copy it into
    the league home atomically and register it (with its run, if new, in the same transaction). The same weights
    already in the league are refused.

    Names are checked before anything is created, so a refused import writes nothing anywhere: no folder, no file,
    no row. The game is ``env`` when given (a name the user typed), else the one the file names if this league
    already plays it (:func:`_league_game`) or it is known here; a module a file or a row names is never imported
    unless this machine names it.
    """
    from ..policies.snapshot_reader import read_snapshot

    file = Path(file)
    if league.home is None:
        raise MarlError("this league has no home directory for snapshot files: pass --home")
    snap = read_snapshot(file, expect_env=env if env is not None else _league_game(league, file))
    meta = snap.meta
    run = run or meta.run or "imported"
    name = name or meta.name
    if league.roster.get_run(run) is None:
        check_name("run name", run)  # a new run: a league name in full
    rel = snapshot_relpath(run, name)  # refuses names that are not league names (/, .., control characters)
    dest = league.home_path(*Path(rel).parts)  # and a run folder that is a symlink leading out of the home
    for p in league.roster.players(env=meta.env, kind="snapshot"):
        if p.meta.get("weights_sha256") == meta.weights_sha256:
            raise MarlError(f"{file}: these weights are already in the league as {p.full_name}")
    existing = league.roster.get_run(run)
    if existing is not None and existing.env != meta.env:
        raise MarlError(f"{file}: run '{run}' plays {existing.env}, the snapshot plays {meta.env}")
    if dest.exists():
        raise MarlError(f"{dest} already exists: choose another --name")
    if league.readonly:
        raise MarlError(f"league {league.home} is open read-only: cannot import into it")
    data = _file_bytes(file, snap.sha256)  # the bytes that were checked (the file may have changed since)
    made = [d for d in (dest.parent.parent, dest.parent) if not d.exists()]
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(dest, data)
    except BaseException as e:
        _remove_empty(made)
        if isinstance(e, OSError):
            raise LeagueIOError(f"cannot write {dest}: {e.strerror or e}") from None
        raise
    try:
        return league.roster.add_snapshot(env=meta.env, run=run, name=name, path=rel, sha256=snap.sha256,
                                          step=meta.step, episode=meta.episode, algo=meta.algo,
                                          meta={"weights_sha256": meta.weights_sha256, "imported_from": str(file)},
                                          run_config={"imported_from": str(file)})
    except BaseException:
        dest.unlink(missing_ok=True)
        _remove_empty(made)
        raise


def _league_game(league: League, file: Path) -> str | None:
    """The game ``file`` names when this league already plays it (a run of it exists), so a file of a game the
    league rates imports without ``--env``: a registered one, or a game of your own this machine names
    (``MARL_GAMES``; the league's row alone, which any member may have written, imports nothing:
    :func:`~selfplay_cli.envs.loading.get_env` refuses it). None for any other name, which
    :func:`~selfplay_cli.policies.snapshot_reader.read_snapshot` then only looks up among the games already known,
    never importing the module a file names."""
    from ..policies.snapshot_reader import read_meta

    named = read_meta(file).env
    return named if league.roster.list_runs(env=named) else None


def _file_bytes(file: Path, sha256: str) -> bytes:
    """The file's bytes, refused unless they are the ones that were validated (hash ``sha256``)."""
    import hashlib

    from ..policies.network import SnapshotError

    try:
        data = file.read_bytes()
    except OSError as e:
        raise SnapshotError(f"{file}: cannot read ({e.strerror or e})") from None
    if hashlib.sha256(data).hexdigest() != sha256:
        raise SnapshotError(f"{file}: the file changed while it was being imported")
    return data


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders an import created, innermost first, if they are still empty."""
    for d in reversed(folders):
        with contextlib.suppress(OSError):
            d.rmdir()


def share_snapshots(league: League, rows: Sequence[PlayerRow]) -> None:
    """Put the snapshot files of ``rows`` in the league (by their sha256) where it has them not yet, so a worker on
    any machine can fetch them; a :class:`MarlError` naming the first that cannot be (its file not here)."""
    report = league.blobs.ensure_blobs([r for r in rows if not r.is_bot], check_legacy=check_legacy_file)
    for name in (*report.missing, *report.refused):
        raise MarlError(f"{name}: {report.reasons.get(name, 'its file is not on this machine')}; workers elsewhere "
                        "could not play it")
