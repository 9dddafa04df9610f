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

  Manual probing (the nozzle itself touching the bed, or measured above it), read only with
  a setup whose probe x, y offset is 0 (the nozzle is not the probe otherwise):

  - ``Z position is Z`` (MANUAL_PROBE then ACCEPT; klippy/extras/manual_probe.py
    ``ManualProbe.manual_probe_finalize``): the nozzle touched the bed at z = Z, at the x, y
    it was moved to before (the last absolute ``G0``/``G1 X Y`` of the log, as the console
    echoes typed commands, or after a ``G28`` the machine's home: the forward kinematics of
    its switch readings, klippy/kinematics/delta.py ``home_position``): ``probe_z`` =
    −z_offset (the probe point that far below the nozzle on the bed);
  - ``Adding manual height: X,Y,Z is actually z=H`` (``DELTA_ANALYZE MANUAL_HEIGHT=H``;
    klippy/extras/delta_calibrate.py ``DeltaCalibrate.add_manual_height``): the nozzle at
    X, Y, Z as the firmware believes was measured H above the bed: ``probe_z`` = H − z_offset.

  Every number is refused, naming its line, when it is not finite or beyond what any
  printer has (:func:`pkmcal.io.limits.magnitude_problem`); a line that mentions a probe
  result but is not one of these formats is counted and its line numbers shown in a note.

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
  the setup's offset is the one the calibration ran with). ``manual_heightN`` and
  ``manual_heightN_pos`` entries (the nozzle's height measured by hand, DELTA_ANALYZE
  MANUAL_HEIGHT) are read the same way, with a setup whose probe x, y offset is 0. A height
  that is not finite or beyond any printer's is refused naming its line.
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

_TOKEN = r"(\S+?)"


@dataclass(frozen=True)
class LineFormat:
    """One console line a probe result is read from: ``pattern`` (its numbers as tokens,
    read with ``float``), what it ``means`` (in the import's note), and how its numbers
    become the nozzle position and the reading: ``kind`` ``nozzle`` (x, y, z: the nozzle at
    the trigger), ``probe-point`` (x, y the probe point, z the nozzle less z_offset: the
    setup's offset added back), ``manual-height`` (the nozzle at x, y, z, actually h above
    the bed) or ``manual-touch`` (the nozzle touching the bed at z; x, y those of the last
    ``G0``/``G1`` move before it)."""

    pattern: re.Pattern
    means: str
    kind: str


#: The lines of Klipper's console (module docstring), each cited to the code that prints it.
KLIPPER_FORMATS = (
    # klippy/extras/probe.py PrinterProbe._probe: "probe at %.3f,%.3f is z=%.6f" (toolhead position)
    LineFormat(re.compile(rf"probe at {_TOKEN}\s*,\s*{_TOKEN} is z={_TOKEN}(?:\s|$)"),
               "probe at X,Y is z=Z (nozzle position)", "nozzle"),
    # Klipper from 2024, probe.py: "probe: at %.3f,%.3f bed will contact at z=%.6f"
    LineFormat(re.compile(rf"probe: at {_TOKEN}\s*,\s*{_TOKEN} bed will contact at z={_TOKEN}(?:\s|$)"),
               "probe: at X,Y bed will contact at z=Z (probe point; the setup's probe offset added back)",
               "probe-point"),
    # klippy/extras/delta_calibrate.py DeltaCalibrate.add_manual_height (DELTA_ANALYZE MANUAL_HEIGHT=H):
    # "Adding manual height: %.3f,%.3f,%.3f is actually z=%.3f"
    LineFormat(re.compile(rf"Adding manual height: {_TOKEN}\s*,\s*{_TOKEN}\s*,\s*{_TOKEN} is actually "
                          rf"z={_TOKEN}(?:\s|$)"),
               "Adding manual height: X,Y,Z is actually z=H (DELTA_ANALYZE MANUAL_HEIGHT: the nozzle at X,Y,Z is H "
               "above the bed)", "manual-height"),
    # klippy/extras/manual_probe.py ManualProbe.manual_probe_finalize (MANUAL_PROBE, ACCEPT):
    # "Z position is %.3f", the nozzle touching the bed at the x, y it was moved to
    LineFormat(re.compile(rf"Z position is {_TOKEN}(?:\s|$)"),
               "Z position is Z (MANUAL_PROBE: the nozzle touching the bed at the x, y of the last G1 move)",
               "manual-touch"),
)
#: A line that names a probe result: one that none of the formats reads is counted as
#: unreadable (shown in the import's note), never silently dropped.
_MENTIONS = re.compile(r"probe at|probe: at|bed will contact|Adding manual height|Z position is|Bed X:",
                       flags=re.IGNORECASE)
