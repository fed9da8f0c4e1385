"""User-facing errors and the exit codes of `marl` (docs/getting-started.md: "Exit codes").

The CLI prints an error as one line on stderr and exits with a code a script or CI job can act on:

====  ==========================================================================================
code  meaning
====  ==========================================================================================
0     success; ``elo gate`` passed; ``match --sprt`` accepted H1
1     ``elo gate`` failed; ``match --sprt`` accepted H0 (a verdict, not an error)
2     user error: a bad option or value, an unknown name, a bad or missing file given by the user
3     ``match --sprt`` ended undecided (``--max-games`` reached)
4     I/O or resource error: disk full, permission denied, read-only, file size limit (path and cause), out of
      memory
5     internal error: a bug in marl (the traceback is written to a file whose path the line gives)
130   interrupted (Ctrl-C)
143   stopped by SIGTERM (``marl train``: the run is kept and can be resumed)
====  ==========================================================================================
"""

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_USAGE = 2
EXIT_UNDECIDED = 3
EXIT_IO = 4
EXIT_INTERNAL = 5
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143

EXIT_CODES: dict[int, str] = {
    EXIT_OK: "success; elo gate passed; match --sprt accepted H1",
    EXIT_FAIL: "elo gate failed; match --sprt accepted H0",
    EXIT_USAGE: "user error: bad option or value, unknown name, bad file",
    EXIT_UNDECIDED: "match --sprt undecided (--max-games reached)",
    EXIT_IO: "I/O or resource error: disk full, permission denied, read-only, file size limit, out of memory",
    EXIT_INTERNAL: "internal error (a bug): the traceback is written to a file",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
    EXIT_TERMINATED: "stopped by SIGTERM (marl train: the run can be resumed)",
}


class MarlError(Exception):
    """A mistake the user can fix (unknown env, missing checkpoint, bad option value, corrupt file)."""

    exit_code = EXIT_USAGE


class MarlIOError(MarlError):
    """Reading or writing a file failed for a reason outside marl (disk full, permissions, read-only, size limit);
    the message names the path and the cause."""

    exit_code = EXIT_IO


class NonFiniteError(MarlError):
    """A number that must be finite is NaN or infinite: a game's observation or reward, a learner's loss or gradient,
    a snapshot's weights. The message names the first place it appeared.

    Exit 2 (a user error), like any other bad input: the numbers come from what the user gave marl (their game, or
    settings such as ``lr`` or ``reward_scale`` that make the learning overflow), and the fix is theirs to make;
    marl's own code is not at fault, so it is not an internal error (5), nor an I/O one (4)."""

    learner: int | None = None  # in training, the learner whose update met it (its index); None: the game's numbers
