"""The identification hot path's shortcuts, each against the slower computation it replaces.

* ``Hexapod.actuator_jacobians`` (one compiled pass) against the NumPy twist Jacobian and
  ∂λ/∂ρ written out here (central differences of IK: tests/mechanisms/test_hexapod.py);
* ``Hexapod.fk_precise`` (one polishing Newton step) against plain FK: same poses to the
  FK tolerance, IK reproduced to rounding;
* ``ScaledJacobian.certainly_full_rank`` against the singular values: never claims full
  rank when σ_P/σ_1 ≤ rtol, and does claim it for well-conditioned matrices;
* ``identify``'s deferred identifiability report against ``analyse_jacobian`` on the same
  Jacobian, and its deferred weak-direction warnings against ``fit_warnings`` on it and an
  independent SVD;
* ``solve_right`` and ``cholesky_inverse`` (compiled loops over tiny matrices) and
  ``qr_triangle`` (LAPACK ``dgeqrf``) against NumPy's ``linalg``.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from helpers import random_poses

from pkmcal.conventions import euler_pose_jacobian, euler_to_matrix
from pkmcal.identification._small_linalg import cholesky_inverse, qr_triangle, solve_right
from pkmcal.identification.engine import identify
from pkmcal.identification.identifiability import RANK_RTOL, ScaledJacobian, analyse_jacobian
from pkmcal.identification.residuals import Model, make_method
from pkmcal.identification.simulation import perturb_machine, simulate_campaign
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine


@pytest.fixture(scope="module")
def machine():
    return builtin_machine("stewart-prototype")


def _poses(machine, seed, n=40):
    return random_poses(machine, n, seed)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_actuator_jacobians_match_numpy_formulas(machine, seed):
    poses = _poses(machine, seed)
    A, B = machine.actuator_jacobians(poses)
    # reference: the NumPy twist Jacobian, and ∂λ/∂ρ written out from u_i = l_i/‖l_i‖,
    # l_i = p + R a_i − b_i (both are checked against central differences in
    # mechanisms/test_hexapod.py, which now run through the kernel)
    A_ref = euler_pose_jacobian(machine.twist_jacobian(poses), poses)
    R = euler_to_matrix(poses[:, 3:6])
    legs = poses[:, None, :3] + np.einsum("nrc,ic->nir", R, machine.platform) - machine.base
    u = legs / np.linalg.norm(legs, axis=2, keepdims=True)
    B_ref = np.zeros((len(poses), 6, 6, 7))
    legs_idx = np.arange(6)
    B_ref[:, legs_idx, legs_idx, 0:3] = -u
    B_ref[:, legs_idx, legs_idx, 3:6] = np.einsum("nir,nrc->nic", u, R)
    B_ref[:, legs_idx, legs_idx, 6] = -1.0
    G_ref = np.zeros((len(poses), 6, 6))
    G_ref[:, legs_idx, legs_idx] = -machine.ik(poses)  # ∂λ_i/∂g_i = −λ_i/g_i, g = 1
    np.testing.assert_allclose(A, A_ref, rtol=0, atol=1e-12 * np.max(np.abs(A_ref)))
    np.testing.assert_allclose(B, np.concatenate([B_ref.reshape(len(poses), 6, 42), G_ref], axis=2), rtol=0,
                               atol=1e-12 * max(1.0, np.max(np.abs(G_ref))))
    assert np.array_equal(machine.actuator_pose_jacobian(poses), A)
    assert np.array_equal(machine.actuator_param_jacobian(poses), B)


def test_fk_precise_polishes_to_rounding(machine):
    poses = _poses(machine, 3, n=2000)
    q = machine.ik(poses)
    guess = poses + np.random.default_rng(4).normal(0.0, 0.5, poses.shape) * np.array([1, 1, 1, 0.01, 0.01, 0.01])
    plain = machine.fk(q, guess=guess)
    fine = machine.fk_precise(q, guess=guess)
    assert plain.converged.all() and fine.converged.all()
    assert np.array_equal(plain.iterations, fine.iterations)          # polishing is not counted
    lengths = machine.leg_lengths(fine.poses)
    scale = np.max(np.abs(lengths))
    # plain FK stops at 1e-9 mm; one more Newton step leaves only rounding (~1e-13 mm here)
    assert np.max(np.abs(machine.ik(fine.poses) - q)) <= 16 * np.finfo(float).eps * scale
    assert np.max(np.abs(fine.poses - plain.poses)) < 1e-6
    assert np.max(np.abs(fine.poses - poses)) < 1e-9


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), log_cond=st.floats(0.0, 12.0), rank_drop=st.integers(0, 2))
def test_full_rank_certificate_is_never_wrong(seed, log_cond, rank_drop):
    rng = np.random.default_rng(seed)
    M, P = 60, 12
    U, _ = np.linalg.qr(rng.normal(size=(M, P)))
    V, _ = np.linalg.qr(rng.normal(size=(P, P)))
    s = np.logspace(0.0, -log_cond, P)
    if rank_drop:
        s[-rank_drop:] = 0.0
    J = (U * s) @ V.T * rng.uniform(0.1, 100.0, P)      # unscaled columns, as in practice
    sj = ScaledJacobian(J)
    sv = np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)
    ok = sj.certainly_full_rank()
    kappa = sj.condition_bound()                 # an upper bound of σ_1/σ_P, or inf
    if sv[-1] > 1e-8 * sv[0]:
        # the QR's backward error moves σ_P by ≲ M·√P·ε·σ_1 ≈ 1e-13·σ_1, ≤ 1e-5 of σ_P here
        assert kappa * sv[-1] >= sv[0] * (1 - 1e-4)
    assert sj.condition_bound() == kappa         # computed once, asked twice by the engine
    if ok:
        assert sv[-1] > RANK_RTOL * sv[0]
    if sv[-1] > 1e3 * P * RANK_RTOL * sv[0]:               # clearly full rank: must be proven
        assert ok
    assert analyse_jacobian(J, tuple(f"p{i}" for i in range(P))).identifiable == (sv[-1] > RANK_RTOL * sv[0])


@pytest.mark.parametrize("setup_name, method", [("full-pose-paper1", "ik-residual"),
                                                ("indicators-prototype", "fk-residual")])
def test_deferred_report_equals_full_analysis(machine, setup_name, method):
    setup = builtin_setup(setup_name)
    rng = np.random.default_rng(11)
    real = perturb_machine(machine, 0.5, rng)
    sim = simulate_campaign(machine, real, setup, _poses(machine, 12, n=30), rng, ignore_limits=("leg_collision",))
    res = identify(machine, setup, q=sim.actuator_readings, y=sim.sensor_readings, commanded=sim.commanded[sim.kept],
                   method=method)
    # the engine judges identifiability on the plan: the commanded poses, noise-free readings
    from pkmcal.identification.identifiability import design_jacobian

    Jd, ok, _ = design_jacobian(machine, setup.sensor, setup.noise, sim.commanded[sim.kept], method)
    J = Jd[ok].reshape(-1, Jd.shape[-1])[:, :42]  # the 42 geometry columns: the gains are held by default
    ref = analyse_jacobian(J, machine.param_names[:42], machine.param_names[:42])
    rep = res.identifiability
    assert rep.rank == ref.rank and rep.fixed == ref.fixed
    np.testing.assert_allclose(rep.singular_values, ref.singular_values, rtol=1e-10, atol=1e-12)
    assert res.gauge == (() if ref.identifiable else ref.fixed)


def test_deferred_warnings_equal_the_eager_ones(machine):
    """Paper 1's corners leave weak directions (σ/σ₁ < WEAK_RATIO) but full rank: the fit
    needs no SVD, so the weak-direction warnings are computed on first read. They must be
    what fit_warnings gives on the report (in the place the eager ones had, before later
    notes), whichever is read first, and name every direction an independent SVD of the
    commanded-pose Jacobian finds below WEAK_RATIO."""
    from pkmcal.identification.engine import fit_warnings
    from pkmcal.identification.identifiability import WEAK_RATIO, design_jacobian

    setup = builtin_setup("full-pose-paper1")
    rng = np.random.default_rng(5)
    real = perturb_machine(machine, 5.0, rng)
    half = np.array([15.0, 15.0, 8.0, *np.deg2rad([6.0, 6.0, 6.0])])
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * 6)).reshape(6, -1).T * half + machine.home_pose
    corners = corners[machine.check_limits(corners).ok][::4][:15]
    sim = simulate_campaign(machine, real, setup, corners, rng, ignore_limits=("leg_collision",))

    def fit():
        return identify(machine, setup, sim.measurements, method="ik-residual")

    first_warnings, first_report = fit(), fit()
    rep = first_report.identifiability
    w1, w2 = first_warnings.warnings, first_report.warnings
    assert w1 == w2
    Jd, ok, _ = design_jacobian(machine, setup.sensor, setup.noise, sim.commanded[sim.kept], "ik-residual")
    sv = np.linalg.svd(Jd[ok].reshape(-1, Jd.shape[-1])[:, :42] / np.linalg.norm(Jd[ok].reshape(-1, Jd.shape[-1])[:, :42],
                                                                                   axis=0), compute_uv=False)
    n_weak = int(np.sum(sv / sv[0] < WEAK_RATIO))
    assert rep.identifiable and n_weak >= 1 and len(rep.weak) == n_weak
    weak = [w for w in w1 if "weakly identifiable" in w]
    assert len(weak) == n_weak
    assert tuple(fit_warnings(rep, first_report.free, first_report.uncertainty, first_report.angle_names())) == w1


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 9), m=st.integers(1, 6), N=st.integers(0, 30))
def test_small_linalg_against_numpy(seed, n, m, N):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N, n, n)) + 3.0 * np.eye(n)
    H = rng.normal(size=(N, m, n))
    X, ok = solve_right(A, H)
    assert ok.all()
    np.testing.assert_allclose(X @ A, H, atol=1e-10 * (1 + np.abs(H).max(initial=0)))
    S = rng.normal(size=(N, n, n))
    C = S @ np.swapaxes(S, 1, 2) + 0.1 * np.eye(n)
    W, bad = cholesky_inverse(C)
    assert bad == -1
    np.testing.assert_allclose(W, np.linalg.inv(np.linalg.cholesky(C)), rtol=1e-9, atol=1e-9)
    assert np.all(np.triu(W, 1) == 0.0)
    T = rng.normal(size=(n + m + 3, n))
    R = qr_triangle(T)
    assert R.shape == (n, n) and np.all(np.tril(R, -1) == 0.0)
    np.testing.assert_allclose(R.T @ R, T.T @ T, atol=1e-10 * np.abs(T.T @ T).max())
    np.testing.assert_allclose(np.abs(R), np.abs(np.linalg.qr(T, mode="r")), atol=1e-10)


def test_small_linalg_flags_singular_and_indefinite():
    A = np.stack([np.eye(3), np.diag([1.0, 1.0, 0.0]), np.eye(3)])
    X, ok = solve_right(A, np.ones((3, 2, 3)))
    assert ok.tolist() == [True, False, True]
    assert np.isnan(X[1]).all() and np.allclose(X[[0, 2]], 1.0)
    C = np.stack([np.eye(2), np.eye(2), np.diag([1.0, -1.0])])
    assert cholesky_inverse(C)[1] == 2
    assert cholesky_inverse(np.stack([np.eye(2), np.diag([1.0, np.nan])]))[1] == 1


@pytest.mark.parametrize("A_shape, H_shape", [((13, 6, 6), (13, 3, 3)), ((4, 3, 3), (5, 2, 3)), ((4, 3, 2), (4, 2, 2))])
def test_small_linalg_refuses_mismatched_shapes(A_shape, H_shape):
    """The compiled loops index without bounds checks: a shape mismatch (a single-pose sensor's
    H against a pose pair's A once wrote past the arrays and corrupted the heap) is an error
    before the loop runs."""
    with pytest.raises(ValueError, match="solve_right needs"):
        solve_right(np.ones(A_shape), np.ones(H_shape))
    with pytest.raises(ValueError, match="cholesky_inverse needs"):
        cholesky_inverse(np.ones((3, 2, 3)))


def test_full_pose_inverse_is_exact_and_measures_the_poses(machine):
    """The full-pose sensor's closed-form inverse (R = R_wᵀ R_T R_tᵀ, p = R_wᵀ(y − p_w) − R p_t)
    gives back the frame it read to rounding, with and without world/tool transforms; the
    ik-residual's measured poses are those frames' poses (for the identity sensor: the
    readings themselves, to rounding)."""
    from pkmcal.sensors.full_pose import FullPoseSensor

    setup = builtin_setup("full-pose-paper1")
    rng = np.random.default_rng(5)
    poses = _poses(machine, 6, n=12)
    frame = machine.frame(poses)
    eps = np.finfo(float).eps
    for s in (setup.sensor, FullPoseSensor(world=np.array([100.0, -50.0, 20.0, 0.1, -0.2, 0.3]),
                                           tool=np.array([5.0, 3.0, 40.0, -0.05, 0.02, 1.0]))):
        back = s.invert(s.predict(frame))
        np.testing.assert_allclose(back.R, frame.R, rtol=0, atol=16 * eps)
        np.testing.assert_allclose(back.p, frame.p, rtol=0, atol=16 * eps * 1000.0)
    y = setup.sensor.predict(frame) + rng.normal(0.0, 0.01, (12, 6))
    q = machine.ik(poses) + rng.normal(0.0, 0.005, (12, 6))
    model = Model(machine, setup.sensor, setup.noise, q, y)
    ev = make_method("ik-residual", model).evaluate(model.theta0, jac=True, cov=True)
    np.testing.assert_allclose(ev.poses, y, rtol=0, atol=16 * eps * np.abs(y).max())


def test_readings_that_are_the_pose_match_the_general_inverse(machine, monkeypatch):
    """A full-pose sensor without world/tool transforms on a hexapod reads the pose itself
    (declared: Sensor.reads_pose and the "pose-convention" ability): the ik-residual takes
    x̂ = y and H = I; the closed-form inverse and H⁻¹ must give the same residual, Jacobian
    (sensor columns included) and covariance."""
    from pkmcal.sensors.full_pose import FullPoseSensor

    setup = builtin_setup("full-pose-paper1")
    assert setup.sensor.reads_pose() and not FullPoseSensor(world=np.array([0, 0, 0, 0, 0, 1e-3])).reads_pose()
    assert not setup.sensor.reads_pose(np.r_[np.zeros(11), 1e-3])
    rng = np.random.default_rng(5)
    poses = _poses(machine, 6, n=12)
    y = setup.sensor.predict(machine.frame(poses)) + rng.normal(0.0, 0.01, (12, 6))
    q = machine.ik(poses) + rng.normal(0.0, 0.005, (12, 6))

    def evaluate():
        model = Model(machine, setup.sensor, setup.noise, q, y)
        return make_method("ik-residual", model).evaluate(model.theta0, jac=True, cov=True)

    fast = evaluate()
    np.testing.assert_array_equal(fast.poses, y)
    monkeypatch.setattr(FullPoseSensor, "reads_pose", lambda self, params=None: False)
    slow = evaluate()
    np.testing.assert_allclose(fast.poses, slow.poses, atol=1e-12)
    np.testing.assert_allclose(fast.r, slow.r, atol=1e-10)
    np.testing.assert_allclose(fast.J, slow.J, atol=1e-10)
    np.testing.assert_allclose(fast.cov, slow.cov, rtol=1e-10, atol=1e-16)
