"""Read a LinuxCNC ``genhexkins`` configuration (HAL file and INI file) as a pkmcal hexapod.

genhexkins (LinuxCNC ``src/emc/kinematics/genhexkins.c``) computes the strut lengths

    joint_N = ‖ p + R a_N − b_N ‖,     R = Rz(C) Ry(B) Rx(A)      (N = 0..5)

from the HAL pins ``genhexkins.base.N.x|y|z`` (b_N, world frame) and
``genhexkins.platform.N.x|y|z`` (a_N, platform frame): pkmcal's leg i = N + 1 with the same
pose convention (``docs/conventions.md``, LinuxCNC genhexkins). Its joint is the strut
length L; pkmcal's reading is λ = L − L0. What this module reads:

* **HAL file** (as ``halcmd -f`` reads it): ``setp NAME VALUE`` and ``NAME = VALUE`` lines;
  ``#`` starts a comment (at a line's start or after a blank); a trailing ``\\`` continues a
  line; ``[SECTION]KEY`` and ``[SECTION](KEY)`` are replaced by the INI file's value and
  ``$NAME``/``$(NAME)`` by the environment's, as halcmd does. The 36 joint coordinates must
  all be set (genhexkins.h's compiled-in defaults are not assumed). ``spindle-offset`` and a
  constant ``tool-offset`` are added by genhexkins to the z of every base *and* platform
  joint; they are folded into the joints exactly (b_z + s, a_z + s), with a note.
  ``screw-lead`` ≠ 0 (a strut-length correction pkmcal does not model) is an error. Other
  ``genhexkins.*`` names must be genhexkins inputs (a misspelt pin is an error, as halcmd's).
* **INI file** (LinuxCNC's rules): ``[SECTION]``, ``KEY = VALUE`` (the value is the rest of
  the line: ``#`` and ``;`` are comments only at a line's start), a trailing ``\\`` continues
  a value, ``#INCLUDE FILE`` (one level), the first of repeated keys wins. Read:
  ``[TRAJ] LINEAR_UNITS`` (mm, metric, cm, inch, in, imperial: HAL and joint values are
  converted to mm; a unit other than mm is kept as ``metadata.linuxcnc.linear_units`` so that
  ``pkmcal export --format linuxcnc`` writes the files back in it) and ``ANGULAR_UNITS``,
  ``[TRAJ] HOME`` (the world home X Y Z A B C: the
  machine's home pose, the FK start pose), ``[KINS] KINEMATICS`` (must be genhexkins) and
  ``JOINTS`` (6), and per joint ``[JOINT_N] TYPE`` (LINEAR), ``UNITS``, ``MIN_LIMIT``,
  ``MAX_LIMIT``, ``HOME_OFFSET`` (LinuxCNC's default 0) and ``HOME``, and the soft limits
  ``[AXIS_X..C] MIN_LIMIT``/``MAX_LIMIT`` (world coordinates, ``[TRAJ]`` units) as the
  workspace box when all six are set (angles beyond A, C ±180° and B ±90°, the range in
  which the Euler angles represent each orientation once, are clipped to it with a note). The joint limits are the
  stroke, widened by the stroke margins of the comment ``# pkmcal.stroke_margin_mm = ...``
  where pkmcal's export wrote one (its limits stand that far inside the stroke).

Leg offsets (``offsets``): ``"home-offset"`` (default) L0_i = HOME_OFFSET_N, the strut
length at the home switch, so that readings are zero there (what
:func:`pkmcal.io.export_linuxcnc.linuxcnc_ini` writes); ``"zero"`` L0_i = 0, genhexkins' own
convention: the reading is the joint value, the strut length (its home-switch value is kept
in ``metadata.linuxcnc.home_switch_reading`` so that an export writes HOME_OFFSET =
L0 + reading). The stroke is [MIN_LIMIT − L0, MAX_LIMIT − L0], written as the file says; a
strut range beyond what struts of their home length reach (between half and twice it:
:mod:`pkmcal.mechanisms.hexapod_reach`; LinuxCNC's own hexapod sample allows ±1000 inch on
29.75-inch struts) is reported in a note naming MIN_LIMIT/MAX_LIMIT, and planning keeps
within the reachable range. ``[JOINT_N] HOME`` is compared with the strut lengths at
``[TRAJ] HOME`` (a note when they differ).

Round trip: machine → :func:`~pkmcal.io.export_linuxcnc.linuxcnc_hal` +
:func:`~pkmcal.io.export_linuxcnc.linuxcnc_ini` → :func:`machine_from_linuxcnc` gives the
same joints, offsets, home pose exactly and the stroke to one rounding
(``tests/io/test_import_linuxcnc.py``). Limits pkmcal checks that LinuxCNC has no setting for
(joint tilts, leg diameter) are not in the files; a note says to add them. Where each limit
came from is recorded in ``metadata.limits_from`` (stroke, workspace), which planning's notes
name.
"""

