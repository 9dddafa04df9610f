"""The linear delta (pkmcal.mechanisms.linear_delta) against independent constructions:
Klipper's own formulas (stepper position z + sqrt(arm² − (x − x_t)² − (y − y_t)²),
abs_endstop = position_endstop + sqrt(arm² − radius²)), IK/FK round trips on leaning,
offset machines, central finite differences of both Jacobians, and the limits."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.linear_delta import PARAM_NAMES, LinearDelta, klipper_delta


def _floats(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def deltas(draw, lean=True):
    """Plausible printers: radius r 60–180 mm, arms 1.6–2.6 r, towers within 8° of 120°
    apart, rails leaning up to 2°, tool offsets up to 0.05 r in each coordinate, a print
    radius of r/2 (so every arm reaches every pose inside it: 0.5 r + 1.03 r + 0.07 r < 1.6 r)."""
    r = draw(_floats(60, 180))
    base = np.deg2rad([210.0, 330.0, 90.0]) + np.deg2rad(draw(st.tuples(*[_floats(-8, 8)] * 3)))
    rho = np.zeros(len(PARAM_NAMES))
    for i in range(3):
        rho[6 * i:6 * i + 6] = [base[i], r + draw(_floats(-3, 3)), r * draw(_floats(1.6, 2.6)),
                                draw(_floats(200, 400)),
                                np.deg2rad(draw(_floats(-2, 2))) if lean else 0.0,
                                np.deg2rad(draw(_floats(-2, 2))) if lean else 0.0]
    if lean:
        rho[-3:] = np.array(draw(st.tuples(*[_floats(-0.05, 0.05)] * 3))) * r
    return LinearDelta(name="drawn", rho=rho, print_radius=0.5 * r)


def _poses(m: LinearDelta, n: int, seed: int) -> np.ndarray:
    """Poses inside the print volume: within the print radius, z up to half the lowest
    switch height."""
    rng = np.random.default_rng(seed)
    rad = m.print_radius * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(0, 0.5 * float(np.min(m.params[3:18:6])), n)
    return np.stack([rad * np.cos(phi), rad * np.sin(phi), z], axis=1)


def test_vertical_rails_are_klippers_stepper_positions_and_abs_endstops():
    m = klipper_delta("k", delta_radius=105.0, arm_length=(215.0, 216.0, 214.5), position_endstop=(300, 301, 299.5),
                      angles_deg=(210.0, 330.5, 89.0))
    p = _poses(m, 50, 1)
    ang = np.deg2rad([210.0, 330.5, 89.0])
    arm = np.array([215.0, 216.0, 214.5])
    tx, ty = 105.0 * np.cos(ang), 105.0 * np.sin(ang)
    klipper = p[:, 2:3] + np.sqrt(arm**2 - (p[:, 0:1] - tx) ** 2 - (p[:, 1:2] - ty) ** 2)
    np.testing.assert_allclose(m.ik(p), klipper, rtol=0, atol=1e-12 * 500)
    np.testing.assert_allclose(m.reading_reference, np.array([300, 301, 299.5]) + np.sqrt(arm**2 - 105.0**2),
                               rtol=0, atol=1e-12 * 500)
    # At (0, 0, position_endstop_i) tower i's carriage is at its switch
    for i, e in enumerate((300, 301, 299.5)):
        assert m.ik([0.0, 0.0, e])[0, i] == pytest.approx(m.reading_reference[i], abs=1e-12 * 500)


@settings(max_examples=40, deadline=None)
@given(m=deltas(), seed=st.integers(0, 2**31))
def test_fk_inverts_ik_on_leaning_offset_machines(m, seed):
    p = _poses(m, 20, seed)
    lam = m.ik(p)
    fk = m.fk(lam)
    assert fk.ok.all()
    # trilateration: a few roundings of the ~500 mm coordinates, amplified by the
    # conditioning of the sphere intersection (arms ≤ 2.6 radii, poses inside the print radius)
    np.testing.assert_allclose(fk.poses, p, rtol=0, atol=1e-9)
    assert m.same_branch(fk.poses, m.home_pose).all()


@settings(max_examples=30, deadline=None)
@given(m=deltas(), seed=st.integers(0, 2**31))
def test_jacobians_match_central_differences(m, seed):
    p = _poses(m, 8, seed)
    lam, A, B = m.ik_and_jacobians(p)
    # distance to the nearest singularity (arm ⊥ rail or out of reach): D = w·u ≥ the
    # arm's vertical extent here; lengths vary on that scale, angles on D over the lever
    # (radius + arm + |p| + |t|); slopes bounded by the largest Jacobian entry (default)
    rho = m.params
    D = float(np.min(np.einsum("ntk,tk->nt", *_arms(m, p))))
    lever = float(np.max(rho[1:18:6]) + np.max(rho[2:18:6]) + np.max(np.abs(p)) + np.max(np.abs(rho[-3:])))
    assert D > 0
    assert_jacobian_matches_fd(m.ik, p, A, scale=D / 2, names=m.pose_names)
    is_angle = np.array(m.param_is_angle)
    assert_jacobian_matches_fd(lambda r: m.with_params(r).ik(p), rho, B,
                               scale=np.where(is_angle, D / (2 * lever), D / 2), names=PARAM_NAMES)


def _arms(m: LinearDelta, p):
    """(w (N, 3, 3), u (3, 3)): the arms C − q and the rail directions, built here from the
    module's definitions independently of its IK."""
    rho = m.params
    th, r, L = rho[0:18:6], rho[1:18:6], rho[2:18:6]
    al, be = rho[4:18:6], rho[5:18:6]
    e_r = np.stack([np.cos(th), np.sin(th), 0 * th], 1)
    e_t = np.stack([-np.sin(th), np.cos(th), 0 * th], 1)
    u = (-np.sin(al)[:, None] * e_r + (np.cos(al) * np.sin(be))[:, None] * e_t
         + np.stack([0 * th, 0 * th, np.cos(al) * np.cos(be)], 1))
    q = p - rho[-3:]
    C = np.empty((len(p), 3, 3))
    for i in range(3):
        # the carriage: |r e_r + s u − q| = L, by bisection on s along the rail (independent
        # of the closed form); s from the effector's height up
        lo, hi = np.full(len(p), -1e3), np.full(len(p), 2e3)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            far = np.linalg.norm(r[i] * e_r[i] + mid[:, None] * u[i] - q, axis=1) > L[i]
            above = (r[i] * e_r[i] + mid[:, None] * u[i] - q) @ u[i] > 0
            hi = np.where(far & above, mid, hi)
            lo = np.where(far & above, lo, mid)
        C[:, i] = r[i] * e_r[i] + hi[:, None] * u[i]
    return C - q[:, None, :], u