#: A typed G0/G1 move (console echo: "G1 X10 Y20", "Send: G1 ...", "$ G1 ..."), and its words.
_MOVE = re.compile(r"(?:^|[\s:$>])G0*[01](?=\s|$)(.*)$", flags=re.IGNORECASE)
_WORD = re.compile(r"\b([XY])\s*([-+]?(?:\d+\.?\d*|\.\d+))", flags=re.IGNORECASE)
_MODE = re.compile(r"(?:^|[\s:$>])G9([01])(?=\s|$)", flags=re.IGNORECASE)
_HOME = re.compile(r"(?:^|[\s:$>])G28(?=\s|$)", flags=re.IGNORECASE)
#: Unreadable lines listed in the note (the rest counted).
SHOWN_LINES = 5


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


def _from_lines(src: str, text: str, machine, offset: np.ndarray, formats=KLIPPER_FORMATS,
                firmware: str = "Klipper") -> ProbeImport:
    """The probe results of a console log's lines (module docstring) in ``formats``
    (:class:`LineFormat`), with the unreadable ones counted."""
    from pkmcal.io.limits import magnitude_problem

    nozzle, readings, lines, used = [], [], [], set()
    unreadable: list[int] = []
    xy: list[float | None] = [None, None]
    relative = False
    for k, line in enumerate(text.splitlines(), start=1):
        mode = _MODE.search(line)
        if mode:
            relative = mode.group(1) == "1"
        if _HOME.search(line) and not _MENTIONS.search(line):
            # a delta homes all towers to its switches, the toolhead then at their forward
            # kinematics (klippy/kinematics/delta.py DeltaKinematics.__init__ home_position, home)
            home = machine.fk(np.asarray(machine.reading_reference, dtype=float)[None, :]).poses[0]
            xy = [float(home[0]), float(home[1])]
            continue
        move = _MOVE.search(line)
        if move and not _MENTIONS.search(line):
            for axis, value in _WORD.findall(move.group(1)):
                i = "XY".index(axis.upper())
                xy[i] = None if relative else float(value)
            continue
        for fmt in formats:
            m = fmt.pattern.search(line)
            if m:
                break
        else:
            if _MENTIONS.search(line):
                unreadable.append(k)
            continue
        try:
            values = [float(v) for v in m.groups()]
        except ValueError:
            unreadable.append(k)
            continue
        for v in values:
            problem = magnitude_problem(v)
            if problem is not None:
                raise InputFileError(src, f"{fmt.means.split(' (')[0]}: {problem}; a probe result is a position on "
                                     "the printer: correct or delete this line", line=k)
        nozzle_k, reading = _result(src, k, fmt, values, xy, relative, offset)
        nozzle.append(nozzle_k)
        readings.append(reading)
        lines.append(k)
        used.add(fmt.means)
    if not nozzle:
        raise NoProbeResults(src, "no probe results found: expected " + ("Klipper lines 'probe at X,Y is z=Z' or "
                             "'probe: at X,Y bed will contact at z=Z' (PROBE, PROBE_ACCURACY, DELTA_CALIBRATE "
                             "output), 'Z position is Z' (MANUAL_PROBE) or 'Adding manual height: X,Y,Z is actually "
                             "z=H' (DELTA_ANALYZE MANUAL_HEIGHT), or a printer.cfg with a DELTA_CALIBRATE #*# block"
                             if firmware == "Klipper" else "Marlin's G30 lines 'Bed X: x Y: y Z: z'")
                             + (f"; {_unreadable_text(unreadable)}" if unreadable else ""))
    poses = np.array(nozzle)
    lam = machine.ik(poses)
    _check_reach(src, lam, np.array(lines), machine)
    meas = Measurements(actuators=lam, readings=np.array(readings)[:, None], commanded=poses, source=src,
                        lines=np.array(lines), rows=np.arange(1, len(poses) + 1))
    notes = [f"{src}: {len(poses)} probe result(s), format {', '.join(sorted(used))}; carriage positions "
             f"from machine '{machine.name}' (its firmware configuration)"]
    if unreadable:
        notes.append(f"{src}: {_unreadable_text(unreadable)}")
    return ProbeImport(meas, tuple(notes))


def _unreadable_text(unreadable: list[int]) -> str:
    shown = ", ".join(str(k) for k in unreadable[:SHOWN_LINES]) + (", ..." if len(unreadable) > SHOWN_LINES else "")
    return (f"{len(unreadable)} line(s) that mention a probe result could not be read and were skipped (line "
            f"{shown}); check them")


