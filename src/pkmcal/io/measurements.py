"""Measurement files (CSV): one row per measured pose.

Columns (names case-insensitive, aliases and ``# units:`` line as in :mod:`pkmcal.io.tables`;
extra columns are ignored):

* actuators: ``lambda1..lambda6`` (actuator readings λ_i, in the machine's
  ``actuator_unit``: mm unless stated), or ``l1..l6`` (leg lengths L_i, mm), converted to
  readings with the machine's leg offsets and gains, λ_i = (L_i − L0_i) / g_i (paper 2
  eq. 2 with a gain; g_i = 1 for readings in mm); planar machines: ``q1..ql`` (encoder readings, mm, or degrees for
  rotary actuators, :attr:`Mechanism.actuator_is_angle`);
* the sensor's readings: ``x,y,z,a,b,c`` (full-pose; mm, degrees), ``px,py,pz``
  (position; mm) or ``d1..dK`` (indicators; mm);
* optional commanded pose ``cmd_x..cmd_c`` (mm, degrees);
* optional ``session``: a free-text label per row (``1``, ``2026-05-01-am``): the
  measurement session of the pose (each session its own sensor parameters,
  :mod:`pkmcal.sensors.sessions`); labels are kept in order of first appearance, and the
  pose numbers stay the file's data rows. Without the column the file is one session.

Inside, angles are radians (:mod:`pkmcal.conventions`). Files are written as a plain CSV
(a units line and comments only when asked), the header and every float as its shortest
round-trip text, so the same data always give the same bytes, atomically.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import POSE_COLUMNS
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.import_mapping import ImportMapping
from pkmcal.io.inputs import read_input_text
from pkmcal.io.orientation import euler_triples, orientation_given, small_angle_limit
from pkmcal.io.tables import DEFAULT_ALIASES, check_magnitudes, column_kinds, from_file_units, mapped_name, read_table, to_file_units, write_table
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import MeasurementSetup
from pkmcal.sensors.sessions import Sessions

#: The optional column of the measurement session of each row (free text).
SESSION_COLUMN = "session"

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
    ``notes`` what the loader did that the user should know (e.g. leg lengths converted);
    ``rows`` (N,) the pose numbers: data rows of ``source`` counted from 1 (None: 1..N), kept
    by :meth:`subset` so that poses keep their numbers when others are left out;
    ``sessions`` the session of each pose (:class:`~pkmcal.sensors.sessions.Sessions`, the
    file's ``session`` column; None: one session), kept by :meth:`subset`.
    """

    actuators: np.ndarray
    readings: np.ndarray
    commanded: np.ndarray | None = None
    source: str | None = None
    lines: np.ndarray | None = None
    notes: tuple[str, ...] = ()
    rows: np.ndarray | None = None
    sessions: Sessions | None = None

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
        if self.sessions is not None and not isinstance(self.sessions, Sessions):
            object.__setattr__(self, "sessions", Sessions.from_labels(self.sessions))
        if self.sessions is not None and len(self.sessions) != a.shape[0]:
            raise PkmcalError(f"{len(self.sessions)} session labels for {a.shape[0]} poses")

    def __len__(self) -> int:
        return self.actuators.shape[0]

    @property
    def pose_numbers(self) -> np.ndarray:
        """(N,) the pose numbers (data rows of the file, from 1; docs/conventions.md)."""
        return np.arange(1, len(self) + 1) if self.rows is None else np.asarray(self.rows, dtype=int)

    def subset(self, keep) -> "Measurements":
        """The poses selected by ``keep`` (a boolean mask or indices), with their lines and
        pose numbers."""
        idx = np.arange(len(self))[keep]
        return Measurements(actuators=self.actuators[idx], readings=self.readings[idx],
                            commanded=None if self.commanded is None else self.commanded[idx], source=self.source,
                            lines=None if self.lines is None else np.asarray(self.lines)[idx], notes=self.notes,
                            rows=self.pose_numbers[idx],
                            sessions=None if self.sessions is None else self.sessions.subset(idx))

    def where(self, k: int) -> str:
        """Where pose ``k`` (0-based) comes from, for error messages: 'file, line 12' or 'pose 3'."""
        if self.source is not None and self.lines is not None:
            return f"{self.source}, line {int(self.lines[k])}"
        return f"pose {k + 1}"


