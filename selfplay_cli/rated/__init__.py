"""Rated play: league players as policies, paired matches, SPRT, gates and tournaments.

This room joins the league (ledger, ratings) with the arena (games) and the policies; commands call it.
"""
