"""6-RSS rotary hexapod (issue 12 item 5): IK against the loop closure built independently
(scipy rotations), both roots of the crank equation, analytic Jacobians against central
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
from pkmcal.mechanisms.rss_hexapod import PARAM_NAMES, RSSHexapod, _legs


@pytest.fixture(scope="module")
def machine() -> RSSHexapod:
    return builtin_machine("servo-stewart")


def test_ik_closes_every_loop(machine):
    """The crank end C = S + c (cos φ v1 + sin φ v2), with Q = Rz(β) Rx(χ) from scipy, is at
    the rod length from the platform joint p + R a, and the crank is perpendicular to the
    motor axis Q e_y; the readings are φ − ζ."""
    poses = _reachable(machine, 30, 0)
    zero = np.deg2rad([1.0, -2.0, 0.5, 0.0, 3.0, -1.5])
    tilt = np.deg2rad([2.0, 0.0, -3.0, 1.0, 0.0, 4.0])
    rho = machine.params
    for i in range(6):
        rho[PARAM_NAMES.index(f"zero_{i + 1}")] = zero[i]
        rho[PARAM_NAMES.index(f"tilt_{i + 1}")] = tilt[i]
    m = machine.with_params(rho)
    lam = m.ik(poses)
    g = _legs(rho)
    R = Rotation.from_euler("ZYX", poses[:, [5, 4, 3]]).as_matrix()
    for i in range(6):
        Q = Rotation.from_euler("ZX", [g["beta"][i], g["tilt"][i]]).as_matrix()   # intrinsic: Rz(β) Rx(χ)
        phi = lam[:, i] + zero[i]
        C = g["S"][i] + g["crank"][i] * (np.cos(phi)[:, None] * Q[:, 0] + np.sin(phi)[:, None] * Q[:, 2])
        P = poses[:, :3] + R @ g["a"][i]
        np.testing.assert_allclose(np.linalg.norm(P - C, axis=1), g["rod"][i], rtol=0, atol=1e-9)
        np.testing.assert_allclose((C - g["S"][i]) @ Q[:, 1], 0.0, atol=1e-12)


def test_home_levels_the_cranks(machine):
    np.testing.assert_allclose(np.mean(machine.ik(machine.home_pose)), 0.0, atol=1e-9)
    np.testing.assert_array_equal(machine.home_pose[[0, 1, 3, 4, 5]], 0.0)


def test_jacobians_match_finite_differences(machine):
    """Scales: the crank angle turns by ~1/(c cos φ) per mm of motion along the crank's
    motion (c = 25 mm), so its derivatives grow towards φ = ±90° (the rod in line with the
    crank's motion); within the ±60° motor range the distance to that, and ℓ, is
    c cos 60° = 12.5 mm for lengths; angles 12.5 / 70 ≈ 0.18 rad (the platform joints' lever);
    the angle parameters move the crank end by c per rad: 0.5 rad."""
    poses = _reachable(machine, 12, 1)
    lam, A, B = machine.ik_and_jacobians(poses)
    assert_jacobian_matches_fd(lambda x: machine.ik(x), poses, A, scale=np.array([12.5] * 3 + [0.18] * 3))
    scale = np.where(machine.param_is_angle, 0.5, 12.5)
    assert_jacobian_matches_fd(lambda th: machine.ik(poses, th), machine.params, B, scale=scale,
                               names=machine.param_names)
    np.testing.assert_array_equal(lam, machine.ik(poses))


def test_fk_round_trip_through_the_shared_solver(machine):
    poses = _reachable(machine, 200, 2)
    fk = machine.fk(machine.ik(poses))
    assert fk.converged.all()
    np.testing.assert_allclose(fk.poses, poses, rtol=0, atol=1e-9)


def test_limits(machine):
    home = machine.home_pose
    too_high = home + [0, 0, 60.0, 0, 0, 0]          # rods + cranks cannot reach
    steep = home + [0, 0, 20.0, 0, 0, 0]             # cranks beyond ±60°?
    rep = machine.check_limits(np.array([home, too_high, steep]))
    assert not any(v[0] for v in rep.violations.values())
    assert rep.violations["reach"][1]
    phi = machine.ik(steep)
    assert rep.violations["motor_range"][2] == bool(np.any(np.abs(phi) > np.deg2rad(60.0)))
    np.testing.assert_allclose(machine.reading_range()[0], np.deg2rad([-60.0, 60.0]))


def test_machine_file_round_trip_and_errors(machine, tmp_path):
    from pkmcal.io.machine_file import load_machine, machine_to_text, save_machine

    rho = machine.params
    rho[PARAM_NAMES.index("tilt_3")] = np.deg2rad(1.25)
    rho[PARAM_NAMES.index("zero_5")] = np.deg2rad(-0.7)
    m = dataclasses.replace(machine.with_params(rho), workspace=machine.workspace_box())
    path = tmp_path / "rss.yaml"
    save_machine(m, path)
    back = load_machine(path)
    assert back == m and back.kind == "6-RSS"
    assert machine_to_text(back) == path.read_text()
    text = path.read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("rod: 180.0", "rod: 10.0", 1))
    with pytest.raises(InputFileError, match="rod_1 must be longer than crank_1"):
        load_machine(bad)
    first_leg_end = text.index("- pivot", text.index("- pivot") + 1)
    bad.write_text(text[:text.index("- pivot")] + text[first_leg_end:])
    with pytest.raises(InputFileError, match="exactly 6"):
        load_machine(bad)
    with pytest.raises(PkmcalError, match="66 parameters"):
        RSSHexapod(name="x", rho=np.zeros(10))


@pytest.mark.parametrize("setup_name", ["full-pose-paper1", "laser-tracker", "indicators-prototype"])
def test_identification_minimal_gauge_and_noise_free_recovery(machine, setup_name):
    """Noise-free readings of a perturbed machine (0.3 mm, 0.3 mrad): the fit leaves
    residuals below 1e-9 and predicts held-out readings of the real machine to 1e-9 mm; the
    gauge the engine chose is minimal: freeing any one of its parameters makes the
    identification Jacobian rank-deficient."""
    from pkmcal.identification.engine import identify
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.identification.simulation import perturb_machine, simulate_campaign
    from pkmcal.io.setup_file import load_setup

    setup = load_setup(setup_name, machine)
    if setup.sensor.kind == "indicators":       # the prototype's indicators, under this smaller platform
        setup = dataclasses.replace(setup, sensor=dataclasses.replace(
            setup.sensor, positions=np.asarray(setup.sensor.positions) * 0.8, plane_offset=0.0))
    quiet = dataclasses.replace(setup, noise=dataclasses.replace(
        setup.noise, reading_std=0 * np.asarray(setup.noise.reading_std), actuator_std=np.array(0.0)))
    real = perturb_machine(machine, 0.3, 7)
    sim = simulate_campaign(machine, real, quiet, _reachable(machine, 150, 3), 7)
    assert len(sim.kept) >= 120
    weights = dataclasses.replace(setup, noise=dataclasses.replace(setup.noise, actuator_std=np.array(1e-4)))
    fit = identify(machine, weights, sim.measurements, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert fit.success and fit.rms_residual < 1e-9
    q = machine.ik(_reachable(machine, 40, 4))
    real_fk, cal_fk = real.fk(q), fit.mechanism.fk(q)
    ok = real_fk.ok & cal_fk.ok
    assert ok.mean() > 0.9
    np.testing.assert_allclose(fit.sensor.predict(fit.mechanism.frame(cal_fk.poses[ok])),
                               quiet.sensor.predict(real.frame(real_fk.poses[ok])), rtol=0, atol=1e-9)
    # minimal gauge: the free set is identifiable, and adding back any gauge parameter is not
    poses = sim.real_poses
    assert identifiability(machine, weights, poses, free=list(fit.free)).rank == len(fit.free)
    for name in fit.gauge:
        assert identifiability(machine, weights, poses, free=list(fit.free) + [name]).rank == len(fit.free), name


def test_fk_from_a_start_outside_a_legs_reach(machine):
    """A start pose where one rod cannot reach its crank (IK NaN there: what a fit's trial
    machine makes of a commanded pose near the reach) still leads to the solution: FK solves
    the loop closure |P − C| = r, finite at every pose. Each start lies 0.5 mm beyond the
    reach boundary on the line from the solution straight up (bisection to 1e-6 mm)."""
    poses = _reachable(machine, 20, 5)
    up = np.array([0, 0, 1.0, 0, 0, 0])
    starts = []
    for x in poses:
        lo, hi = 0.0, 100.0
        assert not np.all(np.isfinite(machine.ik(x + hi * up)))
        while hi - lo > 1e-6:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.all(np.isfinite(machine.ik(x + mid * up))) else (lo, mid)
        starts.append(x + (hi + 0.5) * up)
    starts = np.array(starts)
    assert not np.any(np.all(np.isfinite(machine.ik(starts)), axis=1))
    fk = machine.fk(machine.ik(poses), starts)
    assert fk.ok.all()
    np.testing.assert_allclose(fk.poses, poses, rtol=0, atol=1e-9)


def test_identification_with_hobby_servo_noise(machine):
    """Crank readings with 0.005 rad (0.3°) noise, a hobby servo's, and a 0.01 mm laser
    tracker: the fit's trial machines put commanded poses outside a rod's reach, where FK
    must still solve them. The fit converges with every pose solved, χ²/ν within 4σ of 1
    (σ = √(2/ν)), and predicts held-out readings of the real machine better than the noise
    scatters one measurement: rms error below the fit's rms residual (expected ratio
    √(p/N) ≈ 0.65 for 63 parameters and 150 poses)."""
    from pkmcal.identification.engine import identify
    from pkmcal.identification.simulation import perturb_machine, simulate_campaign
    from pkmcal.io.setup_file import load_setup

    setup = load_setup("laser-tracker", machine)
    assert float(setup.noise.actuator_std) == 0.005
    real = perturb_machine(machine, 0.3, 7)
    sim = simulate_campaign(machine, real, setup, _reachable(machine, 150, 3), 7)
    fit = identify(machine, setup, sim.measurements)
    assert fit.success
    assert not any("could not be solved" in w for w in fit.warnings)
    u = fit.uncertainty
    assert abs(u.chi2 / u.dof - 1.0) < 4 * np.sqrt(2.0 / u.dof)
    held = _reachable(machine, 100, 11)
    q = machine.ik(held)
    real_fk, cal_fk = real.fk(q, held), fit.mechanism.fk(q, held)
    assert real_fk.ok.all() and cal_fk.ok.all()
    err = fit.sensor.predict(fit.mechanism.frame(cal_fk.poses)) - setup.sensor.predict(real.frame(real_fk.poses))
    assert np.sqrt(np.mean(err**2)) < fit.rms_residual
