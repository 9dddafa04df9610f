"""The identification engine: recovery, analytic Jacobians, weighting, errors.

Data are simulated here (commanded poses → nominal IK → real FK → sensor), independent of
the engine's own residual code, so recovery checks the whole chain.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import FALSE_FAILURE, assert_jacobian_matches_fd, random_poses
from scipy.stats import norm

from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import identify, measurement_arrays
from pkmcal.identification.residuals import Model, make_method, whitening
from pkmcal.mechanisms import builtin_machine
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor
from pkmcal.sensors.indicators import IndicatorSensor
from pkmcal.sensors.position import PositionSensor



@pytest.fixture(scope="module")
def nominal():
    return builtin_machine("stewart-prototype")


@pytest.fixture(scope="module")
def real():
    return builtin_machine("stewart-prototype-real")


def commanded(machine, n, seed=0):
    return random_poses(machine, n, seed)


def simulate(nominal, real, sensor, cmd, noise=None, seed=1):
    """Readings of the real machine driven with the nominal machine's commands."""
    q = nominal.ik(cmd)
    fk = real.fk(q, guess=cmd)
    assert fk.all_converged
    y = sensor.predict(real.frame(fk.poses))
    if noise is not None:
        e_y, e_q = noise.sample(np.random.default_rng(seed), y.shape, q.shape)
        y, q = y + e_y, q + e_q
    return q, y


NOISE_FULL = NoiseModel(reading_std=np.array([0.01] * 3 + [1e-4] * 3), actuator_std=np.full(6, 0.005))
NOISE_3 = NoiseModel(reading_std=np.full(3, 0.01), actuator_std=np.full(6, 0.005))
INDICATOR_XY = np.array([[40.0, 0.0], [-20.0, 34.64], [-20.0, -34.64]])


def setups():
    return {
        "full-pose": MeasurementSetup(FullPoseSensor(), NOISE_FULL),
        "position": MeasurementSetup(PositionSensor(target=[5.0, -3.0, 20.0]), NOISE_3),
        "indicators": MeasurementSetup(IndicatorSensor(positions=INDICATOR_XY, plane_offset=10.0), NOISE_3),
    }


CASES = [
    ("full-pose", "ik-residual", 20),
    ("full-pose", "fk-residual", 20),
    ("full-pose", "projection", 20),
    ("position", "fk-residual", 40),
    ("position", "projection", 40),
    ("indicators", "fk-residual", 60),
    ("indicators", "projection", 60),
]


@pytest.mark.parametrize("setup_name,method,n", CASES)
def test_noise_free_recovery(nominal, real, setup_name, method, n):
    """Noise-free data → the real machine (in the chosen gauge): every reading predicted
    to ≤ 1e-6 mm at the measured poses and at fresh validation poses."""
    setup = setups()[setup_name]
    cmd = commanded(nominal, n)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    res = identify(nominal, setup, q=q, y=y, commanded=cmd, method=method)
    assert res.success
    for c in (cmd, commanded(nominal, 10, seed=7)):
        qv, yv = simulate(nominal, real, setup.sensor, c)
        fk = res.mechanism.fk(qv, guess=c)
        assert fk.all_converged
        assert np.max(np.abs(res.sensor.predict(res.mechanism.frame(fk.poses)) - yv)) <= 1e-6
    if setup_name == "full-pose":
        # no gauge freedom: the parameters themselves are recovered
        assert res.gauge == ()
        np.testing.assert_allclose(res.estimate[:48], real.params, atol=1e-6)
    else:
        assert len(res.gauge) == 42 + len(setup.sensor.default_free) - res.identifiability.rank > 0
        assert any("gauge" in w for w in res.warnings)
        # fixed parameters stay at their nominal values
        for name in res.gauge:
            i = res.names.index(name)
            assert res.estimate[i] == res.initial[i]


def test_ik_residual_squared_form_recovers(nominal, real):
    setup = setups()["full-pose"]
    cmd = commanded(nominal, 15)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    for weighted in (True, False):
        res = identify(nominal, setup, q=q, y=y, method="ik-residual", form="squared", weighted=weighted)
        np.testing.assert_allclose(res.estimate[:48], real.params, atol=1e-6)