def _readings_from_lengths(machine: Mechanism, lengths: np.ndarray, path) -> np.ndarray:
    """λ = (L − L0) / g of measured leg lengths L (N, l), mm (:meth:`Hexapod.readings_from_lengths`)."""
    if "leg-lengths" not in machine.abilities:
        raise InputFileError(path, f"has leg lengths l1.. but machine '{machine.name}' has no leg offsets; "
                                   f"give the actuator readings {machine.actuator_names[0]}.. instead")
    return machine.readings_from_lengths(lengths)


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
    # readings in a unit of their own (actuator_unit: rev, count) are not lengths a units line converts
    act_kinds = {n: k for (n, k), u in zip(column_kinds(act, machine.actuator_is_angle).items(), machine.actuator_units)
                 if u in ("mm", "deg")}
    kinds = {**act_kinds, **column_kinds(legs, (False,) * len(legs)),
             **column_kinds(reading_cols, sensor.reading_is_angle),
             **column_kinds(cmd_cols, machine.pose_is_angle)}
    text = read_input_text(src, "measurement file", fix="save it as UTF-8 CSV")
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
        table = read_table(src, columns, either=[act, legs], kinds=kinds, text=text, mapping=mapping,
                           small_angle_deg=small_angle_limit(machine))
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
    notes: tuple[str, ...] = table.notes
    if all(c in table.columns for c in act):
        actuators = from_file_units(table[list(act)], machine.actuator_is_angle)   # rotary encoders: deg in files
    else:
        actuators = _readings_from_lengths(machine, table[list(legs)], src)
        unit_gains = np.all(machine.reading_gains() == 1.0)
        rule = ("lambda_i = l_i - L0_i with the leg offsets" if unit_gains else
                f"lambda_i = (l_i - L0_i) / gain_i ({machine.actuator_units[0]}) with the leg offsets and gains")
        notes += (f"{src}: columns {legs[0]}..{legs[-1]} are leg lengths; converted to actuator readings "
                 f"{rule} of machine '{machine.name}'",)
    commanded = None
    if with_cmd:
        commanded = from_file_units(table[list(cmd_cols)], machine.pose_is_angle)
    sessions = _sessions(src, text, mapping, table.lines) if SESSION_COLUMN in header else None
    return Measurements(actuators=actuators, readings=readings, commanded=commanded, source=src, lines=table.lines,
                        notes=notes, rows=np.arange(1, len(table) + 1), sessions=sessions)


def _sessions(src: str, text: str, mapping: ImportMapping | None, lines: np.ndarray) -> Sessions:
    """The ``session`` labels of the data rows at ``lines`` (the rows the table read, in
    order): each cell stripped, as text; an empty label is an error naming its line."""
    from pkmcal.io.tables import _split

    col = None
    labels: dict[int, str] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        cells = _split(line)
        if col is None:
            names = [mapped_name(c.strip().strip('"'), mapping, DEFAULT_ALIASES) for c in cells]
            col, header_cell = names.index(SESSION_COLUMN), cells[names.index(SESSION_COLUMN)]
            continue
        labels[number] = cells[col].strip() if col < len(cells) else ""
    per_pose = [labels[int(n)] for n in lines]
    empty = next((k for k, lab in enumerate(per_pose) if not lab), None)
    if empty is not None:
        raise InputFileError(src, "empty session label; give every row its session (free text, e.g. 1, 2 or "
                                  "2026-05-01-am), or remove the column for a one-session file",
                             line=int(lines[empty]), column=header_cell)
    return Sessions.from_labels(per_pose)


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
    """The columns of a measurement file (file units: mm, degrees), in order: ``session``
    last when the measurements have sessions."""
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
    cols: dict = {}
    for names, is_angle, values in groups:
        file_values = to_file_units(values, is_angle)
        cols.update({name: file_values[:, j] for j, name in enumerate(names)})
    if measurements.sessions is not None:
        # last: a row never starts with a label, which could start with '#' (a comment line)
        labels = measurements.sessions.labels
        cols[SESSION_COLUMN] = [labels[k] for k in measurements.sessions.index]
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


# -- clipped readings ---------------------------------------------------------------------

#: What :func:`apply_clipped_policy` does with poses whose readings are clipped.
CLIPPED_POLICIES = ("drop", "keep", "error")
#: A reading within this relative distance (× max(1, |end|)) of a stroke end is "at the end".
END_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ClippedReading:
    """One actuator reading outside its stroke, or at one of its ends (file units).

    ``pose`` the pose number (data row from 1), ``line`` its line in the file (or None),
    ``actuator`` the column name, ``reading`` and ``stroke`` (min, max) in file units (mm;
    degrees for rotary actuators), ``kind`` ``"outside"`` or ``"at-end"``."""

    pose: int
    line: int | None
    actuator: str
    reading: float
    stroke: tuple[float, float]
    kind: str

    def describe(self, unit: str = "mm") -> str:
        where = f"pose {self.pose}" + (f" (line {self.line})" if self.line is not None else "")
        what = ("outside its stroke" if self.kind == "outside" else "at an end of its stroke (stuck or clipped?)")
        return (f"{where}: {self.actuator} = {self.reading!r} {unit} is {what} "
                f"[{self.stroke[0]!r}, {self.stroke[1]!r}] {unit}")

    def to_dict(self, unit: str = "mm") -> dict:
        """JSON-ready, every number with its unit (docs/conventions.md, "Units in JSON"):
        ``reading_mm``/``stroke_mm`` (``_deg`` for rotary actuators), or for readings in a
        unit of their own (a hexapod's ``actuator_unit``) ``reading``/``stroke`` with that
        unit in ``units``."""
        units = {"pose": "1", "line": "1"}
        if unit in ("mm", "deg"):
            reading, stroke = f"reading_{unit}", f"stroke_{unit}"
        else:
            reading, stroke = "reading", "stroke"
            units.update(reading=unit, stroke=unit)
        return {"pose": self.pose, "line": self.line, "actuator": self.actuator, reading: self.reading,
                stroke: list(self.stroke), "kind": self.kind, "units": units}