from __future__ import annotations

import difflib
import os
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pkmcal.conventions import EULER_RANGES, wrap_angle
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.export_linuxcnc import HAL_PREFIX
from pkmcal.io.inputs import read_input_bytes
from pkmcal.io.limits import MAX_MAGNITUDE
from pkmcal.mechanisms.hexapod_reach import loose_stroke_note

#: ``[TRAJ] LINEAR_UNITS`` / ``[JOINT_N] UNITS`` values → mm per unit.
LINEAR_UNITS = {"mm": 1.0, "metric": 1.0, "cm": 10.0, "in": 25.4, "inch": 25.4, "imperial": 25.4}
#: ``[TRAJ] ANGULAR_UNITS`` values → degrees per unit.
ANGULAR_UNITS = {"deg": 1.0, "degree": 1.0, "degrees": 1.0, "rad": 180.0 / np.pi, "radian": 180.0 / np.pi,
                 "radians": 180.0 / np.pi, "grad": 0.9, "gon": 0.9}
OFFSET_MODES = ("home-offset", "zero")
#: genhexkins input pins/parameters other than the joint coordinates (accepted by setp).
_OTHER_INPUTS = ("spindle-offset", "tool-offset", "screw-lead", "convergence-criterion", "limit-iterations",
                 "max-error")
_MAX_CONTINUED = 20                      # LinuxCNC's MAX_EXTEND_LINES
_INI_REF = re.compile(r"\[([A-Za-z0-9_]+)\]\(?([A-Za-z0-9_]+)\)?")
_ENV_REF = re.compile(r"\$\(([A-Za-z_][A-Za-z0-9_]*)\)|\$([A-Za-z_][A-Za-z0-9_]*)")


# -- INI ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class IniFile:
    """A LinuxCNC INI file: ``values[SECTION][KEY] = (value, file, line)`` (sections and keys
    as written; looked up case-insensitively), first occurrence of a key kept."""

    path: str
    values: dict[str, dict[str, tuple[str, str, int]]] = field(default_factory=dict)

    def get(self, section: str, key: str) -> tuple[str, str, int] | None:
        sec = self.values.get(section.upper())
        return None if sec is None else sec.get(key.upper())


def _read_text(path: str, what: str) -> str:
    data = read_input_bytes(path, what, 20_000_000)
    if b"\x00" in data:
        raise InputFileError(path, f"contains NUL bytes: not a text {what}")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")     # LinuxCNC reads bytes; comments may be in any encoding


def _logical_lines(path: str, text: str):
    """``(first line number, text)`` of each line, trailing-backslash continuations joined."""
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        start, line, n = k + 1, lines[k], 0
        while line.endswith("\\") and k + 1 < len(lines):
            n += 1
            if n > _MAX_CONTINUED:
                raise InputFileError(path, f"more than {_MAX_CONTINUED} continued lines ('\\' at the end)", line=start)
            k += 1
            line = line[:-1] + lines[k]
        yield start, line
        k += 1


