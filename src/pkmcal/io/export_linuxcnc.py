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
    MIN_LIMIT_N, MAX_LIMIT_N = L0_i + g_i λ_min,i + m_i, L0_i + g_i λ_max,i − m_i
                                              (the stroke less the stroke margin m_i,
                                               :func:`stroke_margins`: 1 % of the stroke)
    HOME_N = L_i at pkmcal's home pose;       [TRAJ] HOME = the home pose X Y Z A B C

LinuxCNC homes the joints to HOME_N, so the INI is refused for a home pose outside the joint
limits or the machine's joint tilts (:func:`check_home`). Lengths are written in mm, or in
the unit of the machine's INI file (:func:`export_unit`: ``[TRAJ] LINEAR_UNITS`` of the file
it was imported from, or of the user's file :func:`updated_ini` updates).

Numbers are rounded to a resolution chosen from the machine's, and the files say so in a
comment line (:data:`LINUXCNC_ROUNDING`). LinuxCNC itself has none to offer: it reads HAL
``setp`` values and INI values as C doubles (``strtod``) and computes genhexkins in double.
What is meaningful is the machine's resolution: its joints count encoder or step increments
([JOINT_N] SCALE counts per unit), 0.1 µm on the finest linear encoders of precision
hexapods' struts, and it is calibrated to micrometres. The rule: lengths to the first decimal
whose step is at most 1 nm, a hundredth of such a count (6 decimals in mm, 8 in inch,
:data:`LINUXCNC_DECIMALS`), and the angles of [TRAJ] HOME to 1e-7° (an arc of 1.7 nm at 1
m, :data:`ANGLE_DECIMALS`); the leg gains, which are comments, are written in full. Importing
an export gives the rounded numbers exactly (in inch: each times 25.4, one rounding);
:func:`rounded_machine` is that machine and
:func:`pkmcal.io.delta_firmware.rounding_effect` what the rounding changes in the strut
lengths LinuxCNC commands (below 1e-5 mm). :func:`updated_ini` writes the
keys pkmcal owns (:data:`OWNED_KEYS`) into a copy of the user's own INI file and keeps every
other byte.

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

import os

import numpy as np

from pkmcal import __version__
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


#: Decimals of the exported lengths per unit (module docstring): the first whose step is at
#: most 1 nm (mm: 1e-6 mm; inch: 1e-8 inch = 0.254 nm, as 1e-7 inch is 2.54 nm).
LINUXCNC_DECIMALS = {"mm": 6, "inch": 8}
#: Decimals of the exported angles (degrees: 1e-7° is an arc of 1.7 nm at 1 m).
ANGLE_DECIMALS = 7
#: The comment line (after ``# ``) of a LinuxCNC export, and the export's message.
LINUXCNC_ROUNDING = ("numbers rounded to 1 nm (6 decimals in mm, 8 in inch) and 1e-7 deg: LinuxCNC reads doubles; "
                     "1 nm is a hundredth of a 0.1 um encoder count")


def _num(v: float) -> str:
    """``v`` as the shortest positional decimal that reads back to the same double (of a
    value already rounded by :func:`_in_unit` or :func:`_deg`, that rounded decimal)."""
    v = float(v)
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v}) to LinuxCNC")
    return np.format_float_positional(v + 0.0, unique=True, trim="0")  # + 0.0 turns -0.0 into 0.0


def _decimals(mm_per_unit: float) -> int:
    """:data:`LINUXCNC_DECIMALS` of the unit of ``mm_per_unit`` (:data:`EXPORT_UNITS`)."""
    name = next((n for n, f in EXPORT_UNITS.items() if f == mm_per_unit), None)
    if name is None:
        raise PkmcalError(f"no LinuxCNC export unit of {mm_per_unit} mm")
    return LINUXCNC_DECIMALS[name]


def _in_unit(v_mm: float, mm_per_unit: float) -> float:
    """``v_mm`` in the export's unit (mm / ``mm_per_unit``), rounded to its
    :data:`LINUXCNC_DECIMALS`: the number written, and what the import reads."""
    v = float(v_mm) / mm_per_unit
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v_mm}) to LinuxCNC")
    return round(v, _decimals(mm_per_unit)) + 0.0


