"""The league: storage, and the ratings derived from it.

The database (:mod:`.db`, :mod:`.models`) holds the players (scripted players and snapshots, :mod:`.roster`), runs,
matches and the append-only game ledger (:mod:`.ledger`), behind one :class:`~.store.League`; game variants are
keyed by :mod:`.variants`. From the ledger come the ladders and their Bradley-Terry ratings (:mod:`.ladder`), two
players' records (:mod:`.pairs`), and forecasts of matches not yet played (:mod:`.forecast`); :mod:`.results_csv`
rates any results file the same way. Resolving the names users type, which needs a game's seats, is rated play's
(:mod:`selfplay_cli.rated.names`).

Three readings still ask the game registry what a game declares, by a lazy import: the rules its results follow
(:func:`.ledger.rules_for_env`), the options that make a variant (:func:`.variants.variant_key`) and the player its
ratings are anchored at (:func:`.ladder.declared_anchor`).
"""
