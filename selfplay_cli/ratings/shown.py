"""Which variant of a game a view of the league shows when nobody says: the one a user asks for first (the views of
the CLI, ``marl league ladder``, ``matrix``, ``plot``, and the pages of ``marl serve`` all start from it)."""

from __future__ import annotations

from selfplay_cli.league.store import League
from selfplay_cli.league.variants import variant_key
from selfplay_cli.players.snapshots import run_options
from selfplay_cli.ratings.ladder import pick_env

__all__ = ["default_variant"]


def default_variant(league: League, env: str | None, run: str | None = None) -> tuple[str, str]:
    """The game and the variant (its key) shown without ``--env-option``: the run's own (``run``: the options its
    snapshots were made for), else the variant the game's newest run with rated games played (``marl train tennis``
    plays ``serve_mode=mixed``: its ladder is what a user asks for first), else the default one where it has games,
    else the one with the most. The game is ``env``, the run's, or the league's only one."""
    if run is not None:
        info = league.roster.get_run(run)
        env = env or (info.env if info is not None else None)
    env = pick_env(league, env)
    if run is not None and league.roster.get_run(run) is not None:
        return env, variant_key(env, run_options(league, run))
    played = league.ledger.variants(env)
    if len(played) <= 1:
        return env, next(iter(played), "")
    for r in reversed(league.roster.list_runs(env)):
        key = variant_key(env, run_options(league, r.name))
        if played.get(key):
            return env, key
    return env, "" if played.get("") else max(played, key=lambda k: (played[k], k))
