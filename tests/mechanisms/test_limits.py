"""Hexapod.check_limits: every limit triggered by a constructed pose, each margin checked
against an independent computation; segment_distance (NumPy, and the compiled kernel the
limit check uses) against brute-force sampling; the compiled limit kernel against the NumPy
formulas it replaces, and its singularity certificate against the SVD."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.optimize import brentq, minimize_scalar

from pkmcal.mechanisms import _hexapod_kernels as kernels
from pkmcal.mechanisms import builtin_machine, symmetric_hexapod
from pkmcal.mechanisms.base import LimitReport
from pkmcal.mechanisms.hexapod import EXACT_VERDICT_TOL, LIMIT_NAMES, LIMITS_COMPILED_FROM, segment_distance

M = builtin_machine("stewart-prototype")
HOME = M.home_pose
DEG = np.pi / 180.0


def pose(x=0.0, y=0.0, z=None, a=0.0, b=0.0, c=0.0):
    return np.array([x, y, HOME[2] if z is None else z, a, b, c])


def explicit_legs(machine, p):
    """Leg vectors by hand: p + Rz(c) Ry(b) Rx(a) a_i − b_i, elementary rotations spelled out."""
    x, y, z, a, b, c = p
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx
    return np.array([x, y, z]) + machine.platform @ R.T - machine.base, R


# -- stroke ----------------------------------------------------------------------------------


def test_stroke_by_hand_computed_leg_lengths():
    # Level platform at (0, 0, z): L_i = sqrt(h_i² + z²), h_i = horizontal |a_i − b_i|
    # (planar base and platform). Solve for the z at which the longest leg reaches the end
    # of the stroke, L0 + 50 mm.
    h = np.linalg.norm((M.platform - M.base)[:, :2], axis=1)
    z_top = np.sqrt((M.offset + 50.0) ** 2 - h**2).min()
    z_bottom = np.sqrt((M.offset + 0.0) ** 2 - h**2).max()
    poses = np.array([pose(z=z_top - 0.01), pose(z=z_top + 0.01), pose(z=z_bottom + 0.01), pose(z=z_bottom - 0.01)])
    rep = M.check_limits(poses)
    assert rep.violations["stroke"].tolist() == [False, True, False, True]
    lam = np.sqrt(h**2 + poses[:, 2:3] ** 2) - M.offset
    expected = np.minimum(lam, 50.0 - lam).min(axis=1)
    np.testing.assert_allclose(rep.margins["stroke"], expected, atol=1e-9)
    # only the stroke is violated at the top (level, centred: tilts and singularity fine)
    assert rep.reasons(1) == ["stroke"]
    # margin shrinks the stroke: 0.01 mm inside is violated with a 0.02 mm safety margin
    assert M.check_limits(poses[:1], margin=0.02).violations["stroke"][0]


# -- joint tilts ------------------------------------------------------------------------------


def _tilts(machine, p):
    legs, R = explicit_legs(machine, p)
    # U joint: angle between the leg and the base z axis, atan2(horizontal, vertical)
    u_tilt = np.arctan2(np.linalg.norm(legs[:, :2], axis=1), legs[:, 2])
    # S joint: angle between the leg and the platform z axis R e_z, atan2(|l × n|, l·n)
    n = R[:, 2]
    s_tilt = np.arctan2(np.linalg.norm(np.cross(legs, n), axis=1), legs @ n)
    return u_tilt, s_tilt


@pytest.mark.parametrize("p", [pose(x=40.0, z=290.0), pose(y=-35.0, a=0.3), pose(x=10.0, b=-0.25, c=0.2),
                               pose(z=330.0, c=0.35)])
def test_tilt_margins_are_the_explicit_angles(p):
    u_tilt, s_tilt = _tilts(M, p)
    rep = M.check_limits(p)
    assert rep.margins["u_joint_tilt"][0] == pytest.approx(45 * DEG - u_tilt.max(), abs=1e-12)
    assert rep.margins["s_joint_tilt"][0] == pytest.approx(29 * DEG - s_tilt.max(), abs=1e-12)
    # the margin option shrinks the angle limits by that many degrees
    rep2 = M.check_limits(p, margin=2.0)
    assert rep2.margins["u_joint_tilt"][0] == pytest.approx(43 * DEG - u_tilt.max(), abs=1e-12)


def test_u_joint_tilt_triggered_alone():
    # U tilt rises with a sideways shift and a low platform. Find the x at which the worst U
    # tilt is exactly 45° with the 'explicit' angle, at a z keeping the legs in stroke.
    m = builtin_machine("symmetric:platform_radius=140,offset=150,stroke=300,s_joint_tilt=off")
    z = 200.0
    x45 = brentq(lambda x: _tilts(m, pose(x=x, z=z))[0].max() - 45 * DEG, 0.0, 400.0)
    rep = m.check_limits(np.array([pose(x=x45 - 0.5, z=z), pose(x=x45 + 0.5, z=z)]))
    assert rep.violations["u_joint_tilt"].tolist() == [False, True]
    assert rep.reasons(1) == ["u_joint_tilt"], rep.margins


def test_s_joint_tilt_triggered_alone():
    # A pure roll tilts the legs relative to the platform axis.
    a29 = brentq(lambda a: _tilts(M, pose(a=a))[1].max() - 29 * DEG, 0.0, 0.6)
    rep = M.check_limits(np.array([pose(a=a29 - 1e-3), pose(a=a29 + 1e-3)]))
    assert rep.violations["s_joint_tilt"].tolist() == [False, True]
    assert rep.reasons(1) == ["s_joint_tilt"], rep.margins


def test_tilt_limits_can_be_disabled():
    m = builtin_machine("symmetric:u_joint_tilt=off,s_joint_tilt=off")
    rep = m.check_limits(pose(a=0.5))
    assert "u_joint_tilt" not in rep.margins and "s_joint_tilt" not in rep.margins


# -- segment distance and leg collision ------------------------------------------------------


def _brute_segment_distance(p1, q1, p2, q2, n=401, zooms=6):
    """min over s of dist(p1 + s(q1 − p1), segment 2), on a grid of s refined ``zooms`` times
    around the best sample. dist(·, segment) is convex (distance to a convex set along a
    line), so the best sample's neighbours bracket the minimum; the inner distance is the
    plain projection onto segment 2, clamped."""
    d2 = q2 - p2
    dd = max(float(d2 @ d2), np.finfo(float).tiny)
    lo, hi = 0.0, 1.0
    for _ in range(zooms):
        s = np.linspace(lo, hi, n)
        x = p1 + s[:, None] * (q1 - p1)
        t = np.clip((x - p2) @ d2 / dd, 0.0, 1.0)
        d = np.linalg.norm(x - p2 - t[:, None] * d2, axis=1)
        i = int(np.argmin(d))
        lo, hi = s[max(i - 1, 0)], s[min(i + 1, n - 1)]
    return float(d.min())


point = arrays(float, (3,), elements=st.floats(-100, 100))


def compiled_segment_distance(p1, q1, p2, q2):
    """The compiled pair distance of the limit kernel, with segment_distance's broadcasting."""
    p1, q1, p2, q2 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (p1, q1, p2, q2)))
    out = np.empty(p1.shape[:-1]).reshape(-1)
    kernels.segment_distances(*(np.ascontiguousarray(v.reshape(-1, 3)) for v in (p1, q1, p2, q2)), out)
    return out.reshape(p1.shape[:-1])