def test_free_sensor_parameters_recovered(nominal, real):
    """A full-pose sensor whose world and tool transforms are unknown: with the machine's
    leg-1/2 joints as the gauge (paper 2 §2.2) the world and tool are recovered."""
    truth = FullPoseSensor(world=[10.0, -5.0, 2.0, 0.01, -0.02, 0.03], tool=[1.0, 2.0, 30.0, 0.0, 0.01, 0.0])
    start = FullPoseSensor(free=tuple(truth.param_names))
    setup = MeasurementSetup(start, NOISE_FULL)
    cmd = commanded(nominal, 25)
    q, y = simulate(nominal, real, truth, cmd)
    for method in ("ik-residual", "fk-residual"):
        res = identify(nominal, setup, q=q, y=y, commanded=cmd, method=method)
        assert len(res.gauge) == 12
        # predictions of the calibrated machine + sensor match the data
        fk = res.mechanism.fk(q, guess=cmd)
        assert np.max(np.abs(res.sensor.reading_residual(y, res.sensor.predict(res.mechanism.frame(fk.poses))))) <= 1e-6


# -- analytic Jacobians against finite differences ----------------------------------------


def _fd_model(model, method, form, x):
    """Error model (helpers.assert_jacobian_matches_fd) of a hexapod method's residual r(θ)
    at poses x: (dict(scale, magnitude, noise, resolution), the angle flags of θ).

    Scales: a leg length L_min per mm, 1 rad per angle (IK: the norm's curvature); through FK
    (fk-residual) divided by (1 + κ)², κ = max ‖A⁻¹‖ of the length-scaled actuator Jacobian,
    since x(ρ) = FK(q, ρ) has x' = −A⁻¹B and x'' ~ A⁻¹ ∂²IK (x')² with ∂²IK ~ 1/L. Slopes
    (_assert_method_jacobian): twice the column's largest entry over the 6 poses and all rows
    (every row is a unit-vector or lever projection, none vanishes at all poses at once).
    Values handled M: the leg lengths, poses and readings (squared form: L²). Noise δ: 32
    roundings of M, plus the pose solves: fk-residual's polished FK is exact to rounding
    (δ·(1 + ‖H A⁻¹‖) into the readings); ik-residual's sensor inversion (redone only when a
    sensor parameter moves) stops at |h(x̂) − y| ≤ 1e-11·(1 + |y|) (residuals._POSE_TOL),
    moving r by up to √6·that·‖A H⁻¹‖ (·2L squared): there the check resolves 1e-3 of a
    sensor column, not 1e-5 (returned as the per-column resolution)."""
    from pkmcal.identification.residuals import _POSE_TOL

    mech, sensor = model.mechanism, model.sensor
    L = mech.leg_lengths(x)
    A = mech.actuator_pose_jacobian(x)
    r_lever = np.max(np.linalg.norm(mech.platform, axis=1))
    A_scaled = A * np.r_[1.0, 1.0, 1.0, [1.0 / r_lever] * 3]
    kappa = np.max(np.linalg.norm(np.linalg.inv(A_scaled), ord=2, axis=(1, 2)))
    H = mech.pose_jacobian_from_twist(sensor.frame_jacobian(mech.frame(x)), x)
    M = max(L.max(), np.abs(x[:, :3]).max(), np.abs(model.y).max())
    ang = np.r_[mech.param_is_angle, sensor.param_is_angle].astype(bool)
    scale = np.where(ang, 1.0, L.min())
    # a leg gain g (unit mm per reading unit): λ = (L − L0)/g curves on the scale g/√3 (third
    # derivative 6|λ|/g³); through FK, L0 + g q moves the legs by q per unit of g
    gain = np.r_[[u not in ("mm", "deg") for u in mech.param_units], np.zeros(len(sensor.param_is_angle), bool)]
    scale[gain] = min(1.0 / np.sqrt(3.0), L.min() / max(1.0, np.abs(model.q).max()))
    resolution = np.full(len(ang), 1e-5)
    if method == "fk-residual":
        scale = scale / (1.0 + kappa) ** 2
        HAi = np.max(np.linalg.norm(H @ np.linalg.inv(A), ord=2, axis=(1, 2)))
        noise = 32 * np.finfo(float).eps * M * (1.0 + HAi)
    else:
        AHi = np.max(np.linalg.norm(A @ np.linalg.inv(H), ord=2, axis=(1, 2)))
        pose_noise = np.sqrt(6.0) * _POSE_TOL * (1.0 + np.abs(model.y).max()) * AHi
        if form == "squared":
            M, pose_noise = M**2, pose_noise * 2.0 * L.max()
        sensor_column = np.arange(len(ang)) >= model.n_mech
        noise = 32 * np.finfo(float).eps * M + np.where(sensor_column, pose_noise, 0.0)
        resolution[sensor_column] = 1e-3
    return dict(scale=scale, magnitude=M, noise=noise, resolution=resolution), ang


