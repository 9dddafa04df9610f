"""Marlin's single Z-probe results (``G30``) as pkmcal measurements of a linear delta measured
with a ``z-probe`` setup, read as :mod:`pkmcal.io.klipper_probe` reads Klipper's console.

Marlin's ``G30 X Y`` probes with the probe at X, Y and prints one line per probe
(Marlin/src/gcode/probe/G30.cpp ``GcodeSuite::G30``): ``Bed X:<x> Y:<y> Z:<z>`` in 2.1.x
(x, y to 2 decimals, z to 3), ``Bed X: <x> Y: <y> Z: <z>`` in 2.0.x and 1.1.x (a space after
each colon). X, Y are the probe's position (``probe.probe_at_point(probepos, …)`` moves the
nozzle to it less the probe's M851 x, y offset) and Z is the nozzle height at the trigger
plus the M851 z offset (Marlin/src/module/probe.cpp ``Probe::probe_at_point``:
``measured_z = run_z_probe() + offset.z``; negative: the probe below the nozzle). In the
setup's terms (Klipper's sign, :mod:`pkmcal.sensors.z_probe`: x_offset, y_offset, z_offset
with z_offset = −M851 Z), the nozzle was at (X − x_offset, Y − y_offset, Z + z_offset): the
conversion of Klipper's ``probe: at X,Y bed will contact at z=Z`` lines. Each line is one
pose, the carriage positions those of the machine file (Marlin's M665/M666 configuration,
``pkmcal import marlin``) at the nozzle position, ``probe_z`` = 0. X, Y are printed to
0.01 mm in 2.1.x: a position error below 0.005 mm.
"""

from __future__ import annotations

import os
import re

import numpy as np

from pkmcal.io.klipper_probe import LineFormat, ProbeImport, _from_lines, read_klipper_file, require_linear_delta

#: Marlin's G30 line (module docstring).
MARLIN_FORMATS = (
    LineFormat(re.compile(r"Bed X:\s*(\S+?)\s+Y:\s*(\S+?)\s+Z:\s*(\S+?)(?:\s|$)"),
               "Bed X: x Y: y Z: z (Marlin G30: the probe's position; the setup's probe offset added back)",
               "probe-point"),
)


def read_marlin_probe(path: str | os.PathLike, machine, probe_offset=(0.0, 0.0, 0.0)) -> ProbeImport:
    """The G30 results of a Marlin terminal log (module docstring) as measurements of
    ``machine`` (a linear delta whose parameters are the firmware's); ``probe_offset``
    Klipper-sign x_offset, y_offset, z_offset (mm) of the z-probe setup."""
    require_linear_delta(machine, "Marlin's probe results")
    src, text, _ = read_klipper_file(path)
    return _from_lines(src, text, machine, np.asarray(probe_offset, dtype=float), MARLIN_FORMATS, "Marlin")


__all__ = ["MARLIN_FORMATS", "read_marlin_probe"]
