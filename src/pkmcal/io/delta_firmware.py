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

The standard deviations of the firmware's numbers (:func:`firmware_sigmas`, what ``export``
judges against its tolerances) are the calibration's covariance Σ propagated through that
rewrite, J Σ Jᵀ, with the angles relative to tower c's (Klipper holds angle_c): numbers of
the firmware's own frame, free of the fit's gauge.

What neither firmware can hold otherwise — rail leans (and, on leaning rails, the radius
differences and tool offset, replaced by their mean and 0) — is listed by
:func:`firmware_subset` with the value that was dropped, so that an export never loses a
parameter silently.

Numbers are written at the firmware's own resolution, and the file says so in a comment line
(:data:`KLIPPER_ROUNDING`, :data:`pkmcal.io.marlin_settings.MARLIN_ROUNDING`): Klipper's to 6
decimals, as its ``SAVE_CONFIG`` writes a delta's calibration (``"%.6f"`` in
``klippy/kinematics/delta.py`` ``DeltaCalibration.save_state`` and
``klippy/kinematics/rotary_delta.py`` ``RotaryDeltaCalibration.save_state``), so that an
export reads as Klipper's own and importing it gives the rounded numbers exactly
(:func:`klipper_rounded`). What the rounding changes is measured by :func:`rounding_effect`:
the largest change of the actuator positions the firmware commands over the machine's
workspace (about 1e-6 mm for the 6th decimal, far below any probe's noise).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io._yaml import rad_to_deg_text
from pkmcal.mechanisms.linear_delta import (
    KLIPPER_TOWER_ANGLES_DEG,
    PARAM_NAMES,
    TOWERS,
    LinearDelta,
    klipper_delta,
)

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
    #: Each carriage's travel below its switch and the flattest arm (rad) that the firmware
    #: commands, when read from a config (:func:`read_klipper`); None: pkmcal's defaults.
    travel: tuple[float, float, float] | None = None
    min_arm_angle: float | None = None

    def machine(self, name: str) -> LinearDelta:
        limits = {}
        if self.print_radius is not None:
            limits["print_radius"] = self.print_radius
        if self.min_z is not None:
            limits["min_z"] = self.min_z
        if self.travel is not None:
            limits["travel"] = np.array(self.travel)
        if self.min_arm_angle is not None:
            limits["min_arm_angle"] = self.min_arm_angle
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


#: The firmware's own numbers of a linear delta whose standard deviations
#: :func:`firmware_sigmas` gives: Klipper's coordinate descent frees the radius, angle_a,
#: angle_b and the endstops (the arms in its extended mode) and holds angle_c
#: (klippy/kinematics/delta.py, ``DeltaCalibration.coordinate_descent_params``), so the
#: angles are those relative to tower c's, free of the turn of the whole tower set.
FIRMWARE_NUMBERS = ("delta_radius", "angle_a", "angle_b", "arm_a", "arm_b", "arm_c", "endstop_a", "endstop_b",
                    "endstop_c")


def firmware_sigmas(machine: LinearDelta, covariance: np.ndarray) -> dict[str, float] | None:
    """Standard deviations of the firmware's numbers (:data:`FIRMWARE_NUMBERS`; mm, rad)
    of a vertical-rail ``machine`` whose parameters have ``covariance`` (p, p): the
    covariance propagated through its :func:`exact_rewrite` (the towers about their circle's
    centre, the angles relative to tower c's), J Σ Jᵀ with J by central differences (steps
    1e-5 mm, 1e-7 rad: the rewrite is smooth, so the truncation error is ~1e-10 of σ). These
    do not depend on the gauge the fit chose (the slide and turn of the tower set are not in
    them). None for a machine with leaning rails (no exact firmware form)."""
    rho = np.asarray(machine.params, dtype=float)
    is_angle = np.asarray(machine.param_is_angle, dtype=bool)

    def numbers(r):
        out = exact_rewrite(_Params(r))
        if out is None:
            return None
        R, ang, E, _ = out
        arms = r[[PARAM_NAMES.index(f"arm_{t}") for t in TOWERS]]
        return np.r_[R, ang[0] - ang[2], ang[1] - ang[2], arms, E]

    if numbers(rho) is None:
        return None
    cov = np.asarray(covariance, dtype=float)
    cols = np.flatnonzero(np.diag(cov) > 0)
    J = np.zeros((len(FIRMWARE_NUMBERS), len(cols)))
    for j, k in enumerate(cols):
        h = 1e-7 if is_angle[k] else 1e-5
        up, down = rho.copy(), rho.copy()
        up[k] += h
        down[k] -= h
        J[:, j] = (numbers(up) - numbers(down)) / (2 * h)
    var = np.einsum("ij,jk,ik->i", J, cov[np.ix_(cols, cols)], J)
    return dict(zip(FIRMWARE_NUMBERS, np.sqrt(np.maximum(var, 0.0)).tolist()))


#: Tolerance of the firmware's numbers (the standard deviation beyond which the measurements
#: do not determine one): 0.1 % of the mean arm for lengths (the tolerance of the delta's
#: named scale direction: a 100 mm print 0.1 mm off); for a tower angle, the angle that
#: moves the tower by that length at the mean radius.
LENGTH_TOLERANCE = 1e-3


def undetermined_firmware_numbers(machine: LinearDelta, covariance: np.ndarray) -> list[tuple[str, str]]:
    """(name, plain line) of each firmware number of ``machine`` whose standard deviation
    under ``covariance`` (:func:`firmware_sigmas`; a machine with leaning rails, which has no
    exact firmware form: its parameters' own) is above its tolerance (:data:`LENGTH_TOLERANCE`):
    what ``export`` refuses unless accepted by name and ``identify`` warns of."""
    names = list(machine.param_names)
    rho = machine.params
    arm = float(np.mean([rho[names.index(f"arm_{t}")] for t in TOWERS]))
    radius = float(np.mean([rho[names.index(f"radius_{t}")] for t in TOWERS]))
    stds = firmware_sigmas(machine, covariance)
    if stds is None:
        own = [f"{p}_{t}" for p in ("radius", "angle", "arm", "endstop") for t in TOWERS]
        cov = np.asarray(covariance, dtype=float)
        stds = {n: float(np.sqrt(max(cov[names.index(n), names.index(n)], 0.0))) for n in own}
        angle_names = {n for n in stds if n.startswith("angle_")}
    else:
        angle_names = {"angle_a", "angle_b"}
    out = []
    for n, sigma in stds.items():
        angle = n in angle_names
        tol = LENGTH_TOLERANCE * arm / (radius if angle else 1.0)
        if not sigma > tol:
            continue
        shown = (f"{np.rad2deg(sigma):.3g} deg, tolerance {np.rad2deg(tol):.3g} deg (the tower moved "
                 f"{LENGTH_TOLERANCE * arm:.3g} mm, 0.1 % of the {arm:.4g} mm arm, at the {radius:.4g} mm radius)"
                 if angle else f"{sigma:.3g} mm, tolerance {tol:.3g} mm (0.1 % of the {arm:.4g} mm arm)")
        out.append((n, f"{n}: the measurements do not determine it (sigma {shown})"))
    return out


class _Params:
    """What :func:`exact_rewrite` reads of a machine: its parameter vector."""

    def __init__(self, params):
        self.params = params


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


@dataclass(frozen=True)
class RotaryFirmware:
    """Klipper's ``kinematics: rotary_delta`` numbers (klippy/kinematics/rotary_delta.py
    ``RotaryDeltaKinematics.__init__``; mm, degrees): ``[printer] shoulder_radius,
    shoulder_height``, per ``[stepper_a|b|c]`` ``angle`` (default 30, 150, 270°),
    ``upper_arm_length``, ``lower_arm_length`` and ``position_endstop`` (b and c default to
    a's), ``minimum_z_position``.

    In pkmcal's :class:`~pkmcal.mechanisms.rotary_delta.RotaryDelta` the frame is
    Klipper's (origin on the bed, z up: every shoulder at ``height`` = shoulder_height),
    arm i's ``angle``, ``radius`` = shoulder_radius, ``upper``, ``forearm`` = lower arm.
    Klipper's stepper angle is the upper arm's angle *above* the outward horizontal
    (``RotaryDeltaCalibration.elbow_coord``), pkmcal's φ the angle below it: φ = −angle.
    The switch: Klipper's ``abs_endstop`` is the stepper angle where the nozzle is at
    (0, 0, position_endstop); pkmcal's motor zero ζ_i is φ there, so a reading
    λ_i = φ_i − ζ_i is the angle the arm turned down from its switch — Klipper's
    ``calc_stable_position`` times the step angle, the quantity its DELTA_CALIBRATE
    stores."""

    shoulder_radius: float
    shoulder_height: float
    angles_deg: tuple[float, float, float]
    upper_arms: tuple[float, float, float]
    lower_arms: tuple[float, float, float]
    endstops: tuple[float, float, float]
    min_z: float = 0.0

    def _nominal(self, name: str, zero=(0.0, 0.0, 0.0), **limits):
        from pkmcal.mechanisms import rotary_delta as rd

        rho = np.zeros(len(rd.PARAM_NAMES))
        for i in range(3):
            rho[rd.param_position("angle", i)] = np.deg2rad(self.angles_deg[i])
            rho[rd.param_position("radius", i)] = self.shoulder_radius
            rho[rd.param_position("height", i)] = self.shoulder_height
            rho[rd.param_position("upper", i)] = self.upper_arms[i]
            rho[rd.param_position("forearm", i)] = self.lower_arms[i]
            rho[rd.param_position("zero", i)] = zero[i]
        return rd.RotaryDelta(name=name, rho=rho, **limits)

    def switch_angles(self) -> np.ndarray:
        """φ_i (rad) of arm i with the nozzle at (0, 0, position_endstop_i): minus Klipper's
        ``abs_endstops`` (``RotaryDeltaCalibration.__init__``)."""
        m = self._nominal("switches")
        phi = m.ik(np.c_[np.zeros((3, 2)), np.array(self.endstops)])
        return np.array([phi[i, i] for i in range(3)])

    def max_xy(self) -> float:
        """rotary_delta.py ``__init__``: max_xy² = min(min(shoulder_radius + upper),
        min(lower − shoulder_radius))²."""
        return float(min(min(self.shoulder_radius + u for u in self.upper_arms),
                         min(lo - self.shoulder_radius for lo in self.lower_arms)))

    def machine(self, name: str):
        zero = self.switch_angles()
        if not np.all(np.isfinite(zero)):
            raise PkmcalError(f"rotary delta '{name}': an arm cannot reach (0, 0, position_endstop); check "
                              "shoulder_radius, shoulder_height and the arm lengths")
        # Klipper limits the nozzle to a cylinder (max_xy, min_z..max_z = min position_endstop);
        # it has no motor range and no joint cone: pkmcal's motor range runs from the highest
        # switch down to the upper arm pointing straight down, the cone is the full 90°
        return self._nominal(name, zero, motor_range=(float(np.min(zero)), float(np.pi / 2)),
                             max_joint_angle=float(np.pi / 2), workspace_radius=self.max_xy(),
                             z_range=(self.min_z, float(min(self.endstops))))


def rotary_firmware_subset(machine) -> tuple[RotaryFirmware, list[Dropped]]:
    """Klipper's rotary-delta numbers of ``machine`` (a pkmcal RotaryDelta) and what they
    drop: one shoulder radius and height (the means), no axis yaw or tilt, the tool offset's
    z in the height (exact: it shifts every shoulder) and its x, y dropped. The endstops:
    each arm's switch angle (its zero ζ_i) with the nozzle on the axis,
    position_endstop_i = E_z − sqrt(b_i² − |E_xy|²) of that elbow E (the nozzle below it)."""
    from pkmcal.mechanisms import rotary_delta as rd

    g = rd.LAYOUT.split(machine.params)
    tool = machine.params[-3:]
    radius = float(g["radius"][0]) if np.all(g["radius"] == g["radius"][0]) else float(np.mean(g["radius"]))
    heights = g["height"] + tool[2]
    height = float(heights[0]) if np.all(heights == heights[0]) else float(np.mean(heights))
    dropped = [Dropped(f"radius_{t}", float(r), radius) for t, r in zip(rd.ARMS, g["radius"]) if r != radius]
    dropped += [Dropped(f"height_{t}", float(h), height - float(tool[2]))
                for t, h in zip(rd.ARMS, g["height"]) if h + tool[2] != height]
    for p in ("axis_yaw", "axis_tilt"):
        dropped += [Dropped(f"{p}_{t}", float(v), 0.0) for t, v in zip(rd.ARMS, g[p]) if v != 0.0]
    dropped += [Dropped(n, float(v), 0.0) for n, v in zip(rd.PARAM_NAMES[-3:-1], tool[:2]) if v != 0.0]
    zeta, a, b = g["zero"], g["upper"], g["forearm"]
    th = g["angle"]
    reach = radius + a * np.cos(zeta)                       # the elbow's distance from the axis
    ez = height - a * np.sin(zeta)
    ends = ez - np.sqrt(b**2 - reach**2)
    fw = RotaryFirmware(shoulder_radius=radius, shoulder_height=height,
                        angles_deg=tuple(float(rad_to_deg_text(t)) for t in th),
                        upper_arms=tuple(float(v) for v in a), lower_arms=tuple(float(v) for v in b),
                        endstops=tuple(float(e) for e in ends), min_z=float(machine.z_range[0]))
    return fw, dropped


@dataclass(frozen=True)
class KlipperPrinter:
    """What ``pkmcal import klipper`` reads from a printer.cfg: the kinematics' numbers,
    the probe's offsets (``[probe]`` or ``[bltouch]`` x_offset, y_offset, z_offset; None
    without either) and notes for the user."""

    firmware: DeltaFirmware | RotaryFirmware
    probe_offset: tuple[float, float, float] | None
    probe_section: str | None
    notes: tuple[str, ...]
    #: The files read: printer.cfg and its includes (an output may be none of them).
    files: tuple[str, ...] = ()

    def machine(self, name: str):
        return self.firmware.machine(name)


#: klippy/kinematics/delta.py: moves slow down where the tower moves SLOW_RATIO times faster
#: than the nozzle; the build radius stops at 4·SLOW_RATIO.
SLOW_RATIO = 3.0


def _half_step(cfg, path: str) -> tuple[float | None, str]:
    """Half the smallest step distance of [stepper_a|b|c] (delta.py ``__init__``:
    ``half_min_step_dist``), or None and why when the file does not give it."""
    from pkmcal.io.klipper_probe import _step_distance

    values = {k: (o.value, o.path, o.line) for k, o in cfg.options.items()}
    try:
        return 0.5 * min(_step_distance(values, t, path) for t in TOWERS), ""
    except InputFileError as exc:
        return None, str(exc)


def _linear(cfg, path: str, notes: list[str]) -> DeltaFirmware:
    """klippy/kinematics/delta.py ``DeltaKinematics.__init__`` (Klipper v0.12)."""
    radius = cfg.float("printer", "delta_radius", above=0.0)
    print_radius = cfg.float("printer", "print_radius", radius, above=0.0)
    arm_a = cfg.float("stepper_a", "arm_length", above=radius)
    arms = tuple(cfg.float(f"stepper_{t}", "arm_length", arm_a, above=radius) for t in TOWERS)
    # stepper.py PrinterRail: position_endstop of b and c default to a's; with
    # need_position_minmax=False the rail's range is [0, position_endstop]
    end_a = cfg.float("stepper_a", "position_endstop")
    ends = tuple(cfg.float(f"stepper_{t}", "position_endstop", end_a) for t in TOWERS)
    for t, e in zip(TOWERS, ends):
        if e < 0:
            opt = cfg.get(f"stepper_{t}", "position_endstop") or cfg.get("stepper_a", "position_endstop")
            raise InputFileError(opt.path, f"[stepper_{t}] position_endstop = {e:g}: Klipper requires it between "
                                 "position_min (0) and position_max", line=opt.line)
    angles = tuple(cfg.float(f"stepper_{t}", "angle", a) for t, a in zip(TOWERS, KLIPPER_TOWER_ANGLES_DEG))
    max_z = min(ends)
    min_z = cfg.float("printer", "minimum_z_position", 0.0, maxval=max_z)
    # the build radius: min(print_radius, shortest arm − radius, ratio_to_xy(4·SLOW_RATIO))
    half, why = _half_step(cfg, path)
    min_arm = min(arms)

    def ratio_to_xy(ratio: float, h: float) -> float:
        return ratio * np.sqrt(min_arm**2 / (ratio**2 + 1.0) - h**2) + h - radius

    ratio_xy = ratio_to_xy(4.0 * SLOW_RATIO, 0.0 if half is None else half)
    max_xy = float(min(print_radius, min_arm - radius, ratio_xy))
    if half is None and max_xy == ratio_xy:
        notes.append(f"Klipper's build radius {max_xy:.6g} mm is computed without its half-step term (a few µm): "
                     f"{why}")
    # the carriage travel: from the switch (abs_endstop = position_endstop + sqrt(arm² −
    # radius²)) down to the lowest carriage Klipper commands, the nozzle at minimum_z at the
    # build radius on the far side of the tower (check_move: z >= min_z, x² + y² <= max_xy²)
    arm = np.array(arms)
    far = np.sqrt(np.maximum(arm**2 - (radius + max_xy) ** 2, 0.0))
    travel = np.array(ends) + np.sqrt(arm**2 - radius**2) - (min_z + far)
    flattest = float(np.min(np.arcsin(far / arm)))
    return DeltaFirmware(radius=radius, angles_deg=angles, arms=arms, endstops=ends, print_radius=max_xy,
                         min_z=min_z, travel=tuple(float(v) for v in travel), min_arm_angle=flattest)


def _rotary(cfg, path: str) -> RotaryFirmware:
    """klippy/kinematics/rotary_delta.py ``RotaryDeltaKinematics.__init__`` (Klipper v0.12)."""
    sr = cfg.float("printer", "shoulder_radius", above=0.0)
    sh = cfg.float("printer", "shoulder_height", above=0.0)
    ua = cfg.float("stepper_a", "upper_arm_length", above=0.0)
    la = cfg.float("stepper_a", "lower_arm_length", above=0.0)
    upper = tuple(cfg.float(f"stepper_{t}", "upper_arm_length", ua, above=0.0) for t in TOWERS)
    lower = tuple(cfg.float(f"stepper_{t}", "lower_arm_length", la, above=0.0) for t in TOWERS)
    angles = tuple(cfg.float(f"stepper_{t}", "angle", a) for t, a in zip(TOWERS, ROTARY_ANGLES_DEG))
    end_a = cfg.float("stepper_a", "position_endstop")
    ends = tuple(cfg.float(f"stepper_{t}", "position_endstop", end_a) for t in TOWERS)
    min_z = cfg.float("printer", "minimum_z_position", 0.0, maxval=min(ends))
    return RotaryFirmware(shoulder_radius=sr, shoulder_height=sh, angles_deg=angles, upper_arms=upper,
                          lower_arms=lower, endstops=ends, min_z=min_z)


#: klippy/kinematics/rotary_delta.py: the default arm angles of stepper_a, b, c (degrees).
ROTARY_ANGLES_DEG = (30.0, 150.0, 270.0)
#: The sections of Klipper's probes whose x_offset, y_offset, z_offset pkmcal reads
#: (klippy/extras/probe.py ``PrinterProbe``: x_offset, y_offset default 0, z_offset
#: required; bltouch.py reads them through the same probe code).
PROBE_SECTIONS = ("probe", "bltouch")


def _probe(cfg, path: str) -> tuple[tuple[float, float, float] | None, str | None]:
    found = [s for s in PROBE_SECTIONS if cfg.has_section(s)]
    if not found:
        return None, None
    if len(found) > 1:
        # Klipper: both register the object 'probe' ("Printer object 'probe' already created")
        raise InputFileError(path, "both [probe] and [bltouch]: Klipper allows one probe; remove one")
    s = found[0]
    return (cfg.float(s, "x_offset", 0.0), cfg.float(s, "y_offset", 0.0), cfg.float(s, "z_offset")), s


def read_klipper_printer(path: str) -> KlipperPrinter:
    """The delta printer a Klipper config describes, read as Klipper reads it
    (:mod:`pkmcal.io.klipper_config`: includes in place, the SAVE_CONFIG block under the main
    file's values), with its probe offsets."""
    from pkmcal.io.klipper_config import read_config

    cfg = read_config(path)
    notes = list(cfg.notes)
    kin = cfg.get("printer", "kinematics")
    if kin is None:
        raise InputFileError(path, "no [printer] kinematics; is this a Klipper printer.cfg?")
    kind = kin.value.strip()
    if kind == "delta":
        fw: DeltaFirmware | RotaryFirmware = _linear(cfg, path, notes)
    elif kind == "rotary_delta":
        fw = _rotary(cfg, path)
    else:
        raise InputFileError(kin.path, f"[printer] kinematics is '{kind}'; pkmcal imports 'kinematics: delta' and "
                             "'kinematics: rotary_delta'", line=kin.line)
    offset, section = _probe(cfg, path)
    return KlipperPrinter(fw, offset, section, tuple(notes), tuple(cfg.files))


def read_klipper(path: str) -> DeltaFirmware | RotaryFirmware:
    """The delta of a Klipper config, read as Klipper reads it (:func:`read_klipper_printer`)."""
    return read_klipper_printer(path).firmware


#: Decimals of the numbers Klipper's SAVE_CONFIG writes for a delta: ``"%.6f"`` in
#: klippy/kinematics/delta.py ``DeltaCalibration.save_state`` (delta_radius, angle,
#: arm_length, position_endstop) and klippy/kinematics/rotary_delta.py
#: ``RotaryDeltaCalibration.save_state`` (shoulder_radius, shoulder_height, angle,
#: position_endstop). pkmcal writes every number of its Klipper exports so.
KLIPPER_DECIMALS = 6
#: The comment line (after ``# ``) of a Klipper export, and the export's message.
KLIPPER_ROUNDING = ("numbers to 6 decimals (1e-6 mm, 1e-6 deg), as Klipper's SAVE_CONFIG writes them "
                    "(klippy/kinematics/delta.py DeltaCalibration.save_state)")


def klipper_number(v: float) -> str:
    """``v`` as Klipper's SAVE_CONFIG writes it, ``"%.6f"`` (:data:`KLIPPER_DECIMALS`); a
    rounded zero without its sign."""
    v = float(v)
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v}) to Klipper")
    text = f"{v:.{KLIPPER_DECIMALS}f}"
    return f"{0.0:.{KLIPPER_DECIMALS}f}" if float(text) == 0.0 else text