def _assert_method_jacobian(meth, model, theta, J, fd_model, ang):
    """The method's J at θ against central differences of its residual (model: _fd_model;
    slope twice each column's largest entry)."""
    size = np.max(np.abs(J).reshape(-1, J.shape[-1]), axis=0)
    assert_jacobian_matches_fd(lambda t: meth.evaluate(t, jac=False, cov=False).r, theta, J, slope=2.0 * size,
                               names=model.names, **fd_model)


JAC_CASES = [
    ("full-pose", "ik-residual", "plain"),
    ("full-pose", "ik-residual", "squared"),
    ("full-pose", "fk-residual", "plain"),
    ("position", "fk-residual", "plain"),
    ("indicators", "fk-residual", "plain"),
]


def _jacobian_setup(name):
    s = setups()[name]
    if name == "full-pose":
        sensor = FullPoseSensor(world=[3.0, -2.0, 1.0, 0.01, 0.02, -0.01], tool=[0.5, 1.0, 25.0, 0.0, 0.02, 0.01])
    elif name == "position":
        sensor = PositionSensor(target=[5.0, -3.0, 20.0], world=[1.0, 2.0, 3.0, 0.01, 0.0, 0.02])
    else:
        sensor = IndicatorSensor(positions=INDICATOR_XY, plane_offset=10.0, zero=[0.1, -0.2, 0.3])
    return replace(s, sensor=sensor)


@pytest.mark.parametrize("setup_name,method,form", JAC_CASES)
def test_jacobian_matches_finite_differences(nominal, real, setup_name, method, form):
    """Every column (machine and sensor parameters), at a perturbed machine with noisy data."""
    setup = _jacobian_setup(setup_name)
    cmd = commanded(nominal, 6)
    q, y = simulate(nominal, real, setup.sensor, cmd, noise=setup.noise)
    model = Model(nominal, setup.sensor, setup.noise, q, y, cmd)
    meth = make_method(method, model, form=form)
    theta = model.theta0 + np.random.default_rng(3).normal(0, 0.3, model.theta0.size) * np.r_[
        np.ones(42), 0.01 * np.ones(6), 0.01 * np.ones(len(setup.sensor.param_names))]  # joints, L0, gains
    ev = meth.evaluate(theta)
    _assert_method_jacobian(meth, model, theta, ev.J, *_fd_model(model, method, form, ev.poses))


