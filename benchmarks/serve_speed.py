"""How fast the pages of ``marl serve`` load over a large league: 500 snapshots of one run and 100,000 rated games
(written in bulk through the league's own API), the app served in this process (Starlette's test client, no network).

The app starts its background fit (:class:`~selfplay_cli.serve.fits.FitCache`: the ladder with its 200 bootstrap
replicates, the matrix's ladder, the forecaster) at once; each page is loaded while that first fit runs (it must
answer at once, with its notice), then the fit is waited for (``first fit in the background: X s``), then each page
is loaded once cold (the server's first sight of it after the fit) and 5 times more, printing ``page NAME: X ms
(target < 1000 ms)`` for the median of the 5 with the first load and the load during the fit beside it.

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


def _load(client, url: str) -> tuple[float, str]:
    t = time.perf_counter()
    r = client.get(url)
    took = time.perf_counter() - t
    assert r.status_code == 200, (url, r.status_code, r.text[:300])
    return took, r.text


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
                 "ladder of a run": "/ladder?run=bench&q=s4", "matrix": "/matrix", "matrix top 20": "/matrix?top=20",
                 "curves": "/curves?run=bench", "player": f"/player/{ids['player']}",
                 "prediction": f"/player/{ids['player']}?vs={ids['other']}", "matches": "/matches",
                 "queue": "/queue", "replays": "/replays"}
        fitted_pages = {"ladder", "ladder sorted by Elo", "ladder of a run", "matrix", "matrix top 20", "curves",
                        "player", "prediction"}
        try:
            app = create_app(reader, str(home))
            fits = app.state.fits
            with TestClient(app, raise_server_exceptions=True) as client:
                started = time.perf_counter()
                during: dict[str, float] = {}
                for name, url in pages.items():  # while the first fit runs: at once, the notice on fitted pages
                    took, text = _load(client, url)
                    during[name] = took
                    if name in fitted_pages and client.get("/health").json()["fitted"] == []:
                        assert "fitting the ratings of" in text, name
                print(f"pages while the first fit runs: slowest {1000 * max(during.values()):.0f} ms "
                      f"({max(during, key=during.__getitem__)}); each showed its notice")
                assert fits.wait(1800), "the first fit did not finish in 30 minutes"
                health = client.get("/health").json()
                assert not health["errors"], health["errors"]
                print(f"first fit in the background: {time.perf_counter() - started:.1f} s after the app started "
                      f"(the fit itself: {health['fitted'][0]['seconds']:.1f} s, {health['fitted'][0]['games']:,} "
                      "games)")
                for name, url in pages.items():
                    cold, text = _load(client, url)
                    if name in fitted_pages:
                        assert "ratings as of " in text, name
                    warm = 1000 * statistics.median(_load(client, url)[0] for _ in range(5))
                    print(f"page {name}: {warm:.0f} ms (target < 1000 ms; {'met' if warm < 1000 else 'NOT met'}); "
                          f"first load {1000 * cold:.0f} ms; during the first fit {1000 * during[name]:.0f} ms")
        finally:
            reader.close()


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from results_file import recorded

    with recorded():
        main()
