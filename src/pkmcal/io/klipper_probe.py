"""Klipper's Z-probe results as pkmcal measurements (actuator readings + ``probe_z``) of a
linear delta measured with a ``z-probe`` setup (:mod:`pkmcal.sensors.z_probe`).

Two sources a Klipper user has:

* **Console or log lines** of ``PROBE``, ``PROBE_ACCURACY``, ``DELTA_CALIBRATE``,
  ``BED_MESH_CALIBRATE`` (Mainsail/Fluidd console, OctoPrint terminal, klippy.log; any
  prefix such as ``// `` or ``Recv: // `` is skipped), in either of Klipper's formats:

  - ``probe at X,Y is z=Z`` (Klipper before 2024): X, Y, Z the toolhead (nozzle)
    position at the trigger, computed by the firmware from the stepper positions;
  - ``probe: at X,Y bed will contact at z=Z`` (later Klipper): X, Y the probe's point
    (nozzle + x_offset, y_offset) and Z the nozzle height less z_offset, so the nozzle was
    at (X − x_offset, Y − y_offset, Z + z_offset).

  Each line is one pose: the carriage positions are those the firmware computed the
  position from, λ = IK(nozzle) of the machine file (the firmware's own configuration: its
  readings are Klipper's stepper positions), and the probe point touched the bed,
  ``probe_z`` = 0. The logged X, Y have 3 decimals (±0.0005 mm; a carriage error below
  that) and Z has 6. ``Result is z=`` lines (a repeat of the samples' average or median) are
  not poses and are skipped.

* **The SAVE_CONFIG block** (``#*#``) of ``printer.cfg`` after ``DELTA_CALIBRATE``, read as
  Klipper reads it (:mod:`pkmcal.io.klipper_config`: a block that anything follows is ignored,
  and said so); the setup's probe x, y offsets must be the config's ``[probe]``/``[bltouch]``
  ones (:func:`check_probe_offset`):
  ``[delta_calibrate] heightN = H`` and ``heightN_pos = a,b,c``, Klipper's *stable
  positions*: the steps each carriage travelled down from its endstop switch, independent of
  the kinematic parameters. With the step distance d of each tower
  (``rotation_distance / (full_steps_per_rotation · microsteps · gear ratio)``, or the older
  ``step_distance``), a carriage is d·steps below its switch, so its reading is
  λ = H^fw − d·steps (H^fw the switch reading of the machine file,
  :attr:`~pkmcal.mechanisms.linear_delta.LinearDelta.reading_reference`). H is the nozzle's
  height above the bed when the probe triggered (Klipper stores its z_offset): the probe
  point was at H − z_offset above the bed, ``probe_z`` = H − z_offset of the setup (0 when
  the setup's offset is the one the calibration ran with). ``manual_heightN`` entries
  (nozzle heights measured by hand) are not probe readings and are skipped with a note.
  The entries are numbered as Klipper reads them back (:func:`numbered_entries`: ``height0``,
  ``height1``, ... to the first missing); one Klipper would not read is an error.

The machine is a linear delta (:func:`require_linear_delta`): carriage readings and stable
positions are Klipper's ``kinematics: delta``'s.

The measurements carry the firmware's belief of each pose as the commanded pose
(``cmd_x, cmd_y, cmd_z``: the logged nozzle position, or the machine's FK of λ).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.inputs import read_input_bytes
from pkmcal.io.measurements import Measurements

_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
#: Klipper before 2024: the nozzle position at the trigger.
OLD_LINE = re.compile(rf"probe at {_NUM}\s*,\s*{_NUM} is z={_NUM}")
#: Later Klipper: the probe point x, y and the nozzle z less z_offset.
NEW_LINE = re.compile(rf"probe: at {_NUM}\s*,\s*{_NUM} bed will contact at z={_NUM}")


class NoProbeResults(InputFileError):
    """A Klipper file without probe results (a printed-distance import may still read it)."""


@dataclass(frozen=True)
class ProbeImport:
    """What :func:`read_klipper_probe` found: the measurements and notes for the user."""

    measurements: Measurements
    notes: tuple[str, ...]


def read_klipper_probe(path: str | os.PathLike, machine, probe_offset=(0.0, 0.0, 0.0)) -> ProbeImport:
    """The probe results of a Klipper log or printer.cfg (module docstring) as measurements
    of ``machine`` (a linear delta whose parameters are the firmware's); ``probe_offset``
    Klipper's x_offset, y_offset, z_offset (mm), as in the z-probe setup."""
    require_linear_delta(machine, "Klipper's probe results")
    src, text, saved = read_klipper_file(path)
    offset = np.asarray(probe_offset, dtype=float)
    if saved:
        return _from_saved_block(src, machine, offset)
    return _from_lines(src, text, machine, offset)


def require_linear_delta(machine, what: str, option: str | None = None) -> None:
    """Refuse a ``machine`` that is not a linear delta: ``what`` (Klipper's probe results, its
    DELTA_ANALYZE distances) are carriage positions of Klipper's ``kinematics: delta``, and
    a stable position counts steps below a carriage's endstop. ``option``: how the user gave
    the machine (``--machine kossel.yaml``), named in the message."""
    if machine.kind != "linear-delta":
        given = f"{option}: " if option else ""
        raise PkmcalError(f"{given}{what} are read with a linear delta printer (Klipper's 'kinematics: delta'); machine "
                          f"'{machine.name}' is a {machine.kind or 'machine of another kind'}: give the printer's "
                          "machine file (pkmcal import klipper printer.cfg) or a built-in linear delta (kossel-mini)")


def read_klipper_file(path: str | os.PathLike) -> tuple[str, str, bool]:
    """(path, text, whether it is a printer.cfg with a DELTA_CALIBRATE ``#*#`` block)."""
    src = os.fspath(path)
    # a console log may hold bytes of any encoding around the probe lines, which are ASCII
    text = read_input_bytes(src, "Klipper file").decode("utf-8", errors="replace")
    return src, text, any(line.startswith("#*#") for line in text.splitlines()) and "[delta_calibrate]" in text


def _from_lines(src: str, text: str, machine, offset: np.ndarray) -> ProbeImport:
    nozzle, lines, formats = [], [], set()
    for k, line in enumerate(text.splitlines(), start=1):
        m_old, m_new = OLD_LINE.search(line), NEW_LINE.search(line)
        if m_old:
            x, y, z = (float(v) for v in m_old.groups())
            formats.add("probe at X,Y is z=Z (nozzle position)")
        elif m_new:
            bx, by, bz = (float(v) for v in m_new.groups())
            x, y, z = bx - offset[0], by - offset[1], bz + offset[2]
            formats.add("probe: at X,Y bed will contact at z=Z (probe point; the setup's probe offset added back)")
        else:
            continue
        if not all(np.isfinite([x, y, z])):
            raise InputFileError(src, "a probe position is not a finite number", line=k)
        nozzle.append((x, y, z))
        lines.append(k)
    if not nozzle:
        raise NoProbeResults(src, "no probe results found: expected Klipper lines 'probe at X,Y is z=Z' or "
                             "'probe: at X,Y bed will contact at z=Z' (PROBE, PROBE_ACCURACY, DELTA_CALIBRATE "
                             "output), or a printer.cfg with a DELTA_CALIBRATE #*# block")
    poses = np.array(nozzle)
    lam = machine.ik(poses)
    _check_reach(src, lam, np.array(lines), machine)
    meas = Measurements(actuators=lam, readings=np.zeros((len(poses), 1)), commanded=poses, source=src,
                        lines=np.array(lines), rows=np.arange(1, len(poses) + 1))
    notes = [f"{src}: {len(poses)} probe result(s), format {', '.join(sorted(formats))}; carriage positions "
             f"from machine '{machine.name}' (its firmware configuration)"]
    return ProbeImport(meas, tuple(notes))


def _check_reach(src, lam, lines, machine) -> None:
    bad = ~np.all(np.isfinite(lam), axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputFileError(src, f"this probe position is out of the reach of machine '{machine.name}'; is it "
                             "the machine file of this printer's configuration?", line=int(lines[k]))


def _step_distance(values, tower: str, src: str) -> float:
    """Klipper's step distance of ``[stepper_<tower>]`` (mm per step)."""
    section = f"stepper_{tower}"

    def get(key):
        entry = values.get((section, key))
        return None if entry is None else entry

    def number(key, entry):
        value, where, line = entry
        try:
            v = float(value)
        except ValueError:
            raise InputFileError(where, f"[{section}] {key}: expected a number, got '{value}'", line=line) from None
        if not (np.isfinite(v) and v > 0):
            raise InputFileError(where, f"[{section}] {key}: expected a positive number, got '{value}'", line=line)
        return v

    if get("rotation_distance") is not None:
        rotation = number("rotation_distance", get("rotation_distance"))
        if get("microsteps") is None:
            raise InputFileError(src, f"[{section}] has rotation_distance but no microsteps; Klipper needs both")
        micro = number("microsteps", get("microsteps"))
        full = number("full_steps_per_rotation", get("full_steps_per_rotation")) \
            if get("full_steps_per_rotation") is not None else 200.0
        gear = 1.0
        if get("gear_ratio") is not None:
            value, where, line = get("gear_ratio")
            for pair in value.split(","):
                parts = pair.split(":")
                try:
                    g1, g2 = (float(p) for p in parts)
                except ValueError:
                    raise InputFileError(where, f"[{section}] gear_ratio: expected pairs 'A:B' separated by commas, "
                                         f"got '{value}'", line=line) from None
                if not (g1 > 0 and g2 > 0):
                    raise InputFileError(where, f"[{section}] gear_ratio: '{pair.strip()}' must be positive",
                                         line=line)
                gear *= g1 / g2
        return rotation / (full * micro * gear)
    if get("step_distance") is not None:
        return number("step_distance", get("step_distance"))
    raise InputFileError(src, f"[{section}] has neither rotation_distance (with microsteps) nor step_distance: "
                         "the stable positions of the #*# block count steps, whose length is needed")


def stable_position(value: str, where: str, line: int | None, key: str) -> np.ndarray:
    parts = value.split(",")
    try:
        spos = np.array([float(p) for p in parts])
    except ValueError:
        spos = np.zeros(0)
    if spos.shape != (3,) or not np.all(np.isfinite(spos)):
        raise InputFileError(where, f"[delta_calibrate] {key}: expected three step counts 'a,b,c', got '{value}'",
                             line=line)
    return spos


def saved_values(src: str) -> dict[tuple[str, str], tuple[str, str, int | None]]:
    """(section, key) → (value, file, line) of a Klipper config with its includes and
    ``#*#`` block, as Klipper reads them (:func:`pkmcal.io.klipper_config.read_config`)."""
    from pkmcal.io.klipper_config import read_config

    return {k: (o.value, o.path, o.line) for k, o in read_config(src).options.items()}


def carriages_from_steps(values, steps: np.ndarray, machine, src: str) -> tuple[np.ndarray, np.ndarray]:
    """Carriage readings λ = H^fw − d·steps (N, 3) of Klipper's stable positions ``steps``
    (N, 3), and the step distances d (3,) of ``[stepper_a|b|c]`` (module docstring)."""
    dist = np.array([_step_distance(values, t, src) for t in ("a", "b", "c")])
    return machine.reading_reference[None, :] - steps * dist[None, :], dist


def check_probe_offset(src: str, offset: np.ndarray) -> list[str]:
    """The setup's probe offset against the printer.cfg's ``[probe]``/``[bltouch]``
    (:func:`pkmcal.io.delta_firmware.read_klipper_printer`): an x, y that differ is an error
    (the probe points would be wrong), a z that differs a note (a z_offset changed since)."""
    from pkmcal.io.delta_firmware import read_klipper_printer

    try:
        printer = read_klipper_printer(src)
    except InputFileError:
        return []                        # not a delta printer.cfg: nothing to compare with
    if printer.probe_offset is None:
        return []
    cfg = np.array(printer.probe_offset)
    if np.any(cfg[:2] != offset[:2]):
        raise InputFileError(src, f"[{printer.probe_section}] x_offset, y_offset are {cfg[0]:g}, {cfg[1]:g} mm but the "
                             f"setup's probe_offset has {offset[0]:g}, {offset[1]:g}: give the setup of this probe "
                             f"(pkmcal import klipper {src} --setup-output PROBE.yaml)")
    if cfg[2] != offset[2]:
        return [f"{src}: [{printer.probe_section}] z_offset {cfg[2]:g} mm, the setup's {offset[2]:g} mm: probe_z uses "
                "the setup's"]
    return []


def numbered_entries(values, name: str) -> list[tuple[int, str, str, str, int | None]]:
    """``(N, key, value, file, line)`` of the ``[delta_calibrate] <name>N`` entries, N = 0, 1,
    2, ..., as Klipper reads them back (klippy/extras/delta_calibrate.py,
    ``DeltaCalibrate.__init__``: ``<name>0``, ``<name>1``, ... up to the first one missing).
    Klipper refuses at start-up an option that no module reads (klippy/configfile.py,
    ``check_unused``), so an entry it would not read — a number with a leading zero
    (``height00``, which would also be ``height0``'s number here), or one after a gap — is an
    error naming it."""
    rx = re.compile(rf"^{re.escape(name)}([0-9]+)$")
    found: dict[int, tuple[str, str, str, int | None]] = {}
    for (section, key), (value, where, line) in values.items():
        m = rx.match(key) if section == "delta_calibrate" else None
        if m is None:
            continue
        if m.group(1) != str(int(m.group(1))):
            raise InputFileError(where, f"[delta_calibrate] {key}: Klipper numbers these entries {name}0, {name}1, ... "
                                 f"without leading zeros, and refuses '{key}' as an option it does not read; rename or "
                                 "remove it", line=line)
        found[int(m.group(1))] = (key, value, where, line)
    for n in sorted(found):
        if n > 0 and n - 1 not in found:
            key, _, where, line = found[n]
            raise InputFileError(where, f"[delta_calibrate] {key}: there is no {name}{n - 1}; Klipper reads {name}0, "
                                 f"{name}1, ... up to the first one missing, and refuses '{key}' as an option it does "
                                 f"not read; number the entries from {name}0 without gaps", line=line)
    return [(n, *found[n]) for n in sorted(found)]


def _from_saved_block(src: str, machine, offset: np.ndarray) -> ProbeImport:
    values = saved_values(src)
    section = "delta_calibrate"
    heights = []
    for n, key, value, where, line in numbered_entries(values, "height"):
        pos_key = f"{key}_pos"
        if (section, pos_key) not in values:
            raise InputFileError(where, f"[delta_calibrate] {key} has no {pos_key}", line=line)
        try:
            h = float(value)
        except ValueError:
            raise InputFileError(where, f"[delta_calibrate] {key}: expected a number, got '{value}'", line=line) \
                from None
        pv, pwhere, pline = values[(section, pos_key)]
        heights.append((n, h, stable_position(pv, pwhere, pline, pos_key), line))
    manual = len(numbered_entries(values, "manual_height"))
    if not heights:
        from pkmcal.io.klipper_config import read_config

        ignored = [n.split(": ", 1)[1] for n in read_config(src).notes if "block is ignored" in n]
        raise NoProbeResults(src, (ignored[0] if ignored else "the #*# block has no [delta_calibrate] heightN / "
                                   "heightN_pos entries; run DELTA_CALIBRATE and SAVE_CONFIG first"))
    heights.sort()
    offset_notes = check_probe_offset(src, offset)   # after the block's own errors
    lam, dist = carriages_from_steps(values, np.array([s for _, _, s, _ in heights]), machine, src)
    lines = np.array([ln if ln is not None else 0 for *_, ln in heights])
    readings = np.array([[h - offset[2]] for _, h, _, _ in heights])
    fk = machine.fk(lam)
    if not np.all(fk.converged):
        k = int(np.flatnonzero(~fk.converged)[0])
        raise InputFileError(src, f"height{heights[k][0]}_pos: the carriages are out of the reach of machine "
                             f"'{machine.name}'; is it the machine file of this printer.cfg?", line=int(lines[k]))
    meas = Measurements(actuators=lam, readings=readings, commanded=fk.poses, source=src, lines=lines,
                        rows=np.arange(1, len(heights) + 1))
    notes = [f"{src}: {len(heights)} DELTA_CALIBRATE height(s) from the #*# block; step distances "
             f"{', '.join(f'{d:.6g}' for d in dist)} mm; probe_z = height - z_offset {float(offset[2])!r} mm of the setup"]
    notes += offset_notes
    if manual:
        notes.append(f"{src}: {manual} manual_height entr{'y' if manual == 1 else 'ies'} skipped (nozzle heights "
                     "measured by hand, not probe readings)")
    return ProbeImport(meas, tuple(notes))


__all__ = ["NEW_LINE", "NoProbeResults", "OLD_LINE", "ProbeImport", "carriages_from_steps", "check_probe_offset",
           "numbered_entries", "read_klipper_file", "read_klipper_probe", "require_linear_delta", "saved_values",
           "stable_position"]