#: Both implementations must pass every segment-distance test.
distances = pytest.mark.parametrize("segment_distance", [segment_distance, compiled_segment_distance],
                                    ids=["numpy", "compiled"])


@distances
@settings(max_examples=150, deadline=None)
@given(point, point, point, point)
def test_segment_distance_against_brute_force(segment_distance, p1, q1, p2, q2):
    if min(np.linalg.norm(q1 - p1), np.linalg.norm(q2 - p2)) < 1e-3:
        q1 = q1 + [1.0, 0.0, 0.0]
        q2 = q2 + [0.0, 1.0, 0.0]
    exact = segment_distance(p1, q1, p2, q2)
    brute = _brute_segment_distance(p1, q1, p2, q2)
    # the sampled distance can only be larger; after 6 zooms the grid spacing is < 1e-9 mm
    assert exact <= brute + 1e-9
    assert brute - exact <= 1e-6


@distances
@settings(max_examples=60, deadline=None)
@given(point, point, arrays(float, (3,), elements=st.floats(-50, 50)), st.floats(-2, 2))
def test_segment_distance_parallel_and_collinear(segment_distance, p1, q1, shift, scale):
    if np.linalg.norm(q1 - p1) < 1e-3:
        q1 = p1 + [0.0, 0.0, 5.0]
    p2 = p1 + shift
    q2 = p2 + scale * (q1 - p1) if abs(scale) > 1e-3 else p2 + (q1 - p1)
    exact = segment_distance(p1, q1, p2, q2)
    brute = _brute_segment_distance(p1, q1, p2, q2)
    assert exact <= brute + 1e-9 and brute - exact <= 1e-6


