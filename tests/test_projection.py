"""Projection identification (paper 3 eq. 4–10): exact recovery from noise-free data,
named unidentifiable combinations, the projector's rank, independence from K and the
load, the encoder sign convention, and the baselines."""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.errors import PkmcalError
from pkmcal.identification.projection import (
    ActuatorSubset,
    calibration_experiment,
    identify_actuator_subset,
    identify_ignoring_redundancy,
    identify_redundant,
    projection_identifiability,
    simulate_measurements,
)
from pkmcal.identification.residuals import Model
from pkmcal.mechanisms import planar as PL
from pkmcal.sensors.base import NoiseModel
from pkmcal.sensors.planar_tool import PlanarToolSensor

NOISE_FREE = {2: NoiseModel(np.zeros(2), np.zeros(3)), 3: NoiseModel(np.zeros(2), np.zeros(4))}


def _case(n_dof):
    if n_dof == 2:
        m = PL.planar_2dof_3act()
        return m, 5e7, np.array([0.0, -30.0]), NoiseModel(np.full(2, 0.01), np.full(3, 1e-5)), ("B1.x", "B1.y", "B2.y", "D1", "D3")
    m = PL.planar_3dof_4act()
    return m, 2e4, np.array([0.0, -30.0]), NoiseModel(np.full(2, 0.01), np.full(4, 1e-3)), ()


def _truth(m, fixed, seed, size=0.2):
    rng = np.random.default_rng(seed)
    d = {}
    for n in m.param_names:
        if n in fixed:
            continue
        ang = n.startswith("alpha") or (n.startswith("dq") and m.n_dof == 2)
        d[n] = rng.normal() * size * (np.deg2rad(0.25) if ang else 1.0)
    return m.with_deltas(d)


def _free(m, fixed, sensor_free=("target.x", "target.y")):
    return tuple(n for n in m.param_names if n not in fixed) + tuple(sensor_free)


@pytest.mark.parametrize("n_dof", [2, 3])
def test_noise_free_data_recover_the_parameters_exactly(n_dof):
    m, K, F, noise, fixed = _case(n_dof)
    s = PlanarToolSensor(n_pose=n_dof)
    real = _truth(m, fixed, seed=1)
    rs = s.with_deltas({"target.x": 0.07, "target.y": -0.10})
    x = m.sample_poses(30, np.random.default_rng(2))
    _, q, y, eq = simulate_measurements(real, rs, m, x, K, F, NOISE_FREE[n_dof], np.random.default_rng(0))
    assert np.abs(eq.following_error).max() > 0          # the redundancy is at work
    fit = identify_redundant(m, s, x, q, y, noise, _free(m, fixed))
    assert fit.report.identifiable
    assert fit.rows_per_pose == 2 + m.n_actuators - m.n_dof
    np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-8)
    np.testing.assert_allclose(fit.sensor.params, rs.params, atol=1e-8)
    # the paper's single linearisation is close but not exact (second-order error)
    one = identify_redundant(m, s, x, q, y, noise, _free(m, fixed), linearisation="single")
    err1 = np.abs(one.mechanism.params - real.params).max()
    assert 1e-8 < err1 < 0.2 * np.abs(real.params - m.params).max()


@pytest.mark.parametrize("n_dof", [2, 3])
def test_stiffness_and_load_do_not_enter_the_identification(n_dof):
    m, K, F, noise, fixed = _case(n_dof)
    s = PlanarToolSensor(n_pose=n_dof)
    real = _truth(m, fixed, seed=3)
    x = m.sample_poses(25, np.random.default_rng(4))
    fits = []
    for k, f in ((K, F), (K * np.array([0.3, 3.0, 1.0, 2.0])[: m.n_actuators], 5 * F)):
        _, q, y, _ = simulate_measurements(real, s, m, x, k, f, NOISE_FREE[n_dof], np.random.default_rng(0))
        fits.append(identify_redundant(m, s, x, q, y, noise, _free(m, fixed)).mechanism.params)
    np.testing.assert_allclose(fits[0], real.params, atol=1e-8)
    np.testing.assert_allclose(fits[1], real.params, atol=1e-8)


def test_encoder_offset_sign_is_the_same_in_simulation_identification_and_compensation():
    m, K, F, noise, fixed = _case(2)
    s = PlanarToolSensor(n_pose=2)
    real = m.with_deltas({"dq1": np.deg2rad(0.05)})
    x = m.sample_poses(20, np.random.default_rng(5))
    _, q, y, _ = simulate_measurements(real, s, m, x, K, None, NOISE_FREE[2], np.random.default_rng(0))
    fit = identify_redundant(m, s, x, q, y, noise, ("dq1", "dq2", "dq3"))
    assert fit.mechanism.p("dq1") == pytest.approx(np.deg2rad(0.05), abs=1e-12)
    # compensation through the fitted model removes the error entirely (no load)
    res = calibration_experiment(m, s, real, s, x, m.sample_poses(5, np.random.default_rng(6)), K, None,
                                 NOISE_FREE[2], np.random.default_rng(0), free=("dq1", "dq2", "dq3"),
                                 methods=("projection",), weights=noise)
    assert res.before.max() > 0.05 and res.after["projection"].max() < 1e-9