def _deg(v_rad: float) -> float:
    """An angle (rad) in degrees, rounded to :data:`ANGLE_DECIMALS`."""
    return round(float(np.rad2deg(float(v_rad))), ANGLE_DECIMALS) + 0.0


def rounded_machine(machine: Hexapod, linear_unit: str | None = None) -> Hexapod:
    """``machine`` with the numbers the export writes of it (joints b_i, a_i, offsets L0_i)
    as written, in mm (:func:`_in_unit` times the unit): the machine LinuxCNC runs."""
    _, factor = export_unit(machine, linear_unit)
    rho = np.array(machine.params, dtype=float)
    names = machine.param_names
    for k, n in enumerate(names):
        if n.startswith(("b", "a", "L0_")) and not n.startswith("gain"):
            rho[k] = _in_unit(rho[k], factor) * factor
    return machine.with_params(rho)


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


#: Default margin between an exported joint limit and the end of the stroke, as a fraction
#: of the stroke (1 %, 0.5 mm of the prototype's 50 mm): LinuxCNC never commands a joint past
#: its soft limit, but the joint itself goes past it by its following error, and its zero is
#: known only to the homing repeatability; the margin leaves that room before the hard stop.
#: ``pkmcal export --stroke-margin MM`` sets it (0: the limits are the stroke's ends).
DEFAULT_STROKE_MARGIN = 0.01
#: The comment line of an exported INI giving the margins (mm), which ``pkmcal import
#: linuxcnc`` adds back to read the stroke.
STROKE_MARGIN_COMMENT = "# pkmcal.stroke_margin_mm ="
#: LinuxCNC's ``[TRAJ] LINEAR_UNITS`` names pkmcal writes, mm per unit. LinuxCNC knows mm,
#: metric, in, inch and imperial (the unit table of its task, ``milltask``; no cm), so a
#: machine is written in mm or in inch.
EXPORT_UNITS = {"mm": 1.0, "inch": 25.4}


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
    factor = LINEAR_UNITS.get(key)
    if factor not in EXPORT_UNITS.values():
        raise PkmcalError(f"machine '{machine.name}': length unit '{linear_unit}' is not one LinuxCNC reads; write "
                          "the configuration in mm or inch ([TRAJ] LINEAR_UNITS = mm, metric, in, inch or imperial)")
    name = next(n for n, f in EXPORT_UNITS.items() if f == factor)
    return name, factor


def stroke_margins(machine: Hexapod, stroke_margin: float | None = None) -> np.ndarray:
    """The margin (6,) in mm of strut length between each exported joint limit and the end of
    the stroke it stands for: ``stroke_margin`` mm when given (0: the limits are the stroke),
    else :data:`DEFAULT_STROKE_MARGIN` of each joint's stroke."""
    g = leg_gains(machine)
    travel = g * (machine.stroke[:, 1] - machine.stroke[:, 0])
    if stroke_margin is None:
        return DEFAULT_STROKE_MARGIN * travel
    m = float(stroke_margin)
    if not (np.isfinite(m) and m >= 0):
        raise PkmcalError(f"--stroke-margin {stroke_margin}: give a length >= 0 (mm)")
    if np.any(2 * m >= travel):
        n = int(np.argmax(2 * m >= travel))
        raise PkmcalError(f"--stroke-margin {m:g} mm leaves joint {n} (leg {n + 1}) no travel: its stroke is "
                          f"{travel[n]:.6g} mm; give less than half of it")
    return np.full(6, m)


