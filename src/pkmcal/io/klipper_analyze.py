"""Klipper's ``DELTA_ANALYZE`` (printed-object distances) and its probe heights as pkmcal
measurements of pose pairs (:mod:`pkmcal.sensors.printed_distance`,
:mod:`pkmcal.mechanisms.pose_pairs`).

The printed object is Klipper's ``docs/prints/calibrate_size.stl``: six pillars around a
centre at the angles a_k = 210, 270, 330, 30, 90, 150° (k = 0…5), each with a ridge; in
Klipper's own numbers (``klippy/extras/delta_calibrate.py``) the ridge radius r = 4.5 mm,
the pillars' distance from the centre 65 mm, all times the object's ``SCALE`` σ (1 unless
printed scaled). With e_k = (cos a_k, sin a_k):

* the six **centre distances**: from σ r e_k to σ (65 + r) e_k, measured ``CENTER_DISTS[k]``
  less the width of the centre pillar it starts from, ``CENTER_PILLAR_WIDTHS`` taken in the
  order w_0, w_2, w_1, w_0, w_2, w_1;
* the six **outer distances**: from σ 65 e_k + σ r e_{k+2} to σ 65 e_k + σ (65 + r) e_{k+2}
  (indices mod 6), measured ``OUTER_DISTS[k]`` less ``OUTER_PILLAR_WIDTHS[k]``.

All points are at z = 0 (the first layers on the bed). Each distance is one row of the pair
machine: the carriage positions of both points, and the reading ``distance``; each probe
height is a row whose two points are one (its carriage positions twice) with the reading
``probe_z``. Two sources:

* **The SAVE_CONFIG block** (``#*#``) after ``DELTA_ANALYZE CALIBRATE=extended`` and
  ``SAVE_CONFIG``: ``[delta_calibrate] distanceN`` (the corrected distance, mm) with
  ``distanceN_pos1``, ``distanceN_pos2`` (Klipper's stable positions of the two points, steps
  below the switches), and the probe heights ``heightN``/``heightN_pos``; the stable positions
  become carriage positions with the step distances (:mod:`pkmcal.io.klipper_probe`).
* **A console or klippy log** with the ``DELTA_ANALYZE`` commands the user typed
  (``DELTA_ANALYZE CENTER_DISTS=… CENTER_PILLAR_WIDTHS=… OUTER_DISTS=…
  OUTER_PILLAR_WIDTHS=… [SCALE=…]``, on one line or several; the last value of each wins, as
  in Klipper) and its probe result lines: the points are those above, the carriage positions
  those the firmware (the machine file) commands there, λ = IK(point).

The commanded poses (``cmd_*``) are the points of each pair as the firmware believes them.
"""

from __future__ import annotations

import os
import re

import numpy as np

from pkmcal.errors import InputFileError
from pkmcal.io.klipper_probe import (
    NoProbeResults,
    ProbeImport,
    carriages_from_steps,
    numbered_entries,
    read_klipper_file,
    read_klipper_probe,
    require_linear_delta,
    saved_values,
    stable_position,
)
from pkmcal.io.measurements import Measurements
from pkmcal.sensors.printed_distance import distance_rows, height_rows

#: Klipper's calibration object (module docstring): pillar angles (deg), pillar distance
#: from the centre and ridge radius (mm, at SCALE 1).
MEASURE_ANGLES_DEG = (210.0, 270.0, 330.0, 30.0, 90.0, 150.0)
MEASURE_OUTER_RADIUS = 65.0
MEASURE_RIDGE_RADIUS = 4.5
#: The DELTA_ANALYZE arguments and how many values each takes.
ANALYZE_ARGS = {"CENTER_DISTS": 6, "CENTER_PILLAR_WIDTHS": 3, "OUTER_DISTS": 6, "OUTER_PILLAR_WIDTHS": 6,
                "SCALE": 1}
_COMMAND = re.compile(r"\bDELTA_ANALYZE\b(.*)$", flags=re.IGNORECASE)
_ARG = re.compile(r"([A-Za-z_]+)\s*=\s*(\S+)")


