"""Ratings of any results file: ``player_a,player_b,result`` lines, fitted like the league's ladder."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from selfplay_cli.league.store import LeagueError
from selfplay_cli.ratings.fit import fit_table
from selfplay_cli.ratings.ladder_rows import LadderRow
from selfplay_cli.stats.bradley_terry import DEFAULT_PRIOR

__all__ = ["CSV_HEADER", "fit_csv", "read_results_csv"]

CSV_HEADER = ("player_a", "player_b", "result")
"""The header a results CSV must have (whitespace around the names tolerated)."""


def _parse_result(text: str) -> float | None:
    t = text.strip()
    if t == "1/2":
        return 0.5
    try:
        v = float(t)
    except ValueError:
        return None
    return v if v in (0.0, 0.5, 1.0) else None


def read_results_csv(path: str | Path) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Read a results file ``player_a,player_b,result`` (result: A's points, ``1``, ``0.5`` or ``0``).

    The first non-blank, non-comment line must be exactly the header (spaces around names tolerated);
    blank lines and lines starting with ``#`` are skipped; fields may be quoted (CSV rules).

    Returns:
        ``(names, a, b, score_a)``: names in order of first appearance, the index arrays of each game's
        players and A's points.

    Raises:
        LeagueError: ``"<path>:<line>: <problem>"`` for a bad header, a wrong number of fields, an empty
            name, a player against itself or a bad result; also for an unreadable or empty file.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise LeagueError(f"cannot read {path}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise LeagueError(f"cannot read {path}: not UTF-8 text") from exc
    index: dict[str, int] = {}
    a: list[int] = []
    b: list[int] = []
    s: list[float] = []
    header_seen = False
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        try:
            fields = [f.strip() for f in next(csv.reader([stripped], skipinitialspace=True))]
        except csv.Error as exc:
            raise LeagueError(f"{path}:{lineno}: malformed CSV line ({exc})") from exc
        if not header_seen:
            if tuple(fields) != CSV_HEADER:
                raise LeagueError(f"{path}:{lineno}: bad header {stripped!r}: expected {','.join(CSV_HEADER)}")
            header_seen = True
            continue
        if len(fields) != 3:
            raise LeagueError(f"{path}:{lineno}: expected 3 fields (player_a,player_b,result), got {len(fields)}")
        pa, pb, res = fields
        if not pa or not pb:
            raise LeagueError(f"{path}:{lineno}: empty player name")
        if pa == pb:
            raise LeagueError(f"{path}:{lineno}: '{pa}' cannot play against itself")
        value = _parse_result(res)
        if value is None:
            raise LeagueError(f"{path}:{lineno}: bad result {res!r}: expected 1, 0.5 or 0 (player_a's points)")
        a.append(index.setdefault(pa, len(index)))
        b.append(index.setdefault(pb, len(index)))
        s.append(value)
    if not header_seen:
        raise LeagueError(f"{path}: empty file (expected the header {','.join(CSV_HEADER)} and one game a line)")
    if not a:
        raise LeagueError(f"{path}: no games after the header")
    return (list(index), np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64),
            np.asarray(s, dtype=np.float64))


def fit_csv(
    path: str | Path,
    anchor: str | None = None,
    anchor_rating: float = 1000.0,
    bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    *,
    prior: float = DEFAULT_PRIOR,
) -> list[LadderRow]:
    """Ladder of a results CSV (:func:`read_results_csv`); the default anchor is the file's first player.

    ``prior``: BayesElo's prior in virtual draws (0 = maximum likelihood). Rows have kind ``"player"`` and no
    id / step / run / bot records.
    """
    names, a, b, s = read_results_csv(path)
    return fit_table(names, a, b, s, anchor=names[0] if anchor is None else anchor, anchor_rating=anchor_rating,
                     bootstrap=bootstrap, confidence=confidence, seed=seed, prior=prior)
