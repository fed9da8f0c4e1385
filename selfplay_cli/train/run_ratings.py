"""What the ledger says of a training run's ratings (:class:`RunRatings`): the rating games its gauntlets stored,
its snapshots that another run's copies answer for, its ladder, each new snapshot's record, its best, and its
rating curves. The trainer (:mod:`.loop`) reads them for its progress and its report; nothing here plays a game.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..envs import EnvSpec
from ..errors import MarlError
from ..league.game_table import KIND_CODES
from ..league.store import League, PlayerRow
from ..ratings.ladder_rows import LadderRow
from ..results import COOPERATIVE
from .config import TrainConfig
from .progress import SnapshotRecord


class RunRatings:
    """The ledger's view of one run's ratings, in its game's ``variant`` (the run's own), its scripted players by
    name (``bot_ids``) and its folder (``run_dir``, where its plot goes). Every figure is read from the ledger when
    asked for: the ledger, not the run, holds what every session's gauntlets stored."""

    def __init__(self, league: League, cfg: TrainConfig, spec: EnvSpec, variant: str, bot_ids: dict[str, int],
                 run_dir: Path) -> None:
        self.league, self.cfg, self.spec = league, cfg, spec
        self.variant, self.bot_ids, self.run_dir = variant, bot_ids, run_dir

    def rating_games(self) -> int:
        """Games the run's gauntlets have stored in the ledger, every session's: the ledger, not a count kept in
        the run state, because a gauntlet that finished after the last snapshot moment of a killed session (or was
        cut short in it: its finished matchups are stored, and not played again on resume) is in the ledger only.
        A game counts once, a cooperative comparison as its two episodes."""
        if not self.cfg.eval_games:
            return 0
        run = self.cfg.run
        ids = [p.id for p in self.league.roster.players(env=self.spec.name, kind="snapshot", include_removed=True)
               if p.run == run]
        table = self.league.ledger.games(self.spec.name, players=ids, any_seat=True, variant=self.variant, pooled=False)
        gauntlets = []
        for match_id in np.unique(table.match_id).tolist():
            kind, params = self.league.ledger.match_info(match_id)
            if kind == "eval" and params.get("gauntlet"):
                gauntlets.append(match_id)
        mine = table.select(np.isin(table.match_id, gauntlets))
        coop = mine.kind == KIND_CODES[COOPERATIVE]
        played = int(np.unique(mine.game_id[~coop]).size + 2 * np.unique(mine.game_id[coop]).size)
        if ids:  # and the games its first moment had the scripted players play each other (keyed under it)
            bots = {p.full_name for p in self.league.roster.players(env=self.spec.name,
                                                                    kind="bot")}  # (as the match names)
            for _, params in self.league.ledger.keyed_matches(f"gauntlet/{min(ids)}/").values():
                if params.get("a") in bots and params.get("b") in bots:
                    played += sum(int(x) for x in params.get("record", [0, 0, 0])[:3])
        return played

    def same_weights(self) -> dict[str, str]:
        """The run's snapshots whose weights a snapshot of another run holds (the same command and seed run again),
        by full name -> the other's full name: rated there, they need no rating games of their own."""
        if not self.cfg.eval_games:
            return {}
        same = self.league.ledger.same_weights(self.spec.name)
        out = {}
        for p in self.league.roster.players(env=self.spec.name, kind="snapshot", include_removed=True):
            if p.run == self.cfg.run and p.id in same:
                other = self.league.roster.get_player(same[p.id])
                if other.run != self.cfg.run:
                    out[p.full_name] = other.full_name
        return out

    def ladder(self, bootstrap: int = 0) -> list[LadderRow]:
        """The ladder of the run's game and variant as the ledger has it now (empty without rating games)."""
        from ..ratings.ladder import ladder

        if not self.cfg.eval_games:
            return []
        return ladder(self.league, self.spec.name, bootstrap=bootstrap, variant=self.variant)

    def records(self, new: list[PlayerRow], rows: list[LadderRow] | None = None) -> list[SnapshotRecord]:
        """Each new snapshot's record against the scripted players and its fitted rating, from the ledger (its row
        of ``rows``, a ladder fitted now, or of a quick fit)."""
        from ..ratings.pairs import head_to_head

        rated = {r.player_id: r for r in (self.ladder() if rows is None else rows)}
        out = []
        for p in new:
            vs, points = {}, {}
            for bot, bot_id in self.bot_ids.items():
                h = head_to_head(self.league, p.id, bot_id, variant=self.variant)
                if h["games"]:
                    vs[bot] = (h["wins"], h["draws"], h["losses"])
                    if any(x not in (0.0, 0.5, 1.0) for r in h["rounds"] for x in r):  # (played for stakes)
                        points[bot] = h["score"] * h["results"]
            r = rated.get(p.id)
            out.append(SnapshotRecord(p.full_name, p.meta.get("learner", ""), p.step, vs,
                                      r.elo if r else None, r.ci_low if r else None, r.ci_high if r else None,
                                      "comparisons" if self.spec.kind == COOPERATIVE else "games", points,
                                      (r.copy_of or "") if r else ""))  # (the ladder's row of a copy names its player)
        return out

    def best(self, rows: list[LadderRow]) -> dict[str, Any]:
        """The report's ``best``: the run's best snapshot in the ladder ``rows`` (its margin over the run's next, or
        the snapshots it is tied with), and ``side_bests``: in a game rated per side, the best of each side. None of
        them without rating games."""
        if not self.cfg.eval_games:
            return {}
        bests = [r for r in rows if r.best and r.run == self.cfg.run]
        return {"best": bests[0] if bests else None, "side_bests": [r for r in bests if r.side is not None]}

    def plot(self) -> Path | str | None:
        """The run's rating curves as ``runs/<run>/ratings.png`` (as ``marl league plot --run`` draws them); None
        without rating games. A plot that cannot be written does not fail a finished run: the reason is returned."""
        from ..report.plots import write_run_plot

        if not self.cfg.eval_games:
            return None
        try:
            return write_run_plot(self.league, self.cfg.run, self.run_dir / "ratings.png")
        except (MarlError, OSError) as e:
            return f"no plot written ({e})"
