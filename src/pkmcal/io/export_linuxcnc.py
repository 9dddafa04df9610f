"""Export a (calibrated) hexapod to LinuxCNC's ``genhexkins`` kinematics module.

genhexkins (LinuxCNC ``src/emc/kinematics/genhexkins.c``) computes, for a pose
``X Y Z A B C`` (mm, degrees), the strut lengths

    joint_N = ‖ p + R a_N − b_N ‖,     R = Rz(C) Ry(B) Rx(A)   (posemath ``pmRpyMatConvert``)

with b_N the base joints in world coordinates (HAL ``genhexkins.base.N.x|y|z``) and a_N the
platform joints in platform coordinates (``genhexkins.platform.N.x|y|z``). That is exactly
pkmcal's leg length L_i = ‖p + R a_i − b_i‖ (paper 1 eq. 1, paper 2 eq. 1) with N = i − 1 and
the same pose convention (:mod:`pkmcal.conventions`), so the joints are copied unchanged.

genhexkins' joints are strut *lengths* (mm); pkmcal's actuator readings are
λ_i = (L_i − L0_i) / g_i in the machine's ``actuator_unit`` (L_i = L0_i + g_i λ_i with the
leg gains g_i, mm per reading unit: 1 for readings in mm, the default). The leg
offsets L0_i have no genhexkins pin: they enter LinuxCNC through homing, as the joint
position assigned at the home switch (``[JOINT_N] HOME_OFFSET`` in the INI file). The INI
settings that match the machine (:func:`joint_settings`):

    HOME_OFFSET_N = L0_i + g_i λ_switch,i     (λ_switch: the reading at the home switch; 0
                                               unless metadata.linuxcnc.home_switch_reading)
    MIN_LIMIT_N, MAX_LIMIT_N = L0_i + g_i λ_min,i, L0_i + g_i λ_max,i      (the stroke)
    HOME_N = L_i at pkmcal's home pose;       [TRAJ] HOME = the home pose X Y Z A B C

:func:`linuxcnc_hal` writes the ``setp`` lines (and these values as comments),
:func:`linuxcnc_ini` the INI sections ``[TRAJ]``, ``[KINS]`` and ``[JOINT_0..5]`` to merge
into the machine's INI file; :mod:`pkmcal.io.import_linuxcnc` reads both back (as a machine
with readings in mm, gains 1: the same strut lengths). The gains set the joints' scale:
LinuxCNC counts strut millimetres, so ``[JOINT_N] SCALE`` (counts per mm) = (encoder or
step counts per reading unit) / g_i; for readings in mm, divide the scale that made those
readings by g_i (the INI comments list the gains). See ``docs/conventions.md``.

The text is safe by construction for ``halcmd -f``, which reads a file with ``fgets`` into
a 1024-byte buffer (``MAX_CMD_LEN``) and treats ``#`` to the end of the line as a comment:
user text (the machine's name and description) only ever appears in comment lines, with
every control character escaped (:func:`pkmcal.errors.one_line`, so no newline can start a
live ``setp`` line), and is wrapped into comment lines of at most :data:`MAX_COMMENT_CHARS`
characters (< 1024 bytes even in 4-byte UTF-8, so no tail of a long line can be read as a
command).
"""

from __future__ import annotations

import numpy as np

from pkmcal import __version__
from pkmcal.conventions import poses_to_file_units
from pkmcal.errors import PkmcalError, one_line
from pkmcal.mechanisms.hexapod import Hexapod

#: HAL prefix of the genhexkins component.
HAL_PREFIX = "genhexkins"
#: Longest comment line written (characters, '# ' included): 4 × 200 bytes < halcmd's 1024.
MAX_COMMENT_CHARS = 200
#: The INI keys pkmcal owns, ``(SECTION, KEY)``: what :func:`linuxcnc_ini` writes and
#: ``export --ini`` updates in a user's INI file; every other key is the user's.
OWNED_KEYS: tuple[tuple[str, str], ...] = (
    ("TRAJ", "LINEAR_UNITS"), ("TRAJ", "ANGULAR_UNITS"), ("TRAJ", "HOME"), ("KINS", "KINEMATICS"), ("KINS", "JOINTS"),
    *((f"JOINT_{n}", key) for n in range(6) for key in ("TYPE", "MIN_LIMIT", "MAX_LIMIT", "HOME_OFFSET", "HOME")))