@pytest.mark.parametrize("setup_name", ["full-pose", "position", "indicators"])
def test_projection_jacobian(nominal, real, setup_name):
    """Projection: at a noise-free solution the Jacobian is exact (the dropped derivative of
    U⊥ multiplies e = 0); with noise, the cost gradient Jᵀr is exact (variable projection)."""
    setup = _jacobian_setup(setup_name)
    cmd = commanded(nominal, 6)
    q, y = simulate(nominal, nominal, setup.sensor, cmd)
    model = Model(nominal, setup.sensor, setup.noise, q, y, cmd)
    meth = make_method("projection", model)
    theta = model.theta0
    ev = meth.evaluate(theta)
    assert np.max(np.abs(ev.r)) < 1e-8
    # r = U⊥ᵀ W e: as the fk-residual's scales (x* solves the poses as FK does), values over σ;
    # the inner pose solve's error moves r only to second order (projected out)
    fd_model, ang = _fd_model(model, "fk-residual", "plain", ev.poses)
    fd_model["magnitude"] = M = max(np.abs(y / model.sigma_y).max(), np.abs(q / model.sigma_q).max())
    fd_model["noise"] = 32 * np.finfo(float).eps * M
    _assert_method_jacobian(meth, model, theta, ev.J, fd_model, ang)
    # noisy data, perturbed machine: gradient of c = ½‖r‖² against finite differences of c,
    # |c'_k| ≤ ‖r‖ ‖∂r/∂θ_k‖ (slope: twice that), δ_c = ‖r‖₁ δ_r + 32 ε c; a component of the
    # gradient can be small by coincidence (the columns of J are checked above): 1e-4 of it
    q, y = simulate(nominal, real, setup.sensor, cmd, noise=setup.noise)
    model = Model(nominal, setup.sensor, setup.noise, q, y, cmd)
    meth = make_method("projection", model)
    ev = meth.evaluate(theta)
    grad = np.einsum("nkp,nk->p", ev.J, ev.r)

    def cost(t):
        return 0.5 * np.sum(meth.evaluate(t, jac=False, cov=False).r ** 2)

    eps = np.finfo(float).eps
    col = np.linalg.norm(ev.J.reshape(-1, theta.size), axis=0)
    slope = 2.0 * np.linalg.norm(ev.r) * np.where(ang, col[ang].max(initial=0.0), col[~ang].max(initial=0.0))
    c = cost(theta)
    noise = np.abs(ev.r).sum() * 32 * eps * fd_model["magnitude"] + 32 * eps * c
    assert_jacobian_matches_fd(cost, theta, grad, scale=fd_model["scale"], slope=slope, magnitude=c, noise=noise,
                               resolution=1e-4, names=model.names)


def test_covariance_of_residuals_matches_sampling(nominal):
    """Σ_j of the fk-residual (first-order noise propagation) against the sample covariance
    of residuals of many noisy copies of one pose."""
    setup = setups()["indicators"]
    cmd = commanded(nominal, 1)
    q0, y0 = simulate(nominal, nominal, setup.sensor, cmd)
    e_y, e_q = setup.noise.sample(np.random.default_rng(5), (4000, 3), (4000, 6))
    model = Model(nominal, setup.sensor, setup.noise, q0 + e_q, y0 + e_y, np.repeat(cmd, 4000, axis=0))
    ev = make_method("fk-residual", model).evaluate(model.theta0)
    # the sample covariance of n Gaussian draws has Var(S_ij) = (Σ_ij² + Σ_ii Σ_jj)/(n − 1):
    # every one of the 6 distinct entries within z of them but with probability FALSE_FAILURE
    # (the first-order Σ_j is exact to ~σ_q/L ~ 2e-5 here, far below that)
    sample, cov = np.cov(ev.r.T), ev.cov[0]
    se = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / (len(ev.r) - 1))
    z = norm.isf(FALSE_FAILURE / (2 * 6))
    assert np.all(np.abs(sample - cov) < z * se), (sample - cov) / se


# -- weighting ------------------------------------------------------------------------------


def test_weighted_and_unweighted(nominal, real):
    """Both fits recover noise-free data; at the same solution the GLS covariance is no
    larger than the unweighted (sandwich) covariance in the Loewner order (Gauss–Markov)."""
    setup = setups()["full-pose"]
    cmd = commanded(nominal, 15)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    fits = {}
    for w in (True, False):
        fits[w] = identify(nominal, setup, q=q, y=y, method="ik-residual", weighted=w)
        np.testing.assert_allclose(fits[w].estimate[:48], real.params, atol=1e-6)
    diff = fits[False].uncertainty.covariance_prior - fits[True].uncertainty.covariance_prior
    assert np.min(np.linalg.eigvalsh(diff)) > -1e-9 * np.max(np.abs(diff))
    assert np.all(fits[True].uncertainty.std_prior <= fits[False].uncertainty.std_prior * (1 + 1e-9))
    assert np.trace(diff) > 0.05 * np.trace(fits[True].uncertainty.covariance_prior)
    # on noisy data both fits end near the truth and differ from each other
    q, y = simulate(nominal, real, setup.sensor, cmd, noise=setup.noise)
    rw = identify(nominal, setup, q=q, y=y, method="ik-residual", weighted=True)
    ru = identify(nominal, setup, q=q, y=y, method="ik-residual", weighted=False)
    assert not np.allclose(rw.estimate, ru.estimate)
    # each within 6 of its own σ (the unweighted fit's is the sandwich, larger than the
    # weighted one): 84 Gaussian estimates, false failure 84 · 2e-9 < 1e-6
    for r in (rw, ru):
        assert np.all(np.abs(r.estimate[:42] - real.params[:42]) < 6 * r.uncertainty.std_prior[:42] + 1e-3)


