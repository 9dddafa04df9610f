"""Built-in machines against paper 2 (Saputra, Ong & Nee 2014): Table 3, Table 4 and §5.

The tables are transcribed here again, independently of ``pkmcal.mechanisms.library``.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms import BUILTIN_MACHINES, DEFAULT_MACHINE, Hexapod, builtin_machine, symmetric_hexapod

# Paper 2, Table 3 (mm), columns = legs 1..6.
TABLE3_B = np.array([
    [-152.500, -132.068, 76.250, 132.068, 76.250, 0.000],
    [0.000, -76.250, -132.068, -76.250, 132.068, 152.500],
    [0.000, 0.000, 0.000, 0.000, 0.000, 0.000],
]).T
TABLE3_A = np.array([
    [-60.622, -35.000, 0.000, 70.000, 60.622, -35.000],
    [35.000, -60.622, -70.000, 0.000, 35.000, 60.622],
    [0.000, 0.000, 0.000, 0.000, 0.000, 0.000],
]).T
# Paper 2, Table 4: δL_O, δb (ε_x, ε_y, ε_z), δa (ε_x, ε_y, ε_z) per leg.
TABLE4 = np.array([
    [1, 0, 0, 0, 0, 0, 0],
    [2, 3, 0, 0.3, -0.9, 0.67, 0.53],
    [3, 0.1, 1.8, 0.7, 3, -2, 0.7],
    [1, -0.1, 1.8, 0.7, 3, -2, 0.7],
    [2, -0.1, 1.8, 0.7, 3, -2, 0.7],
    [3, -0.1, 1.8, 0.7, 3, -2, 0.7],
])


def test_default_machine_is_the_prototype():
    assert DEFAULT_MACHINE == "stewart-prototype"
    assert set(BUILTIN_MACHINES) >= {"stewart-prototype", "stewart-prototype-real"}


def test_prototype_matches_table3_and_section5():
    m = builtin_machine("stewart-prototype")
    assert isinstance(m, Hexapod)
    np.testing.assert_array_equal(m.base, TABLE3_B)
    np.testing.assert_array_equal(m.platform, TABLE3_A)
    np.testing.assert_array_equal(m.offset, np.full(6, 305.0))  # §5: L_Oi = 305.000 mm
    np.testing.assert_array_equal(m.stroke, np.tile([0.0, 50.0], (6, 1)))  # 50 mm stroke
    assert np.rad2deg(m.limits.u_joint_tilt) == pytest.approx(45.0)
    assert np.rad2deg(m.limits.s_joint_tilt) == pytest.approx(29.0)
    assert m.limits.leg_diameter == pytest.approx(36.1)
    # joints on circles of 152.5 mm and 70 mm radius (to the 3 decimals of Table 3)
    np.testing.assert_allclose(np.linalg.norm(m.base, axis=1), 152.5, atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(m.platform, axis=1), 70.0, atol=1e-3)


def test_prototype_home_is_level_centred_mid_stroke():
    m = builtin_machine("stewart-prototype")
    assert np.all(m.home_pose[[0, 1, 3, 4, 5]] == 0.0)
    np.testing.assert_allclose(m.ik(m.home_pose)[0], 25.0, atol=2e-3)  # symmetric to Table 3 rounding
    assert m.check_limits(m.home_pose).ok[0]


def test_real_prototype_is_nominal_plus_table4():
    nominal, real = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype-real")
    np.testing.assert_allclose(real.offset - nominal.offset, TABLE4[:, 0], atol=1e-12)
    np.testing.assert_allclose(real.base - nominal.base, TABLE4[:, 1:4], atol=1e-12)
    np.testing.assert_allclose(real.platform - nominal.platform, TABLE4[:, 4:7], atol=1e-12)
    np.testing.assert_array_equal(real.home_pose, nominal.home_pose)
    assert real.name == "stewart-prototype-real"
    assert real.stroke.tolist() == nominal.stroke.tolist() and real.limits == nominal.limits


def test_symmetric_defaults_reproduce_table3_to_its_rounding():
    # Table 3 gives 3 decimals but not always rounded: 152.5·cos 30° = 132.06887 is printed
    # 132.068 (truncated), 70·cos 30° = 60.62178 is printed 60.622 (rounded). So agreement
    # is to one unit of the last decimal, and no better.
    m = symmetric_hexapod()
    np.testing.assert_allclose(m.base, TABLE3_B, atol=1e-3)
    np.testing.assert_allclose(m.platform, TABLE3_A, atol=1e-3)
    assert np.abs(m.base - TABLE3_B).max() > 5e-4  # the truncation, documented above
    np.testing.assert_array_equal(m.offset, np.full(6, 305.0))
    proto = builtin_machine("stewart-prototype")
    assert m.limits.u_joint_tilt == proto.limits.u_joint_tilt
    assert m.limits.s_joint_tilt == proto.limits.s_joint_tilt


def test_symmetric_by_name():
    m = builtin_machine("symmetric:base_radius=200,platform_separation=20,leg_diameter=30")
    np.testing.assert_allclose(np.linalg.norm(m.base, axis=1), 200.0)
    assert m.limits.leg_diameter == 30.0
    off = builtin_machine("symmetric:u_joint_tilt=off")
    assert off.limits.u_joint_tilt is None
    for bad in ("symmetric:radius=3", "symmetric:base_radius=abc", "symmetric:base_radius"):
        with pytest.raises(PkmcalError, match="symmetric"):
            builtin_machine(bad)
    with pytest.raises(PkmcalError, match="pkmcal machines"):
        builtin_machine("no-such-machine")


@settings(max_examples=40, deadline=None)
@given(st.floats(80, 300), st.floats(30, 150), st.floats(0, 90), st.floats(0, 360))
def test_symmetric_geometry(rb, rp, sep_b, phase):
    m = symmetric_hexapod(base_radius=rb, platform_radius=rp, base_separation=sep_b, phase=phase)
    np.testing.assert_allclose(np.linalg.norm(m.base, axis=1), rb, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(m.platform, axis=1), rp, rtol=1e-12)
    ang = np.rad2deg(np.arctan2(m.base[:, 1], m.base[:, 0]))
    gap = (ang[1::2] - ang[0::2] + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(gap, sep_b, atol=1e-9)


def test_three_six_generator_shares_platform_joints_and_skips_those_pairs():
    m = symmetric_hexapod(platform_separation=0.0, leg_diameter=20.0)
    d = np.linalg.norm(m.platform[:, None] - m.platform[None], axis=2)
    coincident = {(i, j) for i in range(6) for j in range(i + 1, 6) if d[i, j] < 1e-9}
    assert coincident == {(1, 2), (3, 4), (0, 5)}  # legs 2-3, 4-5, 6-1 meet at a joint
    pairs = {tuple(p) for p in m._leg_pairs()}
    assert pairs.isdisjoint(coincident) and len(pairs) == 15 - 3
    # legs meeting at a shared joint are at distance 0: they must not count as colliding
    rep = m.check_limits(m.home_pose)
    assert not rep.violations["leg_collision"][0]
    assert rep.margins["leg_collision"][0] > 0.0
    # ... while the 6-6 prototype checks all 15 pairs
    assert len(builtin_machine("stewart-prototype")._leg_pairs()) == 15
    # and the 3-6 machine's FK still inverts its IK
    poses = m.home_pose + np.random.default_rng(0).uniform(-1, 1, (200, 6)) * [20, 20, 10, 0.2, 0.2, 0.2]
    fk = m.fk_lengths(m.leg_lengths(poses))
    assert fk.all_converged
    np.testing.assert_allclose(fk.poses, poses, atol=1e-8)


def test_machines_are_immutable_and_comparable():
    a, b = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype")
    assert a == b and a != builtin_machine("stewart-prototype-real")
    with pytest.raises(ValueError):
        a.base[0, 0] = 1.0
    rho = a.params.copy()
    rho[6] += 1.0
    assert a.with_params(rho).offset[0] == 306.0 and a.offset[0] == 305.0
