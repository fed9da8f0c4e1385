"""Reports of the league that the CLI and the training loop share: a run's rating curves (:mod:`.plots`), the
score matrix of the best players with its Nash mixture and cycles (:mod:`.matrix`), as PNG files (matplotlib,
Agg, headless; :mod:`.png` writes them) or terminal renderings (:mod:`.terminal`, rich).

May import ``league`` and ``stats``; nothing here imports ``commands``. matplotlib is imported only when a PNG is
drawn.
"""