@settings(max_examples=20, deadline=None)
@given(m=deltas(), seed=st.integers(0, 2**31))
def test_ik_agrees_with_an_independent_construction_of_the_carriages(m, seed):
    """The carriage joints found by bisection along each rail (no closed form) are at the
    rail positions the IK gives: λ − H^fw + S = s, |C − q| = L."""
    p = _poses(m, 10, seed)
    w, u = _arms(m, p)
    q = p - m.params[-3:]
    s_ik = m.ik(p) - m.reading_reference + m.switch_positions()
    C_ik = m.params[1:18:6, None] * np.stack([np.cos(m.params[0:18:6]), np.sin(m.params[0:18:6]), np.zeros(3)], 1)
    C_ik = C_ik[None] + s_ik[:, :, None] * u[None]
    np.testing.assert_allclose(C_ik - q[:, None, :], w, rtol=0, atol=1e-9)


def test_a_calibrated_machine_keeps_the_readings_of_its_firmware():
    """with_params keeps H^fw: the same physical carriage position reads the same; after
    as_firmware_reference the readings are the new configuration's stepper positions."""
    nominal = klipper_delta("k", 100.0, 215.0, 300.0)
    rho = nominal.params
    rho[PARAM_NAMES.index("endstop_b")] += 0.7
    real = nominal.with_params(rho)
    np.testing.assert_array_equal(real.reading_reference, nominal.reading_reference)
    p = np.array([[0.0, 0.0, 10.0]])
    # the real switch of tower b is 0.7 mm higher: homed there, the firmware counts 0.7 mm
    # more travel down to the carriage position that puts the nozzle at p: it reads 0.7 less
    assert real.ik(p)[0, 1] - nominal.ik(p)[0, 1] == pytest.approx(-0.7, abs=1e-12)
    np.testing.assert_array_equal(real.ik(p)[0, [0, 2]], nominal.ik(p)[0, [0, 2]])
    fw = real.as_firmware_reference()
    assert fw.ik(p)[0, 1] == pytest.approx(10.0 + np.sqrt(215.0**2 - 100.0**2), abs=1e-12)


