"""Delta printer firmware configurations, both ways: Klipper's ``printer.cfg`` and Marlin's
``M665``/``M666`` settings, to and from :class:`pkmcal.mechanisms.linear_delta.LinearDelta`.

Both firmwares describe a linear delta by the same ten numbers, which are exactly the
vertical-rail, common-radius subset of pkmcal's model (:func:`firmware_subset`):

* Klipper (``klippy/kinematics/delta.py``): ``[printer] delta_radius``, and per
  ``[stepper_a|b|c]`` ``angle`` (default 210, 330, 90°), ``arm_length`` (b and c default to
  a's) and ``position_endstop`` (b and c default to a's); the tower stands at
  delta_radius·(cos angle, sin angle), and the carriage's switch is at
  position_endstop + sqrt(arm² − radius²). ``DELTA_CALIBRATE`` saves its results in the
  ``#*#`` block at the end of the file, which overrides the sections above it.
* Marlin (``Marlin/src/module/delta.cpp``, ``M665``/``M666``): ``M665 R`` the radius,
  ``L`` the diagonal rod plus per-tower trims ``A B C``, tower angles 210/330/90° plus trims
  ``X Y Z``, ``H`` the nozzle height at home; ``M666 X Y Z`` endstop adjustments ≤ 0 (after
  touching its switch, each carriage moves down by |adj|, and there the nozzle is at height
  H): position_endstop_i = H − adj_i, so H = min position_endstop and adj = H −
  position_endstop. H is the value without a probe's z offset (on a Marlin built with a bed
  probe the stored value is H − the ``M851 Z`` offset; set it after loading with M851 in
  mind).

Unequal radii and a tool offset on vertical rails are rewritten exactly
(:func:`exact_rewrite`): a vertical rail is a point B_i of the bed plane, and the tool offset
t only moves the effector joints, so the readings see the rails at B̃_i = B_i + (t_x, t_y)
from the nozzle (t_z cancels: λ_i − H^fw_i = z + sqrt(L_i² − ρ_i²) − E_i − sqrt(L_i² −
|B̃_i|²), ρ_i the nozzle's horizontal distance from B̃_i). Any three points lie on one
circle: with c its centre (the circumcentre of the B̃_i), R its radius and θ'_i the angles of
B̃_i − c, the firmware's machine (R, θ'_i, L_i, E'_i) with

    E'_i = E_i + sqrt(L_i² − |B̃_i|²) − sqrt(L_i² − R²)

(the switch, a carriage height, is where it was) has the same rails, seen from its own
origin c: in the firmware's x, y every position is the calibrated one less c (``origin``),
z unchanged. Nothing is dropped; the export says where the firmware's origin is.

What neither firmware can hold otherwise — rail leans (and, on leaning rails, the radius
differences and tool offset, replaced by their mean and 0) — is listed by
:func:`firmware_subset` with the value that was dropped, so that an export never loses a
parameter silently. Numbers are written with Python's shortest round-trip repr, so that
machine → Klipper config → machine is exact (Marlin: to the 6 decimals written, beyond its
32-bit floats).
"""

from __future__ import annotations

import configparser
import glob
import os
import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import InputFileError
from pkmcal.io.inputs import read_input_text
from pkmcal.io._yaml import rad_to_deg_text
from pkmcal.mechanisms.linear_delta import (
    KLIPPER_TOWER_ANGLES_DEG,
    PARAM_NAMES,
    TOWERS,
    LinearDelta,
    klipper_delta,
)

#: The lines of Klipper's SAVE_CONFIG block start with this.
SAVED_PREFIX = "#*#"


@dataclass(frozen=True)
class DeltaFirmware:
    """The ten numbers both firmwares hold (mm, degrees), plus the print radius and the
    lowest z (Klipper's ``print_radius`` and ``minimum_z_position``) when given."""

    radius: float
    angles_deg: tuple[float, float, float]
    arms: tuple[float, float, float]
    endstops: tuple[float, float, float]
    print_radius: float | None = None
    min_z: float | None = None
    #: Where the firmware's x, y origin is in the calibrated machine's frame (mm): not
    #: (0, 0) after an :func:`exact_rewrite` of unequal radii or a tool offset.
    origin: tuple[float, float] = (0.0, 0.0)

    def machine(self, name: str) -> LinearDelta:
        limits = {}
        if self.print_radius is not None:
            limits["print_radius"] = self.print_radius
        if self.min_z is not None:
            limits["min_z"] = self.min_z
        return klipper_delta(name, self.radius, self.arms, self.endstops, self.angles_deg, **limits)


@dataclass(frozen=True)
class Dropped:
    """A parameter an export cannot represent: its name, the value dropped (internal units)
    and what the firmware uses instead."""

    name: str
    value: float
    replaced_by: float

    def describe(self, is_angle: bool) -> str:
        unit, f = ("deg", np.rad2deg) if is_angle else ("mm", float)
        return (f"{self.name} = {f(self.value):.6g} {unit} cannot be represented; the firmware uses "
                f"{f(self.replaced_by):.6g} {unit}")