def comment_lines(text: str, first: str = "# ", rest: str = "#   ") -> list[str]:
    """``text`` (one line, control characters escaped) as HAL comment lines of at most
    :data:`MAX_COMMENT_CHARS` characters: ``first`` before the first piece, ``rest`` before
    the others."""
    body = one_line(text)
    out, prefix = [], first
    while True:
        room = MAX_COMMENT_CHARS - len(prefix)
        out.append(prefix + body[:room])
        body, prefix = body[room:], rest
        if not body:
            return out


def _num(v: float) -> str:
    """Shortest text that reads back to the same double (so the export is exact)."""
    v = float(v)
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v}) to LinuxCNC")
    return repr(v + 0.0)  # + 0.0 turns -0.0 into 0.0


def check_hexapod(machine) -> None:
    if "linuxcnc" not in machine.abilities:
        raise PkmcalError(f"LinuxCNC export supports 6-UPS hexapods (genhexkins); machine '{machine.name}' is a "
                          f"{machine.kind} machine")


def leg_gains(machine: Hexapod) -> np.ndarray:
    """g_i (6,): mm of strut length per reading unit, the machine's calibrated gains
    (``legs[i].gain``, 1 unless given or identified). The one place the export reads gains."""
    return np.array(machine.gains, dtype=float)


def home_switch_reading(machine: Hexapod) -> np.ndarray:
    """λ_switch (6,): the actuator readings at the home switches,
    ``metadata.linuxcnc.home_switch_reading`` (written by ``pkmcal import linuxcnc
    --offsets zero``), else zeros (readings zeroed at the switch)."""
    meta = (machine.metadata or {}).get("linuxcnc") or {}
    value = meta.get("home_switch_reading") if isinstance(meta, dict) else None
    if value is None:
        return np.zeros(6)
    arr = np.asarray(value, dtype=float)
    if arr.shape != (6,) or not np.all(np.isfinite(arr)):
        raise PkmcalError(f"machine '{machine.name}': metadata.linuxcnc.home_switch_reading must be 6 finite "
                          f"numbers (mm), got {value!r}")
    return arr


#: LinuxCNC's ``[TRAJ] LINEAR_UNITS`` names pkmcal writes, mm per unit (the reader,
#: :data:`pkmcal.io.import_linuxcnc.LINEAR_UNITS`, takes these and their synonyms).
EXPORT_UNITS = {"mm": 1.0, "cm": 10.0, "inch": 25.4}


def export_unit(machine: Hexapod, linear_unit: str | None = None) -> tuple[str, float]:
    """``(unit, mm per unit)`` of the export: ``linear_unit`` when given (a user's INI file's
    ``[TRAJ] LINEAR_UNITS``), else the unit of the INI file the machine was imported from
    (``metadata.linuxcnc.linear_units``, written by ``pkmcal import linuxcnc``), else mm.
    Synonyms are written as LinuxCNC's main names (in, imperial → inch; metric → mm)."""
    from pkmcal.io.import_linuxcnc import LINEAR_UNITS

    if linear_unit is None:
        meta = (machine.metadata or {}).get("linuxcnc") or {}
        linear_unit = meta.get("linear_units") if isinstance(meta, dict) else None
    if linear_unit is None:
        return "mm", 1.0
    key = str(linear_unit).strip().lower()
    if key not in LINEAR_UNITS:
        raise PkmcalError(f"machine '{machine.name}': LinuxCNC length unit '{linear_unit}' is not one of "
                          f"{', '.join(LINEAR_UNITS)}")
    factor = LINEAR_UNITS[key]
    name = next(n for n, f in EXPORT_UNITS.items() if f == factor)
    return name, factor


