"""Orientations as unit quaternions or rotation vectors in pose and measurement CSVs
(:mod:`pkmcal.io.orientation`, issue 11 item 1a).

Checked against independent constructions: the quaternion of R = Rz(c)·Ry(b)·Rx(a) as the
Hamilton product q_z(c) ⊗ q_y(b) ⊗ q_x(a) of axis quaternions, and the rotation vector's
matrix by Rodrigues' formula, both written out here (not scipy); the angles read back are
compared with the angles written (to 1e-9 degree: the round-off of a 180° angle through a
matrix and atan2 is ~1e-13°), or, at gimbal lock where a and c are not separately defined,
the rotation matrices are compared.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.conventions import POSE_COLUMNS, euler_to_matrix
from pkmcal.errors import InputFileError
from pkmcal.io.import_mapping import ImportMapping
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import load_setup
from pkmcal.io.tables import read_poses, read_table
from pkmcal.mechanisms.library import builtin_machine

EULER_TOL_DEG = 1e-9
ANGLE = st.floats(-179.999, 180.0, allow_nan=False)
PITCH = st.floats(-89.5, 89.5, allow_nan=False)


def hamilton(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """p ⊗ q, both (x, y, z, w)."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return np.array([pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw,
                     pw * qw - px * qx - py * qy - pz * qz])


def quat_of_euler_deg(a: float, b: float, c: float) -> np.ndarray:
    """(x, y, z, w) of Rz(c) Ry(b) Rx(a), from half-angle axis quaternions."""
    ha, hb, hc = np.deg2rad([a, b, c]) / 2
    qx = np.array([np.sin(ha), 0.0, 0.0, np.cos(ha)])
    qy = np.array([0.0, np.sin(hb), 0.0, np.cos(hb)])
    qz = np.array([0.0, 0.0, np.sin(hc), np.cos(hc)])
    return hamilton(qz, hamilton(qy, qx))


def rodrigues(r_rad: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(r_rad)
    if theta == 0:
        return np.eye(3)
    k = r_rad / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))
    return path


def test_hamilton_construction_is_the_pose_convention():
    """The helper itself, against the library's closed-form matrix (an independent check of
    the check): R(q) from the quaternion formula equals euler_to_matrix."""
    a, b, c = 25.0, -40.0, 130.0
    x, y, z, w = quat_of_euler_deg(a, b, c)
    Rq = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                   [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                   [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    np.testing.assert_allclose(Rq, euler_to_matrix(np.deg2rad([a, b, c])), atol=1e-15)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(ANGLE, PITCH, ANGLE), min_size=1, max_size=8), st.booleans())
def test_quaternion_columns_read_as_the_same_euler_angles(tmp_path_factory, angles, flip):
    """Euler → quaternion (independent) → file → Euler: the angles written, to round-off;
    −q reads as exactly what q reads as."""
    d = tmp_path_factory.mktemp("q")
    abc = np.array(angles)
    q = np.array([quat_of_euler_deg(*row) for row in abc])
    rows = [[1.5, -2.0, 300.0, *qq] for qq in q]
    t = read_table(write(d / "q.csv", ["x", "y", "z", "qx", "qy", "qz", "qw"], rows), POSE_COLUMNS)
    assert t.columns == POSE_COLUMNS
    np.testing.assert_array_equal(t["x"], 1.5)
    got = t[["a", "b", "c"]]
    diff = (got - abc + 180.0) % 360.0 - 180.0   # a, c = ±180° are one angle
    assert np.max(np.abs(diff)) < EULER_TOL_DEG
    if flip:
        rows_neg = [[1.5, -2.0, 300.0, *(-qq)] for qq in q]
        t_neg = read_table(write(d / "qneg.csv", ["x", "y", "z", "qx", "qy", "qz", "qw"], rows_neg), POSE_COLUMNS)
        np.testing.assert_allclose(t_neg[["a", "b", "c"]], got, rtol=0, atol=1e-12)


@pytest.mark.parametrize("pitch", [90.0, -90.0])
def test_gimbal_lock_poses_give_the_same_rotation(tmp_path, pitch):
    """At b = ±90° only a ∓ c is defined: the matrix of the angles read is the matrix written."""
    abc = np.array([[30.0, pitch, -20.0], [0.0, pitch, 0.0], [-170.0, pitch, 100.0]])
    rows = [[0.0, 0.0, 300.0, *quat_of_euler_deg(*r)] for r in abc]
    t = read_table(write(tmp_path / "g.csv", ["x", "y", "z", "qx", "qy", "qz", "qw"], rows), POSE_COLUMNS)
    np.testing.assert_allclose(euler_to_matrix(np.deg2rad(t[["a", "b", "c"]])), euler_to_matrix(np.deg2rad(abc)),
                               rtol=0, atol=1e-12)
    assert np.all(np.abs(t["b"] - pitch) < 1e-6)


