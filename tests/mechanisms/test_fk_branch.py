"""FK assembly modes: the per-pose ``same_branch`` flag of :class:`FKResult`, checked against
independent computations (NumPy determinants, the closed-form geometry of the planar
machine), and the continuation that keeps FK from home on home's assembly mode.

Machine used: a wide symmetric hexapod whose limits admit poses of two assembly modes
(a user's machine like it made ``pkmcal info`` print "converged 300/300 … max position error
81.6 mm"). Poses are drawn with fixed seeds (no hash or hypothesis dependence)."""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.io.machine_file import load_machine
from pkmcal.mechanisms.planar import planar_2dof_3act, planar_3dof_4act

WIDE = "symmetric:base_radius=200,platform_radius=150,stroke=300,offset=200,u_joint_tilt=89,s_joint_tilt=89"


@pytest.fixture(scope="module")
def wide():
    return load_machine(WIDE)


def _reachable_poses(machine, n: int, seed: int) -> np.ndarray:
    """``n`` reachable poses (every limit satisfied) uniform in a box around home that
    crosses the singularity between the assembly modes (±250 mm, ±150 mm in z, ±55°, ±80°
    in yaw: about the single-axis ranges ``pkmcal info`` finds for this machine)."""
    rng = np.random.default_rng(seed)
    half = np.array([250.0, 250.0, 150.0, *np.deg2rad([55.0, 55.0, 80.0])])
    out = []
    while sum(len(o) for o in out) < n:
        box = machine.home_pose + rng.uniform(-1.0, 1.0, (4000, 6)) * half
        with np.errstate(all="ignore"):
            out.append(box[machine.check_limits(box).ok])
    return np.concatenate(out)[:n]


def _numpy_signs(machine, poses):
    return np.sign(np.linalg.det(machine.twist_jacobian(poses))).astype(int)


def test_compiled_det_signs_match_numpy_determinants(wide):
    poses = _reachable_poses(wide, 400, seed=1)
    signs = wide.assembly_signs(poses)[:, 0]
    ref = _numpy_signs(wide, poses)
    # |det| is far from 0 on poses that pass the singularity margin: the signs are exact
    assert np.array_equal(signs, ref)
    assert set(np.unique(signs)) == {-1, 1}          # the box does cross the singularity


def test_fk_from_home_stays_on_home_assembly_mode(wide):
    """Old behaviour: Newton from home jumped to the other assembly mode on some poses and
    reported them converged (3 of these 2000), and FKResult had no branch flag. Now
    (continuation from home for those rows) every converged row is on home's assembly mode,
    its IK reproduces the readings, and a pose of the other assembly mode is never returned
    as itself."""
    poses = _reachable_poses(wide, 2000, seed=0)
    lengths = wide.leg_lengths(poses)
    fk = wide.fk_lengths(lengths)
    home_sign = _numpy_signs(wide, wide.home_pose[None])[0]
    conv = fk.converged
    assert conv.mean() > 0.99
    assert np.all(_numpy_signs(wide, fk.poses[conv]) == home_sign)
    assert fk.same_branch.all() and np.array_equal(fk.ok, conv)
    assert np.max(np.abs(wide.leg_lengths(fk.poses[conv]) - lengths[conv])) <= 1e-9
    poses, lengths = poses[conv], lengths[conv]
    fk = wide.fk_lengths(lengths)
    other = _numpy_signs(wide, poses) != home_sign
    assert other.sum() > 50                     # the limits do admit the other assembly mode
    # those readings have a solution on home's mode too, which FK returns; it is not the pose
    assert np.all(np.linalg.norm(fk.poses[other, :3] - poses[other, :3], axis=1) > 1.0)
    assert not np.any(wide.same_branch(fk.poses[other], poses[other]))
    # poses on home's mode come back exactly (to the FK tolerance scaled by the Jacobian)
    same = ~other
    assert np.max(np.linalg.norm(fk.poses[same, :3] - poses[same, :3], axis=1)) < 1e-6


def test_branch_flag_when_start_is_on_the_other_mode(wide):
    """Readings of poses on home's mode, solved from guesses on the other mode: rows that
    converge on a mode other than their guess's have ``same_branch`` False, ``ok`` False,
    and the signs really differ (NumPy determinants)."""
    poses = _reachable_poses(wide, 3000, seed=0)
    sign = _numpy_signs(wide, poses)
    home_sign = _numpy_signs(wide, wide.home_pose[None])[0]
    same, other = poses[sign == home_sign], poses[sign != home_sign]
    n = min(len(same), len(other))
    fk = wide.fk(wide.ik(same[:n]), guess=other[:n])
    s_res, s_ref = _numpy_signs(wide, fk.poses), _numpy_signs(wide, other[:n])
    conv = fk.converged
    assert np.array_equal(fk.same_branch[conv], s_res[conv] == s_ref[conv])
    assert np.array_equal(fk.branch_changed, conv & (s_res != s_ref))
    assert fk.branch_changed.any()
    assert not np.any(fk.ok & fk.branch_changed)


def test_planar_3dof_signs_are_the_sides_of_the_ways():
    """sign b_i = side of guide-way i of the plate joint C_i, from the closed form
    C_1,2 = (x, y) ∓ (L3/2) e(φ), b = (C − O)·n (module docstring of planar.py)."""
    m = planar_3dof_4act()
    rng = np.random.default_rng(3)
    x = m.sample_poses(200, rng)
    L3, y1, y2, a1, a2 = (m.p(k) for k in ("L3", "y1", "y2", "alpha1", "alpha2"))
    e = np.stack([np.cos(x[:, 2]), np.sin(x[:, 2])], axis=1)
    C1, C2 = x[:, :2] - 0.5 * L3 * e, x[:, :2] + 0.5 * L3 * e
    b1 = (C1 - [0.0, y1]) @ np.array([-np.sin(a1), np.cos(a1)])
    b2 = (C2 - [0.0, y2]) @ np.array([-np.sin(a2), np.cos(a2)])
    assert np.array_equal(m.assembly_signs(x), np.sign(np.stack([b1, b2], axis=1)).astype(int))
    fk = m.fk(m.ik(x))
    assert fk.ok.all()
    # a guess with C_2 on the other side of its way (y far beyond way 2) is another assembly mode
    assert not m.same_branch(x[:1], np.array([0.0, 900.0, 0.0]))[0]


def test_planar_2dof_has_no_branch_ambiguity_and_fk_is_on_branch():
    m = planar_2dof_3act()
    x = m.sample_poses(100, np.random.default_rng(4))
    assert m.assembly_signs(x).shape == (100, 0)
    fk = m.fk(m.ik(x))
    assert fk.ok.all() and np.max(np.abs(fk.poses - x)) < 1e-8
