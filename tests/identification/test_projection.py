"""Paper 3 through the one engine (:mod:`pkmcal.identification.projection`): exact recovery
from noise-free data, agreement with an independent joint (poses + parameters) fit, the
reported standard deviations against a Monte Carlo, named unidentifiable combinations,
the projector's rank, independence from K and the load, the encoder sign convention, the
single linearisation, and the baselines (worse than the projection)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    assert_covariance_matches_monte_carlo,
    assert_jacobian_matches_fd,
    mc_mean_bound,
    mc_std_ratio_band,
    planar_fd_model,
)
from scipy.optimize import least_squares

from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.identifiability import identifiability
from pkmcal.identification.projection import ActuatorSubset, single_linearisation
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.identification.residuals import Model
from pkmcal.mechanisms import planar as PL
from pkmcal.mechanisms.statics import StaticsModel
from pkmcal.reproduce.paper3_experiment import calibration_experiment, fit_redundant
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.planar_tool import PlanarToolSensor

NOISE_FREE = {2: NoiseModel(np.zeros(2), np.zeros(3)), 3: NoiseModel(np.zeros(2), np.zeros(4))}
TOOL = ("target.x", "target.y")


def _case(n_dof):
    """(machine, its tracker, K, F, weights, joints held at zero in random machines)."""
    s = PlanarToolSensor(n_pose=n_dof)
    if n_dof == 2:
        m = PL.planar_2dof_3act()
        return m, s, 5e7, np.array([0.0, -30.0]), NoiseModel(np.full(2, 0.01), np.full(3, 1e-5)), ("B1.x", "B1.y", "B2.y", "D1", "D3")
    m = PL.planar_3dof_4act()
    return m, s, 2e4, np.array([0.0, -30.0]), NoiseModel(np.full(2, 0.01), np.full(4, 1e-3)), ()


def _truth(m, fixed, seed, size=0.2):
    rng = np.random.default_rng(seed)
    d = {}
    for n, ang in zip(m.param_names, m.param_is_angle):
        if n in fixed:
            continue
        d[n] = rng.normal() * size * (np.deg2rad(0.25) if ang else 1.0)
    return m.with_deltas(d)


def _free(m, fixed, sensor_free=TOOL):
    return tuple(n for n in m.param_names if n not in fixed) + tuple(sensor_free)


def _measure(m, real, real_sensor, x, K, F, noise, seed=0):
    """The one redundant simulation: the real machine at equilibrium, noisy readings."""
    setup = MeasurementSetup(real_sensor, noise, StaticsModel(K, F))
    sim = simulate_campaign(m, real, setup, x, np.random.default_rng(seed), ignore_limits=("workspace",))
    assert len(sim.kept) == len(x)
    return sim


@pytest.mark.parametrize("n_dof", [2, 3])
def test_noise_free_data_recover_the_parameters_exactly(n_dof):
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=1)
    rs = s.with_deltas({"target.x": 0.07, "target.y": -0.10})
    x = m.sample_poses(30, np.random.default_rng(2))
    sim = _measure(m, real, rs, x, K, F, NOISE_FREE[n_dof])
    assert np.abs(sim.actuator_true - m.ik(x)).max() > 1e-4          # the redundancy is at work
    fit = fit_redundant("projection", m, MeasurementSetup(s, noise), sim.measurements, _free(m, fixed))
    assert fit.success and fit.identifiability.identifiable and fit.gauge == ()
    assert fit.residuals.shape == (30, 2 + m.n_actuators - m.n_dof)
    np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-8)
    np.testing.assert_allclose(fit.sensor.params, rs.params, atol=1e-8)
    # the paper's single linearisation is close but not exact (second-order error)
    one = fit_redundant("projection-single", m, MeasurementSetup(s, noise), sim.measurements, _free(m, fixed))
    err1 = np.abs(one.mechanism.params - real.params).max()
    assert 1e-8 < err1 < 0.2 * np.abs(real.params - m.params).max()


@pytest.mark.parametrize("n_dof", [2, 3])
def test_stiffness_and_load_do_not_enter_the_identification(n_dof):
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=3)
    x = m.sample_poses(25, np.random.default_rng(4))
    for k, f in ((K, F), (K * np.array([0.3, 3.0, 1.0, 2.0])[: m.n_actuators], 5 * F)):
        sim = _measure(m, real, s, x, k, f, NOISE_FREE[n_dof])
        fit = fit_redundant("projection", m, MeasurementSetup(s, noise), sim.measurements, _free(m, fixed))
        np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-8)


@pytest.mark.parametrize("n_dof", [2, 3])
def test_agrees_with_an_independent_joint_fit_of_poses_and_parameters(n_dof):
    """Independent computation: scipy least_squares (finite differences) over the free
    parameters AND every pose x_j of Σ_j ‖W [y_j − h(x_j); q_j − IK(x_j)]‖² — no projection.
    At the joint minimum Qᵀe = 0, so ‖U⊥ᵀe‖ = ‖e‖: both fits have the same minimiser."""
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=21)
    x = m.sample_poses(12, np.random.default_rng(22))
    sim = _measure(m, real, s, x, K, F, noise, seed=23)
    free = _free(m, fixed)
    fit = fit_redundant("projection", m, MeasurementSetup(s, noise), sim.measurements, free)

    q, y = sim.actuator_readings, sim.sensor_readings
    w = 1.0 / np.concatenate([noise.reading_std, noise.actuator_std])
    model = Model(m, s, noise, q=q, y=y)
    idx = [model.names.index(n) for n in free]
    theta0 = model.theta0

    def e(z):
        th = theta0.copy()
        th[idx] = z[: len(idx)]
        mech, sens = model.split(th)
        xs = z[len(idx):].reshape(x.shape)
        return (np.concatenate([y - sens.predict(mech.frame(xs)), q - mech.ik(xs)], axis=1) * w).ravel()

    sol = least_squares(e, np.concatenate([theta0[idx], x.ravel()]), jac="3-point", x_scale="jac", ftol=1e-15,
                        xtol=1e-15, gtol=1e-15)
    # agreement far inside the statistical uncertainty (the weak 2-dof directions make the
    # solvers' stopping points differ by ~1e-6 of a standard deviation)
    assert np.all(np.abs(fit.x - sol.x[: len(idx)]) < 1e-4 * fit.std)
    np.testing.assert_allclose(fit.poses, sol.x[len(idx):].reshape(x.shape), atol=1e-4 * fit.std.min())
    assert fit.cost == pytest.approx(sol.cost, rel=1e-9)


def test_reported_standard_deviations_match_a_monte_carlo():
    """The engine's a-priori std of the weighted projection fit against the spread of 120
    fits of noisy copies of one campaign, and the estimates unbiased: bands from the sampling
    distributions (helpers.mc_std_ratio_band: s/σ in [0.67, 1.37] for 15 parameters;
    mc_mean_bound: Student t), and the whole covariance jointly (mean squared Mahalanobis
    distance, χ²₁₈₀₀/1800: in [0.845, 1.172]); false failure with any seeds below 1e-6."""
    m, s, K, F, noise, fixed = _case(3)
    real = _truth(m, fixed, seed=51)
    x = m.sample_poses(20, np.random.default_rng(52))
    setup = MeasurementSetup(s, noise)
    free = _free(m, fixed)
    exact = _measure(m, real, s, x, K, F, NOISE_FREE[3])
    exact_fit = fit_redundant("projection", m, setup, exact.measurements, free)
    reported = exact_fit.uncertainty.std_prior
    est = []
    for k in range(120):
        sim = _measure(m, real, s, x, K, F, noise, seed=1000 + k)
        est.append(fit_redundant("projection", m, setup, sim.measurements, free).x)
    est = np.array(est)
    truth = np.concatenate([real.params, s.params])[[Model(m, s, noise, exact.actuator_readings,
                                                           exact.sensor_readings).names.index(n) for n in free]]
    spread = est.std(axis=0, ddof=1)
    lo, hi = mc_std_ratio_band(len(est), len(free))
    assert np.all((lo < spread / reported) & (spread / reported < hi)), spread / reported
    assert np.all(np.abs(est.mean(axis=0) - truth) < mc_mean_bound(len(est), len(free)) * spread / np.sqrt(len(est)))
    assert_covariance_matches_monte_carlo(est, truth, exact_fit.uncertainty.covariance_prior)


def test_encoder_offset_sign_is_the_same_in_simulation_identification_and_compensation():
    m, s, K, F, noise, fixed = _case(2)
    real = m.with_deltas({"dq1": np.deg2rad(0.05)})
    x = m.sample_poses(20, np.random.default_rng(5))
    sim = _measure(m, real, s, x, K, None, NOISE_FREE[2])
    fit = fit_redundant("projection", m, MeasurementSetup(s, noise), sim.measurements, ("dq1", "dq2", "dq3"))
    assert fit.mechanism.p("dq1") == pytest.approx(np.deg2rad(0.05), abs=1e-12)
    # compensation through the fitted model removes the error entirely (no load)
    res = calibration_experiment(m, s, real, MeasurementSetup(s, NOISE_FREE[2], StaticsModel(K)), x,
                                 m.sample_poses(5, np.random.default_rng(6)), np.random.default_rng(0),
                                 free=("dq1", "dq2", "dq3"), methods=("projection",), weights=noise)
    assert res.before.max() > 0.05 and res.after["projection"].max() < 1e-9


def test_before_includes_the_tool_point_error_in_closed_form():
    """Real machine = nominal, no load, only the tool point off by d: the 2-dof plate does not
    rotate, so every held-out 'before' error is exactly |d|; calibrating the tool point
    removes it."""
    m, s, K, _, noise, _ = _case(2)
    rs = s.with_deltas({"target.x": 0.06, "target.y": -0.08})
    res = calibration_experiment(m, s, m, MeasurementSetup(rs, NOISE_FREE[2], StaticsModel(K)),
                                 m.sample_poses(10, np.random.default_rng(1)), m.sample_poses(6, np.random.default_rng(2)),
                                 np.random.default_rng(0), free=TOOL, methods=("projection",), weights=noise)
    np.testing.assert_allclose(res.before, 0.1, rtol=1e-9)
    assert res.after["projection"].max() < 1e-9


def test_projector_has_rank_m_plus_l_minus_n_and_annihilates_q():
    for n_dof in (2, 3):
        m, s, _, _, noise, _ = _case(n_dof)
        x = m.sample_poses(10, np.random.default_rng(0))
        model = Model(m, s, noise, q=m.ik(x), y=s.predict(m.frame(x)), commanded=x)
        w = 1.0 / np.concatenate([model.sigma_y, model.sigma_q])
        Q = np.concatenate([m.pose_jacobian_from_twist(s.frame_jacobian(m.frame(x)), x), m.actuator_pose_jacobian(x)], axis=1) * w[:, None]
        U = np.linalg.qr(Q, mode="complete")[0][:, :, n_dof:]
        R = U @ np.swapaxes(U, 1, 2)
        R_paper = np.eye(Q.shape[1]) - Q @ np.linalg.solve(np.swapaxes(Q, 1, 2) @ Q, np.swapaxes(Q, 1, 2))
        np.testing.assert_allclose(R, R_paper, atol=1e-9)
        assert np.abs(R @ Q).max() < 1e-9 * np.abs(Q).max()
        assert all(np.linalg.matrix_rank(Rj) == 2 + m.n_actuators - n_dof for Rj in R)


def _projection_report(m, s, x, noise, free):
    return identifiability(m, MeasurementSetup(s, noise), x, method="projection", free=list(free))


def test_unidentifiable_combinations_are_named():
    m, s, _, _, noise, _ = _case(2)
    x = m.sample_poses(30, np.random.default_rng(0))
    # the paper's Table 1 set: in our reconstruction D3 only moves the plate joint along
    # u3 = +y, exactly like B3.y in the opposite sense; a second combination involves D1
    rep = _projection_report(m, s, x, noise, PL.P2_PAPER_FREE + TOOL)
    assert rep.rank == rep.n_params - 2
    dirs = [set(d) for d in rep.null_space]
    assert {"B3.y", "D3"} in dirs
    assert any({"D1", "D2", "B2.x", "target.x"} <= d for d in dirs)
    # 3-dof machine, tracker frame unknown: the three planar rigid motions are the gauge
    m3, s3, _, _, noise3, _ = _case(3)
    x3 = m3.sample_poses(30, np.random.default_rng(0))
    free = tuple(m3.param_names) + TOOL + ("world.x", "world.y", "world.c")
    rep = _projection_report(m3, s3, x3, noise3, free)
    assert rep.rank == rep.n_params - 3
    assert any(set(d) == {"y1", "y2", "world.y"} for d in rep.null_space)
    assert any({"dq1", "dq2", "world.x"} <= set(d) for d in rep.null_space)
    assert _projection_report(m3, s3, x3, noise3, tuple(n for n in free if n not in rep.fixed)).identifiable


def test_unknown_tracker_frame_is_identified_with_the_gauge_fixed():
    m, s, K, F, noise, _ = _case(3)
    fixed = ("y1", "dq1", "dq3")
    real = _truth(m, fixed, seed=7)
    rs = s.with_deltas({"target.x": -0.11, "target.y": -0.06, "world.x": 12.0, "world.y": -5.0, "world.c": 0.02})
    x = m.sample_poses(30, np.random.default_rng(8))
    sim = _measure(m, real, rs, x, K, F, NOISE_FREE[3])
    fit = fit_redundant("projection", m, MeasurementSetup(s, noise), sim.measurements,
                        _free(m, fixed, TOOL + ("world.x", "world.y", "world.c")))
    assert fit.identifiability.identifiable
    np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-7)
    np.testing.assert_allclose(fit.sensor.params, rs.params, atol=1e-7)
    # the engine's automatic gauge: with the whole frame free, three parameters are fixed
    # at their start and the rest identified; the fit still reproduces the noise-free data
    auto = fit_redundant("projection", m, MeasurementSetup(s, noise), sim.measurements,
                         _free(m, (), TOOL + ("world.x", "world.y", "world.c")))
    assert len(auto.gauge) == 3 and auto.rms_residual < 1e-9


def test_a_repeatable_load_is_not_absorbed_and_not_removed():
    """Load only, no kinematic error: the projection (which eliminates the deflection)
    identifies no error, and the held-out error after calibration is the load deflection."""
    m, s, K, F, noise, fixed = _case(2)
    x = m.sample_poses(30, np.random.default_rng(0))
    check = m.sample_poses(8, np.random.default_rng(1))
    res = calibration_experiment(m, s, m, MeasurementSetup(s, NOISE_FREE[2], StaticsModel(K, 10 * F)), x, check,
                                 np.random.default_rng(0), free=_free(m, fixed),
                                 methods=("projection", "ignore-redundancy"), weights=noise)
    np.testing.assert_allclose(res.fits["projection"].mechanism.params, m.params, atol=1e-8)
    np.testing.assert_allclose(res.after["projection"], res.before, rtol=1e-6)
    assert res.before.min() > 0.01


@pytest.mark.parametrize("n_dof", [2, 3])
def test_baselines(n_dof):
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=11)
    x = m.sample_poses(30, np.random.default_rng(12))
    sim = _measure(m, real, s, x, K, F, NOISE_FREE[n_dof])
    setup = MeasurementSetup(s, noise)
    # n of l actuators: exact for the chains it sees, blind to the others (fixed by the gauge)
    keep = tuple(range(n_dof))
    sub = fit_redundant("actuator-subset", m, setup, sim.measurements, _free(m, fixed), keep=keep)
    assert sub.method == "actuator-subset" and type(sub.mechanism) is type(m)
    unseen = set(sub.identifiability.unseen)
    assert f"dq{m.n_actuators}" in unseen and "dq1" not in unseen
    assert not sub.identifiability.identifiable and unseen <= set(sub.gauge)
    # noise-free, the kept actuators' model reproduces the real readings at the fitted poses
    q = sim.actuator_readings
    np.testing.assert_allclose(ActuatorSubset(sub.mechanism, keep).ik(sub.poses), q[:, list(keep)], atol=1e-8)
    np.testing.assert_allclose(sub.sensor.predict(sub.mechanism.frame(sub.poses)), sim.sensor_readings, atol=1e-8)
    # actuators assumed at their commands: biased (the following errors are real)
    ign = fit_redundant("ignore-redundancy", m, setup, sim.measurements, _free(m, fixed))
    assert ign.method == "ignore-redundancy"
    assert np.abs(ign.mechanism.params - real.params).max() > 1e-4


@pytest.mark.parametrize("n_dof", [2, 3])
def test_baselines_are_worse_than_the_projection_on_held_out_poses(n_dof):
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=61)
    rs = s.with_deltas({"target.x": 0.05, "target.y": -0.04})
    res = calibration_experiment(m, s, real, MeasurementSetup(rs, noise, StaticsModel(K, F)),
                                 m.sample_poses(30, np.random.default_rng(62)), m.sample_poses(10, np.random.default_rng(63)),
                                 np.random.default_rng(64), free=_free(m, fixed))
    proj = res.improvement_pct("projection")
    assert proj > 80.0
    assert proj > res.improvement_pct("ignore-redundancy") and proj > res.improvement_pct("actuator-subset")
    assert abs(res.improvement_pct("projection-single") - proj) < 5.0


def test_bad_requests_are_user_errors():
    m, s, K, F, noise, fixed = _case(2)
    x = m.sample_poses(5, np.random.default_rng(0))
    setup = MeasurementSetup(s, noise)
    data = (m.ik(x), s.predict(m.frame(x)), x)
    with pytest.raises(PkmcalError, match="unknown paper-3 method 'twice'"):
        fit_redundant("twice", m, setup, data, ("l11",))
    with pytest.raises(PkmcalError, match="no parameter matches 'l99'"):
        fit_redundant("projection", m, setup, data, ("l99",))
    with pytest.raises(PkmcalError, match="commanded poses"):
        fit_redundant("projection-single", m, setup, data[:2], ("l11",))
    with pytest.raises(PkmcalError, match="--keep"):
        fit_redundant("actuator-subset", m, setup, data, ("l11",), keep=(0, 0))


@pytest.mark.parametrize("n_dof", [2, 3])
def test_relinearisation_handles_large_errors(n_dof):
    """Errors of several mm: the single linearisation of eq. 10 is visibly biased, the
    engine's re-linearised fit still recovers the machine exactly from noise-free data."""
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=31, size=3.0)
    x = m.sample_poses(30, np.random.default_rng(32), shrink=0.8)
    sim = _measure(m, real, s, x, K, F, NOISE_FREE[n_dof])
    setup = MeasurementSetup(s, noise)
    fit = fit_redundant("projection", m, setup, sim.measurements, _free(m, fixed))
    one = fit_redundant("projection-single", m, setup, sim.measurements, _free(m, fixed))
    np.testing.assert_allclose(fit.mechanism.params, real.params, atol=1e-7)
    assert np.abs(one.mechanism.params - real.params).max() > 1e-3
    assert fit.rms_residual < 1e-9


