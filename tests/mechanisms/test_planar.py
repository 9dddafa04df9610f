"""Planar redundant machines (paper 3 §3) and the planar tool-point sensor: analytic
Jacobians against finite differences, FK round trips, IK continuity, limits, registry."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd, planar_fd_model
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms import builtin_machine
from pkmcal.mechanisms import planar as PL
from pkmcal.sensors.planar_tool import PlanarToolSensor

MACHINES = {"planar-2dof-3act": PL.planar_2dof_3act(), "planar-3dof-4act": PL.planar_3dof_4act()}


def _unit_poses(m, u):
    """Map points of [0, 1]^n into the workspace box."""
    lo, hi = m.workspace[:, 0], m.workspace[:, 1]
    return lo + np.asarray(u) * (hi - lo)


def _perturbed(m, seed, size=0.5):
    rng = np.random.default_rng(seed)
    ang = np.array(m.param_is_angle, dtype=bool)
    return m.with_params(m.params + rng.normal(size=len(m.params)) * size * np.where(ang, 1e-2, 1.0))


unit = st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3)


@pytest.mark.parametrize("name", list(MACHINES))
@settings(max_examples=25, deadline=None)
@given(u=unit, seed=st.integers(0, 2**16))
def test_pose_jacobian_matches_finite_differences(name, u, seed):
    m = _perturbed(MACHINES[name], seed)
    x = _unit_poses(m, u[: m.n_dof])[None]
    pose, _ = planar_fd_model(m, x)
    assert_jacobian_matches_fd(m.ik, x, m.actuator_pose_jacobian(x), **pose, names=m.pose_names)


@pytest.mark.parametrize("name", list(MACHINES))
@settings(max_examples=20, deadline=None)
@given(u=unit, seed=st.integers(0, 2**16))
def test_param_jacobian_matches_finite_differences(name, u, seed):
    m = _perturbed(MACHINES[name], seed)
    x = _unit_poses(m, u[: m.n_dof])[None]
    _, params = planar_fd_model(m, x)
    assert_jacobian_matches_fd(lambda p: m.with_params(p).ik(x), m.params, m.actuator_param_jacobian(x),
                               **params, names=m.param_names)


@pytest.mark.parametrize("name", list(MACHINES))
@settings(max_examples=25, deadline=None)
@given(u=unit, du=unit, seed=st.integers(0, 2**16))
def test_fk_round_trip_from_a_nearby_guess(name, u, du, seed):
    m = _perturbed(MACHINES[name], seed)
    x = _unit_poses(m, u[: m.n_dof])[None]
    step = (np.asarray(du[: m.n_dof]) - 0.5) * np.array([20.0, 20.0, 0.1])[: m.n_dof]
    fk = m.fk(m.ik(x), guess=x[0] + step)
    assert fk.all_converged
    # FK stops once its Gauss–Newton step is ≤ FK_TOL·(1 + |x|); converging at a rate ≤ 1/2
    # the remaining error is below that last step: 2× it is the bound
    np.testing.assert_allclose(fk.poses, x, rtol=0, atol=2 * PL.FK_TOL * (1 + np.abs(x).max()))


@pytest.mark.parametrize("name", list(MACHINES))
def test_fk_from_home_never_reports_a_wrong_pose(name):
    m = MACHINES[name]
    x = m.sample_poses(400, np.random.default_rng(5))
    fk = m.fk(m.ik(x))
    wrong = np.max(np.abs(fk.poses - x), axis=1) > 1e-6
    assert not np.any(wrong & fk.converged)
    assert fk.converged.mean() > 0.95


@pytest.mark.parametrize("name", list(MACHINES))
def test_fk_of_inconsistent_redundant_readings_is_least_squares(name):
    """With l > n the FK minimises ‖q − IK(x)‖: at its answer Γᵀ(q − IK(x)) = 0."""
    m = MACHINES[name]
    rng = np.random.default_rng(2)
    x = m.sample_poses(20, rng)
    q = m.ik(x) + rng.normal(size=(20, m.n_actuators)) * 1e-4
    fk = m.fk(q, guess=x)
    G = m.actuator_pose_jacobian(fk.poses)
    grad = np.einsum("nli,nl->ni", G, q - m.ik(fk.poses))
    grad0 = np.einsum("nli,nl->ni", m.actuator_pose_jacobian(x), q - m.ik(x))
    assert fk.all_converged
    assert np.abs(grad).max() < 1e-3 * np.abs(grad0).max()


@pytest.mark.parametrize("name", list(MACHINES))
def test_ik_is_continuous_over_the_workspace(name):
    """No 2π branch jumps: neighbouring poses give neighbouring readings."""
    m = MACHINES[name]
    x = m.sample_poses(2000, np.random.default_rng(3))
    d = np.zeros(m.n_dof)
    d[0] = 0.01
    jump = np.abs(m.ik(x + d) - m.ik(x)).max()
    assert jump < 0.01 * np.abs(m.actuator_pose_jacobian(x)).max() * 1.5
    assert m.check_limits(x).ok.all()


def test_limits_flag_unreachable_poses():
    m = MACHINES["planar-2dof-3act"]
    rep = m.check_limits(np.array([[0.0, 205.0], [0.0, 600.0]]))
    assert rep.ok.tolist() == [True, False]
    assert "workspace" in rep.reasons(1)
    m3 = MACHINES["planar-3dof-4act"]
    rep = m3.check_limits(np.array([[0.0, 230.0, 0.0], [0.0, 420.0, 0.0]]))
    assert rep.ok.tolist() == [True, False] and "reach" in rep.reasons(1)


def test_registry_names_and_parameters():
    for name, m in MACHINES.items():
        assert builtin_machine(name) == m
        assert len(set(m.param_names)) == len(m.param_names)
        assert m.actuator_param_jacobian(m.home).shape == (1, m.n_actuators, len(m.param_names))
    m = MACHINES["planar-2dof-3act"]
    assert set(PL.P2_PAPER_FREE) <= set(m.param_names)
    assert set(PL.P3_PAPER_FREE) <= set(MACHINES["planar-3dof-4act"].param_names)
    assert m.p("l11") == 280.0 and m.p("B3.y") == 420.0 and m.p("D2") == 215.0
    assert MACHINES["planar-3dof-4act"].p("L3") == 230.0
    moved = m.with_deltas({"l11": 0.089})
    assert moved.p("l11") == pytest.approx(280.089) and moved != m
    with pytest.raises(PkmcalError, match="no parameter 'l99'"):
        m.param_index(["l99"])
    with pytest.raises(PkmcalError, match="2 coordinates"):
        m.ik(np.zeros((1, 3)))


def test_encoder_offset_sign_convention():
    """reading = true actuator position + dq: raising dq raises the reading by dq."""
    for m in MACHINES.values():
        shifted = m.with_deltas({"dq1": 0.01})
        dq = shifted.ik(m.home) - m.ik(m.home)
        np.testing.assert_allclose(dq, [[0.01] + [0.0] * (m.n_actuators - 1)], atol=1e-12)


def test_2dof_matches_closed_form_geometry():
    """Independent check of chain 1: elbow A = B + l11 e(θ) is at l12 from the plate joint."""
    m = MACHINES["planar-2dof-3act"]
    x = m.sample_poses(50, np.random.default_rng(4))
    th = m.ik(x)
    for i in range(3):
        B = np.array([m.p(f"B{i + 1}.x"), m.p(f"B{i + 1}.y")])
        C = x + m.p(f"D{i + 1}") * np.array([np.cos(PL.P2_BETA[i]), np.sin(PL.P2_BETA[i])])
        A = B + m.p(f"l{i + 1}1") * np.stack([np.cos(th[:, i]), np.sin(th[:, i])], axis=1)
        np.testing.assert_allclose(np.linalg.norm(C - A, axis=1), m.p(f"l{i + 1}2"), atol=1e-9)


def test_3dof_matches_closed_form_geometry():
    m = _perturbed(MACHINES["planar-3dof-4act"], 7)
    x = m.sample_poses(50, np.random.default_rng(4))
    s = m.ik(x) - m.params[9:13]
    L3 = m.p("L3")
    e = np.stack([np.cos(x[:, 2]), np.sin(x[:, 2])], axis=1)
    C = [x[:, :2] - 0.5 * L3 * e, x[:, :2] + 0.5 * L3 * e]
    for j, (way, leg) in enumerate([(0, "rho11"), (0, "rho12"), (1, "rho21"), (1, "rho22")]):
        a = m.p(f"alpha{way + 1}")
        A = np.array([0.0, m.p(f"y{way + 1}")]) + s[:, j:j + 1] * np.array([np.cos(a), np.sin(a)])
        np.testing.assert_allclose(np.linalg.norm(C[way] - A, axis=1), m.p(leg), atol=1e-9)


# -- sensor ------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 3])
@settings(max_examples=20, deadline=None)
@given(u=unit, v=st.lists(st.floats(-1.0, 1.0), min_size=5, max_size=5))
def test_tool_sensor_jacobians_match_finite_differences(n, u, v):
    m = MACHINES["planar-2dof-3act" if n == 2 else "planar-3dof-4act"]
    s = PlanarToolSensor(n_pose=n, target=np.array(v[:2]) * 20, world=np.array([v[2] * 50, v[3] * 50, v[4] * 0.5]))
    x = _unit_poses(m, u[:n])[None]
    # readings p_w + R(c_w)(x + R(φ) t): linear in every mm coordinate (ℓ = the 1 m the setup
    # spans sets only the step), the angles φ and c_w turn levers (ℓ = 1 rad)
    pose_scale = np.where(m.pose_is_angle, 1.0, 1000.0)
    # the pose Jacobian is the sensor's twist Jacobian composed with the machine's T
    H = m.pose_jacobian_from_twist(s.frame_jacobian(m.frame(x)), x)
    assert_jacobian_matches_fd(lambda z: s.predict(m.frame(z)), x, H, scale=pose_scale, names=m.pose_names)
    assert_jacobian_matches_fd(lambda p: s.with_params(p).predict(m.frame(x)), s.params, s.param_jacobian(m.frame(x)),
                               scale=np.where(s.param_is_angle, 1.0, 1000.0), names=s.param_names)
    Jf = m.pose_jacobian_from_twist(s.tool_frame_jacobian(m.frame(x)), x)
    assert_jacobian_matches_fd(lambda z: s.tool_point(m.frame(z)), x, Jf, scale=pose_scale, names=m.pose_names)
    # explicit sensor parameters equal with_params' to the bit
    theta = s.params + 0.25
    for f in ("predict", "frame_jacobian", "param_jacobian", "tool_point", "tool_frame_jacobian"):
        np.testing.assert_array_equal(getattr(s, f)(m.frame(x), theta), getattr(s.with_params(theta), f)(m.frame(x)))
    back = m.poses_from_frame(s.frame_for_readings(s.predict(m.frame(x)), m.frame(x).R))
    np.testing.assert_allclose(back, x, atol=1e-9)


def test_tool_sensor_rejects_bad_input():
    with pytest.raises(PkmcalError, match="n_pose"):
        PlanarToolSensor(n_pose=6)
    with pytest.raises(PkmcalError, match="no parameter"):
        PlanarToolSensor(n_pose=2, free=("target.z",))
    assert "not a planar machine" in PlanarToolSensor(n_pose=2).works_with(builtin_machine("stewart-prototype"))
    assert "3 pose coordinates" in PlanarToolSensor(n_pose=3).works_with(MACHINES["planar-2dof-3act"])
    assert PlanarToolSensor(n_pose=3).works_with(MACHINES["planar-3dof-4act"]) is None


def test_angle_parameters_and_summary():
    m2, m3 = MACHINES["planar-2dof-3act"], MACHINES["planar-3dof-4act"]
    assert [n for n, a in zip(m2.param_names, m2.param_is_angle) if a] == ["dq1", "dq2", "dq3"]
    assert [n for n, a in zip(m3.param_names, m3.param_is_angle) if a] == ["alpha1", "alpha2"]
    assert "18 kinematic parameters" in m2.summary() and "l11=280" in m2.summary()
    assert "phi -25..25" in m3.summary()


def test_actuator_is_angle_flags():
    from pkmcal.mechanisms.library import builtin_machine

    assert builtin_machine("planar-2dof-3act").actuator_is_angle == (True, True, True)
    assert builtin_machine("planar-3dof-4act").actuator_is_angle == (False,) * 4
    assert builtin_machine("stewart-prototype").actuator_is_angle == (False,) * 6