def joint_settings(machine: Hexapod, mm_per_unit: float = 1.0, stroke_margin: float | None = None
                   ) -> dict[str, np.ndarray]:
    """The INI values of joints 0..5 (module docstring) in the export's unit (mm /
    ``mm_per_unit``): ``HOME_OFFSET``, ``MIN_LIMIT``, ``MAX_LIMIT`` (the stroke less
    :func:`stroke_margins` at both ends), ``HOME`` (each (6,)), the margins ``margin`` (mm)
    and the gains ``gain`` (mm of strut per reading unit, unscaled)."""
    check_hexapod(machine)
    g = leg_gains(machine)
    margin = stroke_margins(machine, stroke_margin)
    mm = {"HOME_OFFSET": machine.offset + g * home_switch_reading(machine),
          "MIN_LIMIT": machine.offset + g * machine.stroke[:, 0] + margin,
          "MAX_LIMIT": machine.offset + g * machine.stroke[:, 1] - margin,
          "HOME": machine.leg_lengths(machine.home_pose)[0]}
    return {**{k: np.array([_in_unit(x, mm_per_unit) for x in v]) for k, v in mm.items()}, "margin": margin,
            "gain": g}


#: The machine's limits a home pose must keep for an export (LinuxCNC homes there): the
#: joint tilts and the singularity margin; the stroke is checked against the exported joint
#: limits. A leg collision at home is a warning only (:func:`home_warnings`): the modelled legs
#: of tight designs pass within a fraction of a millimetre of each other at home
#: (pkmcal.planning.margins), so a calibration can move them just inside.
HOME_LIMITS = ("u_joint_tilt", "s_joint_tilt", "singularity")


def check_home(machine: Hexapod, settings: dict[str, np.ndarray], unit: str = "mm") -> None:
    """A :class:`PkmcalError` when the home pose is outside the exported joint limits or the
    machine's :data:`HOME_LIMITS`: LinuxCNC homes the joints to ``[JOINT_N] HOME``, so
    :func:`linuxcnc_ini` refuses to write such a machine (the HAL file holds no home; the
    command line warns when it is exported alone)."""
    out = [n for n in range(6) if not settings["MIN_LIMIT"][n] <= settings["HOME"][n] <= settings["MAX_LIMIT"][n]]
    if out:
        n = out[0]
        raise PkmcalError(f"machine '{machine.name}': at its home pose joint {n} (leg {n + 1}) is "
                          f"{settings['HOME'][n]:.6g} {unit}, outside the exported joint limits "
                          f"[{settings['MIN_LIMIT'][n]:.6g}, {settings['MAX_LIMIT'][n]:.6g}] {unit} (the stroke less "
                          f"the stroke margin); LinuxCNC homes there: give the machine a home pose inside its "
                          "stroke ('home:' in the machine file) or a smaller --stroke-margin")
    report = machine.check_limits(np.asarray(machine.home_pose, dtype=float)[None])
    bad = [name for name in HOME_LIMITS if name in report.violations and report.violations[name][0]]
    if bad:
        detail = ", ".join(_limit_text(machine, name, report) for name in bad)
        raise PkmcalError(f"machine '{machine.name}': its home pose violates its own limits ({detail}); LinuxCNC "
                          "homes there: give the machine a home pose inside its limits ('home:' in the machine "
                          "file) or correct the limits")


def _limit_text(machine: Hexapod, name: str, report) -> str:
    margin = report.margins.get(name)
    limit = getattr(machine.limits, name, None)
    if margin is None or limit is None or name == "singularity":
        return name
    return f"{name} {np.rad2deg(float(limit) - float(margin[0])):.3g} deg against {np.rad2deg(float(limit)):.3g} deg"


def home_warnings(machine: Hexapod) -> list[str]:
    """One line per limit outside :data:`HOME_LIMITS` (and the stroke) that the home pose
    violates: exported, with this said."""
    report = machine.check_limits(np.asarray(machine.home_pose, dtype=float)[None])
    return [f"machine '{machine.name}': its home pose violates its {name} limit (exported all the same: LinuxCNC "
            "does not check it)" for name, bad in report.violations.items()
            if bad[0] and name not in HOME_LIMITS and name != "stroke"]


def _home_pose_text(machine: Hexapod, mm_per_unit: float = 1.0) -> str:
    """X Y Z A B C of the home pose (the export's unit, degrees), rounded (:func:`_in_unit`,
    :func:`_deg`)."""
    return " ".join([_num(_in_unit(v, mm_per_unit)) for v in machine.home_pose[:3]]
                    + [_num(_deg(v)) for v in machine.home_pose[3:]])