@distances
def test_segment_distance_broadcasts_and_closed_forms(segment_distance):
    # crossing at right angles, 3 mm apart; and end-to-end collinear with a 2 mm gap
    p1 = np.array([[-1.0, 0, 0], [0, 0, 0]])
    q1 = np.array([[1.0, 0, 0], [1, 0, 0]])
    p2 = np.array([[0.0, -1, 3], [3, 0, 0]])
    q2 = np.array([[0.0, 1, 3], [5, 0, 0]])
    np.testing.assert_allclose(segment_distance(p1, q1, p2, q2), [3.0, 2.0], atol=1e-12)


def _brute_min_leg_distance(machine, p, skip=()):
    legs, _ = explicit_legs(machine, p)
    tops = machine.base + legs
    best = np.inf
    for i in range(6):
        for j in range(i + 1, 6):
            if (i, j) not in skip:
                best = min(best, _brute_segment_distance(machine.base[i], tops[i], machine.base[j], tops[j], n=201))
    return best


def test_leg_collision_margin_against_brute_force():
    for p in (HOME, pose(x=20.0, c=0.3), pose(c=-0.35, a=0.1), pose(y=15.0, b=0.2, c=0.2)):
        rep = M.check_limits(p)
        brute = _brute_min_leg_distance(M, p)
        assert rep.margins["leg_collision"][0] == pytest.approx(brute - 36.1, abs=0.05)


def test_leg_collision_triggered_on_a_path():
    # On the prototype the closest legs at home are 6 and 1, 36.23 mm apart at their
    # platform joints (0.13 mm more than the 36.1 mm diameter). Along this combined
    # shift-and-tilt direction two legs swing into each other: find, with the brute-force
    # distance, where they touch, and check the limit flips there.
    d = np.array([-29.29, -26.50, 11.15, -0.281, 0.328, 0.314])
    t0 = brentq(lambda t: _brute_min_leg_distance(M, HOME + t * d) - 36.1, 0.0, 1.0, xtol=1e-6)
    assert 0.3 < t0 < 0.9
    rep = M.check_limits(np.array([HOME + (t0 - 0.01) * d, HOME + (t0 + 0.01) * d]))
    assert rep.violations["leg_collision"].tolist() == [False, True]
    assert rep.margins["leg_collision"][0] > 0 > rep.margins["leg_collision"][1]


# -- singularity ------------------------------------------------------------------------------


