"""Safety margins of a measurement plan: how far inside the *nominal* machine's limits the
planned poses stay, so that the *real* machine — whose joints differ from the nominal ones by
millimetres before calibration — still reaches them when commanded through the nominal model.

The real machine commanded with the nominal leg readings λ reaches a pose that differs from
the planned one. With joint position errors of size δ (mm):

* the platform turns by up to about δ / r_p (r_p: the smallest platform joint radius), which
  tilts every spherical joint by as much, and each leg's direction changes by about δ / L
  (L: the shortest leg, L0 + lowest reading, within what the geometry reaches:
  :meth:`~pkmcal.mechanisms.base.Mechanism.within_geometry`, so that a configuration that
  allows struts of length ≤ 0 still has one); hence the **joint tilt margin**

      Δθ = atan(δ / r_p) + atan(δ / L_min)                          (degrees on the command line)

  on both the U- and the S-joint limits;
* the **stroke margin** is δ mm at both ends (encoder zero and homing uncertainty of the same
  order; the readings themselves are commanded, so the geometry does not move them);
* the **leg clearance margin** stays small (:data:`CLEARANCE_MARGIN_MM`): the modelled legs of
  tight designs pass within 0.13 mm of each other at home (the prototype), so a margin of δ
  would reject the home pose itself.

The default δ = :data:`ASSUMED_JOINT_ERROR_MM` = 3 mm is the largest joint deviation of
paper 2's Table 4 (1–3 mm). On the prototype (r_p = 70 mm, L_min = 305 mm) it gives 3 mm and
3.02°, and every pose of the indicator tutorial's plan is then reached by
``stewart-prototype-real`` (18 of 45 exceeded its 29° S-joint tilt with the former default of
0.1 mm / 0.1°). A machine expected to deviate more needs larger margins (``--stroke-margin``,
``--tilt-margin``). A margin that is given is not derived (:func:`resolve_margin`).

**Deltas** (:class:`DeltaSafetyMargin`; the platform only translates, so only the arm
direction and the nozzle position move):

* linear delta: **rail travel** δ mm at both ends (as the hexapod's stroke: homing and
  endstop uncertainty), **arm angle** atan(δ / l_min) on the minimum arm elevation (an
  arm's direction changes by about δ over the shortest arm l_min), **print radius and bed**
  2δ mm (the real nozzle is off by about δ per link of its chain: carriage and arm):
  3 mm, 0.799°, 6 mm on ``kossel-mini``;
* rotary delta: **motor range** atan(δ / u_min) at both ends (the elbow moves by about δ on
  the shortest upper arm u_min), **forearm angle** atan(δ / f_min) on the forearm's maximum
  angle from the vertical, **workspace** 3δ mm on the cylinder's radius and both heights
  (shoulder, upper arm, forearm): 0.491°, 0.215°, 9 mm on ``delta-picker``.

With joint errors of up to δ on every length (angles: δ over their lever arm), every pose of
a default plan of either delta is reached by the perturbed machine within its limits, where
3–15 of 30 are not without margins (``tests/planning/test_margins.py``).

Margins apply to machines whose limits take them (the ``"safety-margins"`` ability:
the 6-UPS hexapod and the deltas); the planar machines' limits (workspace box, reach,
transmission angle) and the 6-RSS/6-PUS hexapods' take none. :func:`planning_checks`
returns the nominal machine with its limits shrunk by the margins and the margin the
candidate checks still add (0 but for a linear delta's rail travel, which
``check_limits(margin=)`` keeps at both ends), the same treatment ``pkmcal plan`` and
``pkmcal demo`` give it (:func:`planning_machine` for the hexapod).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism

#: Joint position error the default margins allow for (mm): paper 2 Table 4's largest.
ASSUMED_JOINT_ERROR_MM = 3.0
#: Leg-to-leg clearance margin (mm) of the collision check.
CLEARANCE_MARGIN_MM = 0.1


@dataclass(frozen=True)
class SafetyMargin:
    """Margins inside the nominal limits: stroke (mm, both ends), joint tilts (degrees, U and
    S joints) and leg clearance (mm). ``source`` says where they come from."""

    stroke_mm: float
    tilt_deg: float
    clearance_mm: float
    source: str = ""

    def __post_init__(self) -> None:
        for name in ("stroke_mm", "tilt_deg", "clearance_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise PkmcalError(f"safety margin {name.split('_')[0]} must be a non-negative number; got {v}")

    def describe(self) -> str:
        text = (f"stroke {self.stroke_mm:g} mm, joint tilts {self.tilt_deg:.3g} deg, "
                f"leg clearance {self.clearance_mm:g} mm")
        return f"{text} ({self.source})" if self.source else text


@dataclass(frozen=True)
class DeltaSafetyMargin:
    """Margins inside a delta's limits (module docstring): ``kind`` the machine kind
    (``linear-delta`` or ``rotary-delta``), ``travel`` (mm of rail; rotary: degrees of motor
    angle, both ends), ``angle_deg`` (arm elevation; rotary: forearm angle) and ``space_mm``
    (print radius and bed; rotary: the workspace cylinder)."""

    kind: str
    travel: float
    angle_deg: float
    space_mm: float
    source: str = ""

    def __post_init__(self) -> None:
        for name in ("travel", "angle_deg", "space_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise PkmcalError(f"safety margin {name.split('_')[0]} must be a non-negative number; got {v}")

    def describe(self) -> str:
        if self.kind == "linear-delta":
            text = (f"rail travel {self.travel:g} mm, arm angle {self.angle_deg:.3g} deg, print radius and bed "
                    f"{self.space_mm:g} mm")
        else:
            text = (f"motor range {self.travel:.3g} deg, forearm angle {self.angle_deg:.3g} deg, workspace "
                    f"{self.space_mm:g} mm")
        return f"{text} ({self.source})" if self.source else text


def has_margins(mechanism: Mechanism) -> bool:
    """Whether the machine's limits take safety margins: its declared ``"safety-margins"``
    ability (the 6-UPS hexapod, the deltas)."""
    return "safety-margins" in mechanism.abilities


def _shortest(mechanism: Mechanism, pattern: str) -> float:
    return float(np.min(mechanism.params[mechanism.param_index([pattern])]))


def _delta_margin(mechanism: Mechanism, d: float) -> DeltaSafetyMargin:
    if mechanism.kind == "linear-delta":
        arm = _shortest(mechanism, "arm_*")
        return DeltaSafetyMargin(mechanism.kind, d, math.degrees(math.atan(d / arm)), 2 * d,
                                 f"default for joint errors up to {d:g} mm: atan({d:g}/{arm:.4g}), 2 x {d:g}")
    upper, fore = _shortest(mechanism, "upper_*"), _shortest(mechanism, "forearm_*")
    return DeltaSafetyMargin(mechanism.kind, math.degrees(math.atan(d / upper)), math.degrees(math.atan(d / fore)),
                             3 * d, f"default for joint errors up to {d:g} mm: atan({d:g}/{upper:.4g}), "
                                    f"atan({d:g}/{fore:.4g}), 3 x {d:g}")


def _tilt_margin(mechanism: Mechanism, joint_error_mm: float) -> tuple[float, str]:
    """The default joint tilt margin (degrees) and its derivation: atan(δ / r_p) + atan(δ / L_min),
    L_min the shortest leg the geometry allows (:meth:`~pkmcal.mechanisms.base.Mechanism.within_geometry`:
    a stroke that allows struts of zero length or less gives none)."""
    reach, _ = mechanism.within_geometry()
    r_p = float(np.min(np.linalg.norm(np.asarray(reach.platform), axis=1)))
    l_min = float(np.min(reach.lengths_from_readings(reach.stroke[:, 0])))
    if r_p <= 0 or l_min <= 0:
        raise PkmcalError(f"machine '{mechanism.name}': cannot derive the joint tilt margin (smallest platform joint "
                          f"radius {r_p:g} mm, shortest leg {l_min:g} mm); give --tilt-margin (or --margin)")
    tilt = math.degrees(math.atan(joint_error_mm / r_p) + math.atan(joint_error_mm / l_min))
    return tilt, f"atan({joint_error_mm:g}/{r_p:.4g}) + atan({joint_error_mm:g}/{l_min:.4g})"


def default_margin(mechanism: Mechanism,
                   joint_error_mm: float = ASSUMED_JOINT_ERROR_MM) -> SafetyMargin | DeltaSafetyMargin | None:
    """The margins of the module docstring for ``mechanism`` (None if its limits take none)."""
    if not has_margins(mechanism):
        return None
    if mechanism.kind in ("linear-delta", "rotary-delta"):
        return _delta_margin(mechanism, joint_error_mm)
    tilt, how = _tilt_margin(mechanism, joint_error_mm)
    return SafetyMargin(joint_error_mm, tilt, CLEARANCE_MARGIN_MM,
                        f"default for joint errors up to {joint_error_mm:g} mm: {how}")


def resolve_margin(mechanism: Mechanism, *, stroke_mm: float | None = None, tilt_deg: float | None = None,
                   clearance_mm: float | None = None) -> SafetyMargin | DeltaSafetyMargin | None:
    """The default margins of ``mechanism`` with the given ones replacing them (a default
    that is replaced is not derived: a machine whose tilt margin cannot be derived plans
    with a given one)."""
    given = [n for n, v in (("stroke", stroke_mm), ("tilt", tilt_deg), ("clearance", clearance_mm)) if v is not None]
    if not given or not has_margins(mechanism):
        return default_margin(mechanism)
    if mechanism.kind in ("linear-delta", "rotary-delta"):
        raise PkmcalError(f"machine '{mechanism.name}' is a {mechanism.kind}: its margins are "
                          f"{default_margin(mechanism).describe()}; the stroke, tilt and clearance margins are a "
                          "hexapod's: give --margin X for X on every limit instead")
    source = "given: " + ", ".join(given) + ("" if len(given) == 3 else "; others default")
    return SafetyMargin(ASSUMED_JOINT_ERROR_MM if stroke_mm is None else float(stroke_mm),
                        _tilt_margin(mechanism, ASSUMED_JOINT_ERROR_MM)[0] if tilt_deg is None else float(tilt_deg),
                        CLEARANCE_MARGIN_MM if clearance_mm is None else float(clearance_mm), source)


def planning_checks(mechanism: Mechanism, margin: SafetyMargin | DeltaSafetyMargin | float | None
                    ) -> tuple[Mechanism, float]:
    """(the machine to plan on, the margin its candidate checks add): ``mechanism`` with its
    limits shrunk by a :class:`SafetyMargin` or :class:`DeltaSafetyMargin` (module
    docstring), or unchanged with a number (that margin on every limit) or None (none)."""
    if margin is None:
        return mechanism, 0.0
    if isinstance(margin, SafetyMargin):
        return planning_machine(mechanism, margin), 0.0
    if isinstance(margin, DeltaSafetyMargin):
        return _delta_machine(mechanism, margin)
    return mechanism, float(margin)


def _delta_machine(mechanism, margin: DeltaSafetyMargin) -> tuple[Mechanism, float]:
    d, angle = margin.space_mm, math.radians(margin.angle_deg)
    if margin.kind == "linear-delta":
        if mechanism.print_radius - d <= 0:
            raise PkmcalError(f"a margin of {d:g} mm leaves no print radius on machine '{mechanism.name}'")
        # the checks' margin keeps the travel at both ends and takes as much off the print
        # radius: the machine's radius is shrunk by the rest
        return replace(mechanism, min_arm_angle=mechanism.min_arm_angle + angle, min_z=mechanism.min_z + d,
                       print_radius=mechanism.print_radius - max(d - margin.travel, 0.0)), margin.travel
    lo, hi = mechanism.motor_range
    t = math.radians(margin.travel)
    z_lo, z_hi = mechanism.z_range
    if hi - lo <= 2 * t or mechanism.max_joint_angle <= angle or mechanism.workspace_radius <= d \
            or z_hi - z_lo <= 2 * d:
        raise PkmcalError(f"the safety margins ({margin.describe()}) leave no workspace on machine "
                          f"'{mechanism.name}'; give a smaller --margin")
    return replace(mechanism, motor_range=(lo + t, hi - t), max_joint_angle=mechanism.max_joint_angle - angle,
                   workspace_radius=mechanism.workspace_radius - d, z_range=(z_lo + d, z_hi - d)), 0.0


def planning_machine(mechanism: Mechanism, margin: SafetyMargin | None) -> Mechanism:
    """``mechanism`` with its stroke shrunk by ``margin.stroke_mm`` at both ends, its
    joint-tilt limits by ``margin.tilt_deg`` and its leg diameter grown by
    ``margin.clearance_mm`` (the same machine when there is no margin). Plan on it with no
    further margin in the candidate checks (``margin=0``)."""
    if margin is None:
        return mechanism
    lim = mechanism.limits
    t = math.radians(margin.tilt_deg)
    stroke = np.asarray(mechanism.stroke) + np.array([margin.stroke_mm, -margin.stroke_mm])
    if np.any(stroke[:, 1] <= stroke[:, 0]):
        raise PkmcalError(f"a stroke margin of {margin.stroke_mm:g} mm leaves no stroke on machine "
                          f"'{mechanism.name}'; give a smaller --stroke-margin")
    shrunk = []
    for name in ("u_joint_tilt", "s_joint_tilt"):
        v = getattr(lim, name)
        if v is not None and v - t <= 0:
            raise PkmcalError(f"a tilt margin of {margin.tilt_deg:g}° leaves no {name.replace('_', ' ')} on "
                              f"machine '{mechanism.name}' (limit {math.degrees(v):g}°); give a smaller --tilt-margin")
        shrunk.append(None if v is None else v - t)
    diameter = None if lim.leg_diameter is None else lim.leg_diameter + margin.clearance_mm
    return replace(mechanism, stroke=stroke, limits=replace(lim, u_joint_tilt=shrunk[0], s_joint_tilt=shrunk[1],
                                                           leg_diameter=diameter))


__all__ = ["ASSUMED_JOINT_ERROR_MM", "CLEARANCE_MARGIN_MM", "DeltaSafetyMargin", "SafetyMargin", "default_margin",
           "has_margins", "planning_checks", "planning_machine", "resolve_margin"]