def exact_rewrite(machine: LinearDelta) -> tuple[float, np.ndarray, np.ndarray, np.ndarray] | None:
    """(R, angles θ'_i (rad), endstops E'_i, origin c (2,)) of the exact firmware form of a
    vertical-rail ``machine`` (module docstring); None when a rail leans (no exact form)."""
    rho = machine.params
    g = {p: rho[[PARAM_NAMES.index(f"{p}_{t}") for t in TOWERS]] for p in
         ("angle", "radius", "arm", "endstop", "lean_radial", "lean_tangential")}
    if np.any(g["lean_radial"] != 0.0) or np.any(g["lean_tangential"] != 0.0):
        return None
    tool = rho[[PARAM_NAMES.index(n) for n in PARAM_NAMES[-3:]]]
    B = g["radius"][:, None] * np.stack([np.cos(g["angle"]), np.sin(g["angle"])], axis=1) + tool[None, 0:2]
    # circumcentre c: |B_i − c|² equal for all i ⇔ 2 (B_i − B_0)·c = |B_i|² − |B_0|², i = 1, 2
    M = 2.0 * (B[1:] - B[0])
    c = np.linalg.solve(M, np.sum(B[1:] ** 2, axis=1) - np.sum(B[0] ** 2))
    V = B - c
    R = float(np.mean(np.hypot(V[:, 0], V[:, 1])))
    angles = np.arctan2(V[:, 1], V[:, 0])
    angles = g["angle"] + np.angle(np.exp(1j * (angles - g["angle"])))      # the branch nearest the machine's
    arm = g["arm"]
    endstops = g["endstop"] + np.sqrt(arm**2 - np.sum(B**2, axis=1)) - np.sqrt(arm**2 - R**2)
    return R, angles, endstops, c


def firmware_subset(machine: LinearDelta) -> tuple[DeltaFirmware, list[Dropped]]:
    """The firmware numbers of ``machine`` and what they drop. Vertical rails: the
    :func:`exact_rewrite` (nothing dropped; ``origin`` says where the firmware's origin
    is). Leaning rails: its tower angles, arms and endstops, the mean of its radii, and the
    dropped leans, radius differences and tool offset."""
    rho = machine.params
    g = {p: rho[[PARAM_NAMES.index(f"{p}_{t}") for t in TOWERS]] for p in
         ("angle", "radius", "arm", "endstop", "lean_radial", "lean_tangential")}
    exact = exact_rewrite(machine)
    tool_moved = np.any(rho[-3:] != 0.0)
    if exact is not None and (tool_moved or np.any(g["radius"] != g["radius"][0])):
        R, angles, endstops, c = exact
        return DeltaFirmware(radius=R, angles_deg=tuple(float(rad_to_deg_text(a)) for a in angles),
                             arms=tuple(float(a) for a in g["arm"]), endstops=tuple(float(e) for e in endstops),
                             print_radius=float(machine.print_radius), min_z=float(machine.min_z),
                             origin=(float(c[0]), float(c[1]))), []
    radius = float(g["radius"][0]) if np.all(g["radius"] == g["radius"][0]) else float(np.mean(g["radius"]))
    dropped = [Dropped(f"radius_{t}", float(r), radius) for t, r in zip(TOWERS, g["radius"]) if r != radius]
    for lean in ("lean_radial", "lean_tangential"):
        dropped += [Dropped(f"{lean}_{t}", float(v), 0.0) for t, v in zip(TOWERS, g[lean]) if v != 0.0]
    dropped += [Dropped(n, float(v), 0.0) for n, v in zip(PARAM_NAMES[-3:], rho[-3:]) if v != 0.0]
    # the shortest degree value whose radians are the machine's (exact for 8 in 9 angles;
    # the others to one rounding): machine → config → machine keeps the angles
    fw = DeltaFirmware(radius=radius, angles_deg=tuple(float(rad_to_deg_text(a)) for a in g["angle"]),
                       arms=tuple(float(a) for a in g["arm"]), endstops=tuple(float(e) for e in g["endstop"]),
                       print_radius=float(machine.print_radius), min_z=float(machine.min_z))
    return fw, dropped


# -- Klipper ------------------------------------------------------------------------------------


def _parser() -> configparser.ConfigParser:
    """Klipper's config dialect: ``key: value`` or ``key = value``, ``#``/``;`` comments
    (also after a value), indented continuation lines, no interpolation, case-kept keys,
    sections that may repeat (later values win)."""
    return configparser.ConfigParser(delimiters=(":", "="), comment_prefixes=("#", ";"),
                                     inline_comment_prefixes=("#", ";"), interpolation=None, strict=False)


