"""``marl serve``: read-only web pages of a league (ladder, score matrix, rating curves, players, matches and gates,
the work queue, replays), rendered on the server from Jinja2 templates with every value escaped, over a league opened
so that it cannot write (:mod:`.queries`), by a small Starlette app (:mod:`.app`) with charts as inline SVG
(:mod:`.charts`). Needs the ``serve`` extra: ``pip install -e ".[serve]"``."""
