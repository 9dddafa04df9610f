"""The calibration report: typed input (:mod:`.data`), figures (:mod:`.figures`), and one
self-contained HTML page (:mod:`.html`)."""

from pkmcal.report.data import (
    ErrorMap,
    HeldOutErrors,
    Identifiability,
    ParameterTable,
    ReportData,
    Residuals,
    correlation_from_covariance,
)
from pkmcal.report.html import REPORT_NAME, ReportFiles, write_report

__all__ = [
    "REPORT_NAME",
    "ErrorMap",
    "HeldOutErrors",
    "Identifiability",
    "ParameterTable",
    "ReportData",
    "ReportFiles",
    "Residuals",
    "correlation_from_covariance",
    "write_report",
]

import sys as _sys  # noqa: E402

from pkmcal.api import CallablePackage as _CallablePackage  # noqa: E402

_sys.modules[__name__].__class__ = _CallablePackage   # pkmcal.report(calibration, folder) is pkmcal.api.report (issue 27)
