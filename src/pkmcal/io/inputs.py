"""Input files: opened only when they are regular files, read within a size bound, decoded
as UTF-8 with the place of the first byte that is not.

Every reader of a user's file (machine and setup YAML, CSV tables, measurement files, study
files, LinuxCNC, Klipper and Marlin configurations, Klipper logs) opens it here:

* :func:`open_input` refuses what is not a regular file — a named pipe (``mkfifo``), a
  socket, a device (``/dev/stdin``, ``/dev/zero``), a folder — with an
  :class:`~pkmcal.errors.InputFileError` naming the file and what it is. The file is opened
  with ``O_NONBLOCK`` and checked with ``fstat`` on the descriptor itself, so opening a named
  pipe without a writer returns at once instead of waiting for one (a reader that used
  ``open()`` hung there forever), and a path swapped for a pipe between a check and the
  open is still refused. No pkmcal command reads an input file from standard input.
* :func:`read_input_bytes` reads the whole file, refused when it is larger than the
  reader's bound (a machine file is not 50 MB).
* :func:`read_input_text` decodes it as UTF-8 (a byte-order mark dropped), refusing a file
  with NUL bytes (not text) or with a byte sequence that is not UTF-8; the message names the
  byte offset (from 0), its line (from 1) and the byte, and says to save the file as UTF-8.
"""

from __future__ import annotations

import os
import stat
from typing import BinaryIO

from pkmcal.errors import InputFileError

#: What a file that is not a regular file is, by its ``st_mode`` type.
_KINDS = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISDIR, "a folder"))


def not_a_regular_file(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is when it is not a regular file, or None."""
    if stat.S_ISREG(mode):
        return None
    return next((what for test, what in _KINDS if test(mode)), "not a regular file")


def open_input(path: str | os.PathLike, what: str) -> BinaryIO:
    """The regular file ``path`` opened for reading bytes (module docstring); ``what`` names
    it in messages ("machine file", "Klipper config"). Raises :class:`InputFileError`."""
    src = os.fspath(path)
    try:
        fd = os.open(src, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except FileNotFoundError:
        raise InputFileError(src, f"cannot read the {what}: it does not exist; check the path") from None
    except (OSError, ValueError) as exc:    # ValueError: a NUL byte in the path
        raise InputFileError(src, f"cannot read the {what}: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        kind = not_a_regular_file(os.fstat(fd).st_mode)
        if kind is not None:
            raise InputFileError(src, f"cannot read the {what}: it is {kind}, not a file; pkmcal reads regular "
                                      "files only: save the data to a file and give its path")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_input_bytes(path: str | os.PathLike, what: str, max_bytes: int | None = None) -> bytes:
    """The bytes of the regular file ``path`` (:func:`open_input`); refused when longer
    than ``max_bytes``."""
    src = os.fspath(path)
    try:
        with open_input(src, what) as fh:
            data = fh.read() if max_bytes is None else fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputFileError(src, f"cannot read the {what}: {exc.strerror or exc}") from None
    if max_bytes is not None and len(data) > max_bytes:
        raise InputFileError(src, f"larger than {_size(max_bytes)}: not a {what}")
    return data


def decode_utf8(src: str | os.PathLike, data: bytes, what: str, fix: str = "save it as UTF-8 text") -> str:
    """``data`` (the bytes of the file ``src``) as text: UTF-8, a byte-order mark dropped;
    :class:`InputFileError` with the byte offset and line of the first byte that is not
    UTF-8, or when it holds NUL bytes (module docstring)."""
    nul = data.find(b"\x00")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        start = exc.start + (3 if data.startswith(b"\xef\xbb\xbf") else 0)
        if 0 <= nul < start:
            raise has_nul(src, nul, data.count(b"\n", 0, nul) + 1, what) from None
        raise not_utf8(src, data[start], start, data.count(b"\n", 0, start) + 1, fix) from None
    if nul >= 0:
        raise has_nul(src, nul, data.count(b"\n", 0, nul) + 1, what)
    return text


def not_utf8(src: str | os.PathLike, byte: int, offset: int, line: int, fix: str) -> InputFileError:
    """The error of a file whose byte ``byte`` at ``offset`` (from 0), on line ``line``, is not UTF-8."""
    return InputFileError(src, f"not a UTF-8 text file: byte 0x{byte:02X} at byte offset {offset} is not UTF-8; {fix}",
                          line=line)


def has_nul(src: str | os.PathLike, offset: int, line: int, what: str) -> InputFileError:
    """The error of a file with a NUL byte at ``offset`` (from 0), on line ``line``."""
    return InputFileError(src, f"contains NUL bytes (the first at byte offset {offset}): not a text {what}", line=line)


def read_input_text(path: str | os.PathLike, what: str, max_bytes: int | None = None,
                    fix: str = "save it as UTF-8 text") -> str:
    """The UTF-8 text of the regular file ``path`` (:func:`read_input_bytes`,
    :func:`decode_utf8`); ``fix`` says what to do about a file that is not UTF-8."""
    return decode_utf8(path, read_input_bytes(path, what, max_bytes), what, fix)


def _size(n: int) -> str:
    return f"{n // 1_000_000} MB" if n >= 1_000_000 else f"{n} bytes"


__all__ = ["decode_utf8", "has_nul", "not_a_regular_file", "not_utf8", "open_input", "read_input_bytes",
           "read_input_text"]