def clipped_readings(measurements: Measurements, machine: Mechanism,
                     rel_tol: float = END_TOLERANCE) -> list[ClippedReading]:
    """Every actuator reading outside the machine's stroke [λ_min, λ_max] or within
    ``rel_tol``·max(1, |end|) of an end, in pose order (none for a machine without a
    stroke). A real reading never stands exactly at an end by chance: there, the actuator
    was clipped by its controller, saturated, or stuck at a stop, and the pose it gives is
    not the pose the machine reached."""
    stroke = machine.reading_range()
    if stroke is None:
        return []
    stroke = np.asarray(stroke, dtype=float)
    lam = measurements.actuators
    lo, hi = stroke[:, 0], stroke[:, 1]
    tol_lo = rel_tol * np.maximum(1.0, np.abs(lo))
    tol_hi = rel_tol * np.maximum(1.0, np.abs(hi))
    outside = (lam < lo - tol_lo) | (lam > hi + tol_hi)
    at_end = ~outside & ((np.abs(lam - lo) <= tol_lo) | (np.abs(lam - hi) <= tol_hi))
    flagged = outside | at_end
    if not flagged.any():
        return []
    is_angle = machine.actuator_is_angle
    lam_file = to_file_units(lam, is_angle)
    stroke_file = to_file_units(stroke.T, is_angle).T
    numbers = measurements.pose_numbers
    out = []
    for k, j in zip(*np.nonzero(flagged)):
        out.append(ClippedReading(
            pose=int(numbers[k]), line=None if measurements.lines is None else int(measurements.lines[k]),
            actuator=machine.actuator_names[j], reading=float(lam_file[k, j]),
            stroke=(float(stroke_file[j, 0]), float(stroke_file[j, 1])),
            kind="outside" if outside[k, j] else "at-end"))
    return out


def apply_clipped_policy(measurements: Measurements, machine: Mechanism, policy: str = "drop",
                         ) -> tuple[Measurements, list[ClippedReading], list[str]]:
    """``(measurements to use, clipped readings, warning lines)`` under ``policy``:

    * ``drop`` (default): poses with a clipped reading are left out (they keep their pose
      numbers, :meth:`Measurements.subset`), one warning per reading and one summary;
    * ``keep``: the same warnings, every pose used;
    * ``error``: :class:`~pkmcal.errors.PkmcalError` naming the first readings.

    Dropping every pose is an error (nothing would be left to fit)."""
    if policy not in CLIPPED_POLICIES:
        raise PkmcalError(f"--clipped '{policy}': choose one of {', '.join(CLIPPED_POLICIES)}")
    found = clipped_readings(measurements, machine)
    if not found:
        return measurements, [], []
    src = measurements.source or "the measurements"
    unit = dict(zip(machine.actuator_names, machine.actuator_units))
    lines = [f"{src}: {c.describe(unit[c.actuator])}" for c in found]
    poses = sorted({c.pose for c in found})
    if policy == "error":
        shown = "; ".join(lines[:3]) + (f"; and {len(lines) - 3} more" if len(lines) > 3 else "")
        raise PkmcalError(f"{len(found)} clipped actuator reading(s) in {len(poses)} pose(s): {shown}; "
                          "remove those poses, or use --clipped drop (leave them out) or keep")
    if policy == "keep":
        lines.append(f"{src}: {len(poses)} pose(s) with clipped readings are used (--clipped keep): "
                     f"{', '.join(map(str, poses))}")
        return measurements, found, lines
    keep = ~np.isin(measurements.pose_numbers, poses)
    if not keep.any():
        raise PkmcalError(f"{src}: every pose has a clipped actuator reading ({lines[0]}); check the stroke in the "
                          "machine file and the reading columns (--clipped keep uses them anyway)")
    lines.append(f"{src}: {len(poses)} pose(s) with clipped readings left out (--clipped drop, the default; "
                 f"--clipped keep uses them): {', '.join(map(str, poses))}")
    return measurements.subset(keep), found, lines


@contextlib.contextmanager
def clipped_named_in_errors(lines: list[str]):
    """A :class:`~pkmcal.errors.PkmcalError` raised inside (a fit that fails, too few poses)
    also says which poses :func:`apply_clipped_policy` left out (its last line), so that
    the one error line explains itself."""
    try:
        yield
    except PkmcalError as exc:
        if not lines:
            raise
        raise PkmcalError(f"{exc} ({lines[-1]})") from None
