"""The command reference of the docs site (``docs/reference/cli.md``), generated from the CLI's own metadata: every
command and group with its help, every argument and option with its flags, value, default, environment variable
and help, as ``marl COMMAND --help`` has them. Nothing is typed by hand, so it cannot drift: ``tests/test_docs.py``
renders it again and fails where the file and the CLI differ.

The site's home page (``docs/index.md``) is README's text (:func:`home_page`), and the figures a page quotes from a
benchmark are rendered from that benchmark's output file, with its date and machine (:func:`figures`, between
``<!-- figures:NAME -->`` and ``<!-- /figures -->`` in a page): each checked the same way.
``python -m selfplay_cli.reference --write`` (in the repository) writes them all.
"""

from __future__ import annotations

import inspect
import itertools
import re
from typing import Any

__all__ = ["FIGURES", "figures", "home_page", "render", "with_figures"]

_HEAD = """# Command reference

Every command of `marl`, with its arguments and options, generated from the CLI itself
(`python -m selfplay_cli.reference --write`; a test fails when this page and the CLI differ).
`marl COMMAND --help` prints the same. The pages under *Commands* explain each with examples.
"""


def render() -> str:
    """The whole reference, as Markdown."""
    from typer._click import Context

    from .cli import build_command

    root = build_command()
    out = [_HEAD]
    top = Context(root, info_name="marl")
    for name, command in sorted(_children(root).items()):
        _command(command, Context(command, info_name=name, parent=top), ["marl", name], out)
    return "\n".join(out).rstrip() + "\n"


def _children(command: Any) -> dict[str, Any]:
    return {n: c for n, c in (getattr(command, "commands", None) or {}).items() if not getattr(c, "hidden", False)}


def _command(command: Any, ctx: Any, path: list[str], out: list[str]) -> None:
    """One command's section (a group's, then its commands'): its help, then a table of what it takes, each row as
    ``--help`` prints it (the names with the value they take; the help with its default, range and variable)."""
    from typer._click import Context

    out.append(f"{'#' * min(len(path), 4)} `{' '.join(path)}`\n")
    text = inspect.cleandoc(command.help or "").replace("\b\n", "")
    if text:
        out.append(_escape_text(text) + "\n")
    records = [p.get_help_record(ctx) for p in command.params]
    rows = [f"| `{names}` | {_cell(help_)} |" for names, help_ in (r for r in records if r is not None)]
    if rows:
        out += ["| argument / option | what it is |", "|---|---|", *rows, ""]
    for name, sub in sorted(_children(command).items()):
        _command(sub, Context(sub, info_name=name, parent=ctx), [*path, name], out)


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|").replace("<", "&lt;")


def _escape_text(text: str) -> str:
    """Help text as Markdown: paragraphs kept, nothing read as a heading or HTML."""
    return "\n".join(("\\" + line if line.startswith("#") else line).replace("<", "&lt;") for line in text.splitlines())


def home_page(readme: str) -> str:
    """The site's home page: README, its links into ``docs/`` made the site's own, without CI's markers."""
    text = re.sub(r"<!-- ci:[\w-]+ -->\n", "", readme)
    return re.sub(r"\]\(docs/([^)]*)\)", r"](\1)", text)


def _ladder_truth(data: dict[str, Any]) -> str:
    """``benchmarks/results/ladder_truth.json`` as the league page quotes it: the table, then per game whether it holds
    the targets, then every claim a reader meets that missed (from the checked pairs)."""
    head = f"{_stamp('benchmarks/results/ladder_truth.json', data)}; every checked pair is in the file.\n\n"
    head += ("| game | pairs checked | 95% predictions held | open, met: median width (pairs) | open, never met | "
             "printed margins held: the 200-game range (the expected-difference interval) | order claims held | "
             "row margins (JSON) held: range (interval) |\n|---|---|---|---|---|---|---|---|\n")
    rows = []
    for t in data["table"]:
        met = f"{t['width_met']:.0f} ({t['open_met']})" if t.get("width_met") is not None else "-"
        new = f"{t['width_new']:.0f} ({t['open_new']})" if t.get("width_new") is not None else "-"
        rows.append(f"| {t['label']} | {t['pairs']:,} | {t['held']} | {met} | {new} | {t['printed_margins']} "
                    f"({t.get('printed_expected', '-')}) | {t['order']} | {t['row_margins']} "
                    f"({t.get('rows_expected', '-')}) |")
    return head + "\n".join(rows) + "\n\n" + _ladder_targets(data) + _ladder_misses(data["pairs"])


