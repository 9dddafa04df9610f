"""pkmcal.conventions against independent references: scipy's Rotation, finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from pkmcal.conventions import (
    EULER_RANGES,
    euler_pose_jacobian,
    euler_rate_matrix,
    euler_to_matrix,
    matrix_to_euler,
    poses_from_file_units,
    poses_to_file_units,
    rotation_error,
    rotation_vector_to_matrix,
    wrap_angle,
)

angle = st.floats(-np.pi, np.pi, allow_nan=False)
angles = arrays(float, (3,), elements=angle)
# pitch away from ±90° (gimbal lock), where the Euler angles are not unique
regular_angles = st.tuples(angle, st.floats(-1.5, 1.5), angle).map(np.array)


def _elementary(axis: int, t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


@settings(max_examples=300, deadline=None)
@given(angles)
def test_euler_to_matrix_is_scipy_extrinsic_xyz(abc):
    ref = Rotation.from_euler("xyz", abc).as_matrix()
    np.testing.assert_allclose(euler_to_matrix(abc), ref, atol=1e-14)


@settings(max_examples=100, deadline=None)
@given(angles)
def test_euler_to_matrix_is_rz_ry_rx_product(abc):
    a, b, c = abc
    ref = _elementary(2, c) @ _elementary(1, b) @ _elementary(0, a)
    np.testing.assert_allclose(euler_to_matrix(abc), ref, atol=1e-14)


def test_euler_to_matrix_broadcasts():
    abc = np.random.default_rng(1).uniform(-3, 3, (4, 5, 3))
    R = euler_to_matrix(abc)
    assert R.shape == (4, 5, 3, 3)
    np.testing.assert_allclose(R[2, 3], euler_to_matrix(abc[2, 3]), atol=0)


@settings(max_examples=300, deadline=None)
@given(regular_angles)
def test_matrix_to_euler_round_trip(abc):
    back = matrix_to_euler(euler_to_matrix(abc))
    wrapped = (back - abc + np.pi) % (2 * np.pi) - np.pi  # a, c = ±π are the same angle
    np.testing.assert_allclose(wrapped, 0.0, atol=1e-9)
    assert -np.pi / 2 <= back[1] <= np.pi / 2
    # a, c lie in [−π, π] (both ends occur: scipy's atan2 returns −π for a −0.0 argument)
    assert np.all(np.abs(back[[0, 2]]) <= np.pi)


@settings(max_examples=100, deadline=None)
@given(angles)
def test_matrix_to_euler_gives_the_same_rotation_anywhere(abc):
    # near gimbal lock the angles differ but the rotation must not
    R = euler_to_matrix(abc)
    assert rotation_error(euler_to_matrix(matrix_to_euler(R)), R) < 1e-7


@settings(max_examples=200, deadline=None)
@given(regular_angles, arrays(float, (3,), elements=st.floats(-1, 1)).filter(lambda r: np.linalg.norm(r) > 1e-3))
def test_euler_rate_matrix_against_finite_differences(abc, rate):
    # along abc(t) = abc + t·d (d = the unit rate), dR/dt = [ω]× R with ω = E(abc)·d,
    # against central differences of R(t) at t = 0
    d = rate / np.linalg.norm(rate)
    w = euler_rate_matrix(abc) @ d
    dR = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]) @ euler_to_matrix(abc)
    # R(t) = Rz(c(t)) Ry(b(t)) Rx(a(t)): the n-th derivative of each factor has norm ≤ |d_i|^n,
    # so |dR/dt| ≤ s and |d³R/dt³| ≤ s³ with s = Σ|d_i|: slope s, time scale 1/s (one radian)
    s = np.abs(d).sum()
    assert_jacobian_matches_fd(lambda t: euler_to_matrix(abc + t[0] * d), np.zeros(1), dR[..., None],
                               scale=1.0 / s, slope=s)


def test_euler_pose_jacobian_is_twist_jacobian_times_rate_matrix():
    # the written-out product against diag(I, E(a, b, c)) formed by euler_rate_matrix
    rng = np.random.default_rng(7)
    poses = np.concatenate([rng.normal(size=(50, 3)), rng.uniform(-np.pi, np.pi, size=(50, 3))], axis=1)
    Jt = rng.normal(size=(50, 4, 6))
    expected = np.concatenate([Jt[:, :, :3], Jt[:, :, 3:] @ euler_rate_matrix(poses[:, 3:6])], axis=2)
    np.testing.assert_allclose(euler_pose_jacobian(Jt, poses), expected, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(arrays(float, (3,), elements=st.floats(-3, 3)))
def test_rotation_vector_to_matrix_is_exp(w):
    th = np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    # matrix exponential by scaling and squaring of a Taylor series, independent of Rodrigues
    s = 2 ** 10
    A, term, E = K / s, np.eye(3), np.eye(3)
    for k in range(1, 20):
        term = term @ A / k
        E = E + term
    for _ in range(10):
        E = E @ E
    np.testing.assert_allclose(rotation_vector_to_matrix(w), E, atol=1e-10)
    if th < np.pi:
        assert rotation_error(rotation_vector_to_matrix(w), np.eye(3)) == pytest.approx(th, abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(angles, st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).map(np.array),
       st.floats(1e-9, np.pi - 1e-6))
def test_rotation_error_is_the_angle_between(abc, axis, angle_):
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 0.0, 1.0])
    axis = axis / np.linalg.norm(axis)
    R_b = euler_to_matrix(abc)
    R_a = Rotation.from_rotvec(angle_ * axis).as_matrix() @ R_b
    assert rotation_error(R_a, R_b) == pytest.approx(angle_, rel=1e-7, abs=1e-12)
    assert rotation_error(R_b, R_a) == pytest.approx(angle_, rel=1e-7, abs=1e-12)


def test_rotation_error_small_angles_are_accurate():
    # arccos would lose everything below ~1e-8 rad; the skew-part formula must not
    for t in (1e-12, 1e-10, 1e-8):
        R = Rotation.from_rotvec([0.0, t, 0.0]).as_matrix()
        assert rotation_error(R, np.eye(3)) == pytest.approx(t, rel=1e-6)


def test_file_units_round_trip():
    poses = np.array([[1.0, 2.0, 3.0, 10.0, -20.0, 180.0]])
    internal = poses_from_file_units(poses)
    np.testing.assert_allclose(internal[0, 3:], np.deg2rad([10.0, -20.0, 180.0]))
    np.testing.assert_allclose(internal[0, :3], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(poses_to_file_units(internal), poses)
    assert poses[0, 3] == 10.0  # input not modified


@settings(max_examples=200, deadline=None)
@given(arrays(float, (4,), elements=st.floats(-1, 1)).filter(lambda q: np.linalg.norm(q) > 1e-3))
def test_matrix_to_euler_is_scipy_extrinsic_xyz(quat):
    # the closed form against scipy's own matrix → Euler conversion, on random rotations
    R = Rotation.from_quat(quat / np.linalg.norm(quat)).as_matrix()
    if abs(R[2, 0]) > 1 - 1e-6:
        return  # near gimbal lock a and c are not unique (covered by the rotation test above)
    ref = Rotation.from_matrix(R).as_euler("xyz")
    back = matrix_to_euler(R)
    np.testing.assert_allclose((back - ref + np.pi) % (2 * np.pi) - np.pi, 0.0, atol=1e-10)
    assert matrix_to_euler(np.stack([R, R])).shape == (2, 3)


@pytest.mark.parametrize("a", [-np.pi, np.pi, 0.5])
@pytest.mark.parametrize("c", [-np.pi, np.pi, -2.0])
@pytest.mark.parametrize("b", [0.0, -0.4, 1.2])
def test_matrix_to_euler_range_is_half_open_at_pi(a, b, c):
    # documented range: a, c in (-π, π]; ±π (as computed, R₂₁ = ±1.2e-16) come back as +π
    R = euler_to_matrix(np.array([a, b, c]))
    abc = matrix_to_euler(R)
    assert -np.pi < abc[0] <= np.pi and -np.pi < abc[2] <= np.pi and abs(abc[1]) <= np.pi / 2
    np.testing.assert_allclose(euler_to_matrix(abc), R, atol=1e-14)
    expected = [np.pi if abs(a) == np.pi else a, b, np.pi if abs(c) == np.pi else c]
    np.testing.assert_allclose(abc, expected, atol=1e-12)


def test_matrix_to_euler_exact_half_turns_with_signed_zeros():
    # atan2(−0.0, −1) = −π: exact matrices with negative zeros must still give +π
    Rx = np.array([[1.0, -0.0, 0.0], [-0.0, -1.0, -0.0], [0.0, -0.0, -1.0]])
    Rz = np.array([[-1.0, -0.0, 0.0], [-0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(matrix_to_euler(np.stack([Rx, Rz])), [[np.pi, 0.0, 0.0], [0.0, 0.0, np.pi]])


@settings(max_examples=200, deadline=None)
@given(angles)
def test_matrix_to_euler_range_everywhere(abc):
    out = matrix_to_euler(euler_to_matrix(abc))
    assert np.all(out[[0, 2]] > -np.pi) and np.all(out[[0, 2]] <= np.pi) and abs(out[1]) <= np.pi / 2


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e4, 1e4, allow_nan=False), st.integers(-3, 3))
def test_wrap_angle_is_the_same_rotation_within_minus_pi_to_pi(x, turns):
    """Whole turns only: the result is in (-π, π], differs from x by a multiple of 2π (to the
    rounding of |x|), and an angle already inside is returned bit for bit."""
    w = float(wrap_angle(x))
    assert -np.pi < w <= np.pi
    k = (x - w) / (2 * np.pi)
    assert abs(k - round(k)) <= 8 * np.finfo(float).eps * max(1.0, abs(x)) / (2 * np.pi)
    inside = float(wrap_angle(np.pi))
    assert inside == np.pi and float(wrap_angle(-np.pi)) == np.pi      # the half-open end
    y = float(np.clip(x, -3.14, 3.14))
    assert float(wrap_angle(y)) == y and float(wrap_angle(y + 2 * np.pi * turns)) == pytest.approx(y, abs=1e-12)


def test_euler_ranges_are_those_matrix_to_euler_returns():
    """The planning box's bounds are the range of matrix_to_euler (a, c: ±π; b: ±π/2)."""
    rng = np.random.default_rng(0)
    abc = matrix_to_euler(Rotation.random(2000, random_state=rng).as_matrix())
    for k, (lo, hi) in enumerate(EULER_RANGES):
        assert lo <= abc[:, k].min() and abc[:, k].max() <= hi
        assert abc[:, k].min() < lo + 0.1 and abc[:, k].max() > hi - 0.1     # and they are reached


