"""Measurement files (CSV): one row per measured pose.

Columns (names case-insensitive, aliases and ``# units:`` line as in :mod:`pkmcal.io.tables`;
extra columns are ignored):

* actuators: ``lambda1..lambda6`` (actuator readings λ_i, mm), or ``l1..l6`` (leg lengths
  L_i, mm), converted to readings with the machine's leg offsets, λ_i = L_i − L0_i
  (paper 2 eq. 2); planar machines: ``q1..ql`` (encoder readings, mm, or degrees for
  rotary actuators, :attr:`Mechanism.actuator_is_angle`);
* the sensor's readings: ``x,y,z,a,b,c`` (full-pose; mm, degrees), ``px,py,pz``
  (position; mm) or ``d1..dK`` (indicators; mm);
* optional commanded pose ``cmd_x..cmd_c`` (mm, degrees).

Inside, angles are radians (:mod:`pkmcal.conventions`). Files are written as a plain CSV
(a units line and comments only when asked), the header and every float as its shortest
round-trip text, so the same data always give the same bytes, atomically.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import POSE_COLUMNS
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.import_mapping import ImportMapping
from pkmcal.io.orientation import euler_triples, orientation_given
from pkmcal.io.tables import DEFAULT_ALIASES, check_magnitudes, column_kinds, from_file_units, mapped_name, read_table, to_file_units, write_table
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import MeasurementSetup

#: Commanded-pose columns of a 6-DOF machine (in general ``cmd_`` + the machine's pose names).
COMMAND_COLUMNS = tuple(f"cmd_{c}" for c in POSE_COLUMNS)


def command_columns(machine: Mechanism) -> tuple[str, ...]:
    return tuple(f"cmd_{c}" for c in machine.pose_names)


@dataclass(frozen=True)
class Measurements:
    """Measured poses, internal units (mm, rad).

    ``actuators`` (N, l) actuator readings; ``readings`` (N, m) sensor readings;
    ``commanded`` (N, n) commanded poses or None; ``source`` the file they came from (None
    when simulated); ``lines`` (N,) 1-based line of each row in ``source`` (None if not read);
    ``notes`` what the loader did that the user should know (e.g. leg lengths converted).
    """

    actuators: np.ndarray
    readings: np.ndarray
    commanded: np.ndarray | None = None
    source: str | None = None
    lines: np.ndarray | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        a = np.asarray(self.actuators, dtype=float)
        r = np.asarray(self.readings, dtype=float)
        if a.ndim != 2 or r.ndim != 2 or a.shape[0] != r.shape[0]:
            raise PkmcalError(f"measurements need actuator readings (N, l) and sensor readings (N, m) with the same N; "
                              f"got shapes {a.shape} and {r.shape}")
        object.__setattr__(self, "actuators", a)
        object.__setattr__(self, "readings", r)
        if self.commanded is not None:
            c = np.asarray(self.commanded, dtype=float)
            if c.ndim != 2 or c.shape[0] != a.shape[0]:
                raise PkmcalError(f"commanded poses must have shape ({a.shape[0]}, n); got {c.shape}")
            object.__setattr__(self, "commanded", c)

    def __len__(self) -> int:
        return self.actuators.shape[0]

    def where(self, k: int) -> str:
        """Where pose ``k`` (0-based) comes from, for error messages: 'file, line 12' or 'pose 3'."""
        if self.source is not None and self.lines is not None:
            return f"{self.source}, line {int(self.lines[k])}"
        return f"pose {k + 1}"


def _leg_offsets(machine: Mechanism, path) -> np.ndarray:
    offset = getattr(machine, "offset", None)
    if offset is None:
        raise InputFileError(path, f"has leg lengths l1.. but machine '{machine.name}' has no leg offsets; "
                                   f"give the actuator readings {machine.actuator_names[0]}.. instead")
    return np.asarray(offset, dtype=float)


def load_measurements(path: str | os.PathLike, machine: Mechanism, setup: MeasurementSetup,
                      mapping: ImportMapping | None = None) -> Measurements:
    """Read a measurement CSV for ``machine`` measured with ``setup`` (see module docstring);
    ``mapping`` renames the columns and sets the units of a file from another tool
    (:mod:`pkmcal.io.import_mapping`).

    Raises :class:`~pkmcal.errors.InputFileError` naming the file, the missing columns and
    what the setup expects, or the line and column of a bad cell.
    """
    src = os.fspath(path)
    sensor = setup.sensor
    act = tuple(machine.actuator_names)
    legs = tuple(f"l{i + 1}" for i in range(machine.n_actuators))
    reading_cols = tuple(sensor.reading_names)
    cmd_cols = command_columns(machine)
    kinds = {**column_kinds(act, machine.actuator_is_angle), **column_kinds(legs, (False,) * len(legs)),
             **column_kinds(reading_cols, sensor.reading_is_angle),
             **column_kinds(cmd_cols, machine.pose_is_angle)}
    try:
        with open(src, "rb") as fh:
            text = fh.read().decode("utf-8-sig")
    except OSError as exc:
        raise InputFileError(src, f"cannot read the measurement file: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise InputFileError(src, f"not a UTF-8 text file (byte {exc.start}); save it as UTF-8 CSV") from None
    header = _header(text, mapping)
    given = set(header)
    order = (mapping.quaternion_order if mapping is not None else None) or "xyzw"
    for triple in euler_triples(cmd_cols):
        if orientation_given(header, triple, order):
            given.update(triple)      # cmd_a..cmd_c given as a quaternion or rotation vector
    with_cmd = [c for c in cmd_cols if c in given]
    if with_cmd and len(with_cmd) != len(cmd_cols):
        missing = [c for c in cmd_cols if c not in given]
        raise InputFileError(src, f"has commanded-pose columns {', '.join(with_cmd)} but not {', '.join(missing)}; "
                                  f"give all of {', '.join(cmd_cols)} (mm, deg) or none")
    columns = reading_cols + (cmd_cols if with_cmd else ())
    try:
        table = read_table(src, columns, either=[act, legs], kinds=kinds, text=text, mapping=mapping)
    except InputFileError as exc:
        if "missing column" in str(exc):
            where = f"{exc.path}" + (f", line {exc.line}" if exc.line is not None else "") + ": "
            raise InputFileError(
                src, str(exc)[len(where):] + "; "
                f"the '{sensor.kind}' setup expects columns {', '.join(reading_cols)} "
                f"({_units(sensor)}) and {act[0]}..{act[-1]} (actuator readings, mm) or "
                f"{legs[0]}..{legs[-1]} (leg lengths, mm), optionally cmd_x..cmd_c",
                line=exc.line) from None
        raise
    check_magnitudes(table, kinds)
    readings = from_file_units(table[list(reading_cols)], sensor.reading_is_angle)
    notes: tuple[str, ...] = ()
    if all(c in table.columns for c in act):
        actuators = from_file_units(table[list(act)], machine.actuator_is_angle)   # rotary encoders: deg in files
    else:
        actuators = table[list(legs)] - _leg_offsets(machine, src)
        notes = (f"{src}: columns {legs[0]}..{legs[-1]} are leg lengths; converted to actuator readings "
                 f"lambda_i = l_i - L0_i with the leg offsets of machine '{machine.name}'",)
    commanded = None
    if with_cmd:
        commanded = from_file_units(table[list(cmd_cols)], machine.pose_is_angle)
    return Measurements(actuators=actuators, readings=readings, commanded=commanded, source=src, lines=table.lines,
                        notes=notes)


def _units(sensor) -> str:
    if any(sensor.reading_is_angle):
        return "mm and degrees"
    return "mm"


def _header(text: str, mapping: ImportMapping | None = None) -> set[str]:
    """Canonical names of the header row (first non-blank, non-comment line)."""
    for line in text.splitlines():
        s = line.strip()
        if s and not s.startswith("#"):
            return {mapped_name(c.strip().strip('"'), mapping, DEFAULT_ALIASES) for c in s.split(",")}
    return set()


def measurement_columns(measurements: Measurements, machine: Mechanism, setup: MeasurementSetup) -> dict:
    """The columns of a measurement file (file units: mm, degrees), in order."""
    sensor = setup.sensor
    if measurements.actuators.shape[1] != machine.n_actuators:
        raise PkmcalError(f"{measurements.actuators.shape[1]} actuator readings per pose, but machine "
                          f"'{machine.name}' has {machine.n_actuators} actuators")
    if measurements.readings.shape[1] != sensor.n_readings:
        raise PkmcalError(f"{measurements.readings.shape[1]} sensor readings per pose, but the '{sensor.kind}' "
                          f"sensor gives {sensor.n_readings}")
    groups = [(machine.actuator_names, machine.actuator_is_angle, measurements.actuators),
              (sensor.reading_names, sensor.reading_is_angle, measurements.readings)]
    if measurements.commanded is not None:
        if measurements.commanded.shape[1] != machine.n_dof:
            raise PkmcalError(f"commanded poses have {measurements.commanded.shape[1]} coordinates, but machine "
                              f"'{machine.name}' has {machine.n_dof}")
        groups.append((command_columns(machine), machine.pose_is_angle, measurements.commanded))
    cols: dict[str, np.ndarray] = {}
    for names, is_angle, values in groups:
        file_values = to_file_units(values, is_angle)
        cols.update({name: file_values[:, j] for j, name in enumerate(names)})
    return cols


def save_measurements(
    path: str | os.PathLike,
    measurements: Measurements,
    machine: Mechanism,
    setup: MeasurementSetup,
    comments: tuple[str, ...] = (),
    units_comment: bool = False,
) -> None:
    """Write ``measurements`` as a measurement CSV (atomic, deterministic bytes, full
    precision; a plain CSV, or with ``units_comment`` a units line and ``comments`` first)."""
    write_table(path, measurement_columns(measurements, machine, setup), units_comment=units_comment,
                comments=(f"pkmcal measurements: machine {machine.name}, sensor {setup.sensor.kind}",) + tuple(comments))