def _ladder_targets(data: dict[str, Any]) -> str:
    """Which games hold the targets (at least 90% of the 95% predictions held; open predictions at most 30 points
    wide where the pair met, 45 where it did not; at least 90% of printed margins held), and where one falls short."""
    held, short = [], []
    for t in data["table"]:
        if t["label"].startswith("simulated"):
            continue
        printed = [m["held"] for p in data["pairs"] if p["game"] == t["label"] for m in p["margins"]
                   if m["where"] != "row"]
        misses = []
        if t.get("held_share") is not None and t["held_share"] < 0.9:
            misses.append(f"predictions held {t['held']}")
        if t.get("width_met") is not None and t["width_met"] > 30:
            misses.append(f"open predictions of pairs that met {t['width_met']:.0f} points wide")
        if t.get("width_new") is not None and t["width_new"] > 45:
            misses.append(f"open predictions of pairs that never met {t['width_new']:.0f} points wide")
        if printed and sum(printed) < 0.9 * len(printed):
            misses.append(f"printed margins held {t['printed_margins']}")
        (short.append(f"{t['label']} ({'; '.join(misses)})") if misses else held.append(t["label"]))
    text = ("Targets: at least 90% of the 95% predictions held, open predictions at most 30 points wide where the "
            "pair met and 45 where it did not, at least 90% of the printed margins held. ")
    text += f"Held on {_names(held)}." if held else "Held on no game."
    return text + (f" Missed on {_names(short)}." if short else "") + "\n"


def _ladder_misses(pairs: list[dict[str, Any]]) -> str:
    """Every prediction of a claimed pair that its 200-game match fell outside, and every margin printed under a
    ladder or in a summary whose range or interval missed the match's Elo, one line each."""
    lines = []
    for p in pairs:
        if not p["held"] and set(p["kinds"]) - {"row"}:
            before = f"{p['met']} rated games between them before" if p["met"] else "they had never met"
            lines.append(f"- {p['game']}: `{p['a']}` against `{p['b']}` predicted {100 * p['predicted']:.1f}% "
                         f"[{100 * p['low']:.1f}, {100 * p['high']:.1f}] ({before}); measured "
                         f"{100 * p['measured']:.1f}% over {p['results']} results")
        said: dict[tuple, list[str]] = {}  # one margin printed in two places (a run's best is the ladder's top)
        for m in p["margins"]:
            if m["where"] != "row" and not (m["held"] and m["held_expected"]):
                key = (m["elo"], m["low"], m["high"], m["match_low"], m["match_high"], m["held"], m["held_expected"])
                said.setdefault(key, []).append(_WHERE.get(m["where"], m["where"]))
        for (elo, low, high, match_low, match_high, in_range, in_interval), where in said.items():
            how = ("inside the range, outside the interval" if in_range else
                   "outside the range" + ("" if in_interval else " and the interval"))
            lines.append(f"- {p['game']}: `{p['a']}` over `{p['b']}` {elo:+.0f} [{low:+.0f}, {high:+.0f}] "
                         f"({' and '.join(where)}; 200 games would measure {match_low:+.0f} to {match_high:+.0f}); "
                         f"measured {p['measured_elo']:+.0f}: {how}")
    if not lines:
        return "\nEvery claimed pair's prediction and every printed margin held.\n"
    return "\nWhat missed (predictions of claimed pairs; printed margins, by range or by interval):\n\n" + \
        "\n".join(lines) + "\n"


_WHERE = {"top": "the ladder's top over the next", "best": "the run's best over its next best"}


def _names(names: list[str]) -> str:
    return ", ".join(names[:-1]) + f" and {names[-1]}" if len(names) > 1 else names[0]


def _sizes(sizes: list[int]) -> str:
    """[1, 2, 3, 4] as ``1-4``; [2, 3, 4] as ``2, 3 and 4`` (a run of three or more sizes, or a list)."""
    if len(sizes) > 3 and sizes == list(range(sizes[0], sizes[-1] + 1)):
        return f"{sizes[0]}-{sizes[-1]}"
    return ", ".join(map(str, sizes[:-1])) + f" and {sizes[-1]}" if len(sizes) > 1 else str(sizes[0])