def test_singularity_at_the_yaw_90_configuration():
    # Level 6-6 platform yawed by 90°: find the yaw minimising the smallest singular value
    # of the (unscaled) twist Jacobian numerically, then check det J changes sign across it.
    def inv_cond(c):
        s = np.linalg.svd(M.twist_jacobian(pose(c=c))[0], compute_uv=False)
        return s[-1] / s[0]

    res = minimize_scalar(inv_cond, bounds=(60 * DEG, 120 * DEG), method="bounded", options={"xatol": 1e-10})
    c_sing = res.x
    assert res.fun < 1e-8
    det = lambda c: np.linalg.det(M.twist_jacobian(pose(c=c))[0])  # noqa: E731
    assert det(c_sing - 0.01) * det(c_sing + 0.01) < 0
    rep = M.check_limits(np.array([pose(c=c_sing), pose(), pose(c=c_sing - 0.3)]))
    assert rep.violations["singularity"].tolist() == [True, False, False]
    assert rep.margins["singularity"][0] == pytest.approx(-M.limits.singularity_margin, abs=1e-6)


def test_singularity_margin_is_scaled_inverse_condition_number():
    p = pose(x=5.0, a=0.1, c=0.4)
    J = M.twist_jacobian(p)[0]
    r = np.mean(np.linalg.norm(M.platform, axis=1))
    s = np.linalg.svd(J @ np.diag([1, 1, 1, 1 / r, 1 / r, 1 / r]), compute_uv=False)
    assert M.check_limits(p).margins["singularity"][0] == pytest.approx(s[-1] / s[0] - 0.01, rel=1e-10)


def test_limit_report_bookkeeping():
    poses = np.array([HOME, pose(a=0.5), pose(z=500.0)])
    rep = M.check_limits(poses)
    assert rep.ok.tolist() == [True, False, False]
    verdicts = rep.verdicts()
    assert verdicts[0] == "ok" and "s_joint_tilt" in verdicts[1] and "stroke" in verdicts[2]


def test_symmetric_machine_without_diameter_has_no_collision_check():
    assert "leg_collision" not in symmetric_hexapod().check_limits(symmetric_hexapod().home_pose).margins


# -- robustness: degenerate segments, non-finite poses ----------------------------------------


def _point_segment_distance(x, p, q):
    """Independent closed form: project x on the line p→q, clamp to the segment."""
    d = q - p
    dd = float(d @ d)
    t = 0.0 if dd == 0.0 else float(np.clip((x - p) @ d / dd, 0.0, 1.0))
    return float(np.linalg.norm(p + t * d - x))


@distances
@settings(max_examples=100, deadline=None)
@given(point, point, point)
def test_segment_distance_with_a_zero_length_segment(segment_distance, x, p, q):
    # a zero-length segment is a point: the distance is the point–segment distance, from
    # either side, and the point–point distance when both segments are points
    expected = _point_segment_distance(x, p, q)
    assert segment_distance(x, x, p, q) == pytest.approx(expected, rel=1e-9, abs=1e-9)
    assert segment_distance(p, q, x, x) == pytest.approx(expected, rel=1e-9, abs=1e-9)
    assert segment_distance(x, x, p, p) == pytest.approx(np.linalg.norm(x - p), rel=1e-12, abs=1e-12)
    if np.linalg.norm(q - p) > 1e-3:
        assert segment_distance(x, x, p, q) <= _brute_segment_distance(x, x + 1e-300, p, q) + 1e-9


