"""The revisions of the league's schema, one file each (see :mod:`selfplay_cli.league.migrations`)."""
