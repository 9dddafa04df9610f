"""6-PUS sliding-joint hexapod (issue 12 item 5): IK against the loop closure built
independently (scipy rotations for the rail tilts), analytic Jacobians against central
finite differences, IK→FK round trips through the shared solver, limits, the machine file
round trip and its errors, and identification: a minimal gauge for full-pose, position and
indicator sensors and noise-free recovery predicting held-out readings to 1e-9 mm."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd, reachable_poses as _reachable
from scipy.spatial.transform import Rotation

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.mechanisms.library import builtin_machine
from pkmcal.mechanisms.pus_hexapod import PARAM_NAMES, PUSHexapod, _legs, rail_frames


@pytest.fixture(scope="module")
def machine() -> PUSHexapod:
    return builtin_machine("hexaslide")


def _tilted(machine):
    rho = machine.params
    for i, (tx, ty, off) in enumerate([(1.0, -2.0, 0.5), (0.0, 1.5, -1.0), (-1.0, 0.0, 0.0),
                                       (2.0, 2.0, 3.0), (0.5, -0.5, 0.0), (0.0, 0.0, -2.0)]):
        rho[PARAM_NAMES.index(f"tilt_x_{i + 1}")] = np.deg2rad(tx)
        rho[PARAM_NAMES.index(f"tilt_y_{i + 1}")] = np.deg2rad(ty)
        rho[PARAM_NAMES.index(f"offset_{i + 1}")] = off
    return machine.with_params(rho)


def test_ik_closes_every_loop(machine):
    """The carriage joint O + (λ + o) u, u = Q Rx(θx) Ry(θy) e_z (scipy), is at the leg
    length from the platform joint p + R a, on the machine's branch."""
    m = _tilted(machine)
    poses = _reachable(machine, 30, 0)
    lam = m.ik(poses)
    g = _legs(m.rho)
    R = Rotation.from_euler("ZYX", poses[:, [5, 4, 3]]).as_matrix()
    Q = rail_frames(m.rails)
    for i in range(6):
        u = Q[i] @ Rotation.from_euler("XY", [g["tx"][i], g["ty"][i]]).as_matrix() @ [0.0, 0.0, 1.0]
        B = g["O"][i] + (lam[:, i] + g["offset"][i])[:, None] * u
        P = poses[:, :3] + R @ g["a"][i]
        np.testing.assert_allclose(np.linalg.norm(P - B, axis=1), g["leg"][i], rtol=0, atol=1e-9)
        assert np.all(np.sign((P - B) @ u) == -m.branches[i])   # branch −1: the carriage below the foot


def test_rail_frames_take_e_z_to_the_rail():
    dirs = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 1], [0, 0, -1], [1, 2, 3], [-1, 0, 0.0]])
    Q = rail_frames(dirs)
    np.testing.assert_allclose(Q @ [0.0, 0.0, 1.0], dirs / np.linalg.norm(dirs, axis=1, keepdims=True), atol=1e-15)
    np.testing.assert_allclose(Q @ np.swapaxes(Q, 1, 2), np.broadcast_to(np.eye(3), (6, 3, 3)), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(Q), 1.0, atol=1e-15)


def test_jacobians_match_finite_differences(machine):
    """Scales: a carriage moves by 1/cos of the leg's angle to its rail per mm of platform
    motion; the legs (200 mm) stay within 60° of the platform normal and ≳ 20° off
    perpendicular to their rails in the workspace, so ℓ = 200 · sin 20° ≈ 70 mm for lengths;
    angles ℓ / 70 mm (the platform joints' lever) = 1 rad; the tilts move the carriage by
    s ≤ 150 mm per rad: 0.5 rad."""
    m = _tilted(machine)
    poses = _reachable(machine, 12, 1)
    lam, A, B = m.ik_and_jacobians(poses)
    assert_jacobian_matches_fd(lambda x: m.ik(x), poses, A, scale=np.array([70.0] * 3 + [1.0] * 3))
    scale = np.where(m.param_is_angle, 0.5, 70.0)
    assert_jacobian_matches_fd(lambda th: m.ik(poses, th), m.params, B, scale=scale, names=m.param_names)
    np.testing.assert_array_equal(lam, m.ik(poses))


def test_fk_round_trip_through_the_shared_solver(machine):
    m = _tilted(machine)
    poses = _reachable(machine, 200, 2)
    fk = m.fk(m.ik(poses))
    assert fk.converged.all()
    np.testing.assert_allclose(fk.poses, poses, rtol=0, atol=1e-9)


def test_limits_and_home(machine):
    np.testing.assert_allclose(np.mean(machine.ik(machine.home_pose)), 75.0, atol=1e-9)
    home = machine.home_pose
    rep = machine.check_limits(np.array([home, home + [0, 0, 200.0, 0, 0, 0], home + [0, 0, 80.0, 0, 0, 0]]))
    assert not any(v[0] for v in rep.violations.values())
    assert rep.violations["reach"][1] or rep.violations["stroke"][1]
    assert rep.violations["stroke"][2] == bool(np.any(machine.ik(home + [0, 0, 80.0, 0, 0, 0]) > 150.0))
    np.testing.assert_array_equal(machine.reading_range(), np.tile([0.0, 150.0], (6, 1)))


