"""Training a run: the trainer (:mod:`.loop`) and the parts it composes.

- :mod:`.settings`: a run's settings as `marl train` resolves them (defaults, the game's own, a preset, a config
  file, the options typed; a resumed run's saved configuration); :mod:`.config`: the one dataclass that holds them,
  checked, saved with the run; :mod:`.bounds`: what they must keep within beyond their types (the ranges of its
  numbers, this machine's memory).
- :mod:`.learners`: the run's learners as its settings make them (their names, the seat spaces they learn, built).
- :mod:`.loop`: the :class:`~.loop.Trainer`: the budget, the clock, metrics, and the loop that steps the games,
  takes snapshot moments and collects their ratings; :mod:`.run_ratings`: what the ledger says of the run's ratings
  (its rating games, its snapshots' records, its best, its plot).
- :mod:`.state`: the run state and its snapshot moments (files, rows and state written as one unit; the resume).
- :mod:`.opponents`: who the learners play in the opponent seats, over :mod:`.matchmaking` (self / latest / uniform
  / PFSP and scripted players) and :mod:`.win_rates` (the decayed win-rate book PFSP reads).
- :mod:`.rollouts`: stepping the self-play games and feeding the learners, with curricula (:mod:`.curriculum`)
  and a teacher; the learners side by side (:mod:`.team`).
- :mod:`.progress`: what a run says of itself: its standing, its snapshots' records, its report.
- each moment's gauntlet is handed to a rating executor (:mod:`selfplay_cli.evaluation.executors`: a worker process
  beside training, the league's queue workers, Ray actors).
- :mod:`.lock`: one process per run; :mod:`.needs`: which runs still need a snapshot.
"""