def joint_settings(machine: Hexapod, mm_per_unit: float = 1.0) -> dict[str, np.ndarray]:
    """The INI values of joints 0..5 (module docstring) in the export's unit (mm /
    ``mm_per_unit``): ``HOME_OFFSET``, ``MIN_LIMIT``, ``MAX_LIMIT``, ``HOME`` (each (6,)),
    and the gains ``gain`` (mm of strut per reading unit, unscaled)."""
    check_hexapod(machine)
    g = leg_gains(machine)
    mm = {"HOME_OFFSET": machine.offset + g * home_switch_reading(machine),
          "MIN_LIMIT": machine.offset + g * machine.stroke[:, 0],
          "MAX_LIMIT": machine.offset + g * machine.stroke[:, 1],
          "HOME": machine.leg_lengths(machine.home_pose)[0]}
    return {**{k: v / mm_per_unit for k, v in mm.items()}, "gain": g}


def _home_pose_text(machine: Hexapod, mm_per_unit: float = 1.0) -> str:
    """X Y Z A B C of the home pose (the export's unit, degrees), each angle as the degree
    text that reads back to the same radians (:func:`pkmcal.io._yaml.rad_to_deg_text`)."""
    from pkmcal.io._yaml import rad_to_deg_text

    return " ".join([_num(v / mm_per_unit) for v in machine.home_pose[:3]]
                    + [rad_to_deg_text(float(v) + 0.0) for v in machine.home_pose[3:]])


def linuxcnc_ini(machine: Hexapod, linear_unit: str | None = None) -> str:
    """INI sections (``[TRAJ]``, ``[KINS]``, ``[JOINT_0]`` .. ``[JOINT_5]``) matching
    :func:`linuxcnc_hal` for ``machine``: units, home pose, joint limits, home offsets and
    home positions (:func:`joint_settings`), values written exactly (in mm) or to one
    rounding (another unit, :func:`export_unit`). Merge them into the machine's INI file
    (keep its other keys: velocities, accelerations, homing speeds)."""
    unit, factor = export_unit(machine, linear_unit)
    s = joint_settings(machine, factor)
    lines = comment_lines(f"genhexkins joints of machine '{machine.name}', written by pkmcal {__version__}, "
                          "to match the HAL file of the same export.")
    lines += [
        "# Merge these keys into the machine's INI file (LinuxCNC uses the first of repeated keys).",
        f"# Joint N = strut length of pkmcal leg N+1 ({unit}): HOME_OFFSET = L0 + gain * (reading at the",
        "# home switch), MIN_LIMIT/MAX_LIMIT = L0 + gain * stroke, HOME = strut length at the home",
        f"# pose [TRAJ] HOME (X Y Z {unit}, A B C degrees).",
    ]
    if np.any(s["gain"] != 1.0) or machine.actuator_unit != "mm":
        runit = one_line(machine.actuator_unit)
        lines.append(f"# Leg gains (mm of strut per {runit} of reading): set each joint's SCALE (counts per {unit}) to")
        lines.append(f"# (encoder/step counts per {runit}) * (mm per {unit}) / gain"
                     + (", i.e. divide the scale that made the readings by the gain:" if runit == unit == "mm"
                        else ":"))
        lines += [f"#   joint {n}: gain {_num(g)} mm/{runit}" for n, g in enumerate(s["gain"])]
    lines += ["", "[TRAJ]", f"LINEAR_UNITS = {unit}", "ANGULAR_UNITS = degree",
              f"HOME = {_home_pose_text(machine, factor)}", "", "[KINS]", "KINEMATICS = genhexkins", "JOINTS = 6"]
    for n in range(6):
        lines += ["", f"[JOINT_{n}]", "TYPE = LINEAR"]
        lines += [f"{key} = {_num(s[key][n])}" for key in ("MIN_LIMIT", "MAX_LIMIT", "HOME_OFFSET", "HOME")]
    return "\n".join(lines) + "\n"


