"""Issue 49, section 4: the same work queued (or played) twice stores every game once. A second identical tournament
joins the first's games on their way instead of queuing them again, and says so; one that asks for more games plays
new seeds after them; two submitters at the same moment end with one set of games (the pairs' seed ranges are unique
in the database); a match or a gate started while a pair's games are queued plays after them or joins them; the same
gauntlet queued twice stores its games once. On SQLite and on a real PostgreSQL."""

from __future__ import annotations

import json
import threading
from collections import Counter

import pytest
from cli_helpers import run, run_json
from sqlalchemy import select

from selfplay_cli.evaluation.gauntlet_jobs import gauntlet_job
from selfplay_cli.evaluation.match_jobs import MatchJob
from selfplay_cli.evaluation.tournament import TournamentPlan
from selfplay_cli.evaluation.worker import WorkerOptions, run_worker
from selfplay_cli.league.models import Game, GameSeat, SeedRange
from selfplay_cli.league.store import League

SHORT = ("--env-option", "points_to_win=1")
FIELD = ("league", "tournament", "cpu", "random", "--env", "pong", *SHORT)


@pytest.fixture
def where(db_url, tmp_path, monkeypatch):
    """The league's options for the CLI (its database, its home) and an open :class:`League` on it."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.delenv("MARL_DB", raising=False)
    monkeypatch.delenv("MARL_HOME", raising=False)
    home = tmp_path / "h"
    opts = ("--db", db_url, "--home", str(home))
    lg = League(db_url, home=home)
    lg.roster.ensure_bots("pong", ["random", "cpu"])
    yield opts, lg
    lg.close()


def _games(league) -> list[tuple[int, tuple[int, ...]]]:
    """Every stored game as (seed, the player on each seat)."""
    seats: dict[int, dict[int, int]] = {}
    seeds: dict[int, int] = {}
    with league.session(readonly=True) as s:
        for gid, seed, seat, pid in s.execute(select(Game.id, Game.seed, GameSeat.seat, GameSeat.player_id)
                                              .join(GameSeat, GameSeat.game_id == Game.id)):
            seats.setdefault(gid, {})[seat] = pid
            seeds[gid] = seed
    return [(seeds[g], tuple(seats[g][k] for k in sorted(seats[g]))) for g in sorted(seeds)]


def _once(league) -> list[tuple[int, tuple[int, ...]]]:
    """The stored games, asserting that none is stored twice (the same players on the same seats and seed)."""
    games = _games(league)
    twice = [g for g, n in Counter(games).items() if n > 1]
    assert twice == [], f"{len(twice)} games stored twice, e.g. {twice[:3]}"
    return games


def _work(league) -> None:
    report = run_worker(league, WorkerOptions(until_empty=True, poll=0.01))
    assert report.failed == 0


def _plan(league, games: int) -> TournamentPlan:
    players = {p.id: p for p in league.roster.players("pong") if p.name in ("cpu", "random")}
    return TournamentPlan.of(league, "pong", players, None, games, {"points_to_win": 1})


def test_the_same_tournament_queued_twice_joins_the_first_and_stores_each_game_once(where, capsys):
    """The issue's reproduction: `--queue --no-wait` typed twice, then a worker. The second queues nothing, says it
    joined the first's batch (in words, and in --json), and the ledger holds the 20 games of one tournament, each
    once. Typed a third time after the worker, nothing is queued: every pair has its games."""
    opts, league = where
    code, out, err = run(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    assert code == 0, err
    assert "queued 20 games of 1 pairs as batch tournament:pong:" in out
    (first,) = [b for b, _ in league.queue.batches()]
    code, out, err = run(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    assert code == 0, err
    assert out.startswith(f"nothing queued twice: joined 20 games already queued in batch {first}"), out
    again = run_json(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    jobs = [j.id for j in league.queue.jobs(batch=first)]
    assert again == {"batch": None, "jobs": 0, "games": 0, "pairs": 0, "playing": [],
                     "joined": [{"batch": first, "games": 20, "jobs": jobs}]}
    assert [b for b, _ in league.queue.batches()] == [first] and len(league.queue.jobs()) == len(jobs)
    _work(league)
    games = _once(league)
    assert len(games) == 20 and sorted({s for s, _ in games}) == list(range(10))
    code, out, err = run(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    assert code == 0 and out.startswith("every pair has its games already: nothing queued"), out
    assert len(league.queue.jobs()) == len(jobs)


def test_a_second_tournament_asking_more_games_queues_only_the_rest_on_new_seeds(where, capsys):
    """20 games queued, then 30 asked for before any is played: 10 more are queued, after the first's seeds."""
    opts, league = where
    run_json(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    more = run_json(capsys, *FIELD, "--games-per-pair", "30", "--queue", "--no-wait", *opts)
    assert (more["games"], more["pairs"]) == (10, 1) and [j["games"] for j in more["joined"]] == [20]
    (job,) = league.queue.jobs(batch=more["batch"])
    assert (job.spec["first_seed"], job.spec["rounds"]) == (10, 5)
    _work(league)
    games = _once(league)
    assert len(games) == 30 and sorted({s for s, _ in games}) == list(range(15))


def _twice_at_once(db_url: str, home, work) -> list:
    """``work(league, looked)`` in two threads at once, each on its own connection to the league; ``looked`` is the
    barrier both reach after their first look at the pair (so each looks before either writes). Their results."""
    looked = threading.Barrier(2, timeout=120)
    out, errors = [], []

    def one() -> None:
        lg = League(db_url, home=home)
        try:
            out.append(work(lg, looked.wait))
        except Exception as exc:
            errors.append(exc)
        finally:
            lg.close()

    threads = [threading.Thread(target=one) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert errors == []
    return out


def test_two_submitters_at_the_same_moment_end_with_one_set_of_games(where, db_url):
    """Two users queue the same tournament at the same moment (two connections; both look at the pair before either
    writes): the database keeps one's jobs, the other looks again and joins them. One set of games is stored."""
    _, league = where
    out = _twice_at_once(db_url, league.home, lambda lg, looked: _plan(lg, 20).enqueue(lg, None, "cpu", looked=looked))
    queued = [s for s in out if s.batch is not None]
    joined = [s for s in out if s.batch is None]
    assert len(queued) == len(joined) == 1, out
    assert queued[0].games == 20 and joined[0].joined == {queued[0].batch: 20} and joined[0].jobs == 0
    assert len(league.queue.jobs()) == queued[0].jobs
    _work(league)
    assert len(_once(league)) == 20


def test_two_commands_playing_the_same_tournament_here_at_once_play_it_once(where, db_url):
    """The same at once, each to play the games itself (no --queue): one takes the pair's seeds and plays them; the
    other finds them taken by the first (being played) and plays nothing."""
    _, league = where

    def take(lg: League, looked) -> object:
        plan = _plan(lg, 20)
        sub = plan.take(lg, None, "cpu", looked=looked)
        plan.play_taken(lg, sub, 256, "cpu")
        return sub

    taken = _twice_at_once(db_url, league.home, take)
    assert sorted(len(s.here) for s in taken) == [0, 1]
    (idle,) = [s for s in taken if not s.here]
    assert sum(idle.playing.values()) == 20 and idle.games == 0
    assert len(_once(league)) == 20


def test_a_tournament_played_here_twice_plays_nothing_the_second_time(where, capsys):
    opts, league = where
    code, out, err = run(capsys, *FIELD, "--games-per-pair", "20", *opts)
    assert code == 0 and "1 pairs needed games, 20 played" in out, err
    code, out, err = run(capsys, *FIELD, "--games-per-pair", "20", *opts)
    assert code == 0 and "every pair has its 20 games already: nothing played" in out, err
    assert len(_once(league)) == 20


def test_a_tournament_played_here_joins_the_same_games_queued_and_plays_them(where, capsys):
    """Queued with --no-wait, then typed without --queue, no worker attached: the second joins the queued jobs and
    plays them itself (it queues or plays nothing twice), then prints the ladder."""
    opts, league = where
    run_json(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    (first,) = [b for b, _ in league.queue.batches()]
    code, out, err = run(capsys, *FIELD, "--games-per-pair", "20", *opts)
    assert code == 0, err
    assert f"joined 20 games already queued in batch {first}" in err
    assert "1 pairs needed games, 0 played; 20 on their way already were joined" in out
    assert {j.state for j in league.queue.jobs()} == {"done"} and len(_once(league)) == 20


def test_a_match_started_while_the_pairs_games_are_queued_plays_new_seeds_after_them(where, capsys):
    """`marl match` adds games (it joins nothing): started while a tournament's games of the pair are queued, it
    starts after their seeds and says so; `--seed` into those seeds is refused in one line."""
    opts, league = where
    run_json(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    (first,) = [b for b, _ in league.queue.batches()]
    match = ("match", "cpu", "random", "--env", "pong", *SHORT, "--games", "10", *opts)
    code, out, err = run(capsys, *match, "--seed", "4")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert f"--seed 4: seeds 0-9 of these players are queued already, in batch {first}" in err
    code, out, err = run(capsys, *match)
    assert code == 0, err
    assert f"20 games already queued in batch {first} for these players: this match plays new seeds, from 10" in err
    report = run_json(capsys, *match)  # the next after it, and after the queued ones
    assert report["first_seed"] == 15 and report["after_queued"] == [{"batch": first, "games": 20}]
    _work(league)
    games = _once(league)
    assert len(games) == 40 and sorted({s for s, _ in games}) == list(range(20))


def test_two_matches_taking_seeds_at_the_same_moment_get_seeds_of_their_own(where, db_url):
    """Matches add games: two started at the same moment both play, on seeds that do not meet."""
    _, league = where
    cpu, rnd = (league.roster.find_players(n, "pong")[0] for n in ("cpu", "random"))
    job = MatchJob((cpu,), rnd)
    taken = _twice_at_once(db_url, league.home,
                           lambda lg, looked: job.take_here(lg, 10, None, {"points_to_win": 1}, "cpu", looked=looked))
    assert sorted(t.first_seed for t in taken) == [0, 5] and all(t.rounds == 5 for t in taken)
    with league.session(readonly=True) as s:
        assert sorted(s.execute(select(SeedRange.seq, SeedRange.first_seed))) == [(1, 0), (2, 5)]


def test_a_gate_joins_the_pairs_games_on_their_way_instead_of_playing_them_again(where, capsys):
    opts, league = where
    run_json(capsys, *FIELD, "--games-per-pair", "20", "--queue", "--no-wait", *opts)
    code, out, err = run(capsys, "elo", "gate", "cpu", "--vs", "random", "--env", "pong", *SHORT, "--games", "20",
                         "--queue", "--json", *opts)
    assert code in (0, 1), err
    verdict = json.loads(out)
    assert (verdict["games"], verdict["stored_games"], verdict["played_games"]) == (20, 0, 20)
    assert {j.state for j in league.queue.jobs()} == {"done"} and len(league.queue.batches()) == 1
    assert len(_once(league)) == 20


def test_the_same_gauntlet_queued_twice_stores_its_games_once(rated_league):
    """A gauntlet's games are stored under keys of their matchups: queued in two batches and played twice, they are
    stored once."""
    league, snap = rated_league
    for batch in ("run:a", "run:b"):
        league.queue.enqueue(batch, [gauntlet_job(league, [snap.id], first_seed=0, games=2, older=0)])
    report = run_worker(league, WorkerOptions(until_empty=True, poll=0.01))
    assert (report.done, report.failed) == (2, 0)
    games = _once(league)
    assert len(games) == 6  # s0 against random and cpu, 2 games each; the two bots against each other