@pytest.mark.parametrize("n_dof", [2, 3])
def test_single_linearisation_jacobian_matches_finite_differences(n_dof):
    """Eq. 10 at the commanded poses: on consistent data (e = 0 there) the dropped
    derivative of U⊥ multiplies e, so J must equal central differences of r(θ)."""
    m, s, _, _, noise, _ = _case(n_dof)
    x = m.sample_poses(6, np.random.default_rng(41))
    model = Model(m, s, noise, q=m.ik(x), y=s.predict(m.frame(x)), commanded=x)
    r0, J = single_linearisation(model)
    assert np.abs(r0).max() < 1e-9

    def r(theta):
        mech, sens = model.split(theta)
        return single_linearisation(Model(mech, sens, noise, q=model.q, y=model.y, commanded=x))[0]

    # r = U⊥ᵀ W e: U⊥ orthonormal, W = diag(1/σ), e = (tracker, encoder) residuals. Scales:
    # the machine's (distance to its singularities, which U⊥ shares); the tracker's readings
    # are linear in its mm parameters (ℓ = 1 m, slope 1) and turn levers ≤ 400 mm with
    # world.c (ℓ = 1 rad). Slopes: ‖W ∂e/∂θ_k‖ ≤ √rows · slope / σ. The values handled are the
    # readings and encoder values over their σ.
    _, mech = planar_fd_model(m, x)
    ang = np.asarray(s.param_is_angle, dtype=bool)
    scale = np.r_[mech["scale"], np.where(ang, 1.0, 1000.0)]
    slope = np.r_[np.sqrt(m.n_actuators) * mech["slope"] / model.sigma_q.min(),
                  np.sqrt(2.0) * np.where(ang, 400.0, 1.0) / model.sigma_y.min()]
    M = max(np.abs(model.y / model.sigma_y).max(), np.abs(model.q / model.sigma_q).max())
    assert_jacobian_matches_fd(r, model.theta0, J, scale=scale, slope=slope, magnitude=M, names=model.names)


