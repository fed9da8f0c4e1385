"""The web app of ``marl serve``: Starlette routes that read the league through :class:`~.queries.Reader` and render
Jinja2 templates (autoescape on for every template, so every name, tag, note and error a row holds shows as text).

Pages: ``/`` the games and runs; ``/ladder``; ``/matrix``; ``/curves``; ``/player/{id}``; ``/matches``; ``/queue``;
``/replays``, ``/replay/{id}`` and the file itself at ``/video/{id}`` (only a file the league registered, inside its
videos folder: :meth:`~selfplay_cli.league.videos.Videos.file`); ``/health`` (JSON: the fits done, running, failed).
Sorting and filtering are query parameters read on the server; a bad one is a 400 page, something the league does not
hold a 404 page, and nothing is ever a traceback.

No request fits: the ladder, matrix, curves and player pages show what :class:`~.fits.FitCache` fitted in its
background thread (started and stopped with the app), and say when; before the first fit of a game and variant is
done they are a notice that reloads itself."""

from __future__ import annotations

import contextlib
import logging
import math
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

from jinja2 import Environment, PackageLoader
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from selfplay_cli.league.job_rows import JOB_STATES
from selfplay_cli.league.ledger import MATCH_KINDS
from selfplay_cli.league.store import LeagueError
from selfplay_cli.league.variants import describe_variant
from selfplay_cli.ratings.pairs import PAYOFFS
from selfplay_cli.serve.charts import heat, line_chart
from selfplay_cli.serve.fits import FitCache, KeyState, one_line
from selfplay_cli.serve.queries import NotFound, Reader

__all__ = ["create_app"]

log = logging.getLogger("marl.serve")

LADDER_SORTS = {"rank": lambda r: (r["rank"], -r["elo"]), "elo": lambda r: r["elo"], "games": lambda r: r["games"],
                "score": lambda r: r["score"], "policy": lambda r: r["policy"], "step": lambda r: r["step"] or -1,
                "interval": lambda r: r["ci_high"] - r["ci_low"], "run": lambda r: r["run"] or ""}
PAGE = 50
STOP_SECONDS = 10.0
"""How long the app's shutdown waits for a fit in progress (a daemon thread: the process's end ends it)."""
MAX_TEXT = 200
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; script-src 'none'; style-src 'self' 'unsafe-inline'; "
                               "img-src 'self' data:; media-src 'self'; object-src 'none'; base-uri 'none'; "
                               "form-action 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


class BadRequest(HTTPException):
    def __init__(self, detail: str) -> None:
        super().__init__(400, detail)


def _text(request: Request, name: str) -> str | None:
    value = request.query_params.get(name)
    if value is None or value == "":
        return None
    if len(value) > MAX_TEXT or not value.isprintable():
        raise BadRequest(f"{name}: at most {MAX_TEXT} printable characters")
    return value


def _int(request: Request, name: str, default: int | None, lo: int, hi: int) -> int | None:
    raw = request.query_params.get(name)
    if raw is None or raw == "":
        return default
    try:
        value = int(raw)
    except ValueError:
        raise BadRequest(f"{name} must be a whole number, not {raw[:40]!r}") from None
    if not lo <= value <= hi:
        raise BadRequest(f"{name} must be between {lo} and {hi}, not {value}")
    return value


def _choice(request: Request, name: str, default: str | None, choices: Any) -> str | None:
    value = _text(request, name)
    if value is None:
        return default
    if value not in choices:
        raise BadRequest(f"{name} must be one of {', '.join(sorted(choices))}, not {value!r}")
    return value


def _qs(**params: Any) -> str:
    """A query string of the params that are set (the templates' links)."""
    return urlencode({k: v for k, v in params.items() if v is not None and v != ""})


def _pct(x: float | None) -> str:
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{100 * x:.1f}%"


def _fit_note(state: KeyState) -> dict[str, Any] | None:
    """What a page says of its fit: when it was made, of how many games, a refit running, the latest error."""
    f = state.fitted
    if f is None:
        return None
    running = None if state.running_since is None else {
        "games": state.running_games, "ago": round(time.monotonic() - state.running_since)}
    return {"at": time.strftime("%H:%M:%S", time.localtime(f.fitted_at)), "games": f.games, "seconds": f.seconds,
            "running": running, "error": state.error}


