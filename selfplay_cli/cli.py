"""The `marl` command line: one module per verb under ``commands/``; this file wires them, and turns everything
that can go wrong into one line on stderr and an exit code (see :mod:`selfplay_cli.errors`)."""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
import traceback
from typing import Annotated, Any, get_args

import typer
import typer.main
from typer.core import TyperArgument, TyperOption

try:  # typer >= 0.22 carries its own copy of click
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover
    from click import exceptions as click_exc  # type: ignore[no-redef]

from . import __version__
from .commands import checkpoint as checkpoint_cmd
from .commands import elo as elo_cmd
from .commands import envs as envs_cmd
from .commands import exploit as exploit_cmd
from .commands import league as league_cmd
from .commands import match as match_cmd
from .commands import queue as queue_cmd
from .commands import record as record_cmd
from .commands import serve as serve_cmd
from .commands import study as study_cmd
from .commands import train as train_cmd
from .commands import worker as worker_cmd
from .envs import UnknownEnvError
from .errors import EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_IO, EXIT_USAGE, MarlError

# Help is plain text: rich markup would swallow every [bracket] of a help text ([ppo], [default: ...]), and a
# plain help wraps to the terminal (up to 120 columns) instead of squeezing into a boxed column.
HELP_SETTINGS = {"max_content_width": 120, "help_option_names": ["--help", "-h"]}

