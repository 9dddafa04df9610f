"""Paper 3's machines beyond the kinematics (issue 15 item 3): backlash along a path, the
known-stiffness method of ref. [7], load-compensated commands, and the load deflection the
following errors reveal.

Independent checks: the backlash shift against its definition written as a loop; a
backlash-free block equals no backlash bit for bit; the known-stiffness Jacobian against
central differences of its nonlinear residual; exact recovery on noise-free data; the
pre-deflected commands put the model's own equilibrium on the target (force balance); the
deflection estimate against the linear deflection (ΓᵀKΓ)⁻¹J_fᵀF of paper 3 eq. 1.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pkmcal.errors import PkmcalError
from pkmcal.identification.load_deflection import compliance_warning, load_deflection_estimate
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.identification.tool_errors import commands_for_targets
from pkmcal.io.setup_file import load_setup, setup_to_yaml
from pkmcal.mechanisms.statics import (
    StaticsModel,
    equilibrium,
    force_balance,
    linear_response,
)
from pkmcal.reproduce.known_stiffness import KnownStiffnessModel, fit_known_stiffness
from pkmcal.reproduce.paper3 import CASES, case_models, measurement_path, real_setup
from pkmcal.sensors.base import MeasurementSetup


def _shift_by_loop(commands, b):
    """s b/2 with s the sign of each actuator's last non-zero command change (+1 before any)."""
    out = np.zeros_like(commands)
    s = np.ones(commands.shape[1])
    for k in range(len(commands)):
        if k:
            d = commands[k] - commands[k - 1]
            s = np.where(np.isfinite(d) & (d != 0), np.sign(np.nan_to_num(d)), s)
        out[k] = s * b / 2
    return out


def test_backlash_shift_follows_the_direction_of_the_last_motion():
    rng = np.random.default_rng(0)
    c = np.cumsum(rng.choice([-1.0, 0.0, 1.0], size=(40, 3)), axis=0)
    c[7, 1] = np.nan
    b = np.array([0.2, 0.4, 0.0])
    np.testing.assert_array_equal(StaticsModel(1e4, None, backlash=b).backlash_shift(c), _shift_by_loop(c, b))
    assert StaticsModel(1e4, None, backlash=0.0).backlash is None
    np.testing.assert_array_equal(StaticsModel(1e4).backlash_shift(c), np.zeros_like(c))
    with pytest.raises(PkmcalError, match="non-negative"):
        StaticsModel(1e4, None, backlash=-1.0)
    with pytest.raises(PkmcalError, match="2 actuator backlash values for 3"):
        StaticsModel(1e4, None, backlash=[0.1, 0.2]).backlash_shift(c)


def test_backlash_in_the_simulation_is_direction_dependent():
    """Along a forward-backward path the encoders read motor = joint + s b/2; the joint
    settles as under the commands c − s b/2; with b = 0 the campaign is bit-identical to one
    without backlash."""
    nominal, sensor, noise, real, real_sensor = case_models("paper3-case2")
    points, forward, _ = measurement_path(nominal, 6)
    base = real_setup(real_sensor, noise, CASES["paper3-case2"]["stiffness"])
    zero = dataclasses.replace(base, simulation=StaticsModel(base.simulation.stiffness, base.simulation.load,
                                                             backlash=0.0))
    a = simulate_campaign(nominal, real, base, points, 3, ("workspace",))
    z = simulate_campaign(nominal, real, zero, points, 3, ("workspace",))
    assert np.array_equal(a.actuator_readings, z.actuator_readings) and np.array_equal(a.real_poses, z.real_poses)
    b = 0.01
    withb = dataclasses.replace(base, simulation=StaticsModel(base.simulation.stiffness, base.simulation.load,
                                                              backlash=b))
    s = simulate_campaign(nominal, real, withb, points, 3, ("workspace",))
    c = nominal.ik(points)
    shift = withb.simulation.backlash_shift(c)
    eq = equilibrium(real, c - shift, withb.simulation.stiffness_for(real), withb.simulation.load, real_sensor,
                     guess=points)
    np.testing.assert_allclose(s.real_poses, eq.poses, atol=1e-9)
    np.testing.assert_allclose(s.actuator_true, eq.readings + shift, atol=1e-9)
    # the same point reached forward (pass 1) and backward (pass 2) rests at different poses
    d = np.linalg.norm(s.real_poses[0:10, :2] - s.real_poses[19:9:-1, :2], axis=1)
    assert d.max() > 1e-3 and np.linalg.norm(z.real_poses[0:10, :2] - z.real_poses[19:9:-1, :2], axis=1).max() < 1e-9


