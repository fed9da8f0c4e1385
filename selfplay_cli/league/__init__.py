"""The league: storage only.

The database (:mod:`.db`, :mod:`.models`, migrations) holds the players (scripted players and snapshots,
:mod:`.roster`), runs, matches and the append-only game ledger (:mod:`.ledger`), the seed ranges pairs have played
(:mod:`.seeds`), snapshot blobs (:mod:`.blobs`) and the work queue (:mod:`.queue`), each a part of one
:class:`~.store.League` (``league.roster``, ``league.ledger``, ...); game variants are keyed by :mod:`.variants`. What
the ledger says of strength (ladders, pair records, forecasts) is :mod:`selfplay_cli.ratings`'.

The league imports no game: what it needs of one (the rules its results follow, the options that make a variant,
the player its ratings are anchored at) it looks up in the catalog :mod:`.games` is given.
"""
