"""The root of every exception rimless raises on purpose.

A `UserError` is a mistake in what the user gave (a parameter, a file, a command): the CLI prints its
one-line message and exits with code 2, never with a traceback. A `RunFailure` is a run that could not
produce its result although the input was valid (no gait exists, every trial failed): exit code 1, one
line on stderr.
"""


class RimlessError(Exception):
    """Base class of every rimless exception."""


class UserError(RimlessError, ValueError):
    """Bad input from the user: a parameter, a file, a field, a network command."""


class ParameterError(UserError):
    """A model or configuration parameter is invalid; the message names it."""


class InputFileError(UserError):
    """A file cannot be read or parsed; the message names the file, line and column."""


class OutputFileError(UserError):
    """An output cannot be written where the user asked (no permission, not a folder); names the path."""


class RunFailure(RimlessError, RuntimeError):
    """Valid input, no result: the message says why in a researcher's words (a reason code may follow)."""


def interrupted_by_user(err: BaseException) -> bool:
    """True if `err` is, or was caused by, a KeyboardInterrupt.

    numba re-raises a Ctrl-C that lands in compiled code as a `SystemError` chained to the
    KeyboardInterrupt; code that catches `Exception` to classify failures must re-raise such an error
    (`raise KeyboardInterrupt from err`) so that Ctrl-C still stops the command.
    """
    seen: set[int] = set()
    cur: BaseException | None = err
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return False
