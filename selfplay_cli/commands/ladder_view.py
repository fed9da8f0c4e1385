"""Rendering of ladder rows (shared by `marl league ladder`, `marl league tournament` and `marl elo fit`)."""

from __future__ import annotations

import csv
import sys
from typing import Any

from rich.markup import escape
from rich.table import Table

from ._output import console, print_json


def _fmt_elo(x: float) -> str:
    return f"{x:.1f}"


def prior_caption(prior: float, confidence: float = 0.95) -> str:
    """One line saying how the ratings were fitted and how ranks are counted."""
    how = ("maximum likelihood (--prior 0)" if prior == 0 else
           f"MAP with a prior of {prior:g} virtual draws (BayesElo's; --prior 0 for maximum likelihood)")
    return (f"Elo: {how}. rank: 1 + the players above it beyond doubt (players not told apart share a rank). tier: a "
            "tier boundary says everyone above it is above everyone below it beyond doubt (at "
            f"{100 * confidence:g}% for each pair, head-to-head games and the pairs' spread around their ratings "
            "taken in). (best): best snapshot of its run; (best, tied): best by Elo, not beyond doubt.")


EXPLOITABILITY_NOTE = ("exploitability: how much a best response wins against the player, in the game's returns: "
                       "exact (OpenSpiel's best response over the whole game tree, marl exploit --exact), or >= a "
                       "lower bound (a trained best response's mean return, its 95% interval in brackets).")


def exploitability_text(record: dict[str, Any] | None) -> str:
    """A filed exploitability (:func:`~selfplay_cli.ratings.ladder.shown_exploitability`) as a ladder cell: ``0.183``
    for an exact figure, ``>= 0.120 [0.080, 0.160]`` for a lower bound with its interval; blank for none."""
    if record is None:
        return ""
    if record["kind"] == "exact":
        return f"{record['value']:.3f}"
    low, high = record.get("low"), record.get("high")
    interval = f" [{low:.3f}, {high:.3f}]" if low is not None and high is not None else ""
    return f">= {record['value']:.3f}{interval}"


def _marked(rows: list) -> tuple[bool, bool]:
    """Whether any row has a league role, and whether any has a filed exploitability (their columns show then)."""
    return any(r.league_role for r in rows), any(r.exploitability is not None for r in rows)


def _csv_record(d: dict[str, Any], marks: bool) -> dict[str, Any]:
    """A row's JSON with ``vs`` flattened into ``vs_<bot>_score`` / ``vs_<bot>_games`` columns, and (with ``marks``,
    a ladder where some row has a league role or an exploitability) ``league_role`` and the exploitability as
    ``exploitability_kind`` / ``exploitability`` / ``exploitability_low`` / ``exploitability_high``."""
    out = {k: v for k, v in d.items() if k not in ("vs", "league_role", "exploitability")}
    for bot, rec in d.get("vs", {}).items():
        out[f"vs_{bot}_score"] = "" if rec["score"] is None else rec["score"]
        out[f"vs_{bot}_games"] = rec["games"]
    if marks:
        record = d["exploitability"] or {}
        out["league_role"] = d["league_role"] or ""
        for key, field in (("exploitability_kind", "kind"), ("exploitability", "value"),
                           ("exploitability_low", "low"), ("exploitability_high", "high")):
            out[key] = "" if record.get(field) is None else record[field]
    return out


