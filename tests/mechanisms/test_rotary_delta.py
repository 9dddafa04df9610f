"""The rotary delta (pkmcal.mechanisms.rotary_delta) against independent constructions:
the elbow found by bisection on the upper arm's circle (no closed form), the symmetric
machine's equal motor angles on the axis, IK/FK round trips on machines with tilted and
yawed axes, zero offsets and tool offsets, and central finite differences of both
Jacobians."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.rotary_delta import PARAM_NAMES, RotaryDelta, symmetric_rotary_delta


def _floats(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def machines(draw):
    """Pickers: effective radius 100–200 mm, upper arms 300–400 mm, forearms 2–2.5 upper
    arms, axes within 2° of tangent and level, zero offsets within 3°, tool offsets ≤ 10 mm."""
    r, a = draw(_floats(100, 200)), draw(_floats(300, 400))
    b = a * draw(_floats(2.0, 2.5))
    rho = np.zeros(len(PARAM_NAMES))
    for i, ang in enumerate((90.0, 210.0, 330.0)):
        rho[8 * i:8 * i + 8] = [np.deg2rad(ang + draw(_floats(-3, 3))), r + draw(_floats(-2, 2)), draw(_floats(-2, 2)),
                                a + draw(_floats(-2, 2)), b + draw(_floats(-2, 2)), np.deg2rad(draw(_floats(-3, 3))),
                                np.deg2rad(draw(_floats(-2, 2))), np.deg2rad(draw(_floats(-2, 2)))]
    rho[-3:] = draw(st.tuples(*[_floats(-10, 10)] * 3))
    # the effector 0.75–0.95 forearms below the shoulders: every arm reaches, elbow out,
    # away from both singularities (|S − q| between b − a and a + b with margin)
    return RotaryDelta(name="drawn", rho=rho, workspace_radius=0.4 * a, z_range=(-0.95 * b, -0.75 * b))


def _poses(m: RotaryDelta, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rad = m.workspace_radius * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    return np.stack([rad * np.cos(phi), rad * np.sin(phi), rng.uniform(*m.z_range, n)], axis=1)


def _elbows_by_bisection(m: RotaryDelta, p: np.ndarray) -> np.ndarray:
    """Elbows (N, 3, 3): on each upper arm's circle about its motor axis, the outward point
    at the forearm's length from the effector joint, found by bisection on the angle from
    the outward horizontal over (−90°, 90°): the effector is far below and inside, so the
    distance falls monotonically from the arm pointing up (> b) to pointing down (< b)."""
    rho = m.params
    q = p - rho[-3:]
    out = np.empty((len(p), 3, 3))
    for i in range(3):
        th, r, h, a, b, _, psi, chi = rho[8 * i:8 * i + 8]
        S = np.array([r * np.cos(th), r * np.sin(th), h])
        Rz = np.array([[np.cos(th + psi), -np.sin(th + psi), 0], [np.sin(th + psi), np.cos(th + psi), 0], [0, 0, 1]])
        Rx = np.array([[1, 0, 0], [0, np.cos(chi), -np.sin(chi)], [0, np.sin(chi), np.cos(chi)]])
        Q = Rz @ Rx
        v1, v2 = Q[:, 0], -Q[:, 2]
        lo, hi = np.full(len(p), -np.pi / 2), np.full(len(p), np.pi / 2)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            E = S + a * (np.cos(mid)[:, None] * v1 + np.sin(mid)[:, None] * v2)
            too_far = np.linalg.norm(E - q, axis=1) > b
            lo, hi = np.where(too_far, mid, lo), np.where(too_far, hi, mid)
        out[:, i] = S + a * (np.cos(hi)[:, None] * v1 + np.sin(hi)[:, None] * v2)
    return out


def test_symmetric_machine_on_its_axis_has_equal_angles_from_the_triangle():
    m = symmetric_rotary_delta("pnp", radius=150.0, upper=350.0, forearm=800.0)
    lam = m.ik([0.0, 0.0, -700.0])[0]
    assert np.ptp(lam) < 1e-12
    # on the axis each arm is a planar two-link problem: shoulder (150, 0), wrist (0, −700)
    phi = lam[0]
    elbow = np.array([150.0 + 350.0 * np.cos(phi), -350.0 * np.sin(phi)])
    assert np.hypot(*(elbow - [0.0, -700.0])) == pytest.approx(800.0, abs=1e-9)
    assert elbow[0] > 150.0        # elbow out


@settings(max_examples=30, deadline=None)
@given(m=machines(), seed=st.integers(0, 2**31))
def test_ik_agrees_with_the_elbows_found_by_bisection(m, seed):
    p = _poses(m, 10, seed)
    np.testing.assert_allclose(m.elbows(m.ik(p)), _elbows_by_bisection(m, p), rtol=0, atol=1e-8)


@settings(max_examples=40, deadline=None)
@given(m=machines(), seed=st.integers(0, 2**31))
def test_fk_inverts_ik(m, seed):
    p = _poses(m, 20, seed)
    fk = m.fk(m.ik(p))
    assert fk.ok.all()
    np.testing.assert_allclose(fk.poses, p, rtol=0, atol=1e-9)
    assert m.same_branch(fk.poses, m.home_pose).all()


@settings(max_examples=25, deadline=None)
@given(m=machines(), seed=st.integers(0, 2**31))
def test_jacobians_match_central_differences(m, seed):
    p = _poses(m, 6, seed)
    lam, A, B = m.ik_and_jacobians(p)
    # lengths vary on the scale of the shortest link's distance from the singularity
    # (forearm in line with the elbow's motion): G/|w| ≥ a·sin of that angle; angles on
    # that scale over the lever (radius + upper + forearm)
    rho = m.params
    a = float(np.min(rho[3:24:8]))
    lever = float(np.max(rho[1:24:8]) + np.max(rho[3:24:8]) + np.max(rho[4:24:8]))
    scale_mm = 0.25 * a
    assert_jacobian_matches_fd(m.ik, p, A, scale=scale_mm, names=m.pose_names)
    is_angle = np.array(m.param_is_angle)
    assert_jacobian_matches_fd(lambda r: m.with_params(r).ik(p), rho, B,
                               scale=np.where(is_angle, scale_mm / lever, scale_mm), names=PARAM_NAMES)


def test_zero_offsets_shift_the_readings():
    m = symmetric_rotary_delta("pnp", 150.0, 350.0, 800.0)
    rho = m.params
    rho[PARAM_NAMES.index("zero_b")] = np.deg2rad(1.5)
    p = np.array([[20.0, -30.0, -750.0]])
    np.testing.assert_allclose(m.with_params(rho).ik(p) - m.ik(p), [[0.0, -np.deg2rad(1.5), 0.0]], atol=1e-14)


def test_limits_name_what_is_violated():
    m = symmetric_rotary_delta("pnp", 150.0, 350.0, 800.0, workspace_radius=300.0, z_range=(-900.0, -500.0))
    report = m.check_limits(np.array([[0.0, 0.0, -700.0], [350.0, 0.0, -700.0], [0.0, 0.0, -950.0],
                                      [0.0, 0.0, -2000.0], [0.0, 700.0, -500.0]]))
    assert report.verdicts()[0] == "ok"
    assert "workspace" in report.reasons(1)
    assert "workspace" in report.reasons(2)
    assert "reach" in report.reasons(3)
    assert "joint_angle" in report.reasons(4)


@pytest.mark.parametrize("change, message", [
    ({"upper_a": -1.0}, "upper_a must be positive"),
    ({"forearm_b": 100.0}, "forearm_b must be longer than half"),
    ({"axis_tilt_c": np.deg2rad(60)}, "axis_tilt_c must be within"),
])
def test_impossible_geometry_is_refused_naming_the_parameter(change, message):
    rho = symmetric_rotary_delta("pnp", 150.0, 350.0, 800.0).params
    for k, v in change.items():
        rho[PARAM_NAMES.index(k)] = v
    with pytest.raises(PkmcalError, match=message):
        RotaryDelta(name="bad", rho=rho)