def klipper_rounded(fw: DeltaFirmware | RotaryFirmware) -> DeltaFirmware | RotaryFirmware:
    """``fw`` with every number Klipper's export writes rounded as written
    (:func:`klipper_number`): what Klipper reads back from the export, exactly."""
    from dataclasses import replace

    r = lambda vs: tuple(float(klipper_number(v)) for v in vs)  # noqa: E731
    if isinstance(fw, RotaryFirmware):
        return replace(fw, shoulder_radius=float(klipper_number(fw.shoulder_radius)),
                       shoulder_height=float(klipper_number(fw.shoulder_height)), angles_deg=r(fw.angles_deg),
                       upper_arms=r(fw.upper_arms), lower_arms=r(fw.lower_arms), endstops=r(fw.endstops))
    return replace(fw, radius=float(klipper_number(fw.radius)), angles_deg=r(fw.angles_deg), arms=r(fw.arms),
                   endstops=r(fw.endstops))


def rounding_effect(exact, rounded, n: int = 5, points: np.ndarray | None = None) -> float:
    """The largest change of the actuator positions counted from their switches (internal
    units: mm of a carriage's travel or a strut, rad of an arm) that the firmware commands
    with the ``rounded`` machine instead of the ``exact`` one, at ``points`` (poses of both
    machines' frame; default a grid of ``n`` points per coordinate of the ``exact`` machine's
    workspace box), over the points both machines reach: what writing the numbers at the
    firmware's resolution costs."""
    if points is None:
        box = np.asarray(exact.workspace_box(), dtype=float)
        axes = [np.linspace(lo, hi, n) for lo, hi in box]
        points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, box.shape[0])

    def counted(m):
        # what the motors count from their switches: a linear delta's reading is a carriage
        # height, its stepper counts the travel H^fw − λ below the switch (Klipper's abs_endstop
        # less the carriage height); a rotary delta's and a hexapod's reading is that already
        q = np.asarray(m.ik(points), dtype=float)
        return m.reading_reference[None, :] - q if m.kind == "linear-delta" else q

    with np.errstate(all="ignore"):
        diff = np.abs(counted(rounded) - counted(exact))
    diff = diff[np.all(np.isfinite(diff), axis=1)]
    return float(diff.max()) if diff.size else 0.0


