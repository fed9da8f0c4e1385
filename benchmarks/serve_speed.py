"""How fast the pages of ``marl serve`` load over a large league: 500 snapshots of one run and 100,000 rated games
(written in bulk through the league's own API), the app served in this process (Starlette's test client, no network).

Each page is loaded once cold (the server's first sight of it: the ladder fitted, with its 200 bootstrap replicates)
and then 5 times (the median: the fit kept until the league changes), printing ``page NAME: X ms (target < 1000
ms)`` for the warm median and the cold load beside it.

    python benchmarks/serve_speed.py
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SNAPSHOTS, GAMES, PER_MATCH = 500, 100_000, 1_000


def build(home: Path) -> dict[str, int]:
    from selfplay_cli.league.store import League
    from selfplay_cli.results import GameResult

    rng = np.random.default_rng(0)
    with League.open(home) as lg:
        lg.roster.ensure_bots("pong", ["random", "cpu"])
        items = [dict(env="pong", run="bench", name=f"s{k}", path=f"snapshots/bench/s{k}.safetensors",
                      sha256=f"{k:064x}", step=10_000 * k, algo="ppo") for k in range(SNAPSHOTS)]
        lg.roster.add_snapshots(items, run_config={})
        ids = [p.id for p in lg.roster.players("pong")]
        strength = {pid: s for pid, s in zip(ids, np.linspace(-400, 600, len(ids)), strict=True)}
        for m in range(GAMES // PER_MATCH):
            a = rng.choice(ids, PER_MATCH)
            b = rng.choice(ids, PER_MATCH)
            b = np.where(a == b, ids[0] if a[0] != ids[0] else ids[1], b)
            games = []
            for k, (x, y) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
                p = 1.0 / (1.0 + 10 ** ((strength[y] - strength[x]) / 400))
                s = float(rng.random() < p)
                games.append(GameResult(env="pong", players=(x, y), seed=m * PER_MATCH + k,
                                        scores=(21 * s, 21 * (1 - s)), outcome=(s, 1 - s), length=100,
                                        truncated=False))
            params = {"sprt": {"elo0": 0.0, "elo1": 10.0, "alpha": 0.05, "beta": 0.05}} if m % 10 == 0 else {}
            lg.ledger.record_games(lg.ledger.create_match("pong", "match", params), games)
        return {"player": ids[-1], "other": ids[0]}


def main() -> None:
    from starlette.testclient import TestClient

    from selfplay_cli.serve.app import create_app
    from selfplay_cli.serve.queries import Reader

    with tempfile.TemporaryDirectory(prefix="marl-serve-speed-") as tmp:
        home = Path(tmp) / "league"
        t = time.perf_counter()
        ids = build(home)
        print(f"league: {SNAPSHOTS} snapshots, {GAMES:,} games, written in {time.perf_counter() - t:.1f} s")
        reader = Reader(home, None)
        pages = {"games": "/", "ladder": "/ladder", "ladder sorted by Elo": "/ladder?sort=elo&order=asc",
                 "ladder of a run": "/ladder?run=bench&q=s4", "matrix": "/matrix", "curves": "/curves?run=bench",
                 "player": f"/player/{ids['player']}", "prediction": f"/player/{ids['player']}?vs={ids['other']}",
                 "matches": "/matches", "queue": "/queue", "replays": "/replays"}
        try:
            with TestClient(create_app(reader, str(home)), raise_server_exceptions=True) as client:
                for name, url in pages.items():
                    t = time.perf_counter()
                    r = client.get(url)
                    cold = time.perf_counter() - t
                    assert r.status_code == 200, (url, r.status_code)
                    times = []
                    for _ in range(5):
                        t = time.perf_counter()
                        assert client.get(url).status_code == 200
                        times.append(time.perf_counter() - t)
                    warm = 1000 * statistics.median(times)
                    print(f"page {name}: {warm:.0f} ms (target < 1000 ms; {'met' if warm < 1000 else 'NOT met'}); "
                          f"first load {1000 * cold:.0f} ms")
        finally:
            reader.close()


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from results_file import recorded

    with recorded():
        main()