def _above(cell: dict[str, Any] | None, others: list[dict[str, Any] | None]) -> bool:
    """Whether ``cell``'s 95% interval lies wholly above each of ``others``' (beyond doubt the higher)."""
    if not cell or cell.get("low") is None or not others:
        return False
    return all(o and o.get("high") is not None and cell["low"] > o["high"] for o in others)


def _team_study(source: str) -> Any:
    """A ``marl study team-size --json`` report (``benchmarks/team_study.py`` copies it to ``source``) as the two
    tables the teams page quotes: the mean team return by size trained x flown, and each adapted run against the run
    trained afresh at its size. Each cell is ``marl study team-size``'s own (its ``_ci``: the mean and its 95%
    interval); a cell is bold where its interval lies wholly above every other's it is set against (the best at that
    size, or the better of adapted and fresh, beyond doubt)."""

    def render(r: dict[str, Any]) -> str:
        from .commands.study import _ci

        budget = r["budget"]
        per_run = (f"{budget['minutes']:g} minutes" if budget.get("minutes") is not None
                   else f"{budget['steps']:,} steps")
        sharing = {"fups": "FuPS", "nops": "NoPS"}.get(r["sharing"], r["sharing"])
        out = [f"From `{source}` (study `{r['study']}`, `marl study team-size --json`; the report records no date "
               f"or machine): `{r['env']}`, teams of {_sizes(r['train'])} (`{r['size_option']}`) trained "
               f"{per_run} a run ({sharing}, {(r['algo'] or 'ppo').upper()}), each flown with {_sizes(r['eval'])} "
               f"against `{r['vs']}` for {r['eval_games']} episodes on the same seeds; 95% intervals in brackets.",
               "",
               "Mean team return by size trained (rows) and flown (columns); bold: the best at that size, its "
               "interval above every other's:",
               "",
               "| trained \\ flown | " + " | ".join(map(str, r["eval"])) + " |",
               "|---" * (len(r["eval"]) + 1) + "|"]
        rows = {n: {c["evaluated"]: c for c in r["returns"] if c["trained"] == n} for n in r["train"]}
        vs = {m: c["vs"] for m, c in rows[r["train"][0]].items()}
        table = [(str(n), rows[n]) for n in r["train"]] + [(f"{r['vs']}", vs)]
        for label, cells in table:
            shown = []
            for m in r["eval"]:
                others = [c.get(m) for lab, c in table if lab != label]
                text = _ci(cells.get(m))
                shown.append(f"**{text}**" if _above(cells.get(m), others) else text)
            out.append(f"| {label} | " + " | ".join(shown) + " |")
        out += ["",
                f"Adapted from another size against trained afresh ({per_run} each): the return each reached, and "
                "when the adapted run's snapshots, flown in order on the same seeds, first scored at or above the "
                "fresh run's final return (that snapshot's return in brackets); bold: the one whose interval lies "
                "above the other's:",
                "",
                "| from -> to | adapted | fresh | adapted reached fresh's final at | fresh took |",
                "|---|---|---|---|---|"]
        for x in r["adaptive"]:
            adapted, fresh = x["return"], x["fresh_return"]
            if x["steps_to_reach"] is None:
                reached = "not reached"
            elif x["steps_to_reach"] == 0:
                reached = f"0 steps ({x['reached_return']:.1f}: its parent flown at {x['to']})"
            else:
                reached = (f"{x['steps_to_reach']:,} steps, {x['minutes_to_reach']:.1f} min "
                           f"({x['reached_return']:.1f})")
            took = "-" if x["fresh_steps"] is None else f"{x['fresh_steps']:,} steps, {x['fresh_minutes']:.1f} min"
            a_text, f_text = _ci(adapted), _ci(fresh)
            a_text = f"**{a_text}**" if _above(adapted, [fresh]) else a_text
            f_text = f"**{f_text}**" if _above(fresh, [adapted]) else f_text
            out.append(f"| {x['from']} -> {x['to']} | {a_text} | {f_text} | {reached} | {took} |")
        return "\n".join(out + ["", *_team_reading(r, rows, vs)]) + "\n"

    return render