def read_ini(path: str | os.PathLike) -> IniFile:
    """Parse a LinuxCNC INI file (module docstring); ``#INCLUDE`` files are read in place."""
    src = os.fspath(path)
    ini = IniFile(path=src)
    section: str | None = None

    def parse(file: str, text: str, top: bool) -> None:
        nonlocal section
        for number, raw in _logical_lines(file, text):
            line = raw.strip()
            if not line:
                continue
            if line.upper().startswith("#INCLUDE"):
                if not top:
                    raise InputFileError(file, "#INCLUDE inside an included file (LinuxCNC expands one level only)",
                                         line=number)
                name = os.path.expanduser(line[len("#INCLUDE"):].strip())
                if not name:
                    raise InputFileError(file, "#INCLUDE without a file name", line=number)
                inc = name if os.path.isabs(name) else os.path.join(os.path.dirname(src) or ".", name)
                if not os.path.exists(inc) and os.path.exists(name):
                    inc = name
                parse(inc, _read_text(inc, "INI include file"), False)
                continue
            if line[0] in "#;":
                continue
            if line.startswith("["):
                if not line.endswith("]") or len(line) < 3:
                    raise InputFileError(file, f"'{line[:60]}' is not a section name [NAME]", line=number)
                section = line[1:-1].strip().upper()
                ini.values.setdefault(section, {})
                continue
            key, sep, value = line.partition("=")
            if not sep or section is None:
                continue                                   # LinuxCNC ignores such lines
            ini.values[section].setdefault(key.strip().upper(), (value.strip(), file, number))

    parse(src, _read_text(src, "INI file"), True)
    return ini


def _ini_number(ini: IniFile, section: str, key: str) -> float | None:
    got = ini.get(section, key)
    if got is None:
        return None
    value, file, line = got
    try:
        v = float(value)
    except ValueError:
        raise InputFileError(file, f"[{section}] {key} = '{value[:40]}' is not a number", line=line) from None
    if not np.isfinite(v):
        raise InputFileError(file, f"[{section}] {key} = '{value}' is not a finite number", line=line)
    return v


def _unit_factor(ini: IniFile, section: str, key: str, table: dict[str, float], default: float) -> float:
    got = ini.get(section, key)
    if got is None:
        return default
    value, file, line = got
    unit = value.strip().lower()
    if unit not in table:
        raise InputFileError(file, f"[{section}] {key} = '{value}': unknown unit; LinuxCNC's are "
                                   f"{', '.join(table)}", line=line)
    return table[unit]


# -- HAL ----------------------------------------------------------------------------------

def _joint_pins() -> list[str]:
    return [f"{part}.{n}.{axis}" for part in ("base", "platform") for n in range(6) for axis in "xyz"]


def _known_inputs() -> set[str]:
    known = set(_joint_pins()) | set(_OTHER_INPUTS)
    known |= {f"{part}-n.{n}.{axis}" for part in ("base", "platform") for n in range(6) for axis in "xyz"}
    return known


def _substitute(src: str, number: int, line: str, ini: IniFile | None) -> str:
    def ini_value(m: re.Match) -> str:
        if ini is None:
            raise InputFileError(src, f"uses the INI value {m.group(0)}; give the INI file too "
                                      "(pkmcal import linuxcnc HAL INI)", line=number)
        got = ini.get(m.group(1), m.group(2))
        if got is None:
            raise InputFileError(src, f"{m.group(0)}: the INI file {ini.path} has no key {m.group(2)} in "
                                      f"section [{m.group(1)}]", line=number)
        return got[0]

    def env_value(m: re.Match) -> str:
        name = m.group(1) or m.group(2)
        if name not in os.environ:
            raise InputFileError(src, f"uses the environment variable ${name}, which is not set; set it or write "
                                      "the value", line=number)
        return os.environ[name]

    return _ENV_REF.sub(env_value, _INI_REF.sub(ini_value, line))


def _strip_comment(line: str) -> str:
    for k, ch in enumerate(line):
        if ch == "#" and (k == 0 or line[k - 1].isspace()):
            return line[:k]
    return line