def object_point_pairs(scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The 12 point pairs (12, 3) and (12, 3) of Klipper's object (module docstring): the
    six centre distances, then the six outer ones."""
    a = np.deg2rad(MEASURE_ANGLES_DEG)
    e = np.stack([np.cos(a), np.sin(a), np.zeros(6)], axis=1)
    e_next = np.roll(e, -2, axis=0)                          # e_{k+2}
    inner, outer = MEASURE_RIDGE_RADIUS * scale, (MEASURE_OUTER_RADIUS + MEASURE_RIDGE_RADIUS) * scale
    start = MEASURE_OUTER_RADIUS * scale * e
    first = np.r_[inner * e, start + inner * e_next]
    second = np.r_[outer * e, start + outer * e_next]
    return first, second


def corrected_distances(entry: dict[str, list[float]]) -> np.ndarray:
    """The 12 distances (mm) of the DELTA_ANALYZE values ``entry`` (module docstring)."""
    w = entry["CENTER_PILLAR_WIDTHS"]
    centre = np.asarray(entry["CENTER_DISTS"]) - np.array([w[0], w[2], w[1], w[0], w[2], w[1]])
    return np.r_[centre, np.asarray(entry["OUTER_DISTS"]) - np.asarray(entry["OUTER_PILLAR_WIDTHS"])]


def read_klipper_analyze(path: str | os.PathLike, machine, probe_offset=(0.0, 0.0, 0.0)) -> ProbeImport:
    """The printed distances and probe heights of a printer.cfg or log (module docstring) as
    measurements of ``machine`` read as pose pairs; ``machine`` is the firmware's
    configuration (a linear delta), ``probe_offset`` the z-probe's (mm)."""
    require_linear_delta(machine, "DELTA_ANALYZE results")
    src, text, saved = read_klipper_file(path)
    offset = np.asarray(probe_offset, dtype=float)
    if saved:
        dist = _saved_distances(src, machine)
    else:
        dist = _logged_distances(src, text, machine)
    try:
        heights = read_klipper_probe(src, machine, offset)
    except NoProbeResults:
        heights = None
    return _pairs(src, dist, heights, machine)


def _pairs(src, dist, heights, machine) -> ProbeImport:
    """Height rows (each pose twice) then distance rows, as one pair measurement set."""
    lam1, lam2, d, cmd1, cmd2, lines, notes = dist
    q, y, c = distance_rows(lam1, lam2, d, cmd1, cmd2)
    parts_q, parts_y, parts_c, parts_l = [q], [y], [c], [lines]
    if heights is not None:
        h = heights.measurements
        q, y, c = height_rows(h.actuators, h.readings[:, 0], h.commanded)
        parts_q.insert(0, q)
        parts_y.insert(0, y)
        parts_c.insert(0, c)
        parts_l.insert(0, np.asarray(h.lines))
        notes = list(heights.notes) + notes
    else:
        notes.append(f"{src}: no probe heights found: the distances alone do not fix the endstops; add the "
                     "DELTA_CALIBRATE results (the printer.cfg #*# block, or the probe lines of the log)")
    q = np.concatenate(parts_q)
    meas = Measurements(actuators=q, readings=np.concatenate(parts_y), commanded=np.concatenate(parts_c),
                        source=src, lines=np.concatenate(parts_l), rows=np.arange(1, len(q) + 1))
    return ProbeImport(meas, tuple(notes))


def _saved_distances(src: str, machine):
    values = saved_values(src)
    section = "delta_calibrate"
    found = []
    for n, key, value, where, line in numbered_entries(values, "distance"):
        try:
            d = float(value)
        except ValueError:
            raise InputFileError(where, f"[delta_calibrate] {key}: expected a number, got '{value}'", line=line) \
                from None
        if not (np.isfinite(d) and d > 0):
            raise InputFileError(where, f"[delta_calibrate] {key}: expected a positive distance, got '{value}'",
                                 line=line)
        pos = []
        for suffix in ("_pos1", "_pos2"):
            if (section, key + suffix) not in values:
                raise InputFileError(where, f"[delta_calibrate] {key} has no {key}{suffix}", line=line)
            pv, pwhere, pline = values[(section, key + suffix)]
            pos.append(stable_position(pv, pwhere, pline, key + suffix))
        found.append((n, d, pos[0], pos[1], line or 0))
    if not found:
        raise InputFileError(src, "the #*# block has no [delta_calibrate] distanceN entries; run DELTA_ANALYZE with "
                             "the measured distances, then DELTA_ANALYZE CALIBRATE=extended and SAVE_CONFIG")
    steps = np.array([f[2] for f in found] + [f[3] for f in found])
    lam, step = carriages_from_steps(values, steps, machine, src)
    n = len(found)
    fk = machine.fk(lam)
    if not np.all(fk.converged):
        k = int(np.flatnonzero(~fk.converged)[0]) % n
        raise InputFileError(src, f"distance{found[k][0]}: the carriages are out of the reach of machine "
                             f"'{machine.name}'; is it the machine file of this printer.cfg?", line=found[k][4])
    notes = [f"{src}: {n} DELTA_ANALYZE distance(s) from the #*# block; step distances "
             f"{', '.join(f'{d:.6g}' for d in step)} mm"]
    return (lam[:n], lam[n:], np.array([f[1] for f in found]), fk.poses[:n], fk.poses[n:],
            np.array([f[4] for f in found]), notes)


def _logged_distances(src: str, text: str, machine):
    entry: dict[str, list[float]] = {"SCALE": [1.0]}
    last_line = 0
    for k, line in enumerate(text.splitlines(), start=1):
        m = _COMMAND.search(line)
        if not m:
            continue
        for name, value in _ARG.findall(m.group(1)):
            name = name.upper()
            if name not in ANALYZE_ARGS:
                continue
            try:
                parts = [float(v) for v in value.split(",")]
            except ValueError:
                raise InputFileError(src, f"DELTA_ANALYZE {name}: cannot read '{value}' (expected "
                                     f"{ANALYZE_ARGS[name]} numbers separated by commas)", line=k) from None
            if len(parts) != ANALYZE_ARGS[name] or not all(np.isfinite(parts)):
                raise InputFileError(src, f"DELTA_ANALYZE {name} must have {ANALYZE_ARGS[name]} finite value(s); "
                                     f"got '{value}'", line=k)
            entry[name] = parts
            last_line = k
    missing = [n for n in ANALYZE_ARGS if n not in entry]
    if missing:
        raise InputFileError(src, "no complete DELTA_ANALYZE measurements found" + (f" (missing {', '.join(missing)})"
                             if len(missing) < 4 else "") + ": expected the DELTA_ANALYZE CENTER_DISTS=... "
                             "CENTER_PILLAR_WIDTHS=... OUTER_DISTS=... OUTER_PILLAR_WIDTHS=... commands, or a "
                             "printer.cfg whose #*# block holds [delta_calibrate] distanceN entries")
    scale = entry["SCALE"][0]
    if not scale > 0:
        raise InputFileError(src, f"DELTA_ANALYZE SCALE must be positive; got {scale!r}", line=last_line)
    d = corrected_distances(entry)
    if not np.all(d > 0):
        k = int(np.flatnonzero(~(d > 0))[0])
        raise InputFileError(src, f"DELTA_ANALYZE distance {k + 1} is not positive after subtracting its pillar width "
                             f"({d[k]:g} mm); check the order of the values", line=last_line)
    p1, p2 = object_point_pairs(scale)
    lam = machine.ik(np.r_[p1, p2])
    if not np.all(np.isfinite(lam)):
        raise InputFileError(src, f"the calibration object at SCALE {scale:g} is out of the reach of machine "
                             f"'{machine.name}'", line=last_line)
    notes = [f"{src}: 12 DELTA_ANALYZE distances (SCALE {scale:g}); carriage positions from machine "
             f"'{machine.name}' (its firmware configuration)"]
    return lam[:12], lam[12:], d, p1, p2, np.full(12, last_line), notes


__all__ = ["ANALYZE_ARGS", "MEASURE_ANGLES_DEG", "corrected_distances", "object_point_pairs",
           "read_klipper_analyze"]
