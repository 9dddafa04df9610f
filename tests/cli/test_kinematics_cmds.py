"""``pkmcal ik``, ``pkmcal fk`` and ``pkmcal info``: results checked independently, every
error path (exit code 2, one stderr line, no traceback, no output file)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation
from helpers import assert_user_error

from pkmcal.workflow.machine_info import single_axis_ranges
from pkmcal.cli.main import cli
from pkmcal.io import load_machine, read_table, save_machine
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype

POSES = np.array([
    [0.0, 0.0, 315.0, 0.0, 0.0, 0.0],
    [10.0, 5.0, 320.0, 2.0, -3.0, 4.0],
    [-20.0, 12.5, 305.0, -5.0, 4.0, -15.0],
    [200.0, 0.0, 315.0, 0.0, 0.0, 0.0],  # far outside: violates limits
])


def run(*args: str):
    result = CliRunner().invoke(cli, list(args))
    return result


def _write_poses(path, poses=POSES) -> None:
    path.write_text(format_table({n: poses[:, k] for k, n in enumerate("xyzabc")}))


def _independent_lengths(machine, poses_deg):
    """L_i = ‖p + R a_i − b_i‖ with R from scipy (extrinsic xyz = Rz(c) Ry(b) Rx(a))."""
    R = Rotation.from_euler("xyz", poses_deg[:, 3:], degrees=True).as_matrix()
    tops = poses_deg[:, None, :3] + np.einsum("nrc,ic->nir", R, machine.platform)
    return np.linalg.norm(tops - machine.base[None], axis=2)


def test_ik_values_and_reachability(tmp_path):
    _write_poses(tmp_path / "poses.csv")
    out = tmp_path / "legs.csv"
    result = run("ik", "stewart-prototype", "--poses", str(tmp_path / "poses.csv"), "-o", str(out))
    assert result.exit_code == 0, result.output
    assert "4 poses, 3 reachable" in result.stderr
    m = stewart_prototype()
    cols = ("x", "y", "z", "a", "b", "c") + tuple(f"l{i}" for i in range(1, 7)) + tuple(f"lambda{i}" for i in range(1, 7))
    t = read_table(out, cols)
    np.testing.assert_array_equal(t[list("xyzabc")], POSES)  # echoed exactly
    L = _independent_lengths(m, POSES)
    np.testing.assert_allclose(t[[f"l{i}" for i in range(1, 7)]], L, rtol=0, atol=1e-9)
    np.testing.assert_allclose(t[[f"lambda{i}" for i in range(1, 7)]], L - 305.0, rtol=0, atol=1e-9)
    reach = [line.rsplit(",", 1)[1] for line in out.read_text().splitlines()[1:]]
    assert reach[:3] == ["ok", "ok", "ok"]
    assert reach[3] != "ok" and reach[3].split("+")[0] == "stroke"


def test_ik_to_stdout_and_fk_round_trip(tmp_path):
    _write_poses(tmp_path / "poses.csv", POSES[:3])
    ik = run("ik", "stewart-prototype-real", "--poses", str(tmp_path / "poses.csv"))
    assert ik.exit_code == 0
    (tmp_path / "legs.csv").write_text(ik.stdout)
    fk = run("fk", "stewart-prototype-real", str(tmp_path / "legs.csv"), "-o", str(tmp_path / "back.csv"))
    assert fk.exit_code == 0, fk.output
    assert "3 rows, 3 converged" in fk.stderr
    back = read_table(tmp_path / "back.csv", ("x", "y", "z", "a", "b", "c", "converged", "iterations"))
    np.testing.assert_allclose(back[list("xyz")], POSES[:3, :3], rtol=0, atol=1e-8)
    np.testing.assert_allclose(back[list("abc")], POSES[:3, 3:], rtol=0, atol=1e-9)
    assert back["converged"].tolist() == [1, 1, 1]
    assert np.all(back["iterations"] >= 1)


def test_fk_from_lengths_matches_readings(tmp_path):
    m = stewart_prototype()
    L = _independent_lengths(m, POSES[:3])
    (tmp_path / "l.csv").write_text(format_table({f"l{i + 1}": L[:, i] for i in range(6)}))
    (tmp_path / "q.csv").write_text(format_table({f"lambda{i + 1}": L[:, i] - 305.0 for i in range(6)}))
    a = run("fk", "stewart-prototype", str(tmp_path / "l.csv"))
    b = run("fk", "stewart-prototype", str(tmp_path / "q.csv"), "--guess", "0,0,310,0,0,0")
    assert a.exit_code == b.exit_code == 0
    ta = read_table("a", list("xyzabc"), text=a.stdout)
    tb = read_table("b", list("xyzabc"), text=b.stdout)
    np.testing.assert_allclose(ta.values, POSES[:3], atol=1e-8)
    np.testing.assert_allclose(tb.values, POSES[:3], atol=1e-8)


def test_fk_reports_non_converged_rows_and_exits_0(tmp_path):
    rows = np.array([[25.0] * 6, [-300.0] * 6, [25.0] * 6])  # row 2: legs of length 5 mm: no pose
    (tmp_path / "q.csv").write_text("# readings\n" + format_table({f"lambda{i + 1}": rows[:, i] for i in range(6)},
                                                                   units=None))
    res = run("fk", "stewart-prototype", str(tmp_path / "q.csv"), "-o", str(tmp_path / "p.csv"))
    assert res.exit_code == 0
    assert "3 rows, 2 converged" in res.stderr
    assert "1 rows did not converge (their poses are nan): lines 4 of" in res.stderr
    lines = (tmp_path / "p.csv").read_text().splitlines()
    assert lines[2].startswith("nan,nan,nan,nan,nan,nan,0,")
    assert lines[1].endswith(",1," + lines[1].rsplit(",", 1)[1])


def test_machine_file_argument(tmp_path):
    save_machine(load_machine("stewart-prototype-real"), tmp_path / "m.yaml")
    _write_poses(tmp_path / "poses.csv", POSES[:2])
    a = run("ik", str(tmp_path / "m.yaml"), "--poses", str(tmp_path / "poses.csv"))
    b = run("ik", "stewart-prototype-real", "--poses", str(tmp_path / "poses.csv"))
    assert a.exit_code == 0 and a.stdout == b.stdout


# -- errors: exit 2, one line, nothing written -------------------------------------------------

@pytest.mark.parametrize(
    "content, fragments",
    [
        ("x,y,z,a,b\n1,2,3,4,5\n", ["poses.csv, line 1", "missing column c"]),
        ("x,y,z,a,b,c\n1,2,3,4,5,6\n1,2,oops,4,5,6\n", ["poses.csv, line 3, column 'z'", "'oops' is not a number"]),
        ("", ["poses.csv", "the file is empty"]),
        ("x,y,z,a,b,c\n1,2,3\n", ["poses.csv, line 2", "3 cells"]),
    ],
)
def test_ik_input_errors(tmp_path, content, fragments):
    (tmp_path / "poses.csv").write_text(content)
    out = tmp_path / "out.csv"
    res = run("ik", "stewart-prototype", "--poses", str(tmp_path / "poses.csv"), "-o", str(out))
    assert_user_error(res, *fragments)
    assert not out.exists()


def test_machine_errors(tmp_path):
    _write_poses(tmp_path / "poses.csv")
    out = tmp_path / "out.csv"
    assert_user_error(run("ik", "no-such-machine", "--poses", str(tmp_path / "poses.csv"), "-o", str(out)),
                       "unknown machine 'no-such-machine'")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nlegs:\n  - {base: [0, 0, 0], platform: [0, 0, 0], offset: 1, stroke: [0, 1]}\n")
    assert_user_error(run("fk", str(bad), str(tmp_path / "poses.csv"), "-o", str(out)),
                       "bad.yaml, line 2", "legs: 1 legs given, a hexapod needs exactly 6")
    assert_user_error(run("ik", str(tmp_path / "missing.yaml"), "--poses", str(tmp_path / "poses.csv")), "no such machine file")
    assert not out.exists()


def test_file_errors(tmp_path):
    out = tmp_path / "out.csv"
    assert_user_error(run("ik", "stewart-prototype", "--poses", str(tmp_path / "none.csv"), "-o", str(out)),
                       "none.csv", "cannot read the table")
    assert_user_error(run("ik", "stewart-prototype", "--poses", str(tmp_path), "-o", str(out)), "cannot read the table")
    _write_poses(tmp_path / "poses.csv")
    assert_user_error(run("ik", "stewart-prototype", "--poses", str(tmp_path / "poses.csv"), "-o",
                           str(tmp_path / "no-dir" / "out.csv")), "cannot write")
    assert sorted(os.listdir(tmp_path)) == ["poses.csv"]


def test_output_equal_to_input_is_refused(tmp_path):
    _write_poses(tmp_path / "poses.csv")
    before = (tmp_path / "poses.csv").read_bytes()
    assert_user_error(run("ik", "stewart-prototype", "--poses", str(tmp_path / "poses.csv"), "-o", str(tmp_path / "poses.csv")),
                       "is the input file")
    save_machine(stewart_prototype(), tmp_path / "m.yaml")
    assert_user_error(run("ik", str(tmp_path / "m.yaml"), "--poses", str(tmp_path / "poses.csv"), "-o", str(tmp_path / "m.yaml")),
                       "is the input file")
    assert (tmp_path / "poses.csv").read_bytes() == before


def test_fk_errors(tmp_path):
    (tmp_path / "q.csv").write_text("lambda1,lambda2,l3\n1,2,3\n")
    assert_user_error(run("fk", "stewart-prototype", str(tmp_path / "q.csv")),
                       "needs lambda1..lambda6 or l1..l6", "missing columns lambda3, lambda4, lambda5, lambda6")
    (tmp_path / "q.csv").write_text(format_table({f"lambda{i}": [25.0] for i in range(1, 7)}))
    assert_user_error(run("fk", "stewart-prototype", str(tmp_path / "q.csv"), "--guess", "1,2,3"),
                       "--guess '1,2,3': needs 6 comma-separated numbers")
    assert_user_error(run("fk", "stewart-prototype", str(tmp_path / "q.csv"), "--guess", "0,0,z,0,0,0"),
                       "not all of x,y,z,a,b,c are numbers")


# -- info ---------------------------------------------------------------------------------------

def test_info_lists_the_parameter_names_by_unit():
    """What --free, --fix, --prior and a study's error groups name, grouped by unit: a delta's
    tower angles and leans in degrees, its radii, arms and endstops in mm (every name once)."""
    from pkmcal.mechanisms.library import builtin_machine

    res = run("info", "kossel-mini", "--n-poses", "5")
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("parameters ("))
    texts: dict[str, str] = {}
    unit = None
    for line in lines[start + 1:]:
        if line.startswith("    ") and unit is not None:      # a wrapped continuation
            texts[unit] += " " + line.strip()
        elif line.startswith("  ") and ": " in line:
            unit, _, names = line.strip().partition(": ")
            texts[unit] = names
        else:
            break
    groups = {u: [n.strip() for n in t.split(",")] for u, t in texts.items()}
    machine = builtin_machine("kossel-mini")
    assert lines[start].startswith(f"parameters ({len(machine.param_names)};")
    assert sorted(n for names in groups.values() for n in names) == sorted(machine.param_names)
    assert "angle_a" in groups["deg"] and "lean_radial_c" in groups["deg"] and "radius_b" in groups["mm"]


def test_info_default_machine():
    res = run("info", "--poses", "60")
    assert res.exit_code == 0, res.output
    out = res.stdout
    assert out.startswith("stewart-prototype: 6-UPS hexapod")
    assert "single-axis ranges from home" in out
    assert "converged 60/60" in out
    err = float(out.split("max position error ")[1].split(" mm")[0])
    assert err < 1e-8


def test_info_unknown_machine():
    assert_user_error(run("info", "nope"), "unknown machine 'nope'")


def test_single_axis_ranges_are_the_limits():
    """Just inside each end every limit holds; just outside the named limit is violated."""
    m = stewart_prototype()
    ranges, stops = single_axis_ranges(m, m.home)
    assert np.all(ranges[:, 0] < m.home) and np.all(ranges[:, 1] > m.home)
    for k in range(6):
        for side, sign in ((0, -1.0), (1, 1.0)):
            inside, outside = m.home.copy(), m.home.copy()
            inside[k] = ranges[k, side] - sign * 1e-5
            outside[k] = ranges[k, side] + sign * 1e-5
            rep = m.check_limits(np.array([inside, outside]))
            assert rep.ok.tolist() == [True, False]
            assert rep.verdicts()[1] == stops[k][side]
    # The prototype's x travel is limited by the stroke: at the +x end a leg reads 0 or 50 mm.
    end = m.home.copy()
    end[0] = ranges[0, 1]
    q = m.ik(end)[0]
    assert min(abs(q.min()), abs(q.max() - 50.0)) < 1e-5


def test_planar_machine_ik_fk_round_trip(tmp_path):
    """The commands work for any Mechanism: paper 3's redundant planar machine (x, y, phi; q1..q4)."""
    (tmp_path / "p.csv").write_text("x,y,phi\n0,230,0\n10,200,5\n")
    ik = run("ik", "planar-3dof-4act", "--poses", str(tmp_path / "p.csv"), "-o", str(tmp_path / "q.csv"))
    assert ik.exit_code == 0, ik.output
    assert (tmp_path / "q.csv").read_text().splitlines()[0] == "x,y,phi,q1,q2,q3,q4,reachable"
    fk = run("fk", "planar-3dof-4act", str(tmp_path / "q.csv"))
    assert fk.exit_code == 0, fk.output
    back = read_table("fk", ("x", "y", "phi", "converged"), text=fk.stdout)
    np.testing.assert_allclose(back[["x", "y", "phi"]], [[0, 230, 0], [10, 200, 5]], atol=1e-8)
    assert back["converged"].tolist() == [1, 1]