def _split_saved(text: str) -> tuple[str, str]:
    """(the config above the SAVE_CONFIG block, the block without its ``#*#`` prefixes)."""
    lines = text.splitlines()
    start = next((k for k, line in enumerate(lines) if line.startswith(SAVED_PREFIX)), len(lines))
    saved = [line[len(SAVED_PREFIX):].removeprefix(" ") for line in lines[start:] if line.startswith(SAVED_PREFIX)]
    first = next((k for k, line in enumerate(saved) if line.lstrip().startswith("[")), len(saved))
    # the block's banner lines come before its first section; keep the line count
    return "\n".join(lines[:start]), "\n" * first + "\n".join(saved[first:])


def _key_lines(text: str) -> dict[tuple[str, str], int]:
    """(section, key) → the 1-based line of its last assignment, for the messages."""
    out: dict[tuple[str, str], int] = {}
    section = None
    for k, line in enumerate(text.splitlines(), start=1):
        head = re.match(r"^\[([^\]]+)\]", line)
        if head:
            section = head.group(1).strip()
            continue
        key = re.match(r"^([A-Za-z0-9_]+)\s*[:=]", line)
        if key and section is not None:
            out[(section, key.group(1).lower())] = k
    return out


#: One parsed part of a config: (path, parser, (section, key) → line, line offset).
_Part = tuple[str, configparser.ConfigParser, dict]


def _parse(text: str, path: str, what: str) -> configparser.ConfigParser:
    parser = _parser()
    try:
        parser.read_string(text, source=path)
    except configparser.Error as exc:
        line = getattr(exc, "lineno", None)
        detail = " ".join(str(getattr(exc, "message", exc)).split()).split(" file: ")[0]
        raise InputFileError(path, f"{what}: {detail}", line=line) from None
    return parser


def _read_sections(path: str, seen: tuple[str, ...] = ()) -> list[_Part]:
    """The parsed file and, in Klipper's order, the files its ``[include PATTERN]``
    sections name (relative to the including file; globs allowed), then its SAVE_CONFIG
    block."""
    real = os.path.realpath(path)
    if real in seen:
        raise InputFileError(path, "[include] loops back to this file")
    text = read_input_text(path, "Klipper config")
    body, saved = _split_saved(text)
    parser = _parse(body, path, "not a Klipper config file")
    out: list[_Part] = []
    for section in parser.sections():
        if section.startswith("include "):
            pattern = os.path.join(os.path.dirname(path), section[len("include "):].strip())
            matches = sorted(glob.glob(pattern))
            if not matches and not glob.has_magic(pattern):
                raise InputFileError(path, f"[{section}]: no such file {pattern}")
            for inc in matches:
                out.extend(_read_sections(inc, seen + (real,)))
    out.append((path, parser, _key_lines(body)))
    if saved.strip():
        n_body = len(body.splitlines())
        block = _parse(saved, path, "the SAVE_CONFIG (#*#) block is not valid")
        out.append((path, block, {k: v + n_body for k, v in _key_lines(saved).items()}))
    return out


def read_klipper(path: str) -> DeltaFirmware:
    """The delta of a Klipper config (with its includes and SAVE_CONFIG block)."""
    values: dict[tuple[str, str], tuple[str, str, int | None]] = {}   # (section, key) -> (value, file, line)
    for where, parser, lines in _read_sections(path):
        for section in parser.sections():
            for key, value in parser.items(section):
                values[(section.strip(), key)] = (value, where, lines.get((section.strip(), key)))

    def get(section: str, key: str, default=None, required: bool = False):
        if (section, key) not in values:
            if required:
                raise InputFileError(path, f"[{section}] has no '{key}'; a Klipper delta needs it")
            return default
        value, where, line = values[(section, key)]
        try:
            number = float(value)
        except ValueError:
            raise InputFileError(where, f"[{section}] {key}: expected a number, got '{value}'", line=line) from None
        if not np.isfinite(number):
            raise InputFileError(where, f"[{section}] {key}: expected a finite number, got '{value}'", line=line)
        return number

    kin = values.get(("printer", "kinematics"))
    if kin is None:
        raise InputFileError(path, "no [printer] kinematics; is this a Klipper printer.cfg?")
    if kin[0].strip() != "delta":
        raise InputFileError(kin[1], f"[printer] kinematics is '{kin[0].strip()}'; pkmcal imports "
                             "'kinematics: delta' (linear delta printers)", line=kin[2])
    radius = get("printer", "delta_radius", required=True)
    arm_a = get("stepper_a", "arm_length", required=True)
    end_a = get("stepper_a", "position_endstop", required=True)
    arms = tuple(get(f"stepper_{t}", "arm_length", arm_a) for t in TOWERS)
    ends = tuple(get(f"stepper_{t}", "position_endstop", end_a) for t in TOWERS)
    angles = tuple(get(f"stepper_{t}", "angle", a) for t, a in zip(TOWERS, KLIPPER_TOWER_ANGLES_DEG))
    return DeltaFirmware(radius=radius, angles_deg=angles, arms=arms, endstops=ends,
                         print_radius=get("printer", "print_radius", radius),
                         min_z=get("printer", "minimum_z_position", 0.0))


