"""A Gaussian prior as written: ``NAME=MEAN±STD`` on the command line, ``NAME: [mean, std]`` or
``"MEAN ± STD"`` in a setup file (docs/file-formats.md), in file units (mm, degrees for angle
parameters); ``NAME=±STD`` centres it on the starting machine's value.

Below every layer that reads one: the setup file (:mod:`pkmcal.io.setup_file`), the command
line and the engine's maximum a posteriori fit (:mod:`pkmcal.identification.priors`, which
resolves them against a fit's parameters and gives these names too).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError

_PM = re.compile(r"\s*(±|\+/-|\+-)\s*")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class Prior:
    """One prior as written: ``pattern`` (a name or shell pattern), ``mean`` in file units
    (mm, degrees for angles; None: the starting value of each matched parameter), ``std``
    in file units (> 0), ``source`` where it was written (for messages) and ``origin``
    the list it belongs to (``"--prior"``, or the setup file's path)."""

    pattern: str
    mean: float | None
    std: float
    source: str = "--prior"
    origin: str = "--prior"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.std) and self.std > 0):
            raise PkmcalError(f"prior '{self.pattern}' ({self.source}): the standard deviation must be a positive "
                              f"number; got {self.std:g} (to hold a parameter at a value, use --fix)")
        if self.mean is not None and not np.isfinite(self.mean):
            raise PkmcalError(f"prior '{self.pattern}' ({self.source}): the mean must be a finite number")

    def text(self) -> str:
        return f"{self.pattern}={'' if self.mean is None else f'{self.mean:g}'}±{self.std:g}"


def parse_value(text: str, pattern: str, source: str, origin: str = "--prior") -> Prior:
    """A prior from ``"MEAN ± STD"`` or ``"± STD"`` (``+-`` or ``+/-`` also)."""
    parts = _PM.split(str(text).strip())
    if len(parts) != 3 or not re.fullmatch(_NUMBER, parts[2]) or (parts[0] and not re.fullmatch(_NUMBER, parts[0])):
        raise PkmcalError(f"prior '{pattern}' ({source}): cannot read '{text}'; write MEAN±STD (or MEAN+-STD), e.g. "
                          "640±0.5, or ±STD to centre it on the machine's value")
    return Prior(pattern, None if not parts[0] else float(parts[0]), float(parts[2]), source, origin)


def parse_prior(text: str, source: str | None = None) -> Prior:
    """A prior from the command line: ``NAME=MEAN±STD`` (``L0_*=640±0.5``, ``b1.z=±0.2``)."""
    source = source or f"--prior '{text}'"
    name, eq, value = str(text).partition("=")
    if not eq or not name.strip():
        raise PkmcalError(f"{source}: write NAME=MEAN±STD (or NAME=MEAN+-STD), e.g. --prior 'L0_*=640±0.5'")
    return parse_value(value, name.strip(), source)


__all__ = ["Prior", "parse_prior", "parse_value"]