def test_setup_file_backlash_round_trip(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("sensor: planar-tool\nnoise: {reading: 0.01, actuator: 1.0e-5}\n"
                 "simulation: {stiffness: 5.0e7, load: [0, -30], backlash: [1.0e-4, 2.0e-4, 3.0e-4]}\n")
    s = load_setup(p)
    np.testing.assert_array_equal(s.simulation.backlash, [1e-4, 2e-4, 3e-4])
    q = tmp_path / "back.yaml"
    q.write_text(setup_to_yaml(s))
    np.testing.assert_array_equal(load_setup(q).simulation.backlash, s.simulation.backlash)
    p.write_text("sensor: planar-tool\nnoise: {reading: 0.01, actuator: 1.0e-5}\n"
                 "simulation: {stiffness: 5.0e7, backlash: -1}\n")
    with pytest.raises(PkmcalError, match="simulation.backlash"):
        load_setup(p)


@pytest.fixture(scope="module", params=["paper3-case1", "paper3-case2"])
def campaign(request):
    name = request.param
    nominal, sensor, noise, real, real_sensor = case_models(name)
    setup = real_setup(real_sensor, noise, CASES[name]["stiffness"])
    calib = nominal.sample_poses(30, np.random.default_rng(1))
    sim = simulate_campaign(nominal, real, setup, calib, 2, ("workspace",))
    return name, (nominal, sensor, noise, real, real_sensor), setup, calib, sim


def test_known_stiffness_jacobian_against_central_differences(campaign):
    """The residual solves the statics to 1e-10 relative (equilibrium tolerance), so its
    central difference with step h = 1e-4 carries ~1e-10·|x|/h ≈ 1e-4 relative noise on the
    whitened scale, plus h²-truncation; tolerance 1e-4 of the largest entry."""
    name, (nominal, sensor, noise, real, _), setup, calib, sim = campaign
    m = KnownStiffnessModel(nominal, sensor, CASES[name]["free"], nominal.ik(calib), sim.sensor_readings,
                            sim.actuator_readings, setup.simulation, noise, calib)
    x0 = m.theta0[m.idx] + 1e-3
    J = m.jacobian(x0)
    h = 1e-4
    Jfd = np.stack([(m.residual(x0 + h * e) - m.residual(x0 - h * e)) / (2 * h) for e in np.eye(x0.size)], axis=1)
    assert np.abs(J - Jfd).max() < 1e-4 * np.abs(J).max()


def test_known_stiffness_recovers_the_machine_from_exact_data(campaign):
    """Noise-free readings, K and F known: the fit reproduces them and returns the real
    parameters of the free set (case 2 is identifiable as the paper's; case 1's truth is
    moved by its gauge, so only the readings are checked there)."""
    name, (nominal, sensor, noise, real, real_sensor), setup, calib, sim = campaign
    exact = dataclasses.replace(sim, actuator_readings=sim.actuator_true, sensor_readings=sim.sensor_true)
    r = fit_known_stiffness(nominal, sensor, exact.measurements, calib, CASES[name]["free"], setup.simulation, noise)
    assert r.success and r.rms_whitened < 1e-5
    if name == "paper3-case2":
        truth = dict(zip(real.param_names + real_sensor.param_names, np.r_[real.params, real_sensor.params]))
        np.testing.assert_allclose(r.x, [truth[n] for n in r.free], atol=1e-7)
    wrong = fit_known_stiffness(nominal, sensor, exact.measurements, calib, CASES[name]["free"],
                                StaticsModel(setup.simulation.stiffness * 2, setup.simulation.load), noise)
    assert wrong.rms_whitened > 10 * r.rms_whitened       # a wrong K cannot explain the readings


def test_load_compensated_commands_put_the_model_on_the_target(campaign):
    name, (nominal, sensor, noise, real, real_sensor), setup, calib, _ = campaign
    targets = sensor.predict(nominal.frame(calib))
    angles = calib[:, 2] if nominal.n_dof == 3 else None
    x, c = commands_for_targets(nominal, sensor, targets, angles, setup.simulation)
    K = setup.simulation.stiffness_for(nominal)
    g = force_balance(nominal, c, K, x, setup.simulation.load, sensor)
    assert np.abs(g).max() < 1e-6 * np.abs(K).max() * 1e-3      # balanced at x itself (N or N·mm)
    eq = equilibrium(nominal, c, K, setup.simulation.load, sensor, guess=x)
    np.testing.assert_allclose(sensor.predict(nominal.frame(eq.poses)), targets, atol=1e-7)
    _, plain = commands_for_targets(nominal, sensor, targets, angles)
    assert np.abs(plain - c).max() > 0        # the load changes the commands


def test_deflection_from_following_errors_is_the_linear_deflection():
    """Equal stiffness: the part of the following error along Γ is (ΓᵀKΓ)⁻¹J_fᵀF (paper 3
    eq. 1 with Δρ = 0), also when the kinematic errors make the actuators fight."""
    name = "paper3-case1"
    nominal, sensor, noise, real, real_sensor = case_models(name)
    K = CASES[name]["stiffness"] / 10
    poses = nominal.sample_poses(12, np.random.default_rng(4))
    for machine in (nominal, real):              # no conflict, and the paper's errors (a fight)
        setup = MeasurementSetup(sensor, noise, StaticsModel(K, np.array([0.0, -50.0])))
        sim = simulate_campaign(nominal, machine, dataclasses.replace(setup, noise=dataclasses.replace(
            noise, reading_std=np.zeros(2), actuator_std=np.zeros(3))), poses, 0, ("workspace",))
        e = sim.actuator_true - nominal.ik(poses)
        est = load_deflection_estimate(machine, sensor, sim.real_poses, e)
        _, _, dPt = linear_response(machine, sensor, sim.real_poses, np.zeros(len(machine.params)), np.zeros(5), K,
                                    np.array([0.0, -50.0]))
        np.testing.assert_allclose(est, dPt, rtol=0.02, atol=2e-4 * np.abs(dPt).max())
        assert np.abs(dPt).max() > 0.05                                   # 10x softer: tenths of a mm
    assert compliance_warning(nominal, real, sensor, poses, sim.real_poses, 0.01) is not None
    stiff = MeasurementSetup(sensor, dataclasses.replace(noise, reading_std=np.zeros(2), actuator_std=np.zeros(3)),
                             StaticsModel(K * 1e4, np.array([0.0, -50.0])))
    s2 = simulate_campaign(nominal, nominal, stiff, poses, 0, ("workspace",))
    assert compliance_warning(nominal, nominal, sensor, poses, s2.real_poses, 0.01) is None
