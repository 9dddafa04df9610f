"""Where a result came from: the UTC date, the command line and a fingerprint of each input,
for the calibration record ``pkmcal identify`` writes into the calibrated machine file
(docs/file-formats.md, "The calibration record").

* **Date**: the current UTC time, ISO 8601 to the second (``2026-12-01T18:30:12Z``); when the
  environment variable ``SOURCE_DATE_EPOCH`` is set (seconds since 1970-01-01 UTC, the
  reproducible-builds convention) that time instead, so that the same inputs give the same
  bytes.
* **Command line**: ``pkmcal`` and the arguments as given (:data:`ARGV_KEY` in the click
  context's ``meta``, stored by the ``pkmcal`` group), quoted for a POSIX shell.
* **Inputs**: a file's path, size and SHA-256; a built-in name as ``{"builtin": name}``
  (the pkmcal version identifies it).
"""

from __future__ import annotations

import hashlib
import os
import shlex
from datetime import datetime, timezone

import click

from pkmcal.cli.main import ARGV_KEY
from pkmcal.errors import PkmcalError


def utc_timestamp() -> str:
    """ISO 8601 UTC time of now, or of ``SOURCE_DATE_EPOCH`` when set (module docstring)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch is not None and epoch.strip():
        try:
            seconds = int(epoch.strip())
        except ValueError:
            raise PkmcalError(f"SOURCE_DATE_EPOCH='{epoch}' is not a whole number of seconds since 1970-01-01 UTC; "
                              "unset it or give e.g. SOURCE_DATE_EPOCH=1798761600") from None
        try:
            moment = datetime.fromtimestamp(seconds, tz=timezone.utc)
        except (OverflowError, OSError, ValueError):
            raise PkmcalError(f"SOURCE_DATE_EPOCH={seconds} is outside the dates this computer can represent") from None
    else:
        moment = datetime.now(tz=timezone.utc)
    return moment.strftime("%Y-%m-%dT%H:%M:%SZ")


def command_line() -> str | None:
    """``pkmcal ARGS...`` as typed (None outside a ``pkmcal`` command)."""
    ctx = click.get_current_context(silent=True)
    argv = None if ctx is None else ctx.find_root().meta.get(ARGV_KEY)
    return None if argv is None else shlex.join(["pkmcal", *argv])


def input_record(spec: str | os.PathLike) -> dict:
    """``{"file", "size_bytes", "sha256"}`` of an input file, or ``{"builtin": name}``."""
    path = os.fspath(spec)
    if not os.path.isfile(path):
        return {"builtin": path}
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return {"file": path, "size_bytes": os.path.getsize(path), "sha256": digest.hexdigest()}


__all__ = ["ARGV_KEY", "command_line", "input_record", "utc_timestamp"]