def read_hal_genhexkins(path: str | os.PathLike, ini: IniFile | None = None) -> dict[str, tuple[float, int]]:
    """The genhexkins values a HAL file sets: ``{name without 'genhexkins.': (value, line)}``
    (the last ``setp`` of a name wins, as when halcmd runs the file)."""
    src = os.fspath(path)
    known = _known_inputs()
    out: dict[str, tuple[float, int]] = {}
    for number, raw in _logical_lines(src, _read_text(src, "HAL file")):
        line = _strip_comment(raw).strip()
        if not line or HAL_PREFIX not in line:
            continue
        line = _substitute(src, number, line, ini)
        try:
            words = shlex.split(line)
        except ValueError as exc:
            raise InputFileError(src, f"cannot split the line into words: {exc}", line=number) from None
        if len(words) == 3 and words[0] == "setp":
            name, value = words[1], words[2]
        elif len(words) == 3 and words[1] == "=":
            name, value = words[0], words[2]
        else:
            continue                                      # net, loadrt, ... : not a value
        if not name.startswith(HAL_PREFIX + "."):
            continue
        short = name[len(HAL_PREFIX) + 1:]
        if short not in known:
            close = difflib.get_close_matches(short, sorted(known), n=1)
            hint = f"; did you mean '{HAL_PREFIX}.{close[0]}'?" if close else ""
            raise InputFileError(src, f"'{name}' is not a genhexkins input (halcmd would refuse it){hint}",
                                 line=number)
        try:
            v = float(value)
        except ValueError:
            raise InputFileError(src, f"{name}: '{value[:40]}' is not a number", line=number) from None
        if not np.isfinite(v) or abs(v) > MAX_MAGNITUDE:
            raise InputFileError(src, f"{name}: {value} is not a finite number within ±{MAX_MAGNITUDE:g}", line=number)
        out[short] = (v, number)
    return out


# -- machine ------------------------------------------------------------------------------

def _stroke_margin_comment(path: str) -> np.ndarray | None:
    """The six stroke margins (mm) of the comment pkmcal's export writes into the INI file
    (:data:`pkmcal.io.export_linuxcnc.STROKE_MARGIN_COMMENT`), or None."""
    from pkmcal.io.export_linuxcnc import STROKE_MARGIN_COMMENT

    for number, line in enumerate(_read_text(path, "INI file").splitlines(), start=1):
        if line.strip().startswith(STROKE_MARGIN_COMMENT):
            words = line.strip()[len(STROKE_MARGIN_COMMENT):].split()
            try:
                margin = np.array([float(w) for w in words])
            except ValueError:
                margin = np.array([])
            if margin.shape != (6,) or not np.all(np.isfinite(margin) & (margin >= 0)):
                raise InputFileError(path, f"'{STROKE_MARGIN_COMMENT}' must give 6 lengths >= 0 (mm)", line=number)
            return margin
    return None


@dataclass(frozen=True)
class LinuxcncImport:
    """The machine read from a LinuxCNC configuration and what the user should know
    (``notes``, one line each)."""

    machine: object
    notes: tuple[str, ...]


def _joint_value(ini: IniFile, n: int, key: str, factor: float) -> float | None:
    v = _ini_number(ini, f"JOINT_{n}", key)
    return None if v is None else v * factor