def linuxcnc_hal(machine: Hexapod, linear_unit: str | None = None) -> str:
    """HAL text (``setp`` lines and comments) configuring genhexkins for ``machine``.

    ``setp genhexkins.base.N.x|y|z`` and ``setp genhexkins.platform.N.x|y|z`` for N = 0..5
    (pkmcal leg i = N + 1), values in mm written exactly (shortest round-trip decimal).
    Comment lines carry, per joint, L0_i (``HOME_OFFSET`` when the home switch is at
    reading λ = 0), the joint limits L0_i + stroke, and the strut length at the machine's
    home pose (``HOME``). Run it (``halcmd -f``, or a ``[HAL] HALFILE``) after the HAL file
    that loads genhexkins (``loadrt genhexkins``).
    """
    unit, factor = export_unit(machine, linear_unit)
    s = joint_settings(machine, factor)
    home_file = poses_to_file_units(machine.home_pose)
    home_file[:3] /= factor
    offset = machine.offset / factor
    lines = comment_lines(f"genhexkins configuration for machine '{machine.name}', written by pkmcal {__version__}.")
    lines += [
        f"# Units: {unit} (set [TRAJ] LINEAR_UNITS = {unit}); A B C in degrees.",
        "# Pose X Y Z A B C = pkmcal x y z a b c: the platform frame in the base (world) frame,",
        "#   R = Rz(C) Ry(B) Rx(A), roll-pitch-yaw about the fixed base axes (pmRpyMatConvert).",
        f"# Joint N (N = 0..5) = strut length of pkmcal leg N+1 = |p + R a_N - b_N| ({unit}),",
        "#   base.N = b_N in the base frame, platform.N = a_N in the platform frame.",
        "# The model has no strut-length correction and no frame shift: genhexkins.screw-lead,",
        "#   genhexkins.spindle-offset and genhexkins.tool-offset must be 0 (their defaults).",
    ]
    if machine.description:
        lines += comment_lines(f"Machine: {machine.description}")
    for n in range(6):
        for axis, k in zip("xyz", range(3)):
            lines.append(f"setp {HAL_PREFIX}.base.{n}.{axis} {_num(machine.base[n, k] / factor)}")
    for n in range(6):
        for axis, k in zip("xyz", range(3)):
            lines.append(f"setp {HAL_PREFIX}.platform.{n}.{axis} {_num(machine.platform[n, k] / factor)}")
    lines += [
        "#",
        "# Leg offsets and homing. pkmcal's actuator reading is lambda_i = L_i - L0_i; genhexkins'",
        "# joint is the strut length L_i = L0_i + lambda_i. With the home switch at reading",
        "# lambda_i = 0 set [JOINT_N] HOME_OFFSET = L0 below (else L0 + the reading at the switch).",
        "# MIN_LIMIT/MAX_LIMIT = L0 + stroke; HOME = strut length at pkmcal's home pose",
        f"# x y z a b c = {' '.join(_num(v) for v in home_file)} ({unit}, deg).",
        "# 'pkmcal export --format linuxcnc --ini FILE' writes these as INI sections [JOINT_N].",
    ]
    if np.any(s["gain"] != 1.0) or machine.actuator_unit != "mm":
        unit = one_line(machine.actuator_unit)
        lines += [f"# Readings in {unit} with leg gains (mm of strut per {unit}): strut length L_i = L0_i + gain_i *",
                  "# lambda_i, so HOME_OFFSET = L0 + gain * (reading at the switch) and MIN_LIMIT/MAX_LIMIT =",
                  "# L0 + gain * stroke (the gains: 'gain=' below and in the INI comments)."]
    for n in range(6):
        home_offset = "" if s["HOME_OFFSET"][n] == offset[n] else f" HOME_OFFSET={_num(s['HOME_OFFSET'][n])}"
        lines.append(
            f"# pkmcal.joint.{n} leg={n + 1} L0={_num(offset[n])} MIN_LIMIT={_num(s['MIN_LIMIT'][n])} "
            f"MAX_LIMIT={_num(s['MAX_LIMIT'][n])} HOME={_num(s['HOME'][n])}{home_offset}"
            + ("" if s["gain"][n] == 1.0 else f" gain={_num(s['gain'][n])}")
        )
    return "\n".join(lines) + "\n"
