"""User-facing errors, and the text rules that keep them (and every output) one line per line.

A :class:`PkmcalError` is a problem with the user's input or request (a malformed file, an
unreachable pose, an unidentifiable parameter set). The CLI prints its message on one line
and exits with code 2, without a traceback. Anything else is a bug.

* :func:`one_line` escapes the characters that break a line (``\\n``, ``\\r``, the other C0/C1
  controls, U+2028/U+2029: everything ``str.splitlines`` splits on, and the rest of the
  control characters) as ``\\n``, ``\\x1b``, ``\\u2028``. Every writer that puts user text
  (a machine name, a description, a file path) into a line-oriented output — HAL comments,
  CSV comments, error messages — passes it through here, so no input can add a line.
* :func:`line_problem` says why a text is not acceptable as a one-line field of an input
  file (``name:``, ``description:``), or None.
* :func:`recorded_sources` / :func:`record_source` / :func:`name_sources`: while one command
  runs, the loaders record which file each machine came from, so that an error raised after
  loading ("machine 'x' reaches none of the poses") names the file as well as the machine.
"""

from __future__ import annotations

import contextlib
import unicodedata
from contextvars import ContextVar
from typing import Iterator


class PkmcalError(Exception):
    """An error the user can fix; its message says what is wrong and what to do."""

    exit_code = 2


class PkmcalWarning(UserWarning):
    """Something in the user's input that looks wrong but may be meant (angles that look
    like radians, a quaternion that looks scalar-first): the CLI prints it as one
    ``pkmcal: warning:`` line; from Python it is an ordinary warning."""


class InputFileError(PkmcalError):
    """A malformed input file; the message names the file, and where known line and column."""

    def __init__(self, path: object, message: str, line: int | None = None, column: str | None = None):
        where = one_line(str(path))
        if line is not None:
            where += f", line {line}"
        if column is not None:
            where += f", column '{one_line(str(column))}'"
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line
        self.column = column


# -- one line per line ------------------------------------------------------------------------

def _breaks_lines(ch: str) -> bool:
    return unicodedata.category(ch) in ("Cc", "Zl", "Zp")


def one_line(text: str) -> str:
    """``text`` with every control or line/paragraph-separator character escaped
    (``\\n``, ``\\t``, ``\\x1b``, ``\\u2028``): printable as part of one line, and
    unambiguous (a backslash is left as it is; the escapes only stand for what they say)."""
    if text.isprintable():
        return text
    out = []
    for ch in text:
        if _breaks_lines(ch):
            out.append(repr(ch)[1:-1])
        else:
            out.append(ch)
    return "".join(out)


def line_problem(text: str, max_chars: int | None = None) -> str | None:
    """Why ``text`` cannot be a one-line field of an input file, or None: it holds a line
    break or another control character (shown escaped), or is longer than ``max_chars``."""
    bad = next((ch for ch in text if _breaks_lines(ch)), None)
    if bad is not None:
        return (f"holds a control character ({repr(bad)[1:-1]}) in '{one_line(text[:60])}'; "
                "write it on one line without control characters")
    if max_chars is not None and len(text) > max_chars:
        return f"is {len(text)} characters long; keep it to at most {max_chars}"
    return None


# -- which file a machine came from -------------------------------------------------------------

#: (kind, name, file) of every object loaded from a file during the current command.
_SOURCES: ContextVar[list[tuple[str, str, str]] | None] = ContextVar("pkmcal_sources", default=None)


@contextlib.contextmanager
def recorded_sources() -> Iterator[list[tuple[str, str, str]]]:
    """Record :func:`record_source` calls made inside the block (one CLI command)."""
    token = _SOURCES.set([])
    try:
        yield _SOURCES.get()  # type: ignore[misc]
    finally:
        _SOURCES.reset(token)


def record_source(kind: str, name: str, origin: str) -> None:
    """Note that the ``kind`` (e.g. ``"machine"``) called ``name`` came from ``origin`` (a
    file path, or ``"built-in"``); a no-op outside :func:`recorded_sources`."""
    log = _SOURCES.get()
    if log is not None and (kind, name, origin) not in log:
        log.append((kind, name, origin))


def name_sources(message: str, sources: list[tuple[str, str, str]]) -> str:
    """``message`` with ``kind 'name'`` followed by the file it came from, for every recorded
    object loaded from a file whose file the message does not already name."""
    for kind, name in dict.fromkeys((k, n) for k, n, _ in sources):
        origins = [o for k, n, o in sources if (k, n) == (kind, name)]
        files = [o for o in origins if o != "built-in"]
        phrase = f"{kind} '{name}'"
        if not files or phrase not in message or any(f in message for f in files):
            continue
        if len(origins) == 1:
            where = f"from {files[0]}"
        else:
            where = "named so by " + " and ".join("the built-in" if o == "built-in" else o for o in origins)
        message = message.replace(phrase, f"{phrase} ({where})", 1)
    return message
