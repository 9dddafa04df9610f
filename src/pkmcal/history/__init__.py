"""Every calibration kept: a calibration history for a fleet of machines (issue 28 item 3).

* :mod:`.store`: the embedded SQLite database (one record per calibration: machine identity
  and serial, date, parameters with their covariance, instrument, held-out figures, the
  input files' SHA-256, the pkmcal version), schema versioned, written in transactions that
  concurrent writers share without losing a record.
* :mod:`.stats`: whether two calibrations differ beyond their combined uncertainty (per
  parameter z = Δ/√(σ₁² + σ₂²) and a joint χ² over the identifiable subspace), and
  statistical process control across the serials of a model (leave-one-out prediction
  limits, Student t, Bonferroni over parameters and units).
* :mod:`.plot`: a machine's parameters over time with their σ bars.

``pkmcal history`` (:mod:`pkmcal.cli.history_cmd`) is the command line; docs/history.md the
guide.
"""

from pkmcal.history.store import (
    DB_ENV,
    SCHEMA_VERSION,
    CalibrationRecord,
    History,
    add_calibrated_file,
    default_db_path,
    open_history,
    record_from_machine,
)

__all__ = ["DB_ENV", "SCHEMA_VERSION", "CalibrationRecord", "History", "add_calibrated_file", "default_db_path",
           "open_history", "record_from_machine"]