def klipper_values(fw: DeltaFirmware | RotaryFirmware) -> dict[str, dict[str, str]]:
    """Section → option → text of what Klipper's SAVE_CONFIG saves after DELTA_CALIBRATE
    (delta.py / rotary_delta.py ``save_state``), plus a rotary delta's arm lengths; numbers
    as Klipper writes them, ``"%.6f"`` (:func:`klipper_number`)."""
    k = klipper_number
    if isinstance(fw, RotaryFirmware):
        out = {"printer": {"shoulder_radius": k(fw.shoulder_radius), "shoulder_height": k(fw.shoulder_height)}}
        for t, ang, ua, la, end in zip(TOWERS, fw.angles_deg, fw.upper_arms, fw.lower_arms, fw.endstops):
            out[f"stepper_{t}"] = {"angle": k(ang), "position_endstop": k(end), "upper_arm_length": k(ua),
                                   "lower_arm_length": k(la)}
        return out
    out = {"printer": {"delta_radius": k(fw.radius)}}
    for t, ang, arm, end in zip(TOWERS, fw.angles_deg, fw.arms, fw.endstops):
        out[f"stepper_{t}"] = {"angle": k(ang), "arm_length": k(arm), "position_endstop": k(end)}
    return out


def klipper_text(fw: DeltaFirmware | RotaryFirmware) -> str:
    """The sections Klipper's ``SAVE_CONFIG`` writes for a delta, to paste into (or replace
    in) printer.cfg, after a comment line saying how the numbers are rounded
    (:data:`KLIPPER_ROUNDING`)."""
    lines = [f"# pkmcal: {KLIPPER_ROUNDING}"]
    for section, opts in klipper_values(fw).items():
        lines += [f"[{section}]"] + [f"{k} = {v}" for k, v in opts.items()] + [""]
    return "\n".join(lines)


