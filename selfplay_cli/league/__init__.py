"""The league: storage, and what is derived from it.

The database (:mod:`.db`, :mod:`.models`) holds the players (scripted players and snapshots, :mod:`.roster`), runs,
matches and the append-only game ledger (:mod:`.ledger`), behind one :class:`~.store.League`; names users type
are resolved by :mod:`.names`, game variants keyed by :mod:`.variants`. From the ledger come the ladders and their
Bradley-Terry ratings (:mod:`.ladder`), two players' records (:mod:`.pairs`), and forecasts of matches not yet
played (:mod:`.forecast`); :mod:`.results_csv` rates any results file the same way. Training's opponent sampling
(:mod:`.matchmaking`) lives here too for now (issue 31 moves it to ``train/``).
"""
