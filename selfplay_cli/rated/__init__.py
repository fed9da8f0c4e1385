"""Rated play: evaluation that joins the arena (games) with the league (ledger, ratings).

Names users type become league players (:mod:`.names`, teams included) and those become policies; :mod:`.match`
plays fair rounds between two of them (fixed, or until SPRT decides) and files the games, :mod:`.match_jobs` says
which matches ``marl match A B`` plays, :mod:`.tournament` plays a field's missing games; :mod:`.gauntlet` rates
every new snapshot of a training run against its history, :mod:`.playoff` settles a run's best, :mod:`.gate` asks
whether a candidate is stronger than a baseline by a margin; :mod:`.lineup` seats a policy for a recording,
:mod:`.roles` says who may sit where in a game of roles, :mod:`.snapshots` files and checks snapshot files.
Commands call it; it imports arena, league, stats, policies and the game registry.
"""
