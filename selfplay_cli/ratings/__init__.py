"""What the ledger says of strength: the ladder of a league (:mod:`.ladder`), fitted from a table of games
(:mod:`.fit`: ratings with their intervals, ranks, tiers and margins), its rows (:mod:`.ladder_rows`: with what a
match would measure) and the verdicts and rows shown with it (:mod:`.verdicts`), pair records and payoffs
(:mod:`.pairs`), the forecast of a match before it is played (:mod:`.forecast`), the Nash mixture of a field
(:mod:`.meta_nash`), the names users type turned into players ("best", "latest", teams: :mod:`.names`) and the ledger
as a CSV (:mod:`.results_csv`). It reads the league and does the maths in :mod:`selfplay_cli.stats`; it plays no
game."""