def machine_from_linuxcnc(hal: str | os.PathLike, ini_path: str | os.PathLike | None = None, *,
                          offsets: str = "home-offset", joint_limits: tuple[float, float] | None = None,
                          length_unit: str | None = None, name: str | None = None) -> LinuxcncImport:
    """The hexapod of a genhexkins HAL file (and INI file): see the module docstring.

    ``offsets``: ``"home-offset"`` or ``"zero"``; ``joint_limits``: (min, max) strut length
    (mm) for every joint, replacing the INI's MIN_LIMIT/MAX_LIMIT (required without an INI
    file); ``length_unit``: the HAL/INI length unit, replacing ``[TRAJ] LINEAR_UNITS``
    (default mm); ``name``: the machine's name (default ``[EMC] MACHINE``, else the HAL
    file's name).
    """
    from pkmcal.io._yaml import TextFloat, deg_to_rad
    from pkmcal.mechanisms.hexapod import Hexapod

    if offsets not in OFFSET_MODES:
        raise PkmcalError(f"offsets '{offsets}': choose one of {', '.join(OFFSET_MODES)}")
    hal_src = os.fspath(hal)
    ini = read_ini(ini_path) if ini_path is not None else IniFile(path="")
    have_ini = ini_path is not None
    notes: list[str] = []
    if have_ini:
        kins = ini.get("KINS", "KINEMATICS")
        if kins is not None and kins[0].split()[:1] != ["genhexkins"]:
            raise InputFileError(kins[1], f"[KINS] KINEMATICS = {kins[0]}: not genhexkins; pkmcal imports hexapods "
                                          "configured with genhexkins", line=kins[2])
        joints = _ini_number(ini, "KINS", "JOINTS")
        if joints is not None and joints != 6:
            got = ini.get("KINS", "JOINTS")
            raise InputFileError(got[1], f"[KINS] JOINTS = {got[0]}: genhexkins has 6 joints", line=got[2])
    if length_unit is not None:
        if length_unit.lower() not in LINEAR_UNITS:
            raise PkmcalError(f"--length-unit '{length_unit}': choose one of {', '.join(LINEAR_UNITS)}")
        factor = LINEAR_UNITS[length_unit.lower()]
    else:
        factor = _unit_factor(ini, "TRAJ", "LINEAR_UNITS", LINEAR_UNITS, 1.0)
    values = read_hal_genhexkins(hal_src, ini if have_ini else None)
    missing = [p for p in _joint_pins() if p not in values]
    if missing:
        shown = ", ".join(f"{HAL_PREFIX}.{m}" for m in missing[:4]) + (", ..." if len(missing) > 4 else "")
        raise InputFileError(hal_src, f"sets {36 - len(missing)} of the 36 genhexkins joint coordinates; missing "
                                      f"{shown} (pkmcal does not assume genhexkins.h's compiled-in defaults: "
                                      "set every base.N and platform.N)")
    screw = values.get("screw-lead", (0.0, 0))
    if screw[0] != 0.0:
        raise InputFileError(hal_src, f"{HAL_PREFIX}.screw-lead = {screw[0]!r}: the strut-length correction of "
                                      "non-captive screws is not in pkmcal's model; calibrate with screw-lead 0",
                             line=screw[1])
    base = np.array([[values[f"base.{n}.{a}"][0] for a in "xyz"] for n in range(6)]) * factor
    platform = np.array([[values[f"platform.{n}.{a}"][0] for a in "xyz"] for n in range(6)]) * factor
    shift = sum(values.get(k, (0.0, 0))[0] for k in ("spindle-offset", "tool-offset")) * factor
    if shift != 0.0:
        base[:, 2] += shift
        platform[:, 2] += shift
        notes.append(f"{hal_src}: genhexkins.spindle-offset + tool-offset = {shift!r} mm added to the z of every base "
                     "and platform joint, as genhexkins does (the exported HAL sets them to 0)")
    L0 = np.zeros(6)
    switch = np.zeros(6)
    lo = np.full(6, np.nan)
    hi = np.full(6, np.nan)
    joint_home = np.full(6, np.nan)
    for n in range(6):
        jf = _unit_factor(ini, f"JOINT_{n}", "UNITS", LINEAR_UNITS, factor) if length_unit is None else factor
        typ = ini.get(f"JOINT_{n}", "TYPE")
        if typ is not None and typ[0].strip().upper() != "LINEAR":
            raise InputFileError(typ[1], f"[JOINT_{n}] TYPE = {typ[0]}: genhexkins' joints are LINEAR struts",
                                 line=typ[2])
        home_offset = _joint_value(ini, n, "HOME_OFFSET", jf)
        home_offset = 0.0 if home_offset is None else home_offset      # LinuxCNC's default
        if offsets == "home-offset":
            L0[n] = home_offset
        else:
            switch[n] = home_offset
        if joint_limits is None:
            lo[n] = np.nan if (v := _joint_value(ini, n, "MIN_LIMIT", jf)) is None else v
            hi[n] = np.nan if (v := _joint_value(ini, n, "MAX_LIMIT", jf)) is None else v
        h = _joint_value(ini, n, "HOME", jf)
        joint_home[n] = np.nan if h is None else h
    if joint_limits is not None:
        lo[:], hi[:] = float(joint_limits[0]), float(joint_limits[1])
    elif have_ini:
        margin = _stroke_margin_comment(ini.path)
        if margin is not None:          # pkmcal's export wrote the limits this far inside the stroke
            lo -= margin
            hi += margin
    no_limits = [n for n in range(6) if np.isnan(lo[n]) or np.isnan(hi[n])]
    if no_limits:
        where = (f"the INI file {ini.path} has no [JOINT_N] MIN_LIMIT/MAX_LIMIT for joints "
                 f"{', '.join(map(str, no_limits))}" if have_ini else "no INI file gives the joint limits")
        raise PkmcalError(f"{where}; give the INI file or --joint-limits MIN,MAX (strut lengths, mm)")
    bad = [n for n in range(6) if hi[n] < lo[n]]
    if bad:
        raise PkmcalError(f"joint {bad[0]}: MAX_LIMIT {hi[bad[0]]!r} < MIN_LIMIT {lo[bad[0]]!r} (mm)")
    if offsets == "home-offset" and np.any(L0 < 0):
        n = int(np.argmax(L0 < 0))
        raise PkmcalError(f"[JOINT_{n}] HOME_OFFSET = {L0[n]!r} mm is not a strut length; use --offsets zero "
                          "(readings = joint values) or fix HOME_OFFSET")
    stroke = np.stack([lo - L0, hi - L0], axis=1)
    home = None
    traj_home = ini.get("TRAJ", "HOME")
    if traj_home is not None:
        words = traj_home[0].split()
        try:
            nums = [float(w) for w in words]
        except ValueError:
            raise InputFileError(traj_home[1], f"[TRAJ] HOME = '{traj_home[0][:60]}' is not numbers X Y Z A B C",
                                 line=traj_home[2]) from None
        nums = (nums + [0.0] * 6)[:6]
        afactor = _unit_factor(ini, "TRAJ", "ANGULAR_UNITS", ANGULAR_UNITS, 1.0)
        angles = [deg_to_rad(TextFloat(nums[3 + k], words[3 + k])) if afactor == 1.0 and len(words) > 3 + k
                  else float(np.deg2rad(nums[3 + k] * afactor)) for k in range(3)]
        home = np.array([v * factor for v in nums[:3]] + angles)
        if np.any(wrap_angle(home[3:]) != home[3:]):
            home[3:] = wrap_angle(home[3:])
            notes.append(f"[TRAJ] HOME = {traj_home[0]}: its angles are written within (-180, 180] deg, the same "
                         "orientation by whole turns")
    afactor = _unit_factor(ini, "TRAJ", "ANGULAR_UNITS", ANGULAR_UNITS, 1.0)
    workspace = _axis_limits(ini, factor, afactor, notes) if have_ini else None
    metadata = {"linuxcnc": {"hal": hal_src, **({"ini": ini.path} if have_ini else {}), "offsets": offsets}}
    metadata["limits_from"] = {"stroke": "--joint-limits" if joint_limits is not None
                               else f"[JOINT_N] MIN_LIMIT/MAX_LIMIT of {ini.path}"}
    if workspace is not None:
        metadata["limits_from"]["workspace"] = f"[AXIS_X..C] MIN_LIMIT/MAX_LIMIT of {ini.path}"
    if factor != 1.0:
        # the unit of the controller's files, so that an export writes them back in it
        # (pkmcal.io.export_linuxcnc.export_unit)
        unit = length_unit if length_unit is not None else ini.get("TRAJ", "LINEAR_UNITS")[0]
        metadata["linuxcnc"]["linear_units"] = unit.strip().lower()
    if np.any(switch != 0):
        metadata["linuxcnc"]["home_switch_reading"] = [float(v) for v in switch]
    if name is None:
        got = ini.get("EMC", "MACHINE")
        name = got[0].strip() if got is not None and got[0].strip() else Path(hal_src).stem
    try:
        machine = Hexapod(name=name, base=base, platform=platform, offset=L0, stroke=stroke, home=home,
                          workspace=workspace,
                          description=f"imported from LinuxCNC genhexkins configuration {Path(hal_src).name}"
                                      + (f" + {Path(ini.path).name}" if have_ini else ""),
                          metadata=metadata)
    except PkmcalError as exc:
        raise PkmcalError(f"{hal_src}: {exc}") from None
    _, loose = loose_stroke_note(machine)
    if loose is not None:
        notes.append(loose + ("; genhexkins refuses struts of length 0 or less" if np.any(lo <= 0) else ""))
    if np.any(~np.isnan(joint_home)) and traj_home is not None:
        L = machine.leg_lengths(machine.home_pose)[0]
        dev = np.nanmax(np.abs(L - joint_home))
        if dev > 1e-6 * max(1.0, float(np.nanmax(np.abs(joint_home)))):
            notes.append(f"[JOINT_N] HOME differ from the strut lengths at [TRAJ] HOME by up to {dev:.6g} mm "
                         "(after homing, the joints stand where [JOINT_N] HOME says; check that both describe one pose)")
    notes.append("LinuxCNC has no setting for the joint tilt limits or the leg diameter: add 'limits:' to the "
                 "machine file for planning (docs/file-formats.md)")
    return LinuxcncImport(machine=machine, notes=tuple(notes))


