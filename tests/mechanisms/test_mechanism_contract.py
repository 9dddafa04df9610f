"""The mechanism contract (issue 12 item 1), checked on every built-in machine.

* Declarations: kind, names, angle flags and units line up; abilities are a frozenset;
  the workspace box is (n, 2) around home.
* Explicit parameters: ``ik``, ``ik_and_jacobians``, the Jacobians, ``fk`` and the branch
  signs with ``params=ρ`` equal ``with_params(ρ)``'s to the bit (small and compiled batches).
* The platform frame: T = ∂twist/∂pose against central finite differences of
  (p(x), log(R(x) R(x₀)ᵀ)); ``pose_jacobian_from_twist`` is J · T; ``poses_from_frame``
  inverts ``frame``.
* The shared FK solver (``mechanisms/solver.py``) agrees with the hexapod's compiled Newton
  and reproduces the readings on the planar machines; it flags a pose on another branch.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.conventions import rotation_vector_to_matrix
from pkmcal.io.machine_file import machine_from_text, machine_to_text
from pkmcal.mechanisms import BUILTIN_MACHINES, builtin_machine
from pkmcal.mechanisms.frame import Frame
from pkmcal.mechanisms.solver import solve_fk

MACHINES = {name: builtin_machine(name) for name in BUILTIN_MACHINES}


def _poses(m, n, seed, shrink=0.6):
    """``n`` poses uniform in the machine's workspace box shrunk about its centre."""
    rng = np.random.default_rng(seed)
    box = m.workspace_box()
    c, h = box.mean(axis=1), 0.5 * (box[:, 1] - box[:, 0]) * shrink
    return c + rng.uniform(-1.0, 1.0, (n, m.n_dof)) * h


def _perturbed_params(m, seed, size=0.3):
    rng = np.random.default_rng(seed)
    ang = np.array(m.param_is_angle, dtype=bool)
    return m.params + rng.normal(size=len(m.params)) * size * np.where(ang, 1e-2, 1.0)