def test_whitening_gives_unit_covariance():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(5, 4, 4))
    cov = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(4)
    W = whitening(cov)
    np.testing.assert_allclose(W @ cov @ np.swapaxes(W, 1, 2), np.broadcast_to(np.eye(4), cov.shape), atol=1e-10)
    with pytest.raises(PkmcalError, match="unweighted"):
        whitening(np.zeros((2, 3, 3)))


def test_zero_noise_weighted_is_a_clear_error(nominal, real):
    setup = MeasurementSetup(IndicatorSensor(positions=INDICATOR_XY), NoiseModel(np.zeros(3), np.zeros(6)))
    cmd = commanded(nominal, 40)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    with pytest.raises(PkmcalError, match="noise"):
        identify(nominal, setup, q=q, y=y, commanded=cmd)
    res = identify(nominal, setup, q=q, y=y, commanded=cmd, weighted=False)
    assert res.success and not res.weighted


# -- results, covariance in the machine, bad input ----------------------------------------


def test_result_contents(nominal, real):
    setup = setups()["indicators"]
    cmd = commanded(nominal, 60)
    q, y = simulate(nominal, real, setup.sensor, cmd, noise=setup.noise)
    res = identify(nominal, setup, (q, y, cmd))
    cov = res.mechanism.covariance
    assert cov.shape == (48, 48)
    fixed_idx = [res.names.index(n) for n in res.gauge]
    assert np.all(cov[fixed_idx] == 0) and np.all(cov[:, fixed_idx] == 0)
    free_idx = res.free_index
    np.testing.assert_allclose(cov[np.ix_(free_idx, free_idx)], res.covariance)
    np.testing.assert_allclose(np.sqrt(np.diag(res.covariance)), res.std)
    np.testing.assert_allclose(np.diag(res.correlation), 1.0)
    assert res.residuals.shape == (60, 3) and res.residuals_weighted.shape == (60, 3)
    assert res.residual_names == setup.sensor.reading_names
    # the file covariance is the a-priori one inflated by the Birge ratio when above 1
    f = max(1.0, res.uncertainty.reduced_chi2)
    np.testing.assert_allclose(res.covariance, f * res.uncertainty.covariance_prior)
    d = res.to_dict()
    assert d["identifiability"]["rank"] == res.identifiability.rank
    assert set(d["parameters"]) == set(res.names)
    # weighted residuals ~ unit variance on correctly modelled noise
    assert 0.6 < res.uncertainty.reduced_chi2 < 1.5


def test_unidentifiable_request_is_an_error(nominal, real):
    setup = setups()["indicators"]
    cmd = commanded(nominal, 60)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    with pytest.raises(PkmcalError, match=r"not identifiable.*(a1|a2)\.") as exc:
        identify(nominal, setup, q=q, y=y, free=["b*", "a*", "L0_*"])
    assert "fix" in str(exc.value)
    with pytest.raises(PkmcalError, match="not identifiable"):
        identify(nominal, setup, q=q, y=y, fix=["b1.x"])
    # fixing the suggested gauge works
    res = identify(nominal, setup, q=q, y=y, fix=["a1.x", "a1.y", "a2.x"])
    assert res.success and res.identifiability.identifiable


def test_bad_input_messages(nominal, real):
    setup = setups()["indicators"]
    cmd = commanded(nominal, 10)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    with pytest.raises(PkmcalError, match="full-pose"):
        identify(nominal, setup, q=q, y=y, method="ik-residual")
    with pytest.raises(PkmcalError, match="unknown identification method"):
        identify(nominal, setup, q=q, y=y, method="magic")
    with pytest.raises(PkmcalError, match=r"\(10, 3\)"):
        identify(nominal, setup, q=q, y=y[:, :2])
    with pytest.raises(PkmcalError, match="no parameter matches 'zz'"):
        identify(nominal, setup, q=q, y=y, free=["zz"])
    bad = q.copy()
    bad[4, 0] = np.nan
    with pytest.raises(PkmcalError, match="pose 5"):
        identify(nominal, setup, q=bad, y=y)
    with pytest.raises(PkmcalError, match="measurements"):
        measurement_arrays({"q": q})
    with pytest.raises(PkmcalError, match="jac must be"):
        identify(nominal, setup, q=q, y=y, jac="cs")


