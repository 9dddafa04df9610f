"""Where a result came from: the UTC date, the command line and a fingerprint of each input,
for the calibration record ``pkmcal identify`` writes into the calibrated machine file
(docs/file-formats.md, "The calibration record").

* **Date**: the current UTC time, ISO 8601 to the second (``2026-12-01T18:30:12Z``); when the
  environment variable ``SOURCE_DATE_EPOCH`` is set (seconds since 1970-01-01 UTC, the
  reproducible-builds convention) that time instead, so that the same inputs give the same
  bytes.
* **Command line**: given by the caller (``pkmcal`` and the arguments as typed, quoted for a
  POSIX shell, from the command line: :func:`pkmcal.cli.main.command_line`; None from Python).
* **Inputs**: a file's path, size and SHA-256; a built-in name as ``{"builtin": name}``
  (the pkmcal version identifies it).
"""

from __future__ import annotations

import hashlib
import os
from datetime import datetime, timezone

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


__all__ = ["input_record", "utc_timestamp"]