def test_limits_name_what_is_violated():
    m = klipper_delta("k", 100.0, 215.0, 300.0, print_radius=80.0, travel=400.0)
    report = m.check_limits(np.array([[0.0, 0.0, 10.0], [85.0, 0.0, 10.0], [0.0, 0.0, -1.0], [0.0, 0.0, 320.0],
                                      [0.0, -130.0, 0.0], [300.0, 0.0, 0.0]]))
    assert report.verdicts()[0] == "ok"
    assert "print_radius" in report.reasons(1)
    assert "min_z" in report.reasons(2)
    assert "travel" in report.reasons(3)           # above the switches
    assert "arm_angle" in report.reasons(4)        # far from tower c: its arm nearly flat
    assert "reach" in report.reasons(5)
    assert np.isnan(m.ik([300.0, 0.0, 0.0])).any()


@pytest.mark.parametrize("change, message", [
    ({"radius_a": -1.0}, "radius_a must be positive"),
    ({"arm_b": 50.0}, "arm_b must be longer than radius_b"),
    ({"lean_radial_c": np.deg2rad(50)}, "lean_radial_c must be within"),
    ({"angle_b": np.deg2rad(212)}, "at least 10° apart"),
])
def test_impossible_geometry_is_refused_naming_the_parameter(change, message):
    rho = klipper_delta("k", 100.0, 215.0, 300.0).params
    for k, v in change.items():
        rho[PARAM_NAMES.index(k)] = v
    with pytest.raises(PkmcalError, match=message):
        LinearDelta(name="bad", rho=rho)


def test_fk_of_unreachable_readings_is_not_converged():
    m = klipper_delta("k", 100.0, 215.0, 300.0)
    lam = m.ik(np.array([[0.0, 0.0, 50.0]]))
    lam[0, 0] += 500.0      # one carriage far above the others: the spheres do not meet
    fk = m.fk(lam)
    assert not fk.converged[0] and np.isnan(fk.poses[0]).all()


@settings(max_examples=30, deadline=None)
@given(m=deltas(), seed=st.integers(0, 2**31), axis=st.sampled_from([0, 1]))
def test_the_tower_shift_moves_the_machine_as_a_whole(m, seed, axis):
    """LinearDelta.tower_shift (the named direction "where the tower set stands", issue 25):
    the parameters moved by ε along it read at pose p what the machine read at p − ε e_axis,
    checked on the IK itself (not its Jacobian). The remainder is second order: ε² times a
    curvature of λ in p of at most ~1/(arm · sin³ 20°) ~ 0.1/mm here, i.e. ~1e-7 mm at
    ε = 1e-3 mm, against the shift's own effect of ~ε; leaving out a lean term (β up to 2°)
    gives ~s·ε·sin β / r ~ 1e-4 mm, an endstop term ~ε."""
    p = _poses(m, 12, seed)
    d = m.tower_shift(axis)
    v = np.array([d.get(n, 0.0) for n in PARAM_NAMES])
    eps = 1e-3
    delta = np.zeros(3)
    delta[axis] = eps
    moved = m.ik(p - delta)
    plain = np.max(np.abs(m.ik(p) - moved))
    err = np.max(np.abs(m.ik(p, m.params + eps * v) - moved))
    assert plain > 0.1 * eps
    assert err < 1e-3 * plain, (err, plain)
    # vertical rails: no lean in it (a direction with a held lean would not be judged)
    vertical = m.with_params(np.where([n.startswith("lean_") for n in PARAM_NAMES], 0.0, m.params))
    assert not any(n.startswith("lean_") for n in vertical.tower_shift(axis))