def test_projector_has_rank_m_plus_l_minus_n_and_annihilates_q():
    for n_dof in (2, 3):
        m, _, _, noise, _ = _case(n_dof)
        s = PlanarToolSensor(n_pose=n_dof)
        x = m.sample_poses(10, np.random.default_rng(0))
        model = Model(m, s, noise, q=m.ik(x), y=s.predict(x), commanded=x)
        w = 1.0 / np.concatenate([model.sigma_y, model.sigma_q])
        Q = np.concatenate([s.pose_jacobian(x), m.actuator_pose_jacobian(x)], axis=1) * w[:, None]
        U = np.linalg.qr(Q, mode="complete")[0][:, :, n_dof:]
        R = U @ np.swapaxes(U, 1, 2)
        R_paper = np.eye(Q.shape[1]) - Q @ np.linalg.solve(np.swapaxes(Q, 1, 2) @ Q, np.swapaxes(Q, 1, 2))
        np.testing.assert_allclose(R, R_paper, atol=1e-9)
        assert np.abs(R @ Q).max() < 1e-9 * np.abs(Q).max()
        assert all(np.linalg.matrix_rank(Rj) == 2 + m.n_actuators - n_dof for Rj in R)


def test_unidentifiable_combinations_are_named():
    m, _, _, noise, _ = _case(2)
    s = PlanarToolSensor(n_pose=2)
    x = m.sample_poses(30, np.random.default_rng(0))
    # the paper's Table 1 set: in our reconstruction D3 only moves the plate joint along
    # u3 = +y, exactly like B3.y in the opposite sense; a second combination involves D1
    rep = projection_identifiability(m, s, x, noise, PL.P2_PAPER_FREE + ("target.x", "target.y"))
    assert rep.rank == rep.n_params - 2
    dirs = [set(d) for d in rep.null_space]
    assert {"B3.y", "D3"} in dirs
    assert any({"D1", "D2", "B2.x", "target.x"} <= d for d in dirs)
    # 3-dof machine, tracker frame unknown: the three planar rigid motions are the gauge
    m3, _, _, noise3, _ = _case(3)
    s3 = PlanarToolSensor(n_pose=3)
    x3 = m3.sample_poses(30, np.random.default_rng(0))
    free = tuple(m3.param_names) + ("target.x", "target.y", "world.x", "world.y", "world.c")
    rep = projection_identifiability(m3, s3, x3, noise3, free)
    assert rep.rank == rep.n_params - 3
    assert any(set(d) == {"y1", "y2", "world.y"} for d in rep.null_space)
    assert any({"dq1", "dq2", "world.x"} <= set(d) for d in rep.null_space)
    assert projection_identifiability(m3, s3, x3, noise3, tuple(n for n in free if n not in rep.fixed)).identifiable


def test_unknown_tracker_frame_is_identified_with_the_gauge_fixed():
    m, K, F, noise, _ = _case(3)
    fixed = ("y1", "dq1", "dq3")
    s = PlanarToolSensor(n_pose=3)
    real = _truth(m, fixed, seed=7)
    rs = s.with_deltas({"target.x": -0.11, "target.y": -0.06, "world.x": 12.0, "world.y": -5.0, "world.c": 0.02})
    x = m.sample_poses(30, np.random.default_rng(8))
    _, q, y, _ = simulate_measurements(real, rs, m, x, K, F, NOISE_FREE[3], np.random.default_rng(0))
    fit = identify_redundant(m, s, x, q, y, noise, _free(m, fixed, ("target.x", "target.y", "world.x", "world.y", "world.c")))
    assert fit.report.identifiable
    np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-7)
    np.testing.assert_allclose(fit.sensor.params, rs.params, atol=1e-7)


def test_a_repeatable_load_is_not_absorbed_and_not_removed():
    """Load only, no kinematic error: the projection (which eliminates the deflection)
    identifies no error, and the held-out error after calibration is the load deflection."""
    m, K, F, noise, fixed = _case(2)
    s = PlanarToolSensor(n_pose=2)
    x = m.sample_poses(30, np.random.default_rng(0))
    check = m.sample_poses(8, np.random.default_rng(1))
    res = calibration_experiment(m, s, m, s, x, check, K, 10 * F, NOISE_FREE[2], np.random.default_rng(0),
                                 free=_free(m, fixed), methods=("projection", "ignore-redundancy"), weights=noise)
    np.testing.assert_allclose(res.fits["projection"].mechanism.params, m.params, atol=1e-8)
    np.testing.assert_allclose(res.after["projection"], res.before, rtol=1e-6)
    assert res.before.min() > 0.01


