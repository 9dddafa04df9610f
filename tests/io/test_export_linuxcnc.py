"""LinuxCNC genhexkins export: parse the HAL text back and run the points through
genhexkins' strut-length formula, re-implemented here from LinuxCNC's C source
(``src/emc/kinematics/genhexkins.c``, inverse kinematics; ``pmRpyMatConvert`` and
``pmMatCartMult`` of ``src/libnml/posemath/_posemath.c``), independently of pkmcal."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.io.export_linuxcnc import LINUXCNC_ROUNDING, linuxcnc_hal, linuxcnc_ini, rounded_machine
from pkmcal.mechanisms import builtin_machine, symmetric_hexapod

SETP = re.compile(r"^setp\s+genhexkins\.(base|platform)\.([0-5])\.([xyz])\s+(\S+)\s*$")
JOINT = re.compile(r"^#\s*pkmcal\.joint\.([0-5])\s+leg=(\d)\s+L0=(\S+)\s+MIN_LIMIT=(\S+)\s+MAX_LIMIT=(\S+)\s+HOME=(\S+)$")


def parse_hal(text):
    pts = {"base": np.full((6, 3), np.nan), "platform": np.full((6, 3), np.nan)}
    joints = {}
    for line in text.splitlines():
        if line.startswith("setp"):
            m = SETP.match(line)
            assert m, f"unexpected setp line: {line!r}"
            kind, n, axis, value = m.groups()
            assert np.isnan(pts[kind][int(n), "xyz".index(axis)]), f"duplicate {line!r}"
            pts[kind][int(n), "xyz".index(axis)] = float(value)
        elif JOINT.match(line):
            n, leg, *vals = JOINT.match(line).groups()
            assert int(leg) == int(n) + 1
            joints[int(n)] = [float(v) for v in vals]
        else:
            assert line == "" or line.startswith("#"), f"not a comment: {line!r}"
    assert not np.isnan(pts["base"]).any() and not np.isnan(pts["platform"]).any()
    return pts["base"], pts["platform"], joints


def genhexkins_inverse(base, platform, pos_deg, spindle_offset=0.0, tool_offset=0.0):
    """Strut lengths of genhexkins' inverse kinematics for one pose X Y Z A B C (mm, deg).

    pmRpyMatConvert fills the matrix by columns m.x, m.y, m.z (sa, sb, sg = sin of yaw,
    pitch, roll); pmMatCartMult computes out = m.x·v.x + m.y·v.y + m.z·v.z. The offsets
    are added to the z of both joints, as in genhex_inv.
    """
    x, y, z, a, b, c = pos_deg
    r, p, yw = a * math.pi / 180.0, b * math.pi / 180.0, c * math.pi / 180.0
    sa, sb, sg = math.sin(yw), math.sin(p), math.sin(r)
    ca, cb, cg = math.cos(yw), math.cos(p), math.cos(r)
    mx = (ca * cb, sa * cb, -sb)
    my = (ca * sb * sg - sa * cg, sa * sb * sg + ca * cg, cb * sg)
    mz = (ca * sb * cg + sa * sg, sa * sb * cg - ca * sg, cb * cg)
    out = []
    for n in range(6):
        ax, ay, az = platform[n]
        bx, by, bz = base[n]
        az += spindle_offset + tool_offset
        bz += spindle_offset + tool_offset
        tx = mx[0] * ax + my[0] * ay + mz[0] * az
        ty = mx[1] * ax + my[1] * ay + mz[1] * az
        tz = mx[2] * ax + my[2] * ay + mz[2] * az
        dx, dy, dz = x + tx - bx, y + ty - by, z + tz - bz
        out.append(math.sqrt(dx * dx + dy * dy + dz * dz))
    return np.array(out)


def random_poses(machine, n, seed):
    rng = np.random.default_rng(seed)
    half = np.array([30.0, 30.0, 15.0, *np.deg2rad([20.0, 20.0, 180.0])])
    return machine.home_pose + rng.uniform(-1, 1, (n, 6)) * half


def perturbed(machine, seed, scale=2.0):
    rng = np.random.default_rng(seed)
    rho = machine.params.copy()
    rho[:42] += rng.normal(0.0, scale, 42)  # the geometry; the gains (1) are the readings' unit, not exported
    return machine.with_params(rho, name=machine.name + "-calibrated")


#: Half a unit of the 6th decimal LinuxCNC exports are rounded to (1 nm, export_linuxcnc
#: LINUXCNC_DECIMALS), plus the decimal conversion's round-off of numbers below 1e3.
HALF_NM = 0.5e-6 + np.spacing(1e3)
#: The largest change of a strut length |p + R a − b| when each coordinate of a and b moves
#: by up to HALF_NM: |Δb| + |Δa| (R keeps lengths) ≤ 2·√3·HALF_NM.
STRUT_ROUNDING = 2 * np.sqrt(3) * HALF_NM


def assert_rounded_to_nm(text_values, exact):
    """The written numbers are the exact ones rounded to 6 decimals: at most 6 decimals each,
    and within half a unit of the 6th of the exact value."""
    for t in text_values:
        assert len(t.partition(".")[2]) <= 6, t
    np.testing.assert_allclose(np.array([float(t) for t in text_values]), np.ravel(exact), rtol=0, atol=HALF_NM)


def check_against_genhexkins(machine, seed, n=100):
    text = linuxcnc_hal(machine)
    base, platform, joints = parse_hal(text)
    assert_rounded_to_nm([line.split()[-1] for line in text.splitlines() if line.startswith("setp")],
                         np.concatenate([machine.base.ravel(), machine.platform.ravel()]))
    poses = random_poses(machine, n, seed)
    L = machine.leg_lengths(poses)
    deg = np.column_stack([poses[:, :3], np.rad2deg(poses[:, 3:])])
    ghk = np.array([genhexkins_inverse(base, platform, q) for q in deg])
    np.testing.assert_allclose(ghk, L, rtol=0, atol=STRUT_ROUNDING + 1e-9)
    # and exactly the struts of the machine as written (export_linuxcnc.rounded_machine)
    np.testing.assert_allclose(ghk, rounded_machine(machine).leg_lengths(poses), rtol=0, atol=1e-9)
    return base, platform, joints


@pytest.mark.parametrize("name", ["stewart-prototype", "stewart-prototype-real"])
def test_builtin_machines_reproduce_leg_lengths_through_genhexkins(name):
    check_against_genhexkins(builtin_machine(name), seed=1)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.01, 5.0))
def test_calibrated_machine_reproduces_leg_lengths_through_genhexkins(seed, scale):
    m = perturbed(builtin_machine("stewart-prototype"), seed, scale)
    base, platform, _ = check_against_genhexkins(m, seed)
    # the numbers read back are those of the machine as written, exactly
    np.testing.assert_array_equal(base, rounded_machine(m).base)
    np.testing.assert_array_equal(platform, rounded_machine(m).platform)


def test_joint_comments_carry_offsets_limits_and_home():
    m = perturbed(symmetric_hexapod(stroke=80.0), 4)
    _, _, joints = parse_hal(linuxcnc_hal(m))
    assert sorted(joints) == list(range(6))
    J = np.array([joints[n] for n in range(6)])
    np.testing.assert_array_equal(J[:, 0], rounded_machine(m).offset)
    # the joint limits stand the default stroke margin (1 % of the 80 mm stroke) inside it
    np.testing.assert_allclose(J[:, 1], m.offset + m.stroke[:, 0] + 0.8, rtol=0, atol=HALF_NM)
    np.testing.assert_allclose(J[:, 2], m.offset + m.stroke[:, 1] - 0.8, rtol=0, atol=HALF_NM)
    _, _, joints = parse_hal(linuxcnc_hal(m, stroke_margin=0.0))
    np.testing.assert_allclose([joints[n][1] for n in range(6)], m.offset + m.stroke[:, 0], rtol=0, atol=HALF_NM)
    np.testing.assert_allclose(J[:, 3], m.leg_lengths(m.home_pose)[0], rtol=0, atol=HALF_NM)
    # homing: a joint set to L0 + λ is the strut length genhexkins expects at that reading
    # (the offset rounded to 1 nm: half a unit of its 6th decimal)
    poses = random_poses(m, 20, 2)
    lam = m.ik(poses)
    np.testing.assert_allclose(J[:, 0] + lam, m.leg_lengths(poses), rtol=0, atol=HALF_NM + 1e-9)


def test_header_states_units_and_convention():
    text = linuxcnc_hal(builtin_machine("stewart-prototype"))
    head = "\n".join(line for line in text.splitlines() if line.startswith("#"))
    # the rounding is said in a comment line of both files
    assert f"# pkmcal: {LINUXCNC_ROUNDING}" in text.splitlines()
    assert f"# pkmcal: {LINUXCNC_ROUNDING}" in linuxcnc_ini(builtin_machine("stewart-prototype")).splitlines()
    for needle in ("mm", "degrees", "Rz(C) Ry(B) Rx(A)", "spindle-offset", "screw-lead", "HOME_OFFSET"):
        assert needle in head
    assert text.count("\nsetp ") + text.startswith("setp ") == 36


def test_spindle_offset_would_move_the_frames():
    # why the header insists on spindle-offset = 0: genhexkins adds it to both joint z's,
    # which changes the strut lengths whenever the platform is tilted
    m = builtin_machine("stewart-prototype")
    base, platform, _ = parse_hal(linuxcnc_hal(m))
    q = [1.0, -2.0, 310.0, 5.0, -3.0, 10.0]
    assert np.abs(genhexkins_inverse(base, platform, q, spindle_offset=10.0)
                  - genhexkins_inverse(base, platform, q)).max() > 0.1


def test_rejects_non_finite_and_non_hexapods():
    m = builtin_machine("stewart-prototype")
    rho = m.params.copy()
    rho[0] = np.nan
    with pytest.raises(PkmcalError, match="non-finite"):
        linuxcnc_hal(m.with_params(rho))
    with pytest.raises(PkmcalError, match="6-UPS hexapods .*'servo-stewart' is a 6-RSS machine"):
        linuxcnc_hal(builtin_machine("servo-stewart"))   # the error names the machine's kind, not a Python type
