"""Rating maths, numpy and scipy only (no torch, no database): Elo arithmetic (:mod:`.elo`), head-to-head
statistics (:mod:`.match`), the GSPRT (:mod:`.sprt`), Bradley-Terry fits under BayesElo's prior
(:mod:`.bradley_terry`), their intervals and ranks (:mod:`.intervals`), the Nash equilibrium of a meta-game
(:mod:`.nash`), significant 3-cycles (:mod:`.cycles`) and what a ladder predicts of a match not yet played
(:mod:`.predict`, over one pair's belief and the match it predicts: :mod:`.belief`)."""