@pytest.mark.parametrize("mm, text", [(4.92113, "4.921 mm"), (0.01333, "13.33 µm"), (0.1, "0.1000 mm"),
                                      (0.09999, "99.99 µm"), (123.456, "123.5 mm"), (9.99996, "10.00 mm"),
                                      (-0.0005, "-0.5000 µm")])
def test_lengths_for_people(mm, text):
    """Issue 27 item 4: mm with 4 significant digits, µm below 0.1 mm (hand-written values)."""
    from pkmcal.conventions import length_text

    assert length_text(mm) == text


@pytest.mark.parametrize("deg, text", [(1.5573, "1.557°"), (0.015628, "0.01563°"), (0.0099999, "36.00″"),
                                       (0.0025, "9.000″")])
def test_angles_for_people(deg, text):
    """Degrees with 4 significant digits, arcseconds only below 0.01°."""
    from pkmcal.conventions import angle_text

    assert angle_text(np.deg2rad(deg)) == text


def test_several_values_for_people():
    """No NumPy repr in user output (issue 27 item 4: '[305. 305. 305. 305. 305. 305.]')."""
    from pkmcal.conventions import values_text

    assert values_text([305.0] * 6, "mm") == "305 mm (all 6)"
    assert values_text([305.0, 305.25, 304.9], "mm") == "305, 305.25, 304.9 mm"
    assert values_text([5.0], "mm/rev") == "5 mm/rev"