def test_machine_file_round_trip_and_errors(machine, tmp_path):
    from pkmcal.io.machine_file import load_machine, machine_to_text, save_machine

    m = dataclasses.replace(_tilted(machine), workspace=machine.workspace_box())
    path = tmp_path / "pus.yaml"
    save_machine(m, path)
    back = load_machine(path)
    assert back == m and back.kind == "6-PUS"
    assert machine_to_text(back) == path.read_text()
    text = path.read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("branch: -1", "branch: 0", 1))
    with pytest.raises(InputFileError, match="branch"):
        load_machine(bad)
    bad.write_text(text.replace("leg: 200.0", "leg: -5.0", 1))
    with pytest.raises(InputFileError, match="leg_1 must be positive"):
        load_machine(bad)
    with pytest.raises(PkmcalError, match="60 parameters"):
        PUSHexapod(name="x", rho=np.zeros(10), rails=np.tile([0, 0, 1.0], (6, 1)), stroke=np.tile([0, 1.0], (6, 1)))


@pytest.mark.parametrize("setup_name", ["full-pose-paper1", "laser-tracker", "indicators-prototype"])
def test_identification_minimal_gauge_and_noise_free_recovery(machine, setup_name):
    """Noise-free readings of a perturbed machine (0.3 mm, 0.3 mrad): the fit leaves
    residuals below 1e-9 and predicts held-out readings of the real machine to 1e-9 mm; the
    gauge the engine chose is minimal, and contains a rail-origin/offset direction for each
    leg (the two move together along the rail)."""
    from pkmcal.identification.engine import identify
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.identification.simulation import perturb_machine, simulate_campaign
    from pkmcal.io.setup_file import load_setup

    setup = load_setup(setup_name, machine)
    quiet = dataclasses.replace(setup, noise=dataclasses.replace(
        setup.noise, reading_std=0 * np.asarray(setup.noise.reading_std), actuator_std=np.array(0.0)))
    real = perturb_machine(machine, 0.3, 7)
    sim = simulate_campaign(machine, real, quiet, _reachable(machine, 150, 3), 7)
    assert len(sim.kept) >= 120
    fit = identify(machine, setup, sim.measurements, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert fit.success and fit.rms_residual < 1e-9
    q = machine.ik(_reachable(machine, 40, 4))
    real_fk, cal_fk = real.fk(q), fit.mechanism.fk(q)
    ok = real_fk.ok & cal_fk.ok
    assert ok.mean() > 0.9
    np.testing.assert_allclose(fit.sensor.predict(fit.mechanism.frame(cal_fk.poses[ok])),
                               quiet.sensor.predict(real.frame(real_fk.poses[ok])), rtol=0, atol=1e-9)
    assert identifiability(machine, setup, sim.real_poses, free=list(fit.free)).rank == len(fit.free)
    for name in fit.gauge:
        assert identifiability(machine, setup, sim.real_poses, free=list(fit.free) + [name]).rank == len(fit.free), name
    assert len(fit.gauge) >= 6


def test_fk_closure_equations_match_finite_differences(machine):
    """The loop-closure residual e(x) of FK is zero at IK's solution, and −∂e/∂x is its
    derivative (central differences, steps scaled like the poses)."""
    m = _tilted(machine)
    poses = _reachable(machine, 8, 6)
    lam = m.ik(poses)
    equations = m._closure(m.params)
    e, A = equations(poses, lam, True)
    np.testing.assert_allclose(e, 0.0, rtol=0, atol=1e-9)
    shifted = poses + np.array([3.0, -2.0, 1.0, 0.02, -0.01, 0.03])
    _, A = equations(shifted, lam, True)
    assert_jacobian_matches_fd(lambda x: -equations(x, lam, False)[0], shifted, A,
                               scale=np.array([70.0] * 3 + [1.0] * 3))


def test_fk_from_a_start_outside_a_legs_reach(machine):
    """A start pose where a leg cannot reach its rail (IK NaN there) still leads to the
    solution: FK solves the loop closure |P − B| = ℓ, finite at every pose. Each start lies
    2 mm beyond the reach boundary on the line from the solution along +x (bisection to
    1e-6 mm)."""
    poses = _reachable(machine, 20, 5)
    out = np.array([1.0, 0, 0, 0, 0, 0])
    starts = []
    for x in poses:
        lo, hi = 0.0, 2000.0
        assert not np.all(np.isfinite(machine.ik(x + hi * out)))
        while hi - lo > 1e-6:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.all(np.isfinite(machine.ik(x + mid * out))) else (lo, mid)
        starts.append(x + (hi + 2.0) * out)
    starts = np.array(starts)
    assert not np.any(np.all(np.isfinite(machine.ik(starts)), axis=1))
    fk = machine.fk(machine.ik(poses), starts)
    assert fk.ok.all()
    np.testing.assert_allclose(fk.poses, poses, rtol=0, atol=1e-9)