def test_exactly_determined_fit_is_flagged(nominal, real):
    """As many residuals as free parameters: the fit interpolates (χ² has no degrees of
    freedom), which the result says, and the file covariance stays the a-priori one."""
    setup = setups()["full-pose"]
    cmd = commanded(nominal, 5)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    res = identify(nominal, setup, q=q, y=y, method="ik-residual", free=["b*", "a?.x", "a?.y"])
    assert len(res.free) == 30 and res.uncertainty.dof == 0 and res.gauge == ()
    assert any("interpolates" in w for w in res.warnings)
    np.testing.assert_array_equal(res.uncertainty.covariance, res.uncertainty.covariance_prior)


def test_unsolvable_poses_dropped_or_rejected(nominal, real):
    setup = setups()["indicators"]
    cmd = commanded(nominal, 60)
    q, y = simulate(nominal, real, setup.sensor, cmd)
    q_bad = q.copy()
    q_bad[[3, 17]] = [400.0, -300.0, 400.0, -300.0, 400.0, -300.0]  # no assembly exists
    res = identify(nominal, setup, q=q_bad, y=y, commanded=cmd)
    assert list(res.dropped) == [3, 17]
    assert any("pose(s)" in w and "4, 18" in w for w in res.warnings)
    q_bad[:20] = q_bad[3]
    with pytest.raises(PkmcalError, match="could not be solved for 20 of 60 poses"):
        identify(nominal, setup, q=q_bad, y=y, commanded=cmd)


# -- command line ---------------------------------------------------------------------------


def _cli(args):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    return CliRunner().invoke(cli, args, catch_exceptions=False)


