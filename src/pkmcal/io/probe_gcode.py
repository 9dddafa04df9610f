"""A Z-probe plan as something a printer runs: a Klipper macro of ``G1``/``PROBE`` moves and a
Marlin G-code file of ``G30`` probes, each of whose console output is what ``pkmcal import
klipper-probe`` / ``pkmcal import marlin-probe`` read back (:mod:`pkmcal.io.klipper_probe`).

The plan's poses are nozzle positions on the bed (``pkmcal plan`` with a Z probe:
:mod:`pkmcal.planning.candidates`, "On the bed"); the probe point is the nozzle plus the
setup's probe offset (x_offset, y_offset; Klipper's sign, :mod:`pkmcal.sensors.z_probe`).

* **Klipper** (:func:`klipper_probe_macro`): a ``[gcode_macro PKMCAL_PROBE_PLAN]`` section to
  paste into printer.cfg (or ``[include]``). ``PROBE`` probes at the toolhead's current x, y
  (klippy/extras/probe.py ``PrinterProbe.cmd_PROBE`` → ``run_probe`` → ``_probe``, which
  moves z only), so each point is a ``G1 X Y`` of the *nozzle* (the probe point less the
  probe's x, y offset) at the travel height, then ``PROBE``, then back up. Klipper prints
  ``probe at X,Y is z=Z`` per sample (``_probe``: the toolhead position at the trigger,
  ``%.3f,%.3f`` and ``%.6f``; Klipper from 2024 prints ``probe: at X,Y bed will contact at
  z=Z``, the probe point), which ``import klipper-probe`` reads. The travel height is
  Klipper's default ``horizontal_move_z`` of 5 mm (probe.py ``ProbePointsHelper.__init__``)
  above the trigger height (the nozzle at z_offset: ``start_probe`` refuses a
  horizontal_move_z below the z_offset). The macro homes first (``G28``): ``_probe`` refuses
  to probe unhomed ("Must home before probe").
* **Marlin** (:func:`marlin_probe_gcode`): ``G28``, the travel height, then one
  ``G30 X Y`` per point. Marlin's G30 takes the *probe's* position
  (Marlin/src/gcode/probe/G30.cpp ``GcodeSuite::G30``: ``probe.probe_at_point(probepos, …)``,
  the nozzle moved to it less the probe's offset) and prints
  ``Bed X:<x> Y:<y> Z:<z>`` (x, y to 2 decimals, z to 3; Marlin 2.0.x with a space after each
  colon), z the nozzle height at the trigger plus the probe's M851 z offset (negative: the
  probe below the nozzle), i.e. Klipper's z less z_offset. The points are written to the
  2 decimals Marlin echoes, so that the echoed points are the planned ones.

Coordinates in mm; Klipper's points to 3 decimals (what its console prints back).
"""

from __future__ import annotations

import numpy as np

#: Klipper's default horizontal_move_z (mm): the travel height above the trigger height
#: (klippy/extras/probe.py ProbePointsHelper.__init__).
HORIZONTAL_MOVE_Z = 5.0
#: Travel and lift speeds (mm/min in G-code F words): Klipper's probe-points helper default
#: speed 50 mm/s (also its first move down from home: ``ProbePointsHelper._move_next``, "Use
#: full speed to first probe position") and its probe's default lift speed 5 mm/s
#: (probe.py ``ProbePointsHelper.__init__``, ``PrinterProbe.__init__``).
TRAVEL_F = 3000
LIFT_F = 300
#: The macro's name (Klipper upper-cases G-code commands).
MACRO_NAME = "PKMCAL_PROBE_PLAN"


def _travel_z(probe_offset) -> float:
    return HORIZONTAL_MOVE_Z + max(float(probe_offset[2]), 0.0)


def klipper_probe_macro(nozzle_xy: np.ndarray, probe_offset, header: list[str]) -> str:
    """The Klipper macro (module docstring) probing at the nozzle positions ``nozzle_xy``
    (N, 2) mm; ``probe_offset`` the setup's (x, y, z) mm; ``header`` comment lines."""
    z = _travel_z(probe_offset)
    off = np.asarray(probe_offset, dtype=float)
    lines = [f"# {h}" for h in header]
    lines += [f"[gcode_macro {MACRO_NAME}]", f"description: pkmcal plan: probe {len(nozzle_xy)} points on the bed",
              "gcode:", "    G28", "    G90", f"    G1 Z{z:.3f} F{TRAVEL_F}"]
    for k, (x, y) in enumerate(np.asarray(nozzle_xy, dtype=float), start=1):
        lines += [f"    # point {k} of {len(nozzle_xy)}: the probe point at {x + off[0]:.3f}, {y + off[1]:.3f}",
                  f"    G1 X{x:.3f} Y{y:.3f} F{TRAVEL_F}", "    PROBE", f"    G1 Z{z:.3f} F{LIFT_F}"]
    return "\n".join(lines) + "\n"


def marlin_probe_gcode(probe_xy: np.ndarray, probe_offset, header: list[str]) -> str:
    """The Marlin G-code (module docstring) probing at the probe-point positions ``probe_xy``
    (N, 2) mm; ``probe_offset`` the setup's (x, y, z) mm; ``header`` comment lines."""
    z = _travel_z(probe_offset)
    lines = [f"; {h}" for h in header]
    lines += ["G28", "G90", f"G1 Z{z:.3f} F{TRAVEL_F}"]
    for k, (x, y) in enumerate(np.asarray(probe_xy, dtype=float), start=1):
        lines.append(f"G30 X{x:.2f} Y{y:.2f} ; point {k} of {len(probe_xy)} (the probe's position)")
    return "\n".join(lines) + "\n"


def marlin_points(probe_xy: np.ndarray) -> np.ndarray:
    """The probe points as Marlin's G30 receives and echoes them (2 decimals)."""
    return np.round(np.asarray(probe_xy, dtype=float), 2)


def klipper_points(nozzle_xy: np.ndarray) -> np.ndarray:
    """The nozzle positions as the macro's G1 moves give them (3 decimals)."""
    return np.round(np.asarray(nozzle_xy, dtype=float), 3)


__all__ = ["HORIZONTAL_MOVE_Z", "MACRO_NAME", "klipper_points", "klipper_probe_macro", "marlin_points",
           "marlin_probe_gcode"]