def _result(src: str, k: int, fmt: LineFormat, values: list[float], xy, relative: bool, offset: np.ndarray):
    """(nozzle position (3,), reading probe_z) of one line (:class:`LineFormat`)."""
    if fmt.kind == "nozzle":
        return tuple(values), 0.0
    if fmt.kind == "probe-point":
        return (values[0] - offset[0], values[1] - offset[1], values[2] + offset[2]), 0.0
    if offset[0] != 0 or offset[1] != 0:
        raise InputFileError(src, f"a manual probe result ({fmt.means.split(' (')[0]}) is the nozzle's, not the "
                             f"probe's: with the setup's probe x, y offset {offset[0]:g}, {offset[1]:g} mm it cannot "
                             "be read as the probe's; import the manual results with a setup whose probe_offset has "
                             "x, y 0 (e.g. the built-in z-probe-klipper)", line=k)
    if fmt.kind == "manual-height":          # the nozzle H above the bed: the probe point H - z_offset
        return tuple(values[:3]), values[3] - offset[2]
    if relative or xy[0] is None or xy[1] is None:
        raise InputFileError(src, "a MANUAL_PROBE result (Z position is Z) is read at the x, y of the last absolute "
                             "G0/G1 X Y move before it, and there is none" + (" (G91: relative moves)" if relative
                                                                              else "") + "; keep the G1 X.. Y.. "
                             "command in the log before MANUAL_PROBE", line=k)
    return (xy[0], xy[1], values[0]), -offset[2]   # the nozzle on the bed: the probe point z_offset below


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


def _saved_heights(values, name: str) -> list:
    """``(N, H, steps (3,), line)`` of the ``[delta_calibrate] <name>N`` / ``<name>N_pos``
    entries (``height``, ``manual_height``), each H a finite, plausible height."""
    from pkmcal.io.limits import magnitude_problem

    section = "delta_calibrate"
    heights = []
    for n, key, value, where, line in numbered_entries(values, name):
        pos_key = f"{key}_pos"
        if (section, pos_key) not in values:
            raise InputFileError(where, f"[delta_calibrate] {key} has no {pos_key}", line=line)
        try:
            h = float(value)
        except ValueError:
            raise InputFileError(where, f"[delta_calibrate] {key}: expected a number, got '{value}'", line=line) \
                from None
        problem = magnitude_problem(h)
        if problem is not None:
            raise InputFileError(where, f"[delta_calibrate] {key}: {problem}; correct or delete it", line=line)
        pv, pwhere, pline = values[(section, pos_key)]
        heights.append((n, h, stable_position(pv, pwhere, pline, pos_key), line))
    return sorted(heights, key=lambda h: h[0])


def _from_saved_block(src: str, machine, offset: np.ndarray) -> ProbeImport:
    values = saved_values(src)
    heights = _saved_heights(values, "height")
    manual = _saved_heights(values, "manual_height")
    if not heights and not manual:
        from pkmcal.io.klipper_config import read_config

        ignored = [n.split(": ", 1)[1] for n in read_config(src).notes if "block is ignored" in n]
        raise NoProbeResults(src, (ignored[0] if ignored else "the #*# block has no [delta_calibrate] heightN / "
                                   "heightN_pos entries; run DELTA_CALIBRATE and SAVE_CONFIG first"))
    offset_notes = check_probe_offset(src, offset)   # after the block's own errors
    if manual and (offset[0] != 0 or offset[1] != 0):
        raise InputFileError(src, f"[delta_calibrate] manual_height0: a manual height is the nozzle's, not the "
                             f"probe's: with the setup's probe x, y offset {offset[0]:g}, {offset[1]:g} mm it cannot "
                             "be read as the probe's; import it with a setup whose probe_offset has x, y 0",
                             line=manual[0][3])
    both = heights + manual
    lam, dist = carriages_from_steps(values, np.array([s for _, _, s, _ in both]), machine, src)
    lines = np.array([ln if ln is not None else 0 for *_, ln in both])
    # probe_z: the probe point's height, H - z_offset (delta_calibrate.py: heightN is the nozzle's
    # height at the trigger, Klipper stores its z_offset; manual_heightN the nozzle's measured height)
    readings = np.array([[h - offset[2]] for _, h, _, _ in both])
    fk = machine.fk(lam)
    if not np.all(fk.converged):
        k = int(np.flatnonzero(~fk.converged)[0])
        key = "height" if k < len(heights) else "manual_height"
        raise InputFileError(src, f"{key}{both[k][0]}_pos: the carriages are out of the reach of machine "
                             f"'{machine.name}'; is it the machine file of this printer.cfg?", line=int(lines[k]))
    meas = Measurements(actuators=lam, readings=readings, commanded=fk.poses, source=src, lines=lines,
                        rows=np.arange(1, len(both) + 1))
    notes = [f"{src}: {len(heights)} DELTA_CALIBRATE height(s)" + (f" and {len(manual)} manual height(s) "
             "(DELTA_ANALYZE MANUAL_HEIGHT)" if manual else "") + " from the #*# block; step distances "
             f"{', '.join(f'{d:.6g}' for d in dist)} mm; probe_z = height - z_offset {float(offset[2])!r} mm of the setup"]
    notes += offset_notes
    return ProbeImport(meas, tuple(notes))


__all__ = ["KLIPPER_FORMATS", "LineFormat", "NoProbeResults", "ProbeImport", "carriages_from_steps",
           "check_probe_offset", "numbered_entries", "read_klipper_file", "read_klipper_probe",
           "require_linear_delta", "saved_values", "stable_position"]