@distances
def test_segment_distance_zero_length_closed_forms(segment_distance):
    p = np.zeros(3)
    a, b = np.array([1.0, 1.0, 0.0]), np.array([3.0, 1.0, 0.0])
    # point beside the segment's start, beyond its end, above its middle; vectorised
    x = np.array([[0.0, 0, 0], [5.0, 1, 0], [2.0, 4, 0]])
    got = segment_distance(x, x, np.broadcast_to(a, x.shape), np.broadcast_to(b, x.shape))
    np.testing.assert_allclose(got, [np.sqrt(2.0), 2.0, 3.0], atol=1e-12)
    assert np.isfinite(segment_distance(p, p, p, p)) and segment_distance(p, p, p, p) == 0.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_check_limits_reports_non_finite_poses(bad):
    # documented: a NaN/inf pose cannot be evaluated → every limit violated, margins NaN;
    # the finite poses of the same batch get exactly the margins they get alone
    good = np.array([pose(), pose(x=40.0, z=290.0), pose(y=-35.0, a=0.3)])
    poses = np.vstack([good, good[:1], good[:1]])
    poses[3, 0] = bad  # a position coordinate
    poses[4, 5] = bad  # an angle
    for margin in (0.0, 1.5):
        rep = M.check_limits(poses, margin=margin)
        ref = M.check_limits(good, margin=margin)
        assert set(rep.margins) == set(ref.margins) == {"stroke", "u_joint_tilt", "s_joint_tilt",
                                                         "leg_collision", "singularity"}
        for name in rep.margins:
            np.testing.assert_array_equal(rep.margins[name][:3], ref.margins[name])
            assert np.all(np.isnan(rep.margins[name][3:]))
            assert rep.violations[name][3:].all()
        assert rep.ok.tolist() == ref.ok.tolist() + [False, False]
        assert rep.verdicts()[3] == "+".join(rep.margins)


def test_check_limits_on_a_machine_without_optional_limits_and_nan():
    m = symmetric_hexapod()
    rep = m.check_limits(np.array([m.home_pose, np.full(6, np.nan)]))
    assert rep.ok.tolist() == [True, False]
    assert all(np.isnan(v[1]) for v in rep.margins.values())


# -- LimitReport.verdicts ----------------------------------------------------------------------


def verdicts_by_pose(report: LimitReport) -> list[str]:
    """The definition, one pose at a time: the names of the violated limits, in order, joined by '+'."""
    n = len(next(iter(report.violations.values()))) if report.violations else 0
    out = []
    for k in range(n):
        hit = [name for name, v in report.violations.items() if v[k]]
        out.append("+".join(hit) if hit else "ok")
    return out


@st.composite
def limit_reports(draw):
    name = st.text(alphabet="abcxyz_+", min_size=1, max_size=6)
    # few limits (every machine), or more than the 62 an int64 code holds
    names = draw(st.one_of(st.lists(name, unique=True, max_size=9), st.lists(name, unique=True, min_size=63, max_size=66)))
    n = draw(st.integers(0, 40))
    return LimitReport({name: draw(arrays(bool, n)) for name in names})


@settings(max_examples=150, deadline=None)
@given(limit_reports())
def test_verdicts_match_the_per_pose_definition(report):
    v = report.verdicts()
    assert isinstance(v, list) and all(isinstance(s, str) for s in v)
    assert v == verdicts_by_pose(report)


def test_verdicts_of_a_real_machine_match_the_per_pose_definition():
    rng = np.random.default_rng(5)
    poses = HOME + rng.uniform(-1, 1, (2000, 6)) * np.array([90, 90, 40, 0.4, 0.4, 1.0])
    report = M.check_limits(poses)
    v = report.verdicts()
    assert v == verdicts_by_pose(report)
    assert len(set(v)) > 3  # several different combinations were exercised
    assert [s == "ok" for s in v] == report.ok.tolist()


# -- the compiled limit kernel against the NumPy formulas it replaces --------------------------

limited_machines = st.builds(
    symmetric_hexapod,
    base_radius=st.floats(100.0, 250.0),
    platform_radius=st.floats(50.0, 120.0),
    base_separation=st.floats(8.0, 60.0),
    platform_separation=st.one_of(st.just(0.0), st.floats(8.0, 60.0)),   # 3-6 designs share joints
    phase=st.floats(0.0, 360.0),
    offset=st.floats(200.0, 400.0),
    stroke=st.floats(20.0, 200.0),
    u_joint_tilt=st.one_of(st.none(), st.floats(20.0, 60.0)),
    s_joint_tilt=st.one_of(st.none(), st.floats(20.0, 60.0)),
    leg_diameter=st.one_of(st.none(), st.floats(5.0, 60.0)),
)