def _span(values: list[float], fmt: str = "{:.1f}") -> str:
    lo, hi = fmt.format(min(values)), fmt.format(max(values))
    return lo if lo == hi else f"{lo} to {hi}"


def _team_reading(r: dict[str, Any], rows: dict[int, dict[int, Any]], vs: dict[int, Any]) -> list[str]:
    """What the teams page reads in a study's tables, computed from its report (so the page types no figure): where
    each team is above ``vs`` beyond doubt, its steepest fall from one flown size to the next, how the adapted runs
    ended against the fresh ones, and what the runs cost."""
    def pairs(xs: list[dict[str, Any]]) -> str:
        return _names([f"{x['from']} -> {x['to']}" for x in xs]) if xs else "none"

    out = ["Read from the tables (computed from the same report):", ""]
    for n, cells in rows.items():
        above = [m for m in r["eval"] if _above(cells.get(m), [vs.get(m)])]
        means = [(m, cells[m]["mean"]) for m in r["eval"] if cells.get(m) and cells[m].get("mean") is not None]
        if not means:  # (a size whose team was flown nowhere: its row of the table is all "-")
            continue
        falls = [(b[1] - a[1], a, b) for a, b in itertools.pairwise(means)]
        fall = min(falls, default=None)
        steepest = (f"; its steepest fall, {fall[1][1]:.1f} at {fall[1][0]} to {fall[2][1]:.1f} at {fall[2][0]}"
                    if fall and fall[0] < 0 else "; it never falls from one size to the next")
        where = f"flown with {_sizes(above)}" if above else "at no size flown"
        best = max(means, key=lambda c: c[1])[0]
        out.append(f"- trained with {n}: above `{r['vs']}` beyond doubt {where}; at its best flown with {best}"
                   f"{steepest}")
    adaptive = [x for x in r["adaptive"] if x["return"].get("mean") is not None
                and x["fresh_return"].get("mean") is not None]
    if adaptive:
        gains = [x["return"]["mean"] - x["fresh_return"]["mean"] for x in adaptive]
        out.append(f"- adapted minus fresh, the returns each reached: {_span(gains, '{:+.1f}')}; above beyond doubt: "
                   f"{pairs([x for x in adaptive if _above(x['return'], [x['fresh_return']])])}; below beyond doubt: "
                   f"{pairs([x for x in adaptive if _above(x['fresh_return'], [x['return']])])}; at the fresh run's "
                   f"final return from its start (its parent flown at the new size): "
                   f"{pairs([x for x in adaptive if x['steps_to_reach'] == 0])}")
    runs = r.get("runs") or []
    if runs:
        def steps(n: float) -> str:
            return f"{n / 1e6:.1f}M" if n >= 1e6 else f"{n / 1e3:.0f}k"

        fresh = ", ".join(f"{x['size']}: {steps(x['steps'])}" for x in runs if x["from"] is None)
        out.append(f"- each of the {len(runs)} runs: {_span([x['wall_seconds'] / 60 for x in runs])} min of wall "
                   f"time, mean CPU {_span([x['mean_cpu'] for x in runs], '{:.2f}')} cores, "
                   f"{_span([x['peak_mb'] for x in runs], '{:.0f}')} MB at its peak, "
                   f"{steps(min(x['steps'] for x in runs))} to {steps(max(x['steps'] for x in runs))} game steps "
                   f"(trained afresh, by size: {fresh})")
    return out


def _other_libraries(r: dict[str, Any]) -> str:
    """``benchmarks/other_libraries.py``'s table as printed, then what the games page reads in it (so the page types no
    figure): how much faster the recipe runs in one process than with its worker processes, and how many more game
    steps the bare view plays than the recipe in one process, over the games of the table."""
    text = _printed("benchmarks/results/other_libraries.json")(r)
    lines = r["printed"]
    head = next((i for i, x in enumerate(lines) if x.startswith("game ")), None)
    if head is None:
        raise ValueError("benchmarks/results/other_libraries.json printed no table (no line starting 'game ')")
    rows = []
    for line in lines[head + 1:]:
        if not line.strip() or line.startswith("load average"):
            break
        workers, inproc, bare = (float(x.replace(",", "")) for x in line.split()[-4:-1])
        rows.append((workers, inproc, bare))
    faster = [inproc / workers for workers, inproc, _ in rows]
    more = [bare / inproc for _, inproc, bare in rows]
    return text + (f"\nRead from the table: in one process the recipe runs {_span(faster)} times as fast as with 2 "
                   f"worker processes (in-process / 2 workers), and the bare view plays {_span(more)} times as many "
                   f"game steps as the recipe in one process (bare view / in-process).\n")