def create_app(reader: Reader, where: str, fits: FitCache | None = None) -> Starlette:
    """The app over ``reader``; ``where`` names the league in every page's footer; ``fits``: its background fits
    (by default a :class:`~.fits.FitCache` of ``reader``), started when the app starts and stopped when it stops."""
    fits = fits if fits is not None else FitCache(reader)
    env = Environment(loader=PackageLoader("selfplay_cli.serve", "templates"), autoescape=True,
                      trim_blocks=True, lstrip_blocks=True)
    env.globals.update(qs=_qs, pct=_pct, describe_variant=describe_variant, where=where, heat=heat)

    def page(name: str, status: int = 200, **context: Any) -> HTMLResponse:
        return HTMLResponse(env.get_template(name).render(**context), status_code=status)

    def games_of(state: KeyState, env_name: str, variant: str) -> int:
        """The games a fit of ``env_name`` in ``variant`` takes in: the running one's, else the league's now."""
        if state.running_games is not None:
            return state.running_games
        return next((v["games"] for g in reader.games() if g["env"] == env_name for v in g["variants"]
                     if v["key"] == variant), 0)

    def notice(state: KeyState, env_name: str, variant: str, heading: str) -> Response:
        """The page of a game and variant whose first fit is not done (running, queued) or failed."""
        games = games_of(state, env_name, variant)
        since = None if state.running_since is None else round(time.monotonic() - state.running_since)
        return page("fitting.html", title=heading, heading=heading, env=env_name, variant=variant, games=games,
                    since=since, error=state.error, refresh=None if state.error else 3)

    def game_params(request: Request) -> tuple[str, str]:
        return reader.check_game(_text(request, "env"), request.query_params.get("variant"), _text(request, "run"))

    def home(request: Request) -> Response:
        return page("home.html", title="games", games=reader.games())

    def ladder_page(request: Request) -> Response:
        env_name, variant = reader.check_game(_text(request, "env"), request.query_params.get("variant"))
        run = _text(request, "run")
        if run is not None and reader.league.roster.get_run(run) is None:
            raise NotFound(f"no run named {run!r} in this league")
        sort = _choice(request, "sort", "rank", LADDER_SORTS)
        order = _choice(request, "order", None, ("asc", "desc"))
        kind = _choice(request, "kind", None, ("bot", "snapshot"))
        q = _text(request, "q")
        state = fits.state(env_name, variant)
        if state.fitted is None:
            return notice(state, env_name, variant, f"ladder: {env_name}")
        lad = state.fitted.ladder
        records = [r for r in lad.records if (run is None or r["run"] == run or r["kind"] == "bot")
                   and (kind is None or r["kind"] == kind) and (q is None or q.lower() in r["policy"].lower())]
        descending = order == "desc" if order else sort in ("elo", "games", "score", "step")
        records = sorted(records, key=LADDER_SORTS[sort], reverse=descending)  # (stable: rank order within ties)
        runs = sorted({r["run"] for r in lad.records if r["run"]})
        games = {g["env"]: g for g in reader.games()}
        return page("ladder.html", title=f"ladder: {env_name}", env=env_name, variant=variant, records=records,
                    verdicts=lad.verdicts, runs=runs, run=run, sort=sort, order="desc" if descending else "asc",
                    kind=kind, q=q, games=games, total=len(lad.records), fit=_fit_note(state),
                    ids={r.policy: r.player_id for r in lad.rows},
                    bots=[v.bot for v in lad.rows[0].vs] if lad.rows else [])

    def matrix_page(request: Request) -> Response:
        env_name, variant = game_params(request)
        top = _int(request, "top", 10, 2, 100)
        min_games = _int(request, "min_games", 8, 1, 10_000_000)
        payoff = _choice(request, "payoff", "points", PAYOFFS)
        run = _text(request, "run")
        state = fits.state(env_name, variant)
        if state.fitted is None:
            return notice(state, env_name, variant, f"matrix: {env_name}")
        report = state.fitted.matrix(reader, top, run, min_games, payoff)
        data = report.to_json()
        n = report.n
        cells = [[None if i == j else {"text": report.cell(i, j)[0] if report.measured[i, j] else None,
                                       "place": report.cell(i, j)[1] if report.measured[i, j] else None,
                                       "games": int(report.games[i, j])} for j in range(n)] for i in range(n)]
        weights = {m["policy"]: m["weight"] for m in (data["nash"] or {}).get("mixture", [])}
        return page("matrix.html", title=f"matrix: {env_name}", env=env_name, variant=variant, data=data,
                    cells=cells, weights=weights, top=top, min_games=min_games, payoff=payoff, run=run,
                    fit=_fit_note(state))

    def curves_page(request: Request) -> Response:
        run = _text(request, "run")
        runs = reader.league.roster.list_runs()
        if run is None:
            if not runs:
                raise NotFound("this league has no training runs yet")
            run = runs[-1].name
        env_name, variant = reader.check_game(None, None, run)
        state = fits.state(env_name, variant)
        if state.fitted is None:
            return notice(state, env_name, variant, f"curves: {run}")
        curves = reader.curves(run, state.fitted.ladder.rows)
        elo = line_chart([(c.learner, [(p.step, p.elo, p.ci_low, p.ci_high, f"{p.policy}: {p.elo:.1f} "
                                        f"[{p.ci_low:.1f}, {p.ci_high:.1f}]") for p in c.points])
                          for c in curves.curves], [(b.name, b.elo) for b in curves.bots], "training step", "Elo")
        rows = {r["policy"]: r for r in state.fitted.ladder.records}
        exploit = [(c.learner, [(p.step, float(rows[p.policy]["exploitability"]["value"]), None, None,
                                 f"{p.policy}: {rows[p.policy]['exploitability']['value']:.4g}")
                                for p in c.points if (rows.get(p.policy) or {}).get("exploitability")])
                   for c in curves.curves]
        exploit = [s for s in exploit if s[1]]
        chart_x = line_chart(exploit, [], "training step", "exploitability", log=True) if exploit else None
        # lineage: each snapshot of the run and the one it grew from
        players = [p for p in reader.league.roster.players(env=env_name, kind="snapshot", include_removed=True)
                   if p.run == run]
        by_id = {p.id: p for p in reader.league.roster.players(env=env_name, include_removed=True)}
        lineage = [(p, by_id.get(p.parent_id) if p.parent_id is not None else None) for p in players]
        return page("curves.html", title=f"curves: {run}", run=run, runs=runs, curves=curves.to_json(), elo=elo,
                    exploit=chart_x, lineage=lineage, rows=rows, env=env_name, variant=variant,
                    fit=_fit_note(state))

    def player_page(request: Request) -> Response:
        pid = _path_int(request, "player_id")
        player = reader.player(pid)
        variant = request.query_params.get("variant")
        env_name, variant = reader.check_game(player.env, variant)
        vs = _int(request, "vs", None, 1, 2**62)
        games = _int(request, "games", 200, 1, 10_000_000)
        state = fits.state(env_name, variant)
        fitted = state.fitted
        records = fitted.ladder.records if fitted else []
        record = next((r for r in records if r["policy"] == player.full_name), None)
        prediction = error = None
        if vs is not None:
            other = reader.player(vs)
            if other.env != player.env:
                raise BadRequest(f"{other.full_name} plays {other.env}, not {player.env}")
            if fitted is not None and fitted.forecaster is None:
                error = fitted.forecast_error
            elif fitted is not None:
                try:
                    prediction = reader.predict(env_name, variant, player, other, games, forecast=fitted.forecaster)
                except LeagueError as e:
                    error = str(e)
        up, down = reader.lineage(player)
        try:
            opponents, games_error = reader.opponents(player, variant), None
        except (ValueError, LeagueError) as e:  # (a corrupt row of the ledger: said, the rest of the page shown)
            opponents, games_error = [], one_line(e)
        return page("player.html", title=player.full_name, player=player, record=record, env=env_name,
                    variant=variant, opponents=opponents, games_error=games_error, up=up, down=down,
                    prediction=prediction, error=error, vs=vs, games=games,
                    others=[r for r in records if r["policy"] != player.full_name],
                    ids={r.policy: r.player_id for r in fitted.ladder.rows} if fitted else {},
                    videos=reader.league.videos.list(player_id=player.id), fit=_fit_note(state),
                    fitting=state if fitted is None else None,
                    fitting_games=games_of(state, env_name, variant) if fitted is None else None,
                    refresh=3 if fitted is None and not state.error else None,
                    since=None if state.running_since is None else round(time.monotonic() - state.running_since))

    def matches_page(request: Request) -> Response:
        env_name = _text(request, "env")
        if env_name is not None:
            reader.check_game(env_name, "")
        kind = _choice(request, "kind", None, MATCH_KINDS)
        page_no = _int(request, "page", 1, 1, 1_000_000)
        sprt_only = _choice(request, "sprt", None, ("1",)) == "1"
        matches = reader.matches(env_name, kind)
        if sprt_only:
            matches = [m for m in matches if isinstance(m["params"].get("sprt"), dict)]
        shown = matches[(page_no - 1) * PAGE: page_no * PAGE]
        names = {p.id: p.full_name for p in reader.league.roster.players(include_removed=True)}
        ids = {name: pid for pid, name in names.items()}
        rows = reader.match_rows([m["id"] for m in shown])
        for m in shown:
            the_env, m["stored"] = rows.get(m["id"], (env_name, 0))
            m["sprt_record"] = reader.sprt_record(the_env, m, ids) if the_env else None
        return page("matches.html", title="matches", matches=shown, total=len(matches), page=page_no, per=PAGE,
                    kind=kind, env=env_name, kinds=MATCH_KINDS, names=names, sprt=sprt_only)

    def queue_page(request: Request) -> Response:
        batch = _text(request, "batch")
        states = request.query_params.getlist("state")
        for s in states:
            if s not in JOB_STATES:
                raise BadRequest(f"state must be one of {', '.join(JOB_STATES)}, not {s[:40]!r}")
        last = _int(request, "last", 20, 0, 10_000)
        data = reader.queue(batch, states or None, last)
        return page("queue.html", title="queue", data=data, batch=batch, states=states, last=last,
                    job_states=JOB_STATES)

    def replays_page(request: Request) -> Response:
        names = {p.id: p.full_name for p in reader.league.roster.players(include_removed=True)}
        return page("replays.html", title="replays", videos=reader.league.videos.list(), names=names)

    def replay_page(request: Request) -> Response:
        row = _video(request)
        names = {p.id: p.full_name for p in reader.league.roster.players(include_removed=True)}
        return page("replay.html", title=f"replay {row.id}", video=row, names=names,
                    playable=reader.league.videos.file(row) is not None)

    def video_file(request: Request) -> Response:
        row = _video(request)
        path = reader.league.videos.file(row)
        if path is None:
            raise NotFound(f"recording {row.id}'s file is not in the league's videos folder")
        media = "video/mp4" if path.suffix.lower() == ".mp4" else "image/gif" if path.suffix.lower() == ".gif" \
            else "application/octet-stream"
        return FileResponse(path, media_type=media)

    def _video(request: Request) -> Any:
        vid = _path_int(request, "video_id")
        row = reader.league.videos.get(vid)
        if row is None:
            raise NotFound(f"no recording with id {vid}")
        return row

    def health(request: Request) -> Response:
        return JSONResponse(fits.health())

    async def http_error(request: Request, exc: Exception) -> Response:
        status = getattr(exc, "status_code", 500)
        detail = getattr(exc, "detail", "") or ""
        return page("error.html", status=status, title=f"{status}", status_code=status, detail=detail)

    async def not_found(request: Request, exc: Exception) -> Response:
        return page("error.html", status=404, title="404", status_code=404, detail=str(exc))

    async def bad_value(request: Request, exc: Exception) -> Response:
        return page("error.html", status=400, title="400", status_code=400, detail=str(exc))

    async def crashed(request: Request, exc: Exception) -> Response:
        log.error("marl serve: %s on %s: %s", type(exc).__name__, request.url.path, exc)
        return page("error.html", status=500, title="500", status_code=500,
                    detail="the page could not be made (the server's log says why)")

    def guarded(endpoint: Any) -> Any:
        """The endpoint, with what nobody foresaw as a 500 page and one line in the server's log (no traceback)."""

        def run(request: Request) -> Response:
            try:
                return endpoint(request)
            except (HTTPException, NotFound, LeagueError, ValueError):
                raise
            except Exception as e:
                said = " ".join(str(e).split())[:300]
                log.error("marl serve: %s on %s: %s", type(e).__name__, request.url.path, said)
                return page("error.html", status=500, title="500", status_code=500,
                            detail="the page could not be made (the server's log says why)")

        return run

    static = Path(__file__).parent / "static"
    routes = [Route(path, guarded(fn)) for path, fn in (
        ("/", home), ("/ladder", ladder_page), ("/matrix", matrix_page), ("/curves", curves_page),
        ("/player/{player_id}", player_page), ("/matches", matches_page), ("/queue", queue_page),
        ("/replays", replays_page), ("/replay/{video_id}", replay_page), ("/video/{video_id}", video_file),
        ("/health", health))] + [
        Mount("/static", app=StaticFiles(directory=static), name="static"),
    ]
    handlers = {HTTPException: http_error, NotFound: not_found, LeagueError: not_found, ValueError: bad_value,
                Exception: crashed}

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> Any:
        fits.start()
        try:
            yield
        finally:
            fits.stop(STOP_SECONDS)

    app = Starlette(routes=routes, exception_handlers=handlers,  # type: ignore[arg-type]
                    middleware=[Middleware(_SecurityHeaders)], lifespan=lifespan)
    app.state.fits = fits
    return app


class _SecurityHeaders:
    """ASGI middleware: every response carries :data:`SECURITY_HEADERS` (no script runs, nothing is framed)."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def sending(message: Any) -> None:
            if message["type"] == "http.response.start":
                have = {k.lower() for k, _ in message.get("headers", [])}
                extra = [(k.lower().encode(), v.encode()) for k, v in SECURITY_HEADERS.items()
                         if k.lower().encode() not in have]
                message = {**message, "headers": [*message.get("headers", []), *extra]}
            await send(message)

        await self.app(scope, receive, sending)


def _path_int(request: Request, name: str) -> int:
    raw = request.path_params[name]
    if not raw.isdigit() or len(raw) > 18:
        raise HTTPException(404, f"no such page: {name} must be a whole number")
    return int(raw)