def klipper_text(fw: DeltaFirmware) -> str:
    """The sections Klipper's ``SAVE_CONFIG`` writes for a delta, to paste into (or replace
    in) printer.cfg; numbers in shortest round-trip form."""
    lines = ["[printer]", f"delta_radius = {fw.radius!r}", ""]
    for t, ang, arm, end in zip(TOWERS, fw.angles_deg, fw.arms, fw.endstops):
        lines += [f"[stepper_{t}]", f"angle = {ang!r}", f"arm_length = {arm!r}", f"position_endstop = {end!r}", ""]
    return "\n".join(lines)


# -- Marlin -------------------------------------------------------------------------------------

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_MARLIN_ANGLES = KLIPPER_TOWER_ANGLES_DEG   # Marlin's towers: 210, 330, 90° plus the trims


def read_marlin(path: str) -> DeltaFirmware:
    """The delta of Marlin's ``M665``/``M666`` lines: a G-code file, or ``M503`` output
    (``echo:`` prefixes and ``;`` comments allowed); later lines override earlier ones."""
    lines = read_input_text(path, "Marlin settings file").splitlines()
    m665: dict[str, float] = {}
    m666: dict[str, float] = {}
    for k, raw in enumerate(lines, start=1):
        line = raw.split(";", 1)[0].strip()
        line = re.sub(r"^(echo:|//)\s*", "", line).strip()
        code = re.match(r"^M(665|666)\b(.*)$", line, flags=re.IGNORECASE)
        if not code:
            continue
        target = m665 if code.group(1) == "665" else m666
        rest = code.group(2)
        words = _WORD.findall(rest)
        if _WORD.sub("", rest).strip():
            raise InputFileError(path, f"cannot read '{raw.strip()}' (expected letter-number words such as "
                                 "L215.0 R105.0)", line=k)
        for letter, number in words:
            target[letter.upper()] = float(number)
    for needed in ("L", "R", "H"):
        if needed not in m665:
            raise InputFileError(path, f"no M665 {needed} value; pkmcal needs M665 L (diagonal rod), R (radius) "
                                 "and H (height); print them with M503")
    trims = tuple(m665.get(c, 0.0) for c in "ABC")
    angle_trims = tuple(m665.get(c, 0.0) for c in "XYZ")
    adj = tuple(m666.get(c, 0.0) for c in "XYZ")
    if any(a > 0 for a in adj):
        raise InputFileError(path, "M666 endstop adjustments must be ≤ 0 (Marlin ignores positive ones); got "
                             f"{', '.join(f'{c}{a:g}' for c, a in zip('XYZ', adj))}")
    H = m665["H"]
    return DeltaFirmware(radius=m665["R"], angles_deg=tuple(a + t for a, t in zip(_MARLIN_ANGLES, angle_trims)),
                         arms=tuple(m665["L"] + t for t in trims), endstops=tuple(H - a for a in adj))


def _marlin_number(v: float) -> str:
    """Marlin keeps 32-bit floats (about 7 significant digits): 6 decimals (1 nm, 1e-6°)
    are beyond what it holds, and short enough to read."""
    text = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def marlin_text(fw: DeltaFirmware) -> str:
    """``M665``/``M666`` lines (then ``M500`` to store them): L the mean arm with per-tower
    trims A B C, angle trims X Y Z from 210/330/90°, H the lowest endstop height and the
    M666 adjustments (≤ 0) of the others; numbers to 6 decimals (:func:`_marlin_number`)."""
    L = float(np.mean(fw.arms))
    H = float(min(fw.endstops))
    words = {"L": L, "R": fw.radius, "H": H}
    words.update({c: a - n for c, a, n in zip("XYZ", fw.angles_deg, _MARLIN_ANGLES)})
    words.update({c: a - L for c, a in zip("ABC", fw.arms)})
    adj = {c: min(0.0, H - e) for c, e in zip("XYZ", fw.endstops)}
    m665 = "M665 " + " ".join(f"{c}{_marlin_number(v)}" for c, v in words.items())
    m666 = "M666 " + " ".join(f"{c}{_marlin_number(v)}" for c, v in adj.items())
    return "\n".join([m665, m666, "M500 ; store in EEPROM", ""])


__all__ = ["DeltaFirmware", "Dropped", "exact_rewrite", "firmware_subset", "klipper_text", "marlin_text",
           "read_klipper", "read_marlin"]