def test_rotary_actuators_are_degrees_in_files(tmp_path):
    m = load_machine("planar-2dof-3act")
    (tmp_path / "p.csv").write_text("x,y\n0,200\n10,220\n")
    ik = run("ik", "planar-2dof-3act", "--poses", str(tmp_path / "p.csv"), "-o", str(tmp_path / "q.csv"))
    assert ik.exit_code == 0, ik.output
    q = read_table(tmp_path / "q.csv", ("q1", "q2", "q3"))
    np.testing.assert_allclose(q.values, np.rad2deg(m.ik(np.array([[0, 200.0], [10, 220.0]]))), rtol=1e-15)
    assert np.all(np.abs(q.values) > 10)  # degrees, not radians
    fk = run("fk", "planar-2dof-3act", str(tmp_path / "q.csv"))
    back = read_table("fk", ("x", "y"), text=fk.stdout)
    np.testing.assert_allclose(back.values, [[0, 200], [10, 220]], atol=1e-8)


@pytest.mark.parametrize("args", [["stewart-prototype", "--n-poses", "60"], ["planar-3dof-4act"],
                                  ["kossel-mini", "--n-poses", "40", "--seed", "3"]])
def test_info_json_is_the_text_and_in_mm_and_degrees(args):
    """``info --json`` carries every figure the text prints (the text is made from the same
    dict: info_lines of the parsed JSON is the printed text), its workspace ranges are
    single_axis_ranges in mm and degrees, and its counts add up."""
    import json

    from pkmcal.cli.info_cmd import info_lines

    text, js = run("info", *args), run("info", *args, "--json")
    assert text.exit_code == js.exit_code == 0, js.output
    data = json.loads(js.stdout)
    assert info_lines(data) == text.stdout.splitlines()
    mech, _ = load_machine(args[0]).within_geometry()
    ranges, stops = single_axis_ranges(mech, np.asarray(mech.home_pose, dtype=float))
    for k, name in enumerate(mech.pose_names):
        r = data["workspace"]["ranges"][name]
        scale = 180.0 / np.pi if mech.pose_is_angle[k] else 1.0
        assert r["unit"] == ("deg" if mech.pose_is_angle[k] else "mm") and r["stopped_by"] == stops[k]
        assert [r["min"], r["max"]] == pytest.approx(ranges[k] * scale, rel=1e-12)
    rt = data["round_trip"]
    assert rt["returned"] + rt["other_mode"] + rt["other_pose"] + rt["not_converged"] == rt["n"]