def _random_poses(machine, n, seed, spread=1.0):
    rng = np.random.default_rng(seed)
    half = spread * np.array([80.0, 80.0, 60.0, 0.5, 0.5, 1.2])
    return machine.home_pose + rng.uniform(-1.0, 1.0, (n, 6)) * half


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.just(M), limited_machines), st.integers(0, 2**32 - 1), st.floats(0.0, 3.0))
def test_kernel_margins_match_the_numpy_formulas(machine, seed, margin):
    # the kernel's stroke, tilt and collision margins (before any NumPy recomputation) agree
    # with the NumPy reference to rounding: 1e-11 mm/rad is 100× the ~1e-13 seen on
    # 300 mm legs and 100× below EXACT_VERDICT_TOL, below which poses are recomputed
    poses = _random_poses(machine, 300, seed)
    lim = machine.limits
    table = np.array([np.nan if v is None else v for v in (lim.u_joint_tilt, lim.s_joint_tilt, lim.leg_diameter)]
                     + [lim.singularity_margin, machine.platform_radius, margin, np.deg2rad(margin)])
    on = machine._limits_enabled()
    out = kernels.limit_margins(poses, machine.base, machine.platform, machine.offset, machine.gains, machine.stroke,
                                machine.base_axis, machine.platform_axis, machine._leg_pairs(), on, table)
    ref = machine._limit_margins_numpy(poses, margin)
    assert set(ref) == {n for n, enabled in zip(LIMIT_NAMES, on) if enabled}
    for c, name in enumerate(LIMIT_NAMES[:4]):
        if name in ref:
            np.testing.assert_allclose(out[:, c], ref[name], rtol=0, atol=1e-11, err_msg=name)
        else:
            assert np.isnan(out[:, c]).all()
    # the certificate column: +1 only where the SVD ratio is ≥ the margin, −1 only where below
    cert, sing = out[:, 4], ref["singularity"]
    assert np.all(sing[cert == 1.0] >= 0) and np.all(sing[cert == -1.0] < 0)
    assert np.all(np.isin(cert[~np.isnan(cert)], [1.0, -1.0]))
    # and check_limits, both modes, gives exactly the NumPy verdicts
    for margins in (True, False):
        rep = machine.check_limits(poses, margin=margin, margins=margins)
        assert list(rep.violations) == list(ref)
        for name in ref:
            np.testing.assert_array_equal(rep.violations[name], ~(ref[name] >= 0), err_msg=name)
        if margins:
            for name in ref:
                np.testing.assert_allclose(rep.margins[name], ref[name], rtol=0, atol=1e-11)
        else:
            assert rep.margins == {}