def test_named_columns_in_any_order_and_positional_columns_by_order(tmp_path):
    abc = np.array([[10.0, -20.0, 30.0], [-100.0, 45.0, 170.0]])
    q = np.array([quat_of_euler_deg(*r) for r in abc])
    wxyz = q[:, [3, 0, 1, 2]]
    named = read_table(write(tmp_path / "n.csv", ["qw", "qx", "qy", "qz", "x", "y", "z"],
                             [[*w, 1, 2, 3] for w in wxyz]), POSE_COLUMNS)
    np.testing.assert_allclose(named[["a", "b", "c"]], abc, atol=EULER_TOL_DEG)
    path = write(tmp_path / "p.csv", ["x", "y", "z", "q1", "q2", "q3", "q4"], [[1, 2, 3, *w] for w in wxyz])
    scalar_first = read_table(path, POSE_COLUMNS, mapping=ImportMapping(quaternion_order="wxyz"))
    np.testing.assert_allclose(scalar_first[["a", "b", "c"]], abc, atol=EULER_TOL_DEG)
    path_xyzw = write(tmp_path / "p2.csv", ["x", "y", "z", "q1", "q2", "q3", "q4"], [[1, 2, 3, *v] for v in q])
    np.testing.assert_allclose(read_table(path_xyzw, POSE_COLUMNS)[["a", "b", "c"]], abc, atol=EULER_TOL_DEG)
    # the wrong order is caught only by the angles (a unit quaternion either way): it reads differently
    wrong = read_table(path, POSE_COLUMNS)
    assert np.max(np.abs(wrong[["a", "b", "c"]] - abc)) > 1.0


def test_mapping_renames_a_mocap_export_to_quaternion_columns(tmp_path):
    abc = np.array([[5.0, 6.0, 7.0]])
    q = quat_of_euler_deg(*abc[0])
    path = write(tmp_path / "mocap.csv", ["Pos X", "Pos Y", "Pos Z", "Rot X", "Rot Y", "Rot Z", "Rot W"],
                 [[0.001, 0.002, 0.3, *q]])
    from pkmcal.io.import_mapping import make_mapping

    mapping = make_mapping("Pos X=x,Pos Y=y,Pos Z=z,Rot X=qx,Rot Y=qy,Rot Z=qz,Rot W=qw", "m", None)
    t = read_table(path, POSE_COLUMNS, mapping=mapping)
    np.testing.assert_allclose(t[["x", "y", "z"]], [[1.0, 2.0, 300.0]], rtol=1e-15)
    np.testing.assert_allclose(t[["a", "b", "c"]], abc, atol=EULER_TOL_DEG)


@pytest.mark.parametrize("unit", ["deg", "rad"])
def test_rotation_vector_columns_against_rodrigues(tmp_path, unit):
    rng = np.random.default_rng(4)
    r_rad = rng.normal(size=(6, 3)) * np.array([[0.3, 0.5, 1.2]])
    r_rad[0] = 0.0
    r_rad[1] = [0.0, 0.0, np.pi * 0.999]
    values = np.rad2deg(r_rad) if unit == "deg" else r_rad
    path = write(tmp_path / "r.csv", ["x", "y", "z", "rx", "ry", "rz"], [[0, 0, 300, *v] for v in values])
    mapping = ImportMapping(angle_unit="rad") if unit == "rad" else None
    t = read_table(path, POSE_COLUMNS, mapping=mapping)
    for k in range(len(r_rad)):
        np.testing.assert_allclose(euler_to_matrix(np.deg2rad(t[["a", "b", "c"]][k])), rodrigues(r_rad[k]),
                                   rtol=0, atol=1e-12)
    # the units line says the same as --angle-unit
    if unit == "rad":
        path.write_text("# units: angle=rad\n" + path.read_text())
        np.testing.assert_array_equal(read_table(path, POSE_COLUMNS).values, t.values)


def test_non_unit_quaternion_is_an_error_naming_file_line_and_pose(tmp_path):
    ok = quat_of_euler_deg(1.0, 2.0, 3.0)
    rows = [[0, 0, 300, *ok], [0, 0, 300, *(ok * (1 + 5e-7))], [0, 0, 300, *(ok * (1 + 2e-6))]]
    path = tmp_path / "q.csv"
    path.write_text("# units: length=mm\n" + write(tmp_path / "tmp.csv", ["x", "y", "z", "qx", "qy", "qz", "qw"],
                                                   rows).read_text())
    with pytest.raises(InputFileError) as info:
        read_table(path, POSE_COLUMNS)
    msg = str(info.value)
    assert msg.startswith(f"{path}, line 5: pose 3: the quaternion (qx, qy, qz, qw)") and "norm 1.000002" in msg
    rows[2] = [0, 0, 300, 0.0, 0.0, 0.0, 0.0]
    path.write_text(write(tmp_path / "tmp.csv", ["x", "y", "z", "qx", "qy", "qz", "qw"], rows).read_text())
    with pytest.raises(InputFileError, match=r"line 4: pose 3: .* has norm 0.0"):
        read_table(path, POSE_COLUMNS)
    rows.pop()
    t = read_table(write(path, ["x", "y", "z", "qx", "qy", "qz", "qw"], rows), POSE_COLUMNS)
    np.testing.assert_allclose(t[["a", "b", "c"]], [[1.0, 2.0, 3.0]] * 2, atol=1e-9)   # within 1e-6: normalised