@pytest.fixture(scope="module")
def cli_files(tmp_path_factory, nominal):
    d = tmp_path_factory.mktemp("identify")
    poses = commanded(nominal, 60)
    poses[:, 3:] = np.rad2deg(poses[:, 3:])
    pose_csv = d / "poses.csv"
    np.savetxt(pose_csv, poses, delimiter=",", header="x,y,z,a,b,c", comments="", fmt="%.9f")
    meas = d / "meas.csv"
    res = _cli(["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                "indicators-prototype", "--poses", str(pose_csv), "--seed", "3", "-o", str(meas)])
    assert res.exit_code == 0, res.output
    return d, pose_csv, meas


def test_cli_identify_writes_calibrated_machine(cli_files, real):
    import json

    from pkmcal.io.machine_file import load_machine

    d, _, meas = cli_files
    out = d / "cal.yaml"
    res = _cli(["identify", "stewart-prototype", str(meas), "--setup", "indicators-prototype", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "gauge (fixed)" in res.output and "a1.x" in res.output and "chi2/dof" in res.output
    cal = load_machine(str(out))
    assert cal.covariance.shape == (48, 48)
    i = list(cal.param_names).index("a1.x")
    assert cal.covariance[i, i] == 0.0 and cal.covariance[0, 0] > 0
    out2 = d / "cal2.yaml"
    res = _cli(["identify", "stewart-prototype", str(meas), "--setup", "indicators-prototype", "--unweighted",
                "--method", "projection", "-o", str(out2), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["method"] == "projection" and data["weighted"] is False
    assert data["gauge"] == ["a1.x", "a1.y", "a2.x"] and data["identifiability"]["rank"] == 39


def test_cli_identify_unidentifiable_is_exit_2(cli_files):
    d, _, meas = cli_files
    out = d / "never.yaml"
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    res = CliRunner().invoke(cli, ["identify", "stewart-prototype", str(meas), "--setup", "indicators-prototype",
                                   "--free", "b*,a*,L0_*", "-o", str(out)])
    assert res.exit_code == 2
    assert "not identifiable" in res.output and "a1." in res.output
    assert not out.exists()


def test_cli_identifiability_json(cli_files):
    import json

    _, pose_csv, _ = cli_files
    res = _cli(["identifiability", "stewart-prototype", "--setup", "indicators-prototype", "--poses",
                str(pose_csv), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["n_params"] == 42 and data["rank"] == 39 and len(data["null_space"]) == 3
    assert data["fixed"] == ["a1.x", "a1.y", "a2.x"]
    res = _cli(["identifiability", "stewart-prototype", "--setup", "indicators-prototype", "--poses", str(pose_csv)])
    assert "rank 39 of 42" in res.output and "suggested gauge" in res.output


# -- solver paths and evaluation caching ----------------------------------------------------


@pytest.mark.parametrize("method,setup_name,n", [("ik-residual", "full-pose", 15), ("fk-residual", "indicators", 40)])
def test_lm_path_is_least_squares_lm(nominal, real, method, setup_name, n):
    """The analytic LM fit (MINPACK lmder via leastsq) is the run scipy's
    least_squares(method="lm") makes with the same objective: same iterate, same counts;
    and the finite-difference fit starts from the same point with the same tolerances."""
    from scipy.optimize import least_squares

    from pkmcal.identification.engine import _least_squares, _Objective

    setup = setups()[setup_name]
    cmd = commanded(nominal, n)
    q, y = simulate(nominal, real, setup.sensor, cmd, noise=setup.noise)
    res = identify(nominal, setup, q=q, y=y, commanded=cmd, method=method)
    free = res.free_index
    results = []
    for path in ("engine", "least_squares"):
        model = Model(nominal, setup.sensor, setup.noise, q, y, cmd)
        meth = make_method(method, model)
        W = whitening(meth.evaluate(model.theta0).cov)
        meth.sensor_columns = False
        obj = _Objective(meth, model.theta0, free, W)
        kw = dict(ftol=1e-12, xtol=1e-12, gtol=1e-12)
        if path == "engine":
            sol = _least_squares(obj, model.theta0[free], jac="analytic", method="lm", max_nfev=None, **kw)
            results.append((sol.x, sol.nfev, sol.njev, sol.status))
        else:
            sol = least_squares(obj.fun, model.theta0[free], jac=obj.jac, method="lm", x_scale="jac", **kw)
            results.append((sol.x, sol.nfev, sol.njev, sol.status))
    (x1, nf1, nj1, st1), (x2, nf2, nj2, st2) = results
    np.testing.assert_allclose(x1, x2, rtol=0, atol=1e-9)
    assert (nf1, nj1, st1) == (nf2, nj2, st2)
    np.testing.assert_allclose(res.estimate[free], x1, rtol=0, atol=1e-9)
    fd = identify(nominal, setup, q=q, y=y, commanded=cmd, method=method, jac="2-point")
    assert fd.free == res.free and np.array_equal(fd.initial, res.initial)
    # the finite-difference fit ends at (about) the same minimum, never a better one
    assert fd.success and res.cost * (1 - 1e-9) <= fd.cost <= res.cost * (1 + 1e-3)


@pytest.mark.parametrize("method", ["ik-residual", "fk-residual", "projection"])
def test_cached_evaluation_equals_fresh(nominal, real, method):
    """Residual first, Jacobian second at the same θ (the solver's order, served from the
    method's cache) gives exactly what a fresh method evaluating the Jacobian at θ gives."""
    setup = _jacobian_setup("full-pose")
    cmd = commanded(nominal, 6)
    q, y = simulate(nominal, real, setup.sensor, cmd, noise=setup.noise)
    theta = None
    evs = []
    for order in ("cached", "fresh"):
        model = Model(nominal, setup.sensor, setup.noise, q, y, cmd)
        meth = make_method(method, model)
        if theta is None:
            theta = model.theta0 + np.random.default_rng(4).normal(0, 0.2, model.theta0.size) * np.r_[
                np.ones(42), 0.01 * np.ones(6), 0.01 * np.ones(12)]
        if order == "cached":
            r = meth.evaluate(theta, jac=False, cov=False).r
            ev = meth.evaluate(theta.copy(), jac=True, cov=True)
            np.testing.assert_array_equal(r, ev.r)
        else:
            ev = meth.evaluate(theta, jac=True, cov=True)
        evs.append(ev)
    for field_ in ("r", "J", "cov", "poses"):
        np.testing.assert_array_equal(getattr(evs[0], field_), getattr(evs[1], field_))


def test_identify_with_no_poses_is_a_clear_error():
    """A simulation whose real machine reached none of its poses gives empty measurements:
    identify says so instead of failing inside scipy."""
    from pkmcal.sensors.library import builtin_setup

    m = builtin_machine("stewart-prototype")
    with pytest.raises(PkmcalError, match="no measured poses"):
        identify(m, builtin_setup("full-pose-paper1", m), (np.zeros((0, 6)), np.zeros((0, 6))))


# -- trial points where poses fail ----------------------------------------------------------


@pytest.fixture()
def reading_space_rss(monkeypatch):
    """The 6-RSS with the shared solver on λ − IK(x) (the deltas' and planar machines' FK,
    NaN outside a chain's reach) instead of its loop-closure FK, so that a start pose
    outside a rod's reach fails, as it did on that machine, and a 150-pose hobby-servo
    campaign on it (real machine 0.3 mm / 0.3 mrad off, laser tracker 0.01 mm,
    actuator noise ``sigma_q`` rad)."""
    from pathlib import Path

    from pkmcal.identification.simulation import perturb_machine, simulate_campaign
    from pkmcal.io.setup_file import load_setup
    from pkmcal.mechanisms.base import Mechanism
    from pkmcal.mechanisms.rss_hexapod import RSSHexapod

    monkeypatch.setattr(RSSHexapod, "fk", Mechanism.fk)
    monkeypatch.syspath_prepend(str(Path(__file__).parents[1] / "mechanisms"))
    from test_rss_hexapod import _reachable

    m = builtin_machine("servo-stewart")

    def campaign(n, sigma_q):
        setup = load_setup("laser-tracker", m)
        setup = replace(setup, noise=replace(setup.noise, actuator_std=np.array(sigma_q)))
        sim = simulate_campaign(m, perturb_machine(m, 0.3, 7), setup, _reachable(m, n, 3), 7)
        return setup, sim.measurements

    return m, campaign


def test_fk_residual_after_a_far_trial_point_equals_fresh(reading_space_rss):
    """A trial point far from θ (every crank pivot 5 mm off), where the commanded poses are
    outside a rod's reach, is solved by continuation from θ0 (since issue 24's referee: the
    FK is a function of θ alone, tests/identification/test_fk_residual_path.py); back at θ0 every pose
    solves again and the residual is a fresh method's to the FK's tolerance (1e-11 relative
    steps: ~1e-9 mm), not that of poses stuck at starts outside the reach (an earlier main:
    up to 4 poses failing at θ0, residuals off by 4 mm)."""
    from pkmcal.mechanisms.rss_hexapod import PARAM_NAMES

    m, campaign = reading_space_rss
    setup, meas = campaign(60, 0.005)
    q, y, cmd = measurement_arrays(meas)
    model = Model(m, setup.sensor, setup.noise, q, y, cmd)
    th0 = model.theta0
    fresh = make_method("fk-residual", model).evaluate(th0, jac=False, cov=False)
    assert fresh.converged.all()
    far = th0.copy()
    for i in range(6):
        far[PARAM_NAMES.index(f"s{i + 1}.x")] += 5.0 * (-1) ** i
        far[PARAM_NAMES.index(f"s{i + 1}.y")] += 5.0 * (-1) ** (i // 2)
    meth = make_method("fk-residual", model)
    assert meth.evaluate(far, jac=False, cov=False).converged.all()
    back = meth.evaluate(th0, jac=False, cov=False)
    assert back.converged.all()
    np.testing.assert_allclose(back.r, fresh.r, rtol=0, atol=1e-8)


def test_fit_never_accepts_a_machine_that_cannot_take_a_pose(reading_space_rss):
    """With 0.005 rad actuator noise, Levenberg–Marquardt's trial machines put commanded
    poses outside a rod's reach, where this FK fails. Those trial points are rejected
    (NaN residual rows), so the fit converges with every pose solved and χ²/ν within 4σ
    of 1 (σ = √(2/ν)); main ended at a machine that could not take 41 of the 150 poses, and
    with the warm starts repaired alone at one that could not take 3."""
    m, campaign = reading_space_rss
    setup, meas = campaign(150, 0.005)
    fit = identify(m, setup, meas)
    assert fit.success
    assert not any("could not be solved" in w for w in fit.warnings)
    u = fit.uncertainty
    assert abs(u.chi2 / u.dof - 1.0) < 4 * np.sqrt(2.0 / u.dof)
