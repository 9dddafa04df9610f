"""An offline-corrected program run by the real LinuxCNC (issue 28 item 2): the poses that
``pkmcal correct`` writes for a controller running the hexapod's *nominal* genhexkins
parameters put LinuxCNC's joints (its own inverse kinematics, genhexkins.c
``genhexKinematicsInverse``, world mode ``G53 G0``) at the strut lengths the *calibrated*
model plus a correction needs for the targets.

Tolerance: the commands come from pkmcal's nominal FK, which stops on a step below 1e-11 of
the pose's size (a few 1e-9 mm here, quadratic convergence leaves far less), times ‖∂L/∂x‖₂;
LinuxCNC's joints equal pkmcal's strut lengths of the poses sent to rounding (1e-13 mm,
tests/controllers/test_linuxcnc.py). LinuxCNC not installed: skipped, failed in CI.
"""

from __future__ import annotations

import numpy as np
from helpers import require_controller

from pkmcal.compensation.apply import commands_for
from pkmcal.compensation.basis import PolynomialBasis
from pkmcal.compensation.fit import Field
from pkmcal.controllers import linuxcnc as lc
from pkmcal.conventions import poses_to_file_units
from pkmcal.io import load_machine
from pkmcal.mechanisms.solver import FK_TOL


def test_corrected_poses_put_linuxcnc_nominal_joints_where_the_calibrated_model_needs_them():
    require_controller(lc.missing_reason())
    nominal = load_machine("stewart-prototype")
    calibrated = load_machine("stewart-prototype-real")          # the calibration's result, here the truth
    home = nominal.home_pose
    box = tuple((h - 10.0, h + 10.0) for h in home[:3]) + tuple((-0.05, 0.05) for _ in range(3))
    basis = PolynomialBasis(1, box)
    # a pose field of a few hundredths of a mm and arc seconds (x, y, z, a, b, c; mm and rad)
    coef = np.random.default_rng(4).normal(0.0, 1.0, (basis.size, 6)) * [0.03, 0.03, 0.03, 1e-4, 1e-4, 1e-4]
    fld = Field("pose-field", basis, tuple(nominal.pose_names), coef)
    offsets = np.array([[0, 0, 0, 0, 0, 0], [5, 0, 2, 0.01, 0, 0], [5, 5, 4, 0, 0.01, 0], [0, 5, 2, 0, 0, -0.01],
                        [-5, -5, -3, 0.01, 0.01, 0.01]], dtype=float)
    targets = home + offsets
    out = commands_for(calibrated, nominal, fld, targets, ignore_limits=("leg_collision",))
    assert out.ok.all(), out.reasons
    files = lc.machine_files(nominal)
    run = lc.run_linuxcnc(files, _to_controller(out.commands, files.mm_per_unit), np.zeros((0, 6)))
    joints = run.joints * run.mm_per_unit
    needed = nominal.lengths_from_readings(calibrated.ik(out.model_poses))
    J = np.linalg.norm(nominal.actuator_pose_jacobian(out.commands), ord=2, axis=(1, 2))
    bound = J * FK_TOL * (1.0 + np.max(np.abs(out.commands), axis=1)) + 1e-12
    diff = np.abs(joints - needed)
    print(f"largest |LinuxCNC joint - calibrated model's strut| {diff.max():.3g} mm (bound {bound.max():.3g})")
    assert np.all(diff <= bound[:, None])
    # the test can fail: the targets sent uncorrected put the joints elsewhere by far more
    plain = nominal.lengths_from_readings(nominal.ik(targets))
    assert np.min(np.max(np.abs(plain - needed), axis=1)) > 1e3 * bound.max()


def _to_controller(poses: np.ndarray, mm_per_unit: float) -> np.ndarray:
    p = poses_to_file_units(poses)
    p[:, :3] /= mm_per_unit
    return p