def render_ladder(rows: list, title: str, json_out: bool = False, csv_out: bool = False,
                  online: dict[int, float] | None = None, confidence: float = 0.95,
                  caption: str | None = None, variant: dict[str, Any] | None = None,
                  verdicts: list[str] | None = None, flown: dict[int, dict[str, Any]] | None = None) -> None:
    """Print ladder rows: JSON alone (``--json``), CSV (``--csv``) or a rich table.

    ``variant``: the options of the variant the rows were fitted in (``{}``: the default); each JSON row carries it
    as ``variant`` (a ladder of a results file has none).

    ``online``: the online Elo by player id (an extra column). The table marks the anchor and the best snapshot
    of each run (bold, ``(best)``, or ``(best, tied)`` when it is not separated from the run's others), shows the
    tier, a flag next to the Elo, the mean team return of a cooperative game's players, and one ``vs BOT`` column
    per scripted player (score and games, blank without games); ``verdicts`` (:func:`~selfplay_cli.ratings.verdicts.
    verdict_lines`) follow the table. A ``league role`` column and an ``exploitability`` column
    (:func:`exploitability_text`) show only when some row has one.
    """
    flown = flown or {}
    if json_out:
        print_json([r.to_json() | ({} if variant is None else {"variant": variant})
                    | ({"flown": flown[r.player_id]} if r.player_id in flown else {}) for r in rows])
        return
    if csv_out:
        w = csv.writer(sys.stdout)
        records = [_csv_record(r.to_json(), any(_marked(rows))) for r in rows]
        keys = list(records[0]) if records else ["policy", "kind", "elo", "ci_low", "ci_high", "games", "wins",
                                                  "draws", "losses", "rank"]
        w.writerow(keys)
        for d in records:
            w.writerow([d.get(k, "") for k in keys])
        return
    if caption and any(r.mean_return is not None for r in rows):
        caption += " mean return: the team's mean return per game (all seats together)."
    if caption and _marked(rows)[1]:
        caption += " " + EXPLOITABILITY_NOTE
    sides = list(dict.fromkeys(r.side for r in rows))
    if sides and sides != [None]:  # a game whose sides differ: one table per side, each with its own anchor
        caption = ((caption + " ") if caption else "") + (
            f"This game's sides differ ({', '.join(map(str, sides))}): a player plays only its own side, so each side "
            "is rated on its own, anchored at its anchor on that side; a rating compares only with its side's.")
        for side in sides:
            _table([r for r in rows if r.side == side], f"{title}: {side} side", online, confidence,
                   caption if side == sides[-1] else None)
    else:
        _table(rows, title, online, confidence, caption)
    for line in verdicts or ():
        console.print(line, markup=False, highlight=False)
    for line in _flown_lines(rows, flown):
        console.print(line, markup=False, highlight=False)


def _flown_lines(rows: list, flown: dict[int, dict[str, Any]]) -> list[str]:
    """One line per team (or network) that this ladder's variant flies with another number of seats than it
    trained with: who, from how many to how many, and the rule that seats it."""
    seen: dict[str, str] = {}
    for r in rows:
        f = flown.get(r.player_id)
        if f is not None:
            who = f["team"] or r.policy
            seen.setdefault(who, f"{who}: trained with {f['trained_seats']} seats, flown here with {f['seats']}: "
                                 f"{f['rule']}")
    return list(seen.values())


def _table(rows: list, title: str, online: dict[int, float] | None, confidence: float, caption: str | None) -> None:
    """One ladder table (see :func:`render_ladder`)."""
    table = Table(title=title, caption=caption)
    roles, exploits = _marked(rows)
    for col, just in ((("rank", "right"), ("tier", "right"), ("policy", "left"), ("kind", "left"))
                      + ((("league role", "left"),) if roles else ()) + (
                      ("step", "right"), ("Elo", "right"), (f"{100 * confidence:g}% interval", "center"),
                      ("games", "right"), ("W-D-L", "center"), ("score", "right"))
                      + ((("exploitability", "right"),) if exploits else ())):
        table.add_column(col, justify=just)
    if online:
        table.add_column("online", justify="right")
    returns = any(r.mean_return is not None for r in rows)  # a cooperative game: the team's mean return
    if returns:
        table.add_column("mean return", justify="right")
    bots = [v.bot for v in rows[0].vs] if rows else []
    for bot in bots:
        table.add_column(f"vs {escape(bot)}", justify="right")
    for r in rows:
        note = f" ({r.flag})" if r.flag else ""
        marks = ((" (anchor)" if r.anchor else "") + ((" (best, tied)" if r.tied else " (best)") if r.best else "")
                 + (f" (= {escape(r.copy_of)}: the same weights)" if r.copy_of else ""))
        cells = [str(r.rank), "-" if r.tier is None else str(r.tier), escape(r.policy) + marks, r.kind,
                 *([escape(r.league_role or "")] if roles else []),
                 "" if r.step is None else f"{r.step:,}",
                 _fmt_elo(r.elo) + note, f"{_fmt_elo(r.ci_low)} .. {_fmt_elo(r.ci_high)}", str(r.games),
                 f"{r.wins}-{r.draws}-{r.losses}", f"{100 * r.score:.1f}%",
                 *([exploitability_text(r.exploitability)] if exploits else [])]
        if online:
            value = online.get(r.player_id) if r.player_id is not None else None
            cells.append("" if value is None else f"{value:.0f}")
        if returns:
            cells.append("" if r.mean_return is None else f"{r.mean_return:.1f}")
        for rec in r.vs:
            cells.append("" if rec.score is None else f"{100 * rec.score:.0f}% of {rec.games}")
        table.add_row(*cells, style="bold" if r.best else None)
    console.print(table)
