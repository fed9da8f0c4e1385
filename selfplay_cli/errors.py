"""User-facing errors: the CLI prints these as one line on stderr and exits non-zero, never a traceback."""


class MarlError(Exception):
    """A mistake the user can fix (unknown env, missing checkpoint, bad option value, corrupt file)."""

    exit_code = 2
