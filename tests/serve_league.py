"""A small real league for the pages of ``marl serve``: three snapshots of one run (each grown from the one before),
the scripted players, a tournament and an SPRT match played by ``marl``, and one recorded mp4."""

from __future__ import annotations

import shutil
from pathlib import Path

from selfplay_cli.cli import main

OPTION = ["--env", "pong", "--env-option", "points_to_win=1"]


def build_real_league(home: Path, work: Path) -> None:
    """Fill ``home`` with the league described above (a minute or so of real games)."""
    from selfplay_cli.league.store import League
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    folder = home / "snapshots" / "demo"
    folder.mkdir(parents=True)
    arch = Arch(hidden=(16,))
    items = []
    for k in range(3):
        meta = SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="demo", name=f"s{k}",
                            algo="ppo", step=1000 * k, env_options={"points_to_win": 1})
        path = folder / f"s{k}.safetensors"
        save_snapshot(path, build_network((8, 6), 3, arch, seed=k + 1), meta)
        items.append(path)
    with League.open(home) as lg:
        parent = None
        for k, path in enumerate(items):
            row = lg.roster.add_snapshot(env="pong", run="demo", name=f"s{k}", path=str(path.relative_to(home)),
                                         step=1000 * k, algo="ppo", parent_id=parent,
                                         meta={"env_options": {"points_to_win": 1}},
                                         run_config={"env_options": {"points_to_win": 1}} if k == 0 else None)
            parent = row.id
        lg.roster.ensure_bots("pong", ["random", "cpu"])
    base = ["--home", str(home), "-q"]
    assert main(["league", "tournament", "cpu", "random", "--run", "demo", *OPTION, "--games-per-pair", "8",
                 "--parallel", "64", *base]) == 0
    assert main(["match", "demo/s2", "random", *OPTION, "--sprt", "--elo0", "0", "--elo1", "100", "--games", "40",
                 *base]) in (0, 1, 3)
    assert main(["record", "--ckpt", "demo/s2", "--vs", "cpu", *OPTION, "--seconds", "2", *base]) == 0
    shutil.rmtree(work, ignore_errors=True)