def linuxcnc_ini(machine: Hexapod, linear_unit: str | None = None, stroke_margin: float | None = None) -> str:
    """INI sections (``[TRAJ]``, ``[KINS]``, ``[JOINT_0]`` .. ``[JOINT_5]``) matching
    :func:`linuxcnc_hal` for ``machine``: units, home pose, joint limits, home offsets and
    home positions (:func:`joint_settings`), values written exactly (in mm) or to one
    rounding (another unit, :func:`export_unit`). Merge them into the machine's INI file
    (keep its other keys: velocities, accelerations, homing speeds)."""
    unit, factor = export_unit(machine, linear_unit)
    s = joint_settings(machine, factor, stroke_margin)
    check_home(machine, s, unit)
    lines = comment_lines(f"genhexkins joints of machine '{machine.name}', written by pkmcal {__version__}, "
                          "to match the HAL file of the same export.")
    lines += [f"# pkmcal: {LINUXCNC_ROUNDING}",
        "# Merge these keys into the machine's INI file (LinuxCNC uses the first of repeated keys), or",
        "# let 'pkmcal export --update-ini MACHINE.ini' write them into a copy of it.",
        f"# Joint N = strut length of pkmcal leg N+1 ({unit}): HOME_OFFSET = L0 + gain * (reading at the",
        "# home switch), MIN_LIMIT/MAX_LIMIT = L0 + gain * stroke, each the stroke margin inside (room",
        "# for the following error and the homing repeatability before the end of the stroke), HOME =",
        f"# strut length at the home pose [TRAJ] HOME (X Y Z {unit}, A B C degrees). Stroke margins (mm):",
        f"{STROKE_MARGIN_COMMENT} {' '.join(_num(_in_unit(v, 1.0)) for v in s['margin'])}",
    ]
    if np.any(s["gain"] != 1.0) or machine.actuator_unit != "mm":
        runit = one_line(machine.actuator_unit)
        lines.append(f"# Leg gains (mm of strut per {runit} of reading): set each joint's SCALE (counts per {unit}) to")
        per_unit = "" if unit == "mm" else f" * (mm per {unit})"
        lines.append(f"# (encoder/step counts per {runit}){per_unit} / gain"
                     + (", i.e. divide the scale that made the readings by the gain:" if runit == unit == "mm"
                        else ":"))
        lines += [f"#   joint {n}: gain {_num(g)} mm/{runit}" for n, g in enumerate(s["gain"])]
    lines += ["", "[TRAJ]", f"LINEAR_UNITS = {unit}", "ANGULAR_UNITS = degree",
              f"HOME = {_home_pose_text(machine, factor)}", "", "[KINS]", "KINEMATICS = genhexkins", "JOINTS = 6"]
    for n in range(6):
        lines += ["", f"[JOINT_{n}]", "TYPE = LINEAR"]
        lines += [f"{key} = {_num(s[key][n])}" for key in ("MIN_LIMIT", "MAX_LIMIT", "HOME_OFFSET", "HOME")]
    return "\n".join(lines) + "\n"


