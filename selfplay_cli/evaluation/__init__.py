"""Rated play: the games that join play (:mod:`selfplay_cli.play`) and the league, stored and rated.

Names users type become league players (:mod:`selfplay_cli.ratings.names`) and those become policies
(:mod:`selfplay_cli.players`); :mod:`.match` plays fair rounds between two of them (fixed, or until SPRT decides) and
files the games, :mod:`.match_jobs` says which matches ``marl match A B`` plays, :mod:`.tournament` plays a field's
missing games; :mod:`.gauntlet` rates every new snapshot of a training run against its history (whom it meets:
:mod:`.gauntlet_plan`), :mod:`.playoff` settles a run's best, :mod:`.gate` asks whether a candidate is stronger than a
baseline by a margin; :mod:`.lineup` seats a policy for a recording, :mod:`.roles` says who may sit where in a game of
roles, :mod:`.seeds` gives every pair's games seeds no other command plays.

The same games on the league's work queue: a job's spec (:mod:`.job_spec`), its kinds (:mod:`.games_jobs`,
:mod:`.gauntlet_jobs`), playing a leased job (:mod:`.jobs`), a command's queued match (:mod:`.queued`) and ``marl
worker``'s loop (:mod:`.worker`). Where a training run's gauntlets are played, behind one interface:
:mod:`.executors`.
"""
