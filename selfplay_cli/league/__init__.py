"""The league: storage, and the ratings derived from it.

The database (:mod:`.db`, :mod:`.models`) holds the players (scripted players and snapshots, :mod:`.roster`), runs,
matches and the append-only game ledger (:mod:`.ledger`), behind one :class:`~.store.League`; game variants are
keyed by :mod:`.variants`. From the ledger come the ladders and their Bradley-Terry ratings (:mod:`.ladder`), two
players' records (:mod:`.pairs`), and forecasts of matches not yet played (:mod:`.forecast`); :mod:`.results_csv`
rates any results file the same way. Resolving the names users type, which needs a game's seats, is rated play's
(:mod:`selfplay_cli.rated.names`).

The league imports no game: what it needs of one (the rules its results follow, the options that make a variant,
the player its ratings are anchored at) it looks up in the catalog :mod:`.games` is given.
"""