def klipper_saved_config(path: str, fw: DeltaFirmware | RotaryFirmware) -> str:
    """The user's printer.cfg ``path`` as Klipper's SAVE_CONFIG leaves it with ``fw`` saved
    (:func:`pkmcal.io.klipper_config.save_config_text`): the ``#*#`` block updated, the main
    file's copies of the saved options commented out, and the comment line on the rounding
    (:data:`KLIPPER_ROUNDING`) first unless the file already has it."""
    from pkmcal.io.klipper_config import save_config_text

    kin = read_klipper(path)
    if type(kin) is not type(fw):
        what = {DeltaFirmware: "delta", RotaryFirmware: "rotary_delta"}
        raise InputFileError(path, f"this printer.cfg is a '{what[type(kin)]}' printer; the machine is a "
                             f"'{what[type(fw)]}'")
    text = save_config_text(path, klipper_values(fw))
    note = f"# pkmcal: {KLIPPER_ROUNDING}"
    return text if note in text.splitlines() else f"{note}\n{text}"


# -- Marlin -------------------------------------------------------------------------------------


def read_marlin(path: str, version: str | None = None, **options) -> DeltaFirmware:
    """The delta of Marlin's ``M665``/``M666`` lines as Marlin ``version`` runs them
    (:func:`pkmcal.io.marlin_settings.read_marlin_settings`)."""
    from pkmcal.io.marlin_settings import read_marlin_settings

    return read_marlin_settings(path, version, **options).firmware


def marlin_text(fw: DeltaFirmware, version: str = "2.1.x", **options) -> str:
    """``M665``/``M666`` lines for Marlin ``version`` (:func:`pkmcal.io.marlin_settings.marlin_text`)."""
    from pkmcal.io.marlin_settings import marlin_text as text

    return text(fw, version, **options)[0]


__all__ = ["KLIPPER_DECIMALS", "KLIPPER_ROUNDING", "DeltaFirmware", "Dropped", "KlipperPrinter", "RotaryFirmware",
           "exact_rewrite", "firmware_subset", "klipper_number", "klipper_rounded", "klipper_saved_config",
           "klipper_text", "klipper_values", "marlin_text", "read_klipper", "read_klipper_printer", "read_marlin",
           "rotary_firmware_subset", "rounding_effect"]