def test_poses_on_a_limit_get_the_numpy_verdict():
    # poses exactly on each limit (bisection on the NumPy margin to 1e-15 of the segment):
    # their kernel margins are within EXACT_VERDICT_TOL of zero, so check_limits recomputes
    # them with NumPy and returns its verdict whatever the kernel's rounding
    rng = np.random.default_rng(3)
    start = np.tile(HOME, (100, 1))
    far = HOME + rng.uniform(-1, 1, (100, 6)) * np.array([90, 90, 40, 0.5, 0.5, 1.2])
    bad = ~(M.check_limits(far).ok)
    lo, hi = np.zeros(bad.sum()), np.ones(bad.sum())
    a, b = start[bad], far[bad]
    for _ in range(60):
        mid = (lo + hi) / 2
        ok = M._limit_margins_numpy(a + mid[:, None] * (b - a))
        inside = np.all([m >= 0 for m in ok.values()], axis=0)
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    edge = np.vstack([a + lo[:, None] * (b - a), a + hi[:, None] * (b - a)])
    ref = M._limit_margins_numpy(edge)
    assert np.min(np.abs(np.concatenate([m for m in ref.values()]))) < 1e-12   # really on a limit
    lim = M.limits
    table = np.array([lim.u_joint_tilt, lim.s_joint_tilt, lim.leg_diameter, lim.singularity_margin,
                      M.platform_radius, 0.0, 0.0])
    raw = kernels.limit_margins(edge, M.base, M.platform, M.offset, M.gains, M.stroke, M.base_axis, M.platform_axis,
                                M._leg_pairs(), M._limits_enabled(), table)
    near = np.any(np.abs(raw[:, :4]) <= EXACT_VERDICT_TOL, axis=1)
    assert near.sum() >= len(a)            # at least one side of every edge is recomputed
    assert len(edge) >= LIMITS_COMPILED_FROM  # (the batch goes through the kernel)
    for margins in (True, False):
        rep = M.check_limits(edge, margins=margins)
        for name in ref:
            np.testing.assert_array_equal(rep.violations[name], ~(ref[name] >= 0), err_msg=name)
            if margins:   # the recomputed poses carry the NumPy margins, bit for bit
                np.testing.assert_array_equal(rep.margins[name][near], ref[name][near], err_msg=name)
    assert M.check_limits(edge).ok.sum() == len(a) and not M.check_limits(edge[len(a):]).ok.any()


def _matrix_with_singular_values(rng, sv):
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    return (U * sv) @ V.T


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-8.0, 0.0), st.floats(-6.0, 0.0), st.floats(-3.0, 3.0))
def test_singularity_certificate_against_the_svd(seed, log_ratio, log_m, log_scale):
    rng = np.random.default_rng(seed)
    ratio, m = 10.0**log_ratio, 10.0**log_m
    sv = np.sort(np.concatenate([[1.0, ratio], rng.uniform(ratio, 1.0, 4)]))[::-1] * 10.0**log_scale
    J = _matrix_with_singular_values(rng, sv)
    s = np.linalg.svd(J, compute_uv=False)
    true = s[-1] / s[0]
    cert = kernels.singularity_certificate(J, m, np.empty((6, 6)), np.empty((6, 6)))
    # never wrong
    if cert == 1.0:
        assert true >= m
    elif cert == -1.0:
        assert true < m
    else:
        assert np.isnan(cert)
    # and decisive outside the band its bounds leave: λ_max ∈ [max C_ii, min(tr C, ‖C‖∞)]
    # and tr C ≤ 6 max C_ii, so the band is at most m/√6 .. √6·m (1 % for the shifts), once
    # m² tr is well above the rounding slack 1e-12 tr (m ≥ 1e-4; the default margin is 0.01)
    if m >= 1e-4 and true > 1.01 * np.sqrt(6.0) * m:
        assert cert == 1.0
    if m >= 1e-4 and true < m / (1.01 * np.sqrt(6.0)):
        assert cert == -1.0


def test_singularity_certificate_of_non_finite_or_zero_matrices_is_undecided():
    C, L = np.empty((6, 6)), np.empty((6, 6))
    for J in (np.zeros((6, 6)), np.full((6, 6), np.nan), np.diag([np.inf, 1, 1, 1, 1, 1])):
        assert np.isnan(kernels.singularity_certificate(J, 0.01, C, L))
    # a zero margin: a regular matrix passes; a singular one is left to the SVD (ratio 0 ≥ 0
    # passes there too, but no Cholesky certificate can tell 0 from a tiny negative shift)
    assert kernels.singularity_certificate(np.diag([1.0, 1, 1, 1, 1, 0.5]), 0.0, C, L) == 1.0
    assert np.isnan(kernels.singularity_certificate(np.diag([1.0, 1, 1, 1, 1, 0]), 0.0, C, L))


