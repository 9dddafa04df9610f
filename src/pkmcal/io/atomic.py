"""Atomic output files, and the rule that an output never overwrites an input.

A result is written to a temporary file in the target's directory and moved over the target
with :func:`os.replace` (atomic on POSIX and Windows), so a reader sees either the old file or
the complete new one, and a failed command leaves no partial output behind.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Iterable

from pkmcal.errors import PkmcalError


def _same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def check_output_path(output: str | os.PathLike, inputs: Iterable[str | os.PathLike | None]) -> None:
    """Refuse an output path that names one of the command's input files.

    Raises :class:`PkmcalError` saying which input it is and what to do.
    """
    for inp in inputs:
        if inp is None or not os.path.exists(inp):
            continue
        if _same_file(output, inp):
            raise PkmcalError(
                f"output file '{output}' is the input file '{inp}'; pkmcal never overwrites its "
                "inputs: choose another output path with -o"
            )


def _default_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same directory, then
    :func:`os.replace`). An existing file keeps its permission bits; a new one gets the
    usual ``0o666 & ~umask``. Raises :class:`PkmcalError` if the file cannot be written."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    try:
        mode = os.stat(target).st_mode & 0o7777 if target.exists() else _default_mode()
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise PkmcalError(f"cannot write '{path}': {exc.strerror or exc}; check that the directory exists "
                          "and is writable") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except OSError as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise PkmcalError(f"cannot write '{path}': {exc.strerror or exc}") from None
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """:func:`atomic_write_bytes` of ``text`` encoded as UTF-8 (``\\n`` line ends kept)."""
    atomic_write_bytes(path, text.encode("utf-8"))