def test_two_ways_of_one_orientation_and_missing_ones_are_errors(tmp_path):
    q = quat_of_euler_deg(1.0, 2.0, 3.0)
    both = write(tmp_path / "b.csv", ["x", "y", "z", "a", "b", "c", "qx", "qy", "qz", "qw"],
                 [[0, 0, 300, 1, 2, 3, *q]])
    with pytest.raises(InputFileError, match=r"line 1: the orientation is given twice, as a,b,c and as qx,qy,qz,qw"):
        read_table(both, POSE_COLUMNS)
    t = read_table(both, POSE_COLUMNS, mapping=ImportMapping(rename={"qx": "unused_1"}))
    np.testing.assert_array_equal(t[["a", "b", "c"]], [[1.0, 2.0, 3.0]])
    half = write(tmp_path / "h.csv", ["x", "y", "z", "qx", "qy", "qw"], [[0, 0, 300, 0, 0, 1]])
    with pytest.raises(InputFileError, match="missing columns a, b, c .*or give the orientation as a unit quaternion "
                                             "qx,qy,qz,qw"):
        read_table(half, POSE_COLUMNS)


def test_measurements_with_quaternion_readings_and_commands_equal_the_euler_file(tmp_path):
    """A full-pose (motion-capture) measurement file: sensor pose and commanded pose as
    quaternions read as the same measurements as the file with a, b, c."""
    machine = builtin_machine("stewart-prototype")
    setup = load_setup("full-pose-paper1", machine)
    rng = np.random.default_rng(1)
    n = 5
    lam = rng.uniform(10, 40, size=(n, 6))
    pos = rng.normal(size=(n, 3)) + [0, 0, 315]
    abc = rng.uniform(-8, 8, size=(n, 3))
    cmd = np.hstack([pos + 0.01, abc + 0.02])
    euler_cols = {**{f"lambda{i + 1}": lam[:, i] for i in range(6)},
                  **{c: np.hstack([pos, abc])[:, k] for k, c in enumerate(POSE_COLUMNS)},
                  **{f"cmd_{c}": cmd[:, k] for k, c in enumerate(POSE_COLUMNS)}}
    from pkmcal.io.tables import format_table

    (tmp_path / "e.csv").write_text(format_table(euler_cols))
    quat = {k: v for k, v in euler_cols.items() if k not in ("a", "b", "c", "cmd_a", "cmd_b", "cmd_c")}
    q = np.array([quat_of_euler_deg(*r) for r in abc])
    qc = np.array([quat_of_euler_deg(*r) for r in cmd[:, 3:]])
    quat.update({f"q{c}": q[:, k] for k, c in enumerate("xyzw")})
    quat.update({f"cmd_q{c}": qc[:, k] for k, c in enumerate("xyzw")})
    (tmp_path / "q.csv").write_text(format_table(quat))
    me = load_measurements(tmp_path / "e.csv", machine, setup)
    mq = load_measurements(tmp_path / "q.csv", machine, setup)
    np.testing.assert_array_equal(mq.actuators, me.actuators)
    np.testing.assert_allclose(mq.readings, me.readings, rtol=0, atol=1e-13)
    np.testing.assert_allclose(mq.commanded, me.commanded, rtol=0, atol=1e-13)


def test_cli_reads_quaternion_poses_with_the_order_option(tmp_path):
    abc = np.array([[3.0, -4.0, 20.0], [0.0, 0.0, 0.0]])
    pos = np.array([[1.0, -2.0, 315.0], [0.0, 0.0, 320.0]])
    write(tmp_path / "e.csv", list(POSE_COLUMNS), np.hstack([pos, abc]))
    q = np.array([quat_of_euler_deg(*r) for r in abc])
    write(tmp_path / "q.csv", ["x", "y", "z", "q1", "q2", "q3", "q4"], np.hstack([pos, q[:, [3, 0, 1, 2]]]))
    runner = CliRunner()
    ref = runner.invoke(cli, ["ik", "stewart-prototype", "--poses", str(tmp_path / "e.csv")])
    got = runner.invoke(cli, ["ik", "stewart-prototype", "--poses", str(tmp_path / "q.csv"), "--quaternion-order", "wxyz"])
    assert ref.exit_code == 0 and got.exit_code == 0, got.output
    ref_lines, got_lines = ref.stdout.splitlines(), got.stdout.splitlines()
    assert ref_lines[0] == got_lines[0]
    a = np.array([[float(v) for v in line.split(",")[:-1]] for line in ref_lines[1:]])
    b = np.array([[float(v) for v in line.split(",")[:-1]] for line in got_lines[1:]])
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
    bad = runner.invoke(cli, ["ik", "stewart-prototype", "--poses", str(tmp_path / "q.csv"), "--quaternion-order", "zyxw"])
    assert bad.exit_code == 2
    np.testing.assert_allclose(read_poses(tmp_path / "q.csv", builtin_machine("stewart-prototype"),
                                          ImportMapping(quaternion_order="wxyz"))[:, 3:],
                               np.deg2rad(abc), atol=1e-12)
