"""Snapshot files entering the league: copied under the home, checked, registered."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ..errors import MarlError
from ..league.store import League, PlayerRow


def snapshot_relpath(run: str, name: str) -> str:
    return f"snapshots/{run}/{name}.safetensors"


def import_snapshot(league: League, file: Path, run: str | None = None, name: str | None = None,
                    env: str | None = None) -> PlayerRow:
    """Validate ``file`` (format, game, spaces, weights checksum), copy it into the league home atomically and
    register it. The same weights already in the league are refused."""
    from ..policies.snapshot import file_sha256, import_check

    file = Path(file)
    meta = import_check(file, env=env)
    run = run or meta.run or "imported"
    name = name or meta.name
    for p in league.players(env=meta.env, kind="snapshot"):
        if p.meta.get("weights_sha256") == meta.weights_sha256:
            raise MarlError(f"{file}: these weights are already in the league as {p.full_name}")
    existing = league.get_run(run)
    if existing is None:
        league.create_run(run, meta.env, {"imported_from": str(file)}, algo=meta.algo, status="finished")
    elif existing.env != meta.env:
        raise MarlError(f"{file}: run '{run}' plays {existing.env}, the snapshot plays {meta.env}")
    if league.home is None:
        raise MarlError("this league has no home directory for snapshot files: pass --home")
    rel = snapshot_relpath(run, name)
    dest = league.home / rel
    if dest.exists():
        raise MarlError(f"{dest} already exists: choose another --name")
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(dest.name + f".tmp-{os.getpid()}")
    shutil.copyfile(file, tmp)
    os.replace(tmp, dest)
    try:
        return league.add_snapshot(env=meta.env, run=run, name=name, path=rel, sha256=file_sha256(dest),
                                   step=meta.step, episode=meta.episode, algo=meta.algo,
                                   meta={"weights_sha256": meta.weights_sha256, "imported_from": str(file)})
    except Exception:
        dest.unlink(missing_ok=True)
        raise