@pytest.mark.parametrize("n_dof", [2, 3])
def test_projection_single_is_one_least_squares_step(n_dof):
    """The engine's ``projection-single`` equals eq. 10 solved once by hand: Δθ = −J_F⁺ r
    at the commanded poses and the nominal parameters, over the free columns the fit kept
    (numpy lstsq on the unscaled columns, independent of the engine's column scaling)."""
    m, s, K, F, noise, fixed = _case(n_dof)
    real = _truth(m, fixed, seed=41)
    x = m.sample_poses(25, np.random.default_rng(42))
    sim = _measure(m, real, s, x, K, F, noise)
    setup = MeasurementSetup(s, noise)
    one = fit_redundant("projection-single", m, setup, sim.measurements, _free(m, fixed))
    assert one.method == "projection-single" and one.nfev == 2 and one.njev == 1 and one.success
    model = Model(m, s, noise, sim.actuator_readings, sim.sensor_readings, sim.commanded[sim.kept])
    r, J = single_linearisation(model)
    idx = one.free_index
    delta = -np.linalg.lstsq(J.reshape(r.size, -1)[:, idx], r.reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(one.estimate[idx] - model.theta0[idx], delta, rtol=1e-7, atol=1e-10)
    np.testing.assert_array_equal(np.delete(one.estimate, idx), np.delete(model.theta0, idx))
    with pytest.raises(PkmcalError, match="analytic Jacobian"):
        identify(m, setup, sim.measurements, method="projection-single", jac="2-point")


def test_pose_solve_is_a_function_of_theta_alone():
    """x_j*(θ) starts from the fit's start poses at every evaluation, never from an earlier
    evaluation's poses: θ evaluated after a far θ gives the same bits as θ evaluated first
    (a warm start from the far point's poses ended at other round-off, and on a machine with
    several solutions could end on another one)."""
    from pkmcal.identification.engine import measurement_arrays
    from pkmcal.identification.residuals import make_method

    m, s, K, F, noise, fixed = _case(3)
    real = _truth(m, fixed, seed=5)
    x = m.sample_poses(20, np.random.default_rng(6))
    sim = _measure(m, real, s, x, K, F, noise, seed=7)
    q, y, cmd = measurement_arrays(sim.measurements)
    model = Model(m, s, noise, q, y, cmd)
    theta = model.theta0
    step = np.full(len(theta), 0.5)                      # mm on lengths, 0.01 rad on angles
    step[: len(m.params)][np.asarray(m.param_is_angle)] = 0.01
    far = theta + step
    alone = make_method("projection", model).evaluate(theta, jac=False, cov=False)
    method = make_method("projection", model)
    method.evaluate(far, jac=False, cov=False)
    after = method.evaluate(theta, jac=False, cov=False)
    assert alone.converged.all() and after.converged.all()
    np.testing.assert_array_equal(after.r, alone.r)
