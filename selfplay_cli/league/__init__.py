"""The league: storage only.

The database (:mod:`.db`; its errors and what a driver's failure means, :mod:`.failures`; what its URL names and
where a SQLite file may lie, :mod:`.url`; the home's layout, :mod:`.home`; :mod:`.models`, migrations) holds the
players (scripted players and snapshots, :mod:`.roster`), runs, matches and the append-only game ledger
(:mod:`.ledger`; the table ratings are fitted from, :mod:`.game_table`, derived from the games as :mod:`.derivation`
says), the seed ranges pairs have played (:mod:`.seeds`), snapshot blobs (:mod:`.blobs`) and the work queue
(:mod:`.queue`; its job and worker records, timings and limits, :mod:`.job_rows`), each a part of one
:class:`~.store.League` (``league.roster``, ``league.ledger``, ...); game variants are keyed by :mod:`.variants`. What
the ledger says of strength (ladders, pair records, forecasts) is :mod:`selfplay_cli.ratings`'.

The league imports no game: what it needs of one (the rules its results follow, the options that make a variant,
the player its ratings are anchored at) it looks up in the catalog :mod:`.games` is given.
"""