@pytest.mark.parametrize("n_dof", [2, 3])
def test_baselines(n_dof):
    m, K, F, noise, fixed = _case(n_dof)
    s = PlanarToolSensor(n_pose=n_dof)
    real = _truth(m, fixed, seed=11)
    x = m.sample_poses(30, np.random.default_rng(12))
    c, q, y, _ = simulate_measurements(real, s, m, x, K, F, NOISE_FREE[n_dof], np.random.default_rng(0))
    # n of l actuators: exact for the chains it sees, blind to the others
    keep = tuple(range(n_dof))
    sub = identify_actuator_subset(m, s, x, q, y, noise, keep, _free(m, fixed))
    unseen = set(sub.report.unseen)
    assert f"dq{m.n_actuators}" in unseen and "dq1" not in unseen
    assert not sub.report.identifiable
    # noise-free, the kept actuators' model reproduces the real readings at the real poses
    np.testing.assert_allclose(ActuatorSubset(sub.mechanism, keep).ik(sub.poses), q[:, list(keep)], atol=1e-8)
    np.testing.assert_allclose(sub.sensor.predict(sub.poses), y, atol=1e-8)
    # actuators assumed at their commands: biased (the following errors are real)
    ign = identify_ignoring_redundancy(m, s, x, c, y, noise, _free(m, fixed))
    assert np.abs(ign.mechanism.params - real.params).max() > 1e-4


def test_bad_requests_are_user_errors():
    m, K, F, noise, fixed = _case(2)
    s = PlanarToolSensor(n_pose=2)
    x = m.sample_poses(5, np.random.default_rng(0))
    with pytest.raises(PkmcalError, match="linearisation"):
        identify_redundant(m, s, x, m.ik(x), s.predict(x), noise, ("l11",), linearisation="twice")
    with pytest.raises(PkmcalError, match="no parameter 'l99'"):
        identify_redundant(m, s, x, m.ik(x), s.predict(x), noise, ("l99",))


@pytest.mark.parametrize("n_dof", [2, 3])
def test_agrees_with_the_engine_projection_method(n_dof):
    """Independent solver check: our re-linearised Gauss–Newton and the engine's
    scipy least_squares on the same projected residual reach the same estimate."""
    from pkmcal.identification.engine import identify
    from pkmcal.sensors.base import MeasurementSetup

    m, K, F, noise, fixed = _case(n_dof)
    s = PlanarToolSensor(n_pose=n_dof)
    real = _truth(m, fixed, seed=21)
    x = m.sample_poses(30, np.random.default_rng(22))
    _, q, y, _ = simulate_measurements(real, s, m, x, K, F, noise, np.random.default_rng(23))
    free = _free(m, fixed)
    ours = identify_redundant(m, s, x, q, y, noise, free)
    engine = identify(m, MeasurementSetup(s, noise), method="projection", free=free, q=q, y=y, commanded=x)
    scale = np.abs(ours.mechanism.params - m.params).max()
    np.testing.assert_allclose(engine.mechanism.params, ours.mechanism.params, atol=1e-6 * scale)
    np.testing.assert_allclose(engine.sensor.params, ours.sensor.params, atol=1e-6 * scale)


@pytest.mark.parametrize("n_dof", [2, 3])
def test_relinearisation_handles_large_errors(n_dof):
    """Errors of several mm: the single linearisation of eq. 10 is visibly biased, the
    re-linearised fit still recovers the machine exactly from noise-free data."""
    m, K, F, noise, fixed = _case(n_dof)
    s = PlanarToolSensor(n_pose=n_dof)
    real = _truth(m, fixed, seed=31, size=3.0)
    x = m.sample_poses(30, np.random.default_rng(32), shrink=0.8)
    _, q, y, _ = simulate_measurements(real, s, m, x, K, F, NOISE_FREE[n_dof], np.random.default_rng(0))
    fit = identify_redundant(m, s, x, q, y, noise, _free(m, fixed))
    one = identify_redundant(m, s, x, q, y, noise, _free(m, fixed), linearisation="single")
    np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-7)
    assert np.abs(one.mechanism.params - real.params).max() > 1e-3
    assert fit.cost[-1] < 1e-12 * fit.cost[0]


@pytest.mark.parametrize("n_dof", [2, 3])
def test_single_linearisation_jacobian_matches_finite_differences(n_dof):
    """Eq. 10 at the commanded poses: on consistent data (e = 0 there) the dropped
    derivative of U⊥ multiplies e, so J must equal central differences of r(θ)."""
    from pkmcal.identification.projection import single_linearisation

    m, _, _, noise, _ = _case(n_dof)
    s = PlanarToolSensor(n_pose=n_dof)
    x = m.sample_poses(6, np.random.default_rng(41))
    model = Model(m, s, noise, q=m.ik(x), y=s.predict(x), commanded=x)
    r0, J = single_linearisation(model)
    assert np.abs(r0).max() < 1e-9
    theta0 = model.theta0
    fd = np.empty_like(J)
    for i in range(theta0.size):
        h = 1e-6 * max(1.0, abs(theta0[i]))
        cols = []
        for sgn in (1.0, -1.0):
            th = theta0.copy()
            th[i] += sgn * h
            mech, sens = model.split(th)
            cols.append(single_linearisation(Model(mech, sens, noise, q=model.q, y=model.y, commanded=x))[0])
        fd[..., i] = (cols[0] - cols[1]) / (2 * h)
    np.testing.assert_allclose(J, fd, atol=1e-6 * np.abs(fd).max())