FIGURES: dict[str, tuple[str, Any]] = {
    "ladder_truth": ("benchmarks/results/ladder_truth.json", _ladder_truth),
    "team_study_pursuit": ("docs/team-study-pursuit.json", _team_study("docs/team-study-pursuit.json")),
    "team_study_lander": ("docs/team-study-lander.json", _team_study("docs/team-study-lander.json")),
    "other_libraries": ("benchmarks/results/other_libraries.json", _other_libraries),
}
"""The blocks of figures a docs page may quote that are rendered as tables: the benchmark output each is rendered from,
and how (any other block quotes what a benchmark printed, from ``benchmarks/results/NAME.json``)."""


def _took(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} minutes"


def _stamp(source: str, r: dict[str, Any]) -> str:
    """Where a benchmark's figures come from: its file, the command, when, on what machine, at what load and on what
    code it ran, and how long it took."""
    load = f"load {r['load_start'][0]:.1f} at its start, {r['load_end'][0]:.1f} at its end"
    code = f", code {r['commit']}" if r.get("commit") else ""
    return (f"From `{source}`: `{r['command']}`, run {r['date']} on {r['machine']} ({load}{code}; "
            f"{_took(r['seconds'])})")


def _printed(source: str, view: str = "") -> Any:
    """A benchmark's results file (``benchmarks/results_file.py`` writes it) as what the script printed, under a line
    saying the command, when, on what machine, at what load and on what code it ran. ``view``: ``top``, its
    unindented lines alone (a benchmark's summary, without the tables it printed under each line); another name, the
    lines of the script's section of that name (``sections`` in the file: the part of a worked example a page
    quotes)."""

    def render(r: dict[str, Any]) -> str:
        if view == "top":
            lines = [x for x in r["printed"] if x.strip() and not x[0].isspace()]
        elif view:
            if view not in r.get("sections", {}):
                raise ValueError(f"{source} has no section {view!r} (its sections: "
                                 f"{', '.join(r.get('sections', {})) or 'none'})")
            lines = r["sections"][view]
        else:
            lines = r["printed"]
        return f"{_stamp(source, r)}:\n\n```text\n" + "\n".join(lines) + "\n```\n"

    return render


def figures(name: str, root: Any) -> str:
    """The figures block ``name``, rendered from its output file under the repository ``root``: a block of
    :data:`FIGURES`, or else what ``benchmarks/results/NAME.json`` says a benchmark printed (``NAME/top``: its
    unindented lines alone; ``NAME/SECTION``: one section of it)."""
    import json
    from pathlib import Path

    name, _, view = name.partition("/")
    source = f"benchmarks/results/{name}.json"
    source, make = FIGURES.get(name) or (source, _printed(source, view))
    return make(json.loads((Path(root) / source).read_text()))


def with_figures(page: str, root: Any) -> str:
    """``page`` with every ``<!-- figures:NAME -->`` ... ``<!-- /figures -->`` block rendered anew."""

    def block(m: re.Match[str]) -> str:
        return f"<!-- figures:{m.group(1)} -->\n{figures(m.group(1), root)}<!-- /figures -->"

    return re.sub(r"<!-- figures:(\w+(?:/\w+)?) -->\n.*?<!-- /figures -->", block, page, flags=re.S)


if __name__ == "__main__":
    import sys
    from pathlib import Path

    if sys.argv[1:] == ["--write"]:
        try:
            Path("docs/reference/cli.md").write_text(render())
            readme = Path("README.md").read_text()
            if "<!-- figures:" in readme:
                Path("README.md").write_text(readme := with_figures(readme, "."))
            Path("docs/index.md").write_text(home_page(readme))
            for page in Path("docs").rglob("*.md"):
                text = page.read_text()
                if "<!-- figures:" in text:
                    page.write_text(with_figures(text, "."))
        except OSError as e:
            sys.exit(f"reference: {e.filename}: {e.strerror} (run it in the repository: it writes docs/)")
        except ValueError as e:
            sys.exit(f"reference: {e}")
    else:
        sys.stdout.write(render())
