"""Commanding a machine whose controller runs its nominal kinematics so that it goes where
the calibrated model plus a correction says it should.

A target t (the pose the program asks for; for a printer, relative to the bed surface) is
reached by the calibrated model at the pose x_m with x_m + δ(x_m) = t (δ the correction,
:class:`pkmcal.compensation.fit.Field`; none: x_m = t), solved by the fixed-point iteration
x ← t − δ(x) (δ is small and smooth: it contracts by the field's slope, a few iterations to
10⁻⁹ mm); a bed mesh depends on the nozzle's x, y only, so x_m = t + (0, 0, w(t_x, t_y)).
The actuators must then be at q = IK(x_m, ρ̂), and a controller with the nominal kinematics
ρ₀ puts them there when commanded

    c = FK(q, ρ₀)

(for a delta printer: the position whose nominal carriage heights are the calibrated
ones, Klipper's or Marlin's stepper positions; for a hexapod under LinuxCNC's genhexkins
with its nominal parameters: the pose whose nominal leg lengths are the calibrated ones).
Everything is vectorised over the targets; a target the calibrated machine cannot reach (its
limits at x_m) or whose nominal FK fails is reported with its reason, never commanded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.compensation.fit import Field
from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import limits_violated
from pkmcal.mechanisms.base import Mechanism

#: Fixed-point iterations for x_m and the largest step left (mm or rad) that counts as solved.
ITERATIONS = 50
STEP_TOL = 1e-10


@dataclass(frozen=True)
class Commands:
    """``commands`` (N, n) what to command the nominal controller (NaN where not ``ok``);
    ``model_poses`` (N, n) x_m; ``ok`` (N,); ``reasons`` (N,) why not ('' where ok)."""

    commands: np.ndarray
    model_poses: np.ndarray
    ok: np.ndarray
    reasons: tuple[str, ...]


def model_poses(calibrated: Mechanism, fld: Field | None, targets: np.ndarray) -> np.ndarray:
    """x_m (N, n) with x_m + δ(x_m) = t (module docstring)."""
    t = calibrated.as_pose_array(targets)
    if fld is None:
        return t.copy()
    if fld.kind == "bed-mesh":
        return t - fld.displacement(calibrated, t, at=t[:, :2])
    x = t.copy()
    for _ in range(ITERATIONS):
        new = t - fld.displacement(calibrated, x)
        step = np.max(np.abs(new - x)) if len(x) else 0.0
        x = new
        if step <= STEP_TOL:
            return x
    raise PkmcalError(f"the correction does not settle (still moving the poses by {step:.3g} after {ITERATIONS} "
                      "iterations): it is too steep to invert; refit it or leave it out")


def commands_for(calibrated: Mechanism, nominal: Mechanism, fld: Field | None, targets: np.ndarray,
                 ignore_limits: tuple[str, ...] = ()) -> Commands:
    """What a controller with ``nominal``'s kinematics must be commanded so that the
    machine ``calibrated`` (+ the correction ``fld``) reaches ``targets`` (module docstring);
    ``ignore_limits`` names limits not checked (e.g. ``leg_collision``, which a calibration of
    a tight design may bring into contact on paper)."""
    if calibrated.kind != nominal.kind or calibrated.n_dof != nominal.n_dof:
        raise PkmcalError(f"the nominal machine '{nominal.name}' ({nominal.kind}) is not of the kind of the "
                          f"calibrated one '{calibrated.name}' ({calibrated.kind})")
    x_m = model_poses(calibrated, fld, targets)
    bad, checked = limits_violated(calibrated, x_m, tuple(ignore_limits))
    reasons = ["outside the calibrated machine's limits (" + ", ".join(n for n, v in checked.items() if v[k]) + ")"
               if bad[k] else "" for k in range(len(x_m))]
    with np.errstate(invalid="ignore"):
        q = calibrated.ik(x_m)
    ok = ~bad & np.all(np.isfinite(q), axis=1)
    fk = nominal.fk(np.where(ok[:, None], q, nominal.ik(nominal.home_pose[None])[0]), guess=x_m)
    for k in np.flatnonzero(ok & ~fk.ok):
        reasons[k] = "the nominal kinematics have no pose for these actuator positions (FK failed)"
    ok &= fk.ok
    commands = np.where(ok[:, None], fk.poses, np.nan)
    return Commands(commands, x_m, ok, tuple(reasons))


__all__ = ["Commands", "commands_for", "model_poses"]
