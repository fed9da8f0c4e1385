"""What the ledger says of strength: the ladder (:mod:`.ladder`: ratings fitted with their intervals, tiers, margins
and what a match would measure), pair records and payoffs (:mod:`.pairs`), the forecast of a match before it is
played (:mod:`.forecast`), the Nash mixture of a field (:mod:`.meta_nash`), the names users type turned into players
("best", "latest", teams: :mod:`.names`) and the ledger as a CSV (:mod:`.results_csv`). It reads the league and
does the maths in :mod:`selfplay_cli.stats`; it plays no game."""
