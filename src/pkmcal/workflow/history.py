"""A calibration recorded in the fleet's history as it is written (``pkmcal identify --history
DB --serial SERIAL``): the request checked before the fit (a database that cannot take the
record is refused before anything is computed), the record added after the calibrated file
is written (:mod:`pkmcal.history.store`)."""

from __future__ import annotations

from pkmcal.history.store import check_history_request, record_identified

__all__ = ["check_history_request", "record_identified"]