def linuxcnc_hal(machine: Hexapod, linear_unit: str | None = None, stroke_margin: float | None = None) -> str:
    """HAL text (``setp`` lines and comments) configuring genhexkins for ``machine``.

    ``setp genhexkins.base.N.x|y|z`` and ``setp genhexkins.platform.N.x|y|z`` for N = 0..5
    (pkmcal leg i = N + 1), values in mm written exactly (shortest round-trip decimal).
    Comment lines carry, per joint, L0_i (``HOME_OFFSET`` when the home switch is at
    reading λ = 0), the joint limits L0_i + stroke, and the strut length at the machine's
    home pose (``HOME``). Run it (``halcmd -f``, or a ``[HAL] HALFILE``) after the HAL file
    that loads genhexkins (``loadrt genhexkins``).
    """
    unit, factor = export_unit(machine, linear_unit)
    s = joint_settings(machine, factor, stroke_margin)
    home_file = [_in_unit(v, factor) for v in machine.home_pose[:3]] + [_deg(v) for v in machine.home_pose[3:]]
    offset = np.array([_in_unit(v, factor) for v in machine.offset])
    lines = comment_lines(f"genhexkins configuration for machine '{machine.name}', written by pkmcal {__version__}.")
    lines += [f"# pkmcal: {LINUXCNC_ROUNDING}",
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
            lines.append(f"setp {HAL_PREFIX}.base.{n}.{axis} {_num(_in_unit(machine.base[n, k], factor))}")
    for n in range(6):
        for axis, k in zip("xyz", range(3)):
            lines.append(f"setp {HAL_PREFIX}.platform.{n}.{axis} {_num(_in_unit(machine.platform[n, k], factor))}")
    lines += [
        "#",
        "# Leg offsets and homing. pkmcal's actuator reading is lambda_i = L_i - L0_i; genhexkins'",
        "# joint is the strut length L_i = L0_i + lambda_i. With the home switch at reading",
        "# lambda_i = 0 set [JOINT_N] HOME_OFFSET = L0 below (else L0 + the reading at the switch).",
        f"# MIN_LIMIT/MAX_LIMIT = L0 + stroke, each the stroke margin inside (up to {_num(_in_unit(max(s['margin']), 1.0))} mm);",
        "# HOME = strut length at pkmcal's home pose",
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


# -- a user's INI file, updated --------------------------------------------------------------

#: ``[TRAJ] ANGULAR_UNITS`` values meaning degrees (pkmcal writes [TRAJ] HOME's A B C in degrees).
_DEGREES = ("deg", "degree", "degrees")


def ini_units(path: str | os.PathLike) -> str:
    """The ``[TRAJ] LINEAR_UNITS`` of a user's INI file (mm when absent), checked: angles in
    degrees, and no ``[JOINT_N] UNITS`` other than it (the export writes one unit)."""
    from pkmcal.errors import InputFileError
    from pkmcal.io.import_linuxcnc import LINEAR_UNITS, read_ini

    ini = read_ini(path)
    got = ini.get("TRAJ", "LINEAR_UNITS")
    unit = "mm" if got is None else got[0].strip().lower()
    if got is not None and unit not in LINEAR_UNITS:
        raise InputFileError(got[1], f"[TRAJ] LINEAR_UNITS = {got[0]}: unknown unit; LinuxCNC's are "
                                     f"{', '.join(LINEAR_UNITS)}", line=got[2])
    ang = ini.get("TRAJ", "ANGULAR_UNITS")
    if ang is not None and ang[0].strip().lower() not in _DEGREES:
        raise InputFileError(ang[1], f"[TRAJ] ANGULAR_UNITS = {ang[0]}: pkmcal writes [TRAJ] HOME's A B C in degrees; "
                                     "use ANGULAR_UNITS = degree", line=ang[2])
    for n in range(6):
        ju = ini.get(f"JOINT_{n}", "UNITS")
        if ju is not None and LINEAR_UNITS.get(ju[0].strip().lower()) != LINEAR_UNITS[unit]:
            raise InputFileError(ju[1], f"[JOINT_{n}] UNITS = {ju[0]} differs from [TRAJ] LINEAR_UNITS = {unit}; "
                                        "pkmcal writes the joints in the trajectory's unit", line=ju[2])
    return unit


def updated_ini(path: str | os.PathLike, machine: Hexapod, stroke_margin: float | None = None) -> str:
    """The text of the user's INI file ``path`` with the keys pkmcal owns (:data:`OWNED_KEYS`)
    set for ``machine``, in the file's own length unit (:func:`ini_units`), and every other
    byte kept: a key's first occurrence (the one LinuxCNC reads) has its value replaced, its
    spelling, spacing and line ending kept (a value continued with ``\\`` becomes one line);
    a key the file lacks is added after its section's last key (a section it lacks, at the
    end). The unit keys are left as written (they already say what the values are in);
    ``[KINS] KINEMATICS`` keeps its arguments when it already names genhexkins. A key set in
    an ``#INCLUDE``d file is an error (pkmcal writes one file)."""
    from pkmcal.errors import InputFileError
    from pkmcal.io.import_linuxcnc import _read_text, read_ini

    src = os.fspath(path)
    unit = ini_units(src)
    values = _owned_values(machine, unit, stroke_margin)
    parsed = read_ini(src)
    for (section, key) in values:
        got = parsed.get(section, key)
        if got is not None and os.path.abspath(got[1]) != os.path.abspath(src):
            raise InputFileError(got[1], f"[{section}] {key} is set in this file, included by {src}; pkmcal updates "
                                         "one file: move the key into it", line=got[2])
    kins = parsed.get("KINS", "KINEMATICS")
    if kins is not None and kins[0].split()[:1] == ["genhexkins"]:
        values.pop(("KINS", "KINEMATICS"))
    text = _read_text(src, "INI file")
    physical = text.splitlines(keepends=True)
    newline = "\r\n" if text.count("\r\n") * 2 > text.count("\n") else "\n"
    out: list[str] = []
    section, in_first, seen = None, False, set()
    last_key_at: dict[str, int] = {}        # section → index in out after its last key line (first block)
    done: set[tuple[str, str]] = set()
    k = 0
    while k < len(physical):
        line = physical[k]
        logical = [line]
        while logical[-1].rstrip("\r\n").endswith("\\") and k + 1 < len(physical):
            k += 1
            logical.append(physical[k])
        k += 1
        stripped = line.strip()
        if stripped.startswith("[") and stripped.rstrip().endswith("]") and len(stripped) >= 3:
            section = stripped[1:-1].strip().upper()
            in_first = section not in seen          # keys are added to a section's first block
            seen.add(section)
            out += logical
            if in_first:
                last_key_at[section] = len(out)
            continue
        out += logical
        if section is None or not stripped or stripped[0] in "#;" or "=" not in stripped:
            continue
        if in_first:
            last_key_at[section] = len(out)
        key = stripped.partition("=")[0].strip().upper()
        if (section, key) in values and (section, key) not in done:
            done.add((section, key))
            head = line[: line.index("=") + 1]
            spaces = line[len(head):][: len(line[len(head):]) - len(line[len(head):].lstrip(" \t"))]
            ending = logical[-1][len(logical[-1].rstrip("\r\n")):] or newline
            out[len(out) - len(logical):] = [f"{head}{spaces}{values[(section, key)]}{ending}"]
            if in_first:
                last_key_at[section] = len(out)
    missing: dict[str, list[str]] = {}
    for (sec, key), value in values.items():
        if (sec, key) not in done and key not in ("LINEAR_UNITS", "ANGULAR_UNITS"):
            missing.setdefault(sec, []).append(f"{key} = {value}{newline}")
    for sec in sorted((s for s in missing if s in last_key_at), key=lambda s: -last_key_at[s]):
        at = last_key_at[sec]
        if at and not out[at - 1].endswith(("\n", "\r")):
            out[at - 1] += newline
        out[at:at] = missing[sec]
    tail = [s for s in missing if s not in last_key_at]
    if tail:
        if out and not out[-1].endswith(("\n", "\r")):
            out[-1] += newline
        for sec in tail:
            out += [newline, f"[{sec}]{newline}", *missing[sec]]
    return "".join(out)


def _owned_values(machine: Hexapod, unit: str, stroke_margin: float | None) -> dict[tuple[str, str], str]:
    """``{(SECTION, KEY): text}`` of :data:`OWNED_KEYS` for ``machine`` in ``unit`` (what
    :func:`linuxcnc_ini` writes), the home checked (:func:`check_home`)."""
    name, factor = export_unit(machine, unit)
    s = joint_settings(machine, factor, stroke_margin)
    check_home(machine, s, name)
    values = {("TRAJ", "LINEAR_UNITS"): name, ("TRAJ", "ANGULAR_UNITS"): "degree",
              ("TRAJ", "HOME"): _home_pose_text(machine, factor), ("KINS", "KINEMATICS"): "genhexkins",
              ("KINS", "JOINTS"): "6"}
    for n in range(6):
        values[(f"JOINT_{n}", "TYPE")] = "LINEAR"
        for key in ("MIN_LIMIT", "MAX_LIMIT", "HOME_OFFSET", "HOME"):
            values[(f"JOINT_{n}", key)] = _num(s[key][n])
    assert set(values) == set(OWNED_KEYS)
    return values
