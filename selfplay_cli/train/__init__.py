"""Training a run: its settings (:mod:`.config`), the loop (:mod:`.loop`: learners play endless batched self-play
games, take snapshot moments into the league and resume from them), the learners side by side (:mod:`.team`),
curricula (:mod:`.curriculum`), the rating worker that plays each moment's gauntlet beside training
(:mod:`.evaluator`), the run's lock (:mod:`.lock`), and which runs still need a snapshot (:mod:`.needs`).
"""
