"""Static equilibrium of the redundant machines (paper 3 eq. 1–3): force balance, energy
minimum, agreement with the linearised error propagation, closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.errors import PkmcalError
from pkmcal.identification.projection import ActuatorSubset
from pkmcal.mechanisms import planar as PL
from pkmcal.mechanisms.statics import equilibrium, force_balance, linear_response, potential_energy
from pkmcal.sensors.planar_tool import PlanarToolSensor

CASES = {
    "planar-2dof-3act": (PL.planar_2dof_3act(), 5e7, np.array([20.0, -30.0])),
    "planar-3dof-4act": (PL.planar_3dof_4act(), 1e3, np.array([20.0, -30.0])),
}


def _errors(m, seed, size):
    rng = np.random.default_rng(seed)
    ang = np.array([n.startswith("alpha") or (n.startswith("dq") and m.n_dof == 2) for n in m.param_names])
    return rng.normal(size=len(m.params)) * size * np.where(ang, 1e-3, 1.0)


def _setup(name, seed=0, size=0.2, n=40):
    m, K, F = CASES[name]
    s = PlanarToolSensor(n_pose=m.n_dof)
    d = _errors(m, seed, size)
    ds = np.array([0.3, -0.2, 0.0, 0.0, 0.0]) * size
    x = m.sample_poses(n, np.random.default_rng(seed + 100))
    K = K * np.random.default_rng(seed).uniform(0.5, 2.0, m.n_actuators)
    return m, s, d, ds, x, K, F


@pytest.mark.parametrize("name", list(CASES))
def test_force_balance_residual_and_energy_minimum(name):
    m, s, d, ds, x, K, F = _setup(name, size=0.5)
    real, rs = m.with_params(m.params + d), s.with_params(s.params + ds)
    c = m.ik(x)
    eq = equilibrium(real, c, K, F, rs, guess=x)
    assert eq.converged.all()
    # balance of generalised forces, relative to the actuator forces involved
    g = force_balance(real, c, K, eq.poses, F, rs)
    G = real.actuator_pose_jacobian(eq.poses)
    scale = np.abs(np.einsum("nli,nl->ni", G, eq.actuator_force)).max() + np.abs(F).max()
    assert np.abs(g).max() < 1e-8 * scale
    # the reported actuator forces carry the load: Γᵀ τ = −J_fᵀ F (τ = K (c − q))
    Jf = real.pose_jacobian_from_twist(rs.tool_frame_jacobian(real.frame(eq.poses)), eq.poses)
    np.testing.assert_allclose(np.einsum("nli,nl->ni", G, eq.actuator_force), -np.einsum("nki,k->ni", Jf, F),
                               atol=1e-8 * scale)
    # a stable equilibrium: every small displacement raises the energy
    U0 = potential_energy(real, c, K, eq.poses, F, rs)
    rng = np.random.default_rng(1)
    for _ in range(5):
        dx = rng.normal(size=eq.poses.shape) * np.array([1e-3, 1e-3, 1e-5])[: m.n_dof]
        assert np.all(potential_energy(real, c, K, eq.poses + dx, F, rs) > U0)


@pytest.mark.parametrize("name", list(CASES))
def test_no_error_no_load_rests_at_the_command(name):
    m, s, _, _, x, K, _ = _setup(name)
    eq = equilibrium(m, m.ik(x), K, guess=x + 0.5)
    np.testing.assert_allclose(eq.poses, x, atol=1e-9)
    assert np.abs(eq.following_error).max() < 1e-10


@pytest.mark.parametrize("name", list(CASES))
def test_nonlinear_solution_agrees_with_linearised_propagation(name):
    """Eq. 1–3: the difference is second order in the errors (×10 errors → ~×100)."""
    m, s, d, ds, x, K, F = _setup(name, size=0.01)
    out = []
    for k in (1.0, 10.0):
        real, rs = m.with_params(m.params + k * d), s.with_params(s.params + k * ds)
        eq = equilibrium(real, m.ik(x), K, k * F, rs, guess=x)
        dx, dqm, dpt = linear_response(m, s, x, k * d, k * ds, K, k * F)
        assert eq.converged.all()
        dev = [np.abs(eq.poses - x - dx).max(), np.abs(eq.following_error - dqm).max(),
               np.abs(rs.tool_point(real.frame(eq.poses)) - s.tool_point(m.frame(x)) - dpt).max()]
        size = [np.abs(dx).max(), np.abs(dqm).max(), np.abs(dpt).max()]
        out.append((np.array(dev), np.array(size)))
    (dev1, size1), (dev10, _) = out
    assert np.all(dev1 < 1e-3 * size1)                  # linearisation good for small errors
    ratio = dev10 / dev1
    assert np.all((ratio > 50) & (ratio < 200)), ratio  # quadratic remainder


@pytest.mark.parametrize("name", list(CASES))
def test_load_deflection_closed_form(name):
    """No kinematic error: dx = (ΓᵀKΓ)⁻¹ J_fᵀ F; doubling K halves it (to first order)."""
    m, s, _, _, x, K, F = _setup(name)
    G = m.actuator_pose_jacobian(x)
    Jf = m.pose_jacobian_from_twist(s.tool_frame_jacobian(m.frame(x)), x)
    dx = np.linalg.solve(np.einsum("nli,l,nlj->nij", G, K, G), np.einsum("nki,k->ni", Jf, F)[..., None])[..., 0]
    eq = equilibrium(m, m.ik(x), K, F, s, guess=x)
    np.testing.assert_allclose(eq.poses - x, dx, atol=2e-3 * np.abs(dx).max())
    eq2 = equilibrium(m, m.ik(x), 2 * K, F, s, guess=x)
    np.testing.assert_allclose(eq2.poses - x, dx / 2, atol=2e-3 * np.abs(dx).max())


@pytest.mark.parametrize("name", list(CASES))
def test_non_redundant_machine_has_no_internal_force(name):
    """With only n actuators (l = n) the machine goes exactly where its (erroneous)
    actuators put it, whatever K: the equilibrium is the FK and the following error zero."""
    m, s, d, _, x, K, _ = _setup(name, size=0.5)
    real = ActuatorSubset(m.with_params(m.params + d), tuple(range(m.n_dof)))
    c = ActuatorSubset(m, tuple(range(m.n_dof))).ik(x)
    eq = equilibrium(real, c, K[: m.n_dof], guess=x)
    fk = real.fk(c, guess=x)
    np.testing.assert_allclose(eq.poses, fk.poses, atol=1e-9)
    assert np.abs(eq.following_error).max() < 1e-9


def test_redundant_conflict_produces_following_errors_that_balance():
    """A length error on a redundant chain makes the actuators fight: non-zero following
    errors whose forces are in the null space of Γᵀ (no load): Γᵀ K dq_m = 0."""
    m, s, _, _, x, K, _ = _setup("planar-2dof-3act")
    real = m.with_deltas({"l31": 0.3})
    eq = equilibrium(real, m.ik(x), K, guess=x)
    assert np.abs(eq.following_error).max() > 1e-5
    G = real.actuator_pose_jacobian(eq.poses)
    f = np.einsum("nli,nl->ni", G, K * eq.following_error)
    assert np.abs(f).max() < 1e-8 * np.abs(K * eq.following_error).max()


def test_bad_stiffness_and_missing_load_point_are_user_errors():
    m, s, _, _, x, K, F = _setup("planar-2dof-3act")
    with pytest.raises(PkmcalError, match="stiffness"):
        equilibrium(m, m.ik(x), -1.0)
    with pytest.raises(PkmcalError, match="load_point"):
        equilibrium(m, m.ik(x), K, F)