def _rotvec(R):
    """Rotation vectors (N, 3) of rotations (N, 3, 3) (scipy)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


@pytest.mark.parametrize("name", list(MACHINES))
def test_declarations_line_up(name):
    m = MACHINES[name]
    assert m.kind and isinstance(m.kind, str)
    assert isinstance(m.abilities, frozenset)
    p = len(m.param_names)
    assert len(m.param_is_angle) == len(m.param_units) == len(m.params) == p
    # mm, degrees, pure numbers, or mm per reading unit (a hexapod's leg gains with readings in rev, ...)
    assert all(u in {"mm", "deg", "1"} or u.startswith("mm/") for u in m.param_units)
    assert [u == "deg" for u in m.param_units] == list(m.param_is_angle)
    assert len(m.actuator_units) == len(m.actuator_is_angle) == m.n_actuators
    assert len(m.pose_is_angle) == m.n_dof
    assert isinstance(m.default_fixed, tuple)
    box = m.workspace_box()
    assert box.shape == (m.n_dof, 2) and np.all(box[:, 0] < box[:, 1])
    assert np.all((box[:, 0] <= m.home_pose) & (m.home_pose <= box[:, 1]))
    assert m.summary().startswith(m.name)


def test_hexapod_kind_and_its_alias_load_the_same_machine():
    m = MACHINES["stewart-prototype"]
    assert m.kind == "6-UPS" and "leg-lengths" in m.abilities
    text = machine_to_text(m)
    assert "kind: hexapod" in text
    assert machine_from_text(text.replace("kind: hexapod", "kind: 6-UPS")) == m == machine_from_text(text)


@pytest.mark.parametrize("name", list(MACHINES))
@pytest.mark.parametrize("n", [5, 80])  # below and above the hexapod's compiled-kernel batch size
def test_explicit_params_equal_with_params_to_the_bit(name, n):
    m = MACHINES[name]
    rho = _perturbed_params(m, seed=n)
    other = m.with_params(rho)
    x = _poses(m, n, seed=1)
    np.testing.assert_array_equal(m.ik(x, rho), other.ik(x))
    for a, b in zip(m.ik_and_jacobians(x, rho), other.ik_and_jacobians(x)):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(m.actuator_jacobians(x, rho), other.actuator_jacobians(x)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(m.actuator_pose_jacobian(x, rho), other.actuator_pose_jacobian(x))
    np.testing.assert_array_equal(m.assembly_signs(x, rho), other.assembly_signs(x))
    q = other.ik(x)
    a, b = m.fk(q, x, rho), other.fk(q, x)
    for field in ("poses", "converged", "iterations", "residual", "same_branch"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    np.testing.assert_array_equal(m.fk_precise(q, x, rho).poses, other.fk_precise(q, x).poses)
    fa, fb = m.frame(x, rho), other.frame(x)
    np.testing.assert_array_equal(fa.p, fb.p)
    np.testing.assert_array_equal(fa.R, fb.R)
    # and the default is the machine's own parameters
    np.testing.assert_array_equal(m.ik(x), m.ik(x, m.params))


@pytest.mark.parametrize("name", list(MACHINES))
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_frame_jacobian_matches_finite_differences(name, seed):
    """T = ∂(δp, δω)/∂x: central differences of (p(x), log(R(x) R(x₀)ᵀ)) at x₀. Error model:
    a coordinate in mm moves p 1:1 (slope 1) and is linear (scale: the box); an angle turns
    R at unit rate (slope 1), the log map and the Euler rates vary over 1 rad (scale 1)."""
    m = MACHINES[name]
    x0 = _poses(m, 1, seed)
    f0 = m.frame(x0)
    T, T_rho = m.frame_jacobians(x0)
    assert T.shape == (1, 6, m.n_dof) and T_rho is None

    def twist(x):
        f = m.frame(x)
        return np.concatenate([f.p, _rotvec(f.R @ np.swapaxes(f0.R, 1, 2))], axis=1)

    ang = np.array(m.pose_is_angle, dtype=bool)
    box = m.workspace_box()
    assert_jacobian_matches_fd(twist, x0, T, scale=np.where(ang, 1.0, box[:, 1] - box[:, 0]), slope=1.0,
                               magnitude=np.max(np.abs(f0.p)) + np.pi, names=m.pose_names)


@pytest.mark.parametrize("name", list(MACHINES))
def test_pose_jacobian_from_twist_is_the_product_with_T(name):
    m = MACHINES[name]
    x = _poses(m, 20, seed=3)
    rng = np.random.default_rng(4)
    J = rng.normal(size=(20, 4, 6))
    T, _ = m.frame_jacobians(x)
    got = m.pose_jacobian_from_twist(J, x)
    exact = J @ T
    np.testing.assert_allclose(got, exact, rtol=0, atol=8 * np.finfo(float).eps * np.abs(J).max() * np.abs(T).max())


@pytest.mark.parametrize("name", list(MACHINES))
def test_poses_from_frame_inverts_frame(name):
    m = MACHINES[name]
    x = _poses(m, 50, seed=5)
    back = m.poses_from_frame(m.frame(x))
    np.testing.assert_allclose(back, x, rtol=0, atol=8 * np.finfo(float).eps * (1 + np.abs(x).max()))


def test_frame_moved_by_a_twist_is_the_base_frame_rotation():
    """Frame.moved: p + δp and exp([δω]×) R (conventions: δω in the base frame)."""
    f = Frame.from_poses(np.array([[1.0, 2.0, 3.0, 0.1, -0.2, 0.3]]))
    w = np.array([0.01, -0.02, 0.03])
    g = f.moved(np.r_[0.5, 0.0, -0.5, w])
    np.testing.assert_array_equal(g.p, f.p + [[0.5, 0.0, -0.5]])
    np.testing.assert_allclose(g.R, rotation_vector_to_matrix(w[None]) @ f.R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(f.point([1.0, 0.0, 0.0]), f.p + f.R[:, :, 0], rtol=0, atol=1e-15)


# -- the shared FK solver ---------------------------------------------------------------


@pytest.mark.parametrize("name", ["stewart-prototype", "stewart-prototype-real"])
def test_shared_solver_agrees_with_the_hexapods_compiled_newton(name):
    """The compiled SO(3) Newton and the generic Gauss–Newton on (x, y, z, a, b, c) find the
    same pose: both converge to the tolerance of their step test (1e-11 relative for the shared
    solver; the compiled one to 1e-9 mm of leg length, polished to rounding by fk_precise)."""
    m = MACHINES[name]
    x = _poses(m, 200, seed=6)
    q = m.ik(x)
    ours = solve_fk(m, q)
    theirs = m.fk_precise(q)
    assert ours.ok.all() and theirs.ok.all()
    # a converged pose reproduces the readings: the pose error is at most cond(A) × 1e-9 mm
    np.testing.assert_allclose(ours.poses, theirs.poses, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ours.poses, x, rtol=0, atol=1e-7)
    assert np.max(ours.residual) <= 1e-9


@pytest.mark.parametrize("name", ["planar-2dof-3act", "planar-3dof-4act"])
def test_planar_fk_is_the_shared_solver(name):
    m = MACHINES[name]
    x = _poses(m, 30, seed=7)
    q = m.ik(x)
    a, b = m.fk(q), solve_fk(m, q)
    np.testing.assert_array_equal(a.poses, b.poses)
    assert a.ok.all()
    np.testing.assert_allclose(a.poses, x, rtol=0, atol=1e-9)


def test_shared_solver_flags_another_assembly_mode():
    """The solver's branch check is the mechanism's declared signature at the answer against
    its guess: with a signature sign(x) (a mechanism declaring the plate's side of x = 0 its
    assembly mode), FK of readings at x = +20 from a guess at x = −10 converges (the pose is
    unique) but is flagged as another branch (ok False); from a guess at x = +10 it is not."""
    from dataclasses import dataclass

    from pkmcal.mechanisms.planar import Planar3Dof4Act

    @dataclass(frozen=True, eq=False)
    class SidedPlate(Planar3Dof4Act):
        def assembly_signs(self, poses, params=None):
            return np.sign(self.as_pose_array(poses)[:, :1]).astype(np.int8)

    base = MACHINES["planar-3dof-4act"]
    m = SidedPlate(name="sided", rho=base.rho, home=base.home, workspace=base.workspace)
    x = base.home_pose + np.array([20.0, 5.0, 0.05])
    q = m.ik(x[None])
    flagged = solve_fk(m, q, guess=x - [30.0, 0.0, 0.0])
    assert flagged.converged.all() and flagged.branch_changed.all() and not flagged.ok.any()
    np.testing.assert_allclose(flagged.poses[0], x, rtol=0, atol=1e-9)
    kept = solve_fk(m, q, guess=x - [10.0, 0.0, 0.0])
    assert kept.ok.all()


def test_frame_z_axis_is_the_third_column_of_R():
    """Frame.from_poses' closed-form normal (the indicators' formula) is R e_z to one rounding;
    a frame without one gives R e_z itself."""
    x = _poses(MACHINES["stewart-prototype"], 100, seed=8)
    f = Frame.from_poses(x)
    np.testing.assert_allclose(f.z_axis, f.R[:, :, 2], rtol=0, atol=4 * np.finfo(float).eps)
    g = Frame(p=f.p, R=f.R)
    np.testing.assert_array_equal(g.z_axis, f.R[:, :, 2])
    np.testing.assert_array_equal(f[3:5].z_axis, f.z_axis[3:5])