def _axis_limits(ini: IniFile, factor: float, afactor: float, notes: list[str]) -> np.ndarray | None:
    """The workspace box (6, 2) (mm, rad) of the soft limits ``[AXIS_X..C] MIN_LIMIT/MAX_LIMIT``
    (in ``[TRAJ]`` units: ``factor`` mm and ``afactor`` degrees per unit), or None with a
    note when one is not set (LinuxCNC's default is ±1e99, no limit: ``src/emc/ini/iniaxis.cc``
    loadAxis with ``DEFAULT_AXIS_MIN_LIMIT``/``MAX_LIMIT``) or beyond any machine. Angles
    beyond the Euler angles' range (a, c ±180°, b ±90°) are clipped to it, with a note."""
    box = np.full((6, 2), np.nan)
    for k, axis in enumerate("XYZABC"):
        for j, key in enumerate(("MIN_LIMIT", "MAX_LIMIT")):
            v = _ini_number(ini, f"AXIS_{axis}", key)
            if v is not None and abs(v * (factor if k < 3 else afactor)) <= MAX_MAGNITUDE:
                box[k, j] = v * factor if k < 3 else np.deg2rad(v * afactor)
    unset = [f"AXIS_{a}" for a, row in zip("XYZABC", box) if np.isnan(row).any()]
    if unset:
        which = "[AXIS_*]" if len(unset) == 6 else f"[{'], ['.join(unset)}]"
        notes.append(f"no {which} MIN_LIMIT/MAX_LIMIT within ±{MAX_MAGNITUDE:g} (LinuxCNC's default: no limit): no "
                     "'workspace:' imported; planning searches the reach about home")
        return None
    bad = [a for a, row in zip("XYZABC", box) if row[1] < row[0]]
    if bad:
        got = ini.get(f"AXIS_{bad[0]}", "MAX_LIMIT")
        raise InputFileError(got[1], f"[AXIS_{bad[0]}] MAX_LIMIT < MIN_LIMIT", line=got[2])
    bounds = np.array(EULER_RANGES)
    clipped = np.stack([np.maximum(box[3:, 0], bounds[:, 0]), np.minimum(box[3:, 1], bounds[:, 1])], axis=1)
    wide = [k for k in range(3) if np.any(clipped[k] != box[3 + k])]
    if wide:
        notes.append("; ".join(f"[AXIS_{'ABC'[k]}] MIN_LIMIT/MAX_LIMIT = {np.rad2deg(box[3 + k, 0]):.6g}/"
                               f"{np.rad2deg(box[3 + k, 1]):.6g} deg" for k in wide)
                     + " reach beyond the range in which the Euler angles represent each orientation once (A, C "
                       "±180 deg, B ±90 deg): the workspace keeps within it")
        box[3:] = clipped
    return box


__all__ = ["ANGULAR_UNITS", "IniFile", "LINEAR_UNITS", "LinuxcncImport", "OFFSET_MODES", "machine_from_linuxcnc",
           "read_hal_genhexkins", "read_ini"]
