"""Plausibility bounds of the numbers and texts read from pkmcal's input files.

A value that passes the schemas must also be one a machine, a setup or a measurement can
have: no parallel kinematic machine has a dimension, a reading or a pose coordinate beyond
:data:`MAX_MAGNITUDE` (10⁶ mm = 1 km; 10⁶ degrees for angles), and values that large only come
from a wrong unit or a corrupted file. Refusing them on load keeps overflows (``1e308``
squared is infinite) out of every computation, where they would give ``inf``/``nan``
results that look like answers. Names and descriptions are one line of printable text
(:func:`pkmcal.errors.line_problem`) of at most :data:`MAX_NAME_CHARS` /
:data:`MAX_DESCRIPTION_CHARS` characters.
"""

from __future__ import annotations

import math

#: Largest magnitude accepted for a length (mm) or an angle (degrees) in an input file.
MAX_MAGNITUDE = 1e6
MAX_NAME_CHARS = 200
MAX_DESCRIPTION_CHARS = 2000


def magnitude_problem(value: float, unit: str | None = "mm") -> str | None:
    """Why ``value`` (in ``unit``, file units; None: mm or degrees) cannot be a machine's or a
    measurement's number, or None."""
    if not math.isfinite(value):
        return f"{value!r} is not a finite number"
    if abs(value) > MAX_MAGNITUDE:
        bound = f"±{MAX_MAGNITUDE:g} {unit}" if unit else f"±{MAX_MAGNITUDE:g} (mm or degrees)"
        shown = f"{value!r} {unit}" if unit else repr(value)
        return f"{shown} is beyond {bound}, larger than any machine; check the number and its unit"
    return None
