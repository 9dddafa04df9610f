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

**Two configurations** (a console log). Klipper's enhanced procedure (docs/Delta_Calibrate.md)
runs DELTA_CALIBRATE, saves its result with SAVE_CONFIG, then prints the object: the probe
lines were computed by the config before the save (``machine``) and the object printed by
the one after (``object_machine``). A log with both is refused without ``object_machine``
(the same machine when nothing was saved in between; a note when the log shows a
SAVE_CONFIG after the probe lines and both are the same). The object's points are
commanded through ``object_machine`` (λ_B = IK_B(p)), i.e. its carriages stood
s = (H_B − λ_B)/d steps below their switches, which ``machine``'s readings call
λ = H_A − d s = λ_B + H_A − H_B (H the switch readings,
:attr:`~pkmcal.mechanisms.linear_delta.LinearDelta.reading_reference`; the steps per mm do
not change): every row is in ``machine``'s readings. The ``#*#`` block stores steps and
needs no second config.

**Typos.** A corrected distance more than :data:`TYPO_FRACTION` from the object's nominal
(65 mm × SCALE) is refused naming the line of its ``DELTA_ANALYZE`` value: a misplaced decimal
point (743.3 for 74.33), a digit dropped or doubled, a width typed wrong. Klipper itself only
checks the number of values (klippy/extras/delta_calibrate.py ``cmd_DELTA_ANALYZE``).
"""

from __future__ import annotations

import os
import re

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.klipper_probe import (
    SHOWN_LINES,
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
#: A DELTA_ANALYZE distance (less its pillar's width) more than this fraction from the
#: printed object's nominal is refused as a likely typo: a decimal point one place off is a
#: factor of 10, a dropped or doubled digit 10-90 %, while a printer that prints its object
#: 10 % off is beyond what this calibration starts from (its nominal config is far off).
TYPO_FRACTION = 0.10
#: Largest SCALE of the printed object: Klipper's object is 139 mm across at SCALE 1
#: (klippy/extras/delta_calibrate.py MeasureOuterRadius 65 + MeasureRidgeRadius 4.5, both sides).
MAX_SCALE = 10.0
#: DELTA_ANALYZE's other arguments (klippy/extras/delta_calibrate.py cmd_DELTA_ANALYZE): not distances.
OTHER_ARGS = ("MANUAL_HEIGHT", "CALIBRATE")
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


def read_klipper_analyze(path: str | os.PathLike, machine, probe_offset=(0.0, 0.0, 0.0),
                         object_machine=None) -> ProbeImport:
    """The printed distances and probe heights of a printer.cfg or log (module docstring) as
    measurements of ``machine`` read as pose pairs; ``machine`` is the firmware's
    configuration the probe ran with (a linear delta), ``probe_offset`` the z-probe's (mm);
    ``object_machine`` the configuration the object was printed with (a console log with
    both parts needs it: module docstring, "Two configurations")."""
    require_linear_delta(machine, "DELTA_ANALYZE results")
    src, text, saved = read_klipper_file(path)
    offset = np.asarray(probe_offset, dtype=float)
    if saved:
        if object_machine is not None:
            raise PkmcalError(f"{src}: the #*# block stores Klipper's stable positions (steps below the endstops), "
                              "which do not depend on the config: drop --object-machine")
        dist = _saved_distances(src, machine)
    else:
        dist = _logged_distances(src, text, object_machine or machine, machine)
    try:
        heights = read_klipper_probe(src, machine, offset)
    except NoProbeResults:
        heights = None
    if saved:
        _check_saved_typos(src, dist)        # after the block's own errors (its heights' numbering)
    elif heights is not None:
        dist[-1].extend(_check_configs(src, text, machine, object_machine, heights))
    return _pairs(src, dist, heights, machine)


def _check_saved_typos(src: str, dist) -> None:
    """A #*# ``distanceN`` far from the firmware's own distance between its two points
    (Klipper's ``get_position_from_stable`` of the config of this file): the measured one is
    that within a printer's error, not :data:`TYPO_FRACTION` off (module docstring, "Typos")."""
    _, _, d, cmd1, cmd2, lines, _ = dist
    nominal = np.linalg.norm(cmd1[:, :3] - cmd2[:, :3], axis=1)
    for k in range(len(d)):            # distance0, 1, ... in order (numbered_entries)
        if not abs(d[k] / nominal[k] - 1.0) <= TYPO_FRACTION:
            raise InputFileError(src, f"[delta_calibrate] distance{k} = {d[k]:g} mm is {d[k] / nominal[k]:.3g} "
                                 f"times the {nominal[k]:.4g} mm between its two points (distance{k}_pos1, "
                                 "_pos2): a likely typo; correct it (or run DELTA_ANALYZE again)", line=int(lines[k]))


def _check_configs(src: str, text: str, machine, object_machine, heights: ProbeImport) -> list[str]:
    """A console log with probe results and the object's distances needs the config the
    object was printed with (module docstring, "Two configurations"); a note when a
    SAVE_CONFIG of the log came between and that config is the probe's."""
    saves = [k for k, line in enumerate(text.splitlines(), start=1) if _SAVE.search(line)]
    probed = np.asarray(heights.measurements.lines)
    if object_machine is None:
        between = [k for k in saves if k > probed.min()]
        raise PkmcalError(f"{src}: the log has probe results (lines {probed.min()}-{probed.max()}) and the printed "
                          "object's DELTA_ANALYZE distances" + (f", with SAVE_CONFIG at line {between[0]} in between"
                                                               if between else "") + ": Klipper's procedure saves "
                          "DELTA_CALIBRATE's result (SAVE_CONFIG) before the object is printed, so the two parts ran "
                          "with different configs; give --object-machine OBJECT.yaml, the machine file of the config "
                          "the object was printed with ('pkmcal import klipper' of printer.cfg after that SAVE_CONFIG; "
                          "the --machine file itself if nothing was saved in between)")
    between = [k for k in saves if k > probed.max()]
    if between and object_machine == machine:
        return [f"{src}: SAVE_CONFIG at line {between[0]} came after the probe results, but --object-machine is the "
                "--machine's config: is it the printer.cfg that SAVE_CONFIG wrote?"]
    return []


_SAVE = re.compile(r"(?:^|[\s:$>])SAVE_CONFIG(?=\s|$)", flags=re.IGNORECASE)


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


def _logged_distances(src: str, text: str, printer, machine):
    """The 12 distances of a log's DELTA_ANALYZE commands, the object's points commanded by
    ``printer`` (the config it was printed with), their carriage positions written in
    ``machine``'s readings (module docstring, "Two configurations")."""
    entry: dict[str, list[float]] = {"SCALE": [1.0]}
    where: dict[str, int] = {}
    unknown: list[str] = []
    last_line = 0
    for k, line in enumerate(text.splitlines(), start=1):
        m = _COMMAND.search(line)
        if not m:
            continue
        for name, value in _ARG.findall(m.group(1)):
            name = name.upper()
            if name not in ANALYZE_ARGS:
                if name not in OTHER_ARGS:
                    unknown.append(f"{name} (line {k})")
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
            where[name] = k
            last_line = k
    missing = [n for n in ANALYZE_ARGS if n not in entry]
    if missing:
        raise InputFileError(src, "no complete DELTA_ANALYZE measurements found" + (f" (missing {', '.join(missing)})"
                             if len(missing) < 4 else "") + ": expected the DELTA_ANALYZE CENTER_DISTS=... "
                             "CENTER_PILLAR_WIDTHS=... OUTER_DISTS=... OUTER_PILLAR_WIDTHS=... commands, or a "
                             "printer.cfg whose #*# block holds [delta_calibrate] distanceN entries")
    scale = entry["SCALE"][0]
    if not 0 < scale <= MAX_SCALE:
        raise InputFileError(src, f"DELTA_ANALYZE SCALE must be positive and at most {MAX_SCALE:g}; got {scale!r}",
                             line=where.get("SCALE", last_line))
    d = corrected_distances(entry)
    p1, p2 = object_point_pairs(scale)
    nominal = np.linalg.norm(p2 - p1, axis=1)
    for k in range(12):
        dists, widths = ("CENTER_DISTS", "CENTER_PILLAR_WIDTHS") if k < 6 else ("OUTER_DISTS", "OUTER_PILLAR_WIDTHS")
        i = k % 6
        raw = entry[dists][i]
        if not (d[k] > 0):
            raise InputFileError(src, f"DELTA_ANALYZE {dists} value {i + 1} ({raw:g}) is not larger than its pillar's "
                                 f"width ({raw - d[k]:g}, {widths}); check the order of the values",
                                 line=where[dists])
        if abs(d[k] / nominal[k] - 1.0) > TYPO_FRACTION:
            raise InputFileError(src, f"DELTA_ANALYZE {dists} value {i + 1} ({raw:g} mm, less its pillar's width "
                                 f"{raw - d[k]:g} mm from {widths}: {d[k]:g} mm) is {d[k] / nominal[k]:.3g} times the "
                                 f"printed object's {nominal[k]:g} mm at SCALE {scale:g}: a likely typo (a misplaced "
                                 "decimal point or digit); correct the value in the log (a printer that far off is "
                                 "not calibrated by this object)", line=where[dists])
    lam = printer.ik(np.r_[p1, p2])
    if not np.all(np.isfinite(lam)):
        raise InputFileError(src, f"the calibration object at SCALE {scale:g} is out of the reach of machine "
                             f"'{printer.name}'", line=last_line)
    # the same carriage steps read in machine's frame: a carriage d*steps below its switch reads
    # H - d*steps in a config whose switch reads H (module docstring)
    lam = lam + (machine.reading_reference - printer.reading_reference)[None, :]
    notes = [f"{src}: 12 DELTA_ANALYZE distances (SCALE {scale:g}); carriage positions from machine "
             f"'{printer.name}' (the config the object was printed with)" + (
                 "" if printer is machine else f", in the readings of machine '{machine.name}'")]
    if unknown:
        shown = ", ".join(unknown[:SHOWN_LINES]) + (", ..." if len(unknown) > SHOWN_LINES else "")
        notes.append(f"{src}: {len(unknown)} DELTA_ANALYZE argument(s) that are none of Klipper's were skipped "
                     f"(Klipper ignores them too): {shown}")
    return lam[:12], lam[12:], d, p1, p2, np.full(12, last_line), notes


__all__ = ["ANALYZE_ARGS", "MEASURE_ANGLES_DEG", "corrected_distances", "object_point_pairs",
           "read_klipper_analyze"]
