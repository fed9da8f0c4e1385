"""Rating maths, numpy only (no torch, no database): Elo arithmetic (:mod:`.elo`), head-to-head statistics
(:mod:`.match`), the GSPRT (:mod:`.sprt`), Bradley-Terry fits with priors, bootstrap intervals and ranks
(:mod:`.bradley_terry`)."""