app = typer.Typer(
    name="marl",
    help="Self-play league training and Elo evaluation of multi-agent RL policies.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings=HELP_SETTINGS,
    epilog="Exit codes: 0 success (gate passed, SPRT accepted H1); 1 gate failed, SPRT accepted H0 or exploitability "
    "above --max-exploitability; 2 a mistake "
    "in the command (bad option or value, unknown name, bad file); 3 SPRT undecided; 4 I/O or resource error "
    "(disk full, permission denied, read-only, file size limit, out of memory); 5 internal error (a bug: the "
    "traceback goes to a file); 130 interrupted; 143 stopped by SIGTERM.",
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"marl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """Self-play league training and Elo evaluation of multi-agent RL policies."""


# Each command's help is its docstring: the first paragraph is its line in `marl --help`, the rest (what a team
# name does, how long a recording is, exit codes) shows in `marl COMMAND --help`.
app.command("envs")(envs_cmd.envs)
app.command("train")(train_cmd.train)
app.add_typer(checkpoint_cmd.app, name="checkpoint", help="List, inspect, tag, remove, export and import snapshots.")
app.command("match")(match_cmd.match)
app.add_typer(elo_cmd.app, name="elo", help="Fit ratings with confidence intervals; gate a model on its strength.")
app.command("exploit")(exploit_cmd.exploit)
app.add_typer(league_cmd.app, name="league", help="The league: ladder, tournaments, score matrix, rating plots.")
app.command("record")(record_cmd.record)
app.add_typer(study_cmd.app, name="study", help="Multi-run studies: team size (train N, fly M, adapt vs afresh).")
app.command("worker", help=worker_cmd.WORKER_HELP)(worker_cmd.worker)
app.add_typer(queue_cmd.app, name="queue", help="The league's work queue: batches, jobs, workers; cancel jobs.")
app.command("serve")(serve_cmd.serve)


# ---------------------------------------------------------------------------------------------------------------
# The command tree as click sees it, with every number checked the same way everywhere.

MAX_INT = 2**53
"""No integer option takes more (a count, a step budget, a seed): beyond it nothing is meant, only overflow."""

_METAVARS = {int: "N", float: "X", str: "TEXT"}


def _annotation(param: Any) -> Any:
    desc = getattr(param, "type_descriptor", None)
    return getattr(desc, "annotation", None)


def _checked(param: Any, kind: type) -> Any:
    """A callback that refuses NaN and infinities (floats) and absurd magnitudes (ints), then runs the param's own."""
    own = param.callback
    name = param.opts[0] if param.opts and param.opts[0].startswith("-") else (param.metavar or param.name)

    def check(ctx: Any, p: Any, value: Any) -> Any:
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            if v is None or isinstance(v, bool):
                continue
            if kind is float and not math.isfinite(v):
                raise click_exc.BadParameter(f"must be a finite number, not {v}", ctx=ctx, param=p,
                                             param_hint=f"'{name}'")
            if kind is int and abs(v) > MAX_INT:
                raise click_exc.BadParameter(f"must be at most {MAX_INT:,}, not {v}", ctx=ctx, param=p,
                                             param_hint=f"'{name}'")
        return own(ctx, p, value) if own is not None else value

    return check


class _Argument(TyperArgument):
    """An argument shown the POSIX way: ``A`` when required, ``[A]`` when not (typer 0.29 writes ``{A}``), and no
    ``<str>`` type column next to its name (the help says what it takes)."""

    def _usage_display_name(self) -> str:
        name = self.display_name_raw if self.required else f"[{self.display_name_raw}]"
        return name + ("..." if self.nargs != 1 else "")

    def display_type_rich(self, ctx: Any) -> str | None:
        return None


def _number(x: float) -> str:
    return f"{x:,}" if isinstance(x, int) else f"{x:g}"


class _Option(TyperOption):
    """An option whose range reads ``1 to 10,000,000`` (typer: ``1<=x<=10000000``) and whose large whole-number
    default has thousands separators (``6,000,000``)."""

    def _get_number_range_help_str(self) -> str | None:
        low, high = self.min, self.max
        if low is None and high is None:
            return None
        if high is None:
            return f">= {_number(low)}"
        return f"<= {_number(high)}" if low is None else f"{_number(low)} to {_number(high)}"

    def _get_default_string(self, *, ctx: Any, show_default_is_str: bool, default_value: Any) -> str:
        if isinstance(default_value, int) and not isinstance(default_value, bool) and abs(default_value) >= 10_000:
            return f"{default_value:,}"
        return super()._get_default_string(ctx=ctx, show_default_is_str=show_default_is_str,
                                           default_value=default_value)


def _short_help(command: Any) -> None:
    """The one-line description in a group's list of commands: the whole first sentence, never cut with '...'."""
    if command.short_help is None and command.help:
        first = command.help.strip().split("\n\n")[0]
        command.short_help = " ".join(first.split())


def _harden(command: Any) -> None:
    """Every float option refuses NaN/inf, every int option absurd magnitudes; value-taking options show a metavar
    (N, X, TEXT, PATH) instead of typer's ``<int range>``-style type column."""
    _short_help(command)
    for param in command.params:
        if isinstance(param, TyperArgument):
            param.__class__ = _Argument
        elif type(param) is TyperOption:
            param.__class__ = _Option
        ann = _annotation(param)
        inner = get_args(ann) if ann is not None else ()
        base = next((a for a in (ann, *inner) if a in (int, float)), None)
        if base is not None:
            param.callback = _checked(param, base)
        if getattr(param, "is_flag", False) or param.metavar is not None:
            continue
        if param.param_type_name == "argument":
            param.metavar = param.name.upper()
        else:
            kinds = [a for a in (ann, *inner) if a is not type(None)]
            param.metavar = next((_METAVARS[k] for k in kinds if k in _METAVARS), "PATH")
    for sub in getattr(command, "commands", {}).values():
        _harden(sub)


class _Interrupted(Exception):
    """Ctrl-C that no command caught, carried past typer (which would turn it into a silent exit 130) to
    :func:`main`, which says so."""


def build_command() -> Any:
    """The click command tree of `marl` (what :func:`main` runs; tests walk it)."""
    command = typer.main.get_command(app)
    _harden(command)
    invoke = command.invoke

    def invoke_saying_ctrl_c(ctx: Any) -> Any:
        try:
            return invoke(ctx)
        except KeyboardInterrupt:
            raise _Interrupted from None

    command.invoke = invoke_saying_ctrl_c
    return command


# ---------------------------------------------------------------------------------------------------------------
# Errors: one line each, and an exit code that says what kind of failure it was.

_IO_HINTS = {
    "ENOSPC": "free some space on that disk and run it again",
    "EDQUOT": "the disk quota is used up: free some space",
    "EACCES": "check the permissions of that path, or use another --home",
    "EPERM": "check the permissions of that path, or use another --home",
    "EROFS": "the file system is read-only: use a writable --home (or MARL_HOME)",
    "EFBIG": "a file size limit stops the write (ulimit -f): raise it",
    "EIO": "the device reported an error: check the disk",
}
_IO_WORDS = {  # messages of libraries that wrap an OSError in their own exception
    "database or disk is full": "ENOSPC", "no space left": "ENOSPC", "file write failed": "ENOSPC",
    "readonly database": "EROFS", "read-only file system": "EROFS", "permission denied": "EACCES",
    "file too large": "EFBIG", "disk quota": "EDQUOT", "disk i/o error": "EIO",
    "unable to open database file": "EACCES",
}
_DB_URLS: dict[int, str] = {}  # id(exception) -> the database URL it came from (see _watch_databases)


def _chain(exc: BaseException) -> list[BaseException]:
    out: list[BaseException] = []
    while exc is not None and exc not in out:
        out.append(exc)
        exc = exc.__cause__ or exc.__context__  # type: ignore[assignment]
    return out


def _path_in_frames(exc: BaseException) -> str | None:
    """The file an exception was writing or reading, from the innermost frame that has one in a local variable
    (torch.save's ``f``, safetensors' ``filename``, ``path``...)."""
    tb = exc.__traceback__
    frames = []
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    for frame in reversed(frames):
        for key in ("filename", "f", "path", "tmp", "file", "target"):
            value = frame.f_locals.get(key)
            if isinstance(value, (str, os.PathLike)) and str(value):
                return os.fspath(value)  # type: ignore[arg-type]
    return None


_NOT_FOUND = ("ENOENT", "ENOTDIR", "EISDIR", "ENAMETOOLONG")  # a path that is not what it should be: a user error


def io_failure(exc: BaseException) -> tuple[int, str] | None:
    """(exit code, one line) for an exception that is an I/O or resource failure, naming the path and the cause
    and what to do: 4 (disk full, permissions, read-only, size limit, out of memory), or 2 for a path that does not
    exist or is not what it should be. None for anything else."""
    import errno as errno_mod

    for e in _chain(exc):
        if isinstance(e, MemoryError) or "can't allocate memory" in str(e).lower():
            return EXIT_IO, ("out of memory: use fewer games at once (--games, --parallel) or a smaller network "
                             f"({type(e).__name__}: {_one_line(str(e))[:120]})")
    for e in _chain(exc):
        if isinstance(e, OSError) and e.errno is not None:
            code = errno_mod.errorcode.get(e.errno, "")
            where = e.filename or _path_in_frames(exc) or "a file"
            hint = _IO_HINTS.get(code, "")
            line = f"{where}: {e.strerror or e} ({code or e.errno})" + (f"; {hint}" if hint else "")
            return (EXIT_USAGE if code in _NOT_FOUND else EXIT_IO), line
    for e in _chain(exc):
        text = str(e).lower()
        code = next((c for words, c in _IO_WORDS.items() if words in text), None)
        if code is None:
            continue
        where = _DB_URLS.get(id(e)) or _path_in_frames(e) or "a file"
        cause = str(getattr(e, "orig", None) or e).splitlines()[0].strip()
        if len(cause) > 160:
            cause = cause[:157] + "..."
        return EXIT_IO, f"{where}: {cause}; {_IO_HINTS[code]}"
    return None


def _remember_database(context: Any) -> None:
    """SQLAlchemy's ``handle_error`` hook: note the database an error came from (by the error's id)."""
    url = context.engine.url if context.engine is not None else None
    if url is not None:
        where = url.database if url.get_backend_name() == "sqlite" and url.database else url.render_as_string()
        for e in (context.sqlalchemy_exception, context.original_exception):
            if e is not None:
                _DB_URLS[id(e)] = where


def _watch_databases() -> None:
    """Remember which database an SQLAlchemy error came from, so an I/O error can name it (once per process)."""
    try:
        from sqlalchemy import event
        from sqlalchemy.engine import Engine
    except ImportError:  # pragma: no cover
        return
    if not event.contains(Engine, "handle_error", _remember_database):
        event.listen(Engine, "handle_error", _remember_database)


def _crash_report(exc: BaseException, argv: list[str]) -> str | None:
    """Write the traceback of an unexpected exception to a file; its path, or None if even that failed."""
    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    header = (f"marl {__version__} crashed at {time.strftime('%Y-%m-%d %H:%M:%S')}\n"
              f"command: marl {' '.join(argv)}\npython {sys.version.split()[0]} on {sys.platform}\n\n")
    try:
        fd, path = tempfile.mkstemp(prefix="marl-crash-", suffix=".txt")
        with os.fdopen(fd, "w") as f:
            f.write(header + text)
        return path
    except OSError:
        return None


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


_WANTS = (  # typer's (pydantic's) words for a value out of range or of the wrong type -> ours
    ("greater than or equal to", "at least {min}"), ("greater than", "more than {min}"),
    ("less than or equal to", "at most {max}"), ("less than", "less than {max}"),
    ("valid integer", "a whole number"), ("valid number", "a number"), ("valid boolean", "true or false"),
)


def _given(args: list[str], names: list[str]) -> str | None:
    """The last value typed for an option (``--games 5`` or ``--games=5``), as typed."""
    value = None
    for i, token in enumerate(args):
        for name in names:
            if token == name and i + 1 < len(args):
                value = args[i + 1]
            elif token.startswith(name + "=") and name.startswith("--"):
                value = token[len(name) + 1:]
    return value


def _bad_value(e: click_exc.BadParameter, args: list[str]) -> str | None:
    """``--games must be at least 1, not 0``: an option's bad value in our words (None if it is not one)."""
    p = e.param
    opts = [o for o in getattr(p, "opts", []) if o.startswith("-")] if p is not None else []
    if not opts or isinstance(e, click_exc.MissingParameter):
        return None
    name = max(opts, key=len)
    message = str(e.message)
    if message.startswith("must be "):
        return f"{name} {message}"
    low, high = getattr(p, "min", None), getattr(p, "max", None)
    value = _given(args, [*p.opts, *getattr(p, "secondary_opts", [])])
    try:
        nonfinite = value is not None and not math.isfinite(float(value))
    except ValueError:
        nonfinite = False
    if nonfinite:  # NaN fails every comparison: say what is wrong with it, not which bound it "broke"
        return f"{name} must be a finite number, not {value}"
    for words, wanted in _WANTS:
        if words in message:
            what = wanted.format(min=f"{low:,}" if isinstance(low, int) else low,
                                 max=f"{high:,}" if isinstance(high, int) else high)
            return f"{name} must be {what}" + (f", not {value}" if value is not None else "")
    return None


def _usage_error(e: click_exc.UsageError, args: list[str]) -> str:
    """A click usage error as one line: what is wrong (and for a missing option what it is for), and where the
    help is; the usage line too when the command line's shape is wrong (missing or unknown words)."""
    where = f" (see {e.ctx.command_path} --help)" if e.ctx is not None else ""
    if isinstance(e, click_exc.BadParameter):
        said = _bad_value(e, args)
        if said is not None:
            return said + where
    msg = _one_line(e.format_message()).rstrip(".")
    if isinstance(e, click_exc.MissingParameter) and e.param is not None and getattr(e.param, "help", None):
        what = _one_line(e.param.help).rstrip(".")
        msg += f": {what[:1].lower()}{what[1:]}"
    if e.ctx is not None and not isinstance(e, click_exc.BadParameter) or isinstance(e, click_exc.MissingParameter):
        usage = _one_line(e.ctx.get_usage()).replace("Usage: ", "") if e.ctx is not None else ""
        return f"{msg}; usage: {usage}{where}" if usage else msg
    return msg + where


MAX_WORD = 400  # characters of one word of an error line (a name, a value, a path: most paths fit) before it is cut
MAX_LINE = 2_000  # characters of a whole error line


def _shortened(line: str) -> str:
    """An error line as printed: on one line, control characters escaped, each word (a quoted name or value, a
    path) cut at :data:`MAX_WORD` characters and the whole line at :data:`MAX_LINE`, so a 10 MB name read from a
    file or typed by mistake is named, not echoed. The one place every message is shortened, whoever wrote it."""
    words = []
    for word in _one_line(line).split(" "):
        if not word.isprintable():
            word = "".join(c if c.isprintable() else repr(c)[1:-1] for c in word)
        words.append(word if len(word) <= MAX_WORD else f"{word[:MAX_WORD - 3]}...")
    text = " ".join(words)
    return text if len(text) <= MAX_LINE else f"{text[:MAX_LINE - 3]}..."


def _err(line: str) -> None:
    sys.stderr.write(_shortened(line) + "\n")
    sys.stderr.flush()


def _new_homes(undo: bool) -> None:
    """The league homes a command created (:mod:`selfplay_cli.league.home`): forgotten as a command starts (an earlier
    command of this process made them), removed while they hold nothing when it is refused (``undo``: a refused
    command leaves no league behind). Nothing is imported for a command that opened no league."""
    home = sys.modules.get("selfplay_cli.league.home")
    if home is not None and undo:
        home.undo_new_homes()
    elif home is not None:
        home.forget_new_homes()


def main(argv: list[str] | None = None) -> int:
    """Console entry point: every failure is one line on stderr and an exit code (see selfplay_cli.errors), never
    a traceback on the terminal."""
    args = list(sys.argv[1:] if argv is None else argv)
    _watch_databases()
    from .league.bounded_json import forget_said  # (light: no database code)

    forget_said()  # a row that cannot be read is said once per command
    _new_homes(undo=False)
    command = build_command()
    try:
        rv = command.main(args=args, prog_name="marl", standalone_mode=False)
    except click_exc.NoArgsIsHelpError as e:  # `marl`, `marl elo`: the help, as --help shows it
        sys.stdout.write(e.ctx.get_help() + "\n")
        return 0
    except click_exc.UsageError as e:
        _new_homes(undo=True)
        _err(f"marl: error: {_usage_error(e, args)}")
        return EXIT_USAGE
    except click_exc.ClickException as e:
        _new_homes(undo=True)
        _err(f"marl: error: {_one_line(e.format_message())}")
        return e.exit_code or EXIT_USAGE
    except (typer.Abort, KeyboardInterrupt, _Interrupted):
        _err("marl: interrupted")
        return EXIT_INTERRUPTED
    except MarlError as e:
        if e.exit_code == EXIT_USAGE:
            _new_homes(undo=True)
        _err(f"marl: {'I/O error' if e.exit_code == EXIT_IO else 'error'}: {_one_line(str(e))}")
        return e.exit_code
    except UnknownEnvError as e:  # the envs room raises its own error (it imports nothing from the project)
        _new_homes(undo=True)
        _err(f"marl: error: {e}")
        return EXIT_USAGE
    except SystemExit as e:
        return int(e.code or 0) if not isinstance(e.code, str) else EXIT_USAGE
    except Exception as e:
        io = io_failure(e)
        if io is not None:
            code, line = io
            _err(f"marl: {'I/O error' if code == EXIT_IO else 'error'}: {_one_line(line)}")
            return code
        path = _crash_report(e, args)
        where = f"the traceback is in {path}" if path else "the traceback could not be written"
        _err(f"marl: internal error (a bug in marl, please report it): {type(e).__name__}: "
             f"{_one_line(str(e))[:200]}; {where}")
        return EXIT_INTERNAL
    return rv if isinstance(rv, int) else 0


def run() -> None:
    """The ``marl`` program: :func:`main`, then out at once. Every command has closed its league, its files and its
    worker process by then; what is left is the interpreter's teardown of torch, ~0.6 s of nothing on every
    command, which ``os._exit`` skips."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