def test_check_limits_without_margins_on_non_finite_poses_and_threads():
    # NaN / inf poses violate everything in both modes; a batch large enough to be split over
    # threads gives the verdicts of its rows checked one by one
    poses = _random_poses(M, 2 * kernels._LIMIT_GRAIN + 13, 11)
    poses[5, 2] = np.nan
    poses[7, 4] = np.inf
    fast = M.check_limits(poses, margin=0.1, margins=False)
    full = M.check_limits(poses, margin=0.1)
    for name in full.violations:
        np.testing.assert_array_equal(fast.violations[name], full.violations[name])
        assert fast.violations[name][5] and fast.violations[name][7]
    rows = [M.check_limits(p, margin=0.1, margins=False).ok[0] for p in poses[:50]]   # one by one
    assert rows == fast.ok[:50].tolist()
    assert 0 < fast.ok.sum() < len(poses)


# -- what the geometry reaches (pkmcal.mechanisms.hexapod_reach; issue 24 item 5) ----------------


def test_machines_within_their_geometry_are_kept_as_they_are():
    """Every built-in hexapod's stroke lies within 1/2..2 times its home strut length and its
    tilt limits below 90°: the same machine, no note (plans on it do not change)."""
    for name in ("stewart-prototype", "stewart-prototype-real"):
        m = builtin_machine(name)
        assert m.within_geometry() == (m, ())
    planar = builtin_machine("planar-3dof-4act")
    assert planar.within_geometry() == (planar, ())


def test_linuxcnc_sample_is_clipped_to_half_and_twice_its_home_struts(tmp_path):
    """LinuxCNC's hexapod sample (±1000 inch struts, no tilt limits): the stroke becomes
    [L_h / 2, 2 L_h] with L_h the strut at home, computed here from the typed-in joints, and
    the tilt limits 90°; the notes name the INI limits and the missing tilt limits."""
    from helpers import (
        LINUXCNC_SAMPLE_BASE_IN,
        LINUXCNC_SAMPLE_HOME_IN,
        LINUXCNC_SAMPLE_PLATFORM_IN,
        write_linuxcnc_hexapod_sample,
    )

    from pkmcal.io.import_linuxcnc import machine_from_linuxcnc

    hal, ini = write_linuxcnc_hexapod_sample(tmp_path)
    m = machine_from_linuxcnc(hal, ini).machine
    home = np.linalg.norm(25.4 * (np.array(LINUXCNC_SAMPLE_HOME_IN) + LINUXCNC_SAMPLE_PLATFORM_IN
                                  - np.array(LINUXCNC_SAMPLE_BASE_IN)), axis=1)
    clipped, notes = m.within_geometry()
    lengths = clipped.offset[:, None] + clipped.stroke
    np.testing.assert_allclose(lengths, np.stack([home / 2, 2 * home], axis=1), rtol=1e-12)
    assert clipped.limits.u_joint_tilt == clipped.limits.s_joint_tilt == np.pi / 2
    assert m.stroke[0, 0] < -25000 and m.limits.u_joint_tilt is None      # the machine itself unchanged
    assert len(notes) == 2 and f"[JOINT_N] MIN_LIMIT/MAX_LIMIT of {ini}" in notes[0]
    assert "U (base) joint none, S (platform) joint none" in notes[1]
    # idempotent: the clipped machine is within its geometry
    assert clipped.within_geometry() == (clipped, ())
    # a tilt limit beyond 90° is brought to 90°, one below is kept
    wide = replace(clipped, limits=replace(clipped.limits, u_joint_tilt=2.0, s_joint_tilt=0.5))
    again, notes = wide.within_geometry()
    assert again.limits.u_joint_tilt == np.pi / 2 and again.limits.s_joint_tilt == 0.5
    assert notes == (notes[0],) and "U (base) joint 114.6°" in notes[0]
