"""User-facing errors.

A :class:`PkmcalError` is a problem with the user's input or request (a malformed file, an
unreachable pose, an unidentifiable parameter set). The CLI prints its message on one line
and exits with code 2, without a traceback. Anything else is a bug.
"""

from __future__ import annotations


class PkmcalError(Exception):
    """An error the user can fix; its message says what is wrong and what to do."""

    exit_code = 2


class InputFileError(PkmcalError):
    """A malformed input file; the message names the file, and where known line and column."""

    def __init__(self, path: object, message: str, line: int | None = None, column: str | None = None):
        where = str(path)
        if line is not None:
            where += f", line {line}"
        if column is not None:
            where += f", column '{column}'"
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line
        self.column = column
