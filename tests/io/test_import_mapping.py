"""Files from other tools: ``--columns OLD=NEW,...``, ``--length-unit``, ``--angle-unit``.

Every command that reads a pose or measurement CSV is run twice: on a pkmcal file, and on
the same data as another tool would write it (other column names, other column order, an
extra column, metres/inches and radians, a units line that the options replace). The
results must agree (to the rounding of the unit conversion)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io import load_machine, read_table
from pkmcal.io.import_mapping import ImportMapping, make_mapping, parse_column_mapping
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype

POSE_NAMES = ("x", "y", "z", "a", "b", "c")
FOREIGN_POSE = {"x": "X [m]", "y": "Y [m]", "z": "Z [m]", "a": "Roll", "b": "Pitch", "c": "Yaw"}
MAP_POSE = ",".join(f"{v}={k}" for k, v in FOREIGN_POSE.items())


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


def user_error(res, *fragments):
    assert res.exit_code == 2, res.output
    err = res.stderr.strip()
    assert err.startswith("pkmcal: error: ") and "\n" not in err and "Traceback" not in res.output
    for f in fragments:
        assert f in err, err
    return err


def poses_deg(n=12, seed=0):
    """Poses near the prototype's home (mm, deg), all reachable by the nominal and the real machine."""
    rng = np.random.default_rng(seed)
    home = stewart_prototype().home_pose
    half = np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])
    p = rng.uniform(-1, 1, (n, 6)) * half
    p[:, :3] += home[:3]
    return p


def write_pkmcal(path, cols: dict):
    path.write_text(format_table(cols), encoding="utf-8")


def write_foreign(path, cols: dict, rename: dict, length_names=(), angle_names=(), length_factor=1000.0,
                  units_line="# units: length=mm, angle=deg"):
    """``cols`` (mm, deg) as another tool writes them: renamed, reversed order, lengths divided
    by ``length_factor`` (mm per unit), angles in radians, an extra text column, and a units
    line that is wrong for the file (the options must replace it)."""
    out = {"comment": ["row"] * len(next(iter(cols.values())))}
    for name in reversed(list(cols)):
        v = np.asarray(cols[name], dtype=float)
        if name in length_names:
            v = v / length_factor
        elif name in angle_names:
            v = np.deg2rad(v)
        out[rename.get(name, name)] = v
    text = format_table(out, units=None)
    path.write_text(f"{units_line}\n" + text if units_line else text, encoding="utf-8")


def pose_cols(p):
    return {n: p[:, k] for k, n in enumerate(POSE_NAMES)}


def write_pose_pair(tmp_path, p):
    write_pkmcal(tmp_path / "poses.csv", pose_cols(p))
    write_foreign(tmp_path / "foreign.csv", pose_cols(p), FOREIGN_POSE, length_names="xyz", angle_names="abc")
    return tmp_path / "poses.csv", tmp_path / "foreign.csv"


FOREIGN_OPTS = ("--columns", MAP_POSE, "--length-unit", "m", "--angle-unit", "rad")


# -- the mapping itself ------------------------------------------------------------------------

def test_parse_column_mapping():
    assert parse_column_mapping("X [m]=x, Leg 1 = lambda1") == {"x [m]": "x", "leg 1": "lambda1"}
    assert parse_column_mapping(None) == {} and parse_column_mapping("  ") == {}
    with pytest.raises(PkmcalError, match="item 'x' is not OLD=NEW"):
        parse_column_mapping("a=b,x")
    with pytest.raises(PkmcalError, match="'a' is mapped twice"):
        parse_column_mapping("a=x,A=y")
    with pytest.raises(PkmcalError, match="several columns are mapped to 'x'"):
        parse_column_mapping("a=x,b=x")
    with pytest.raises(PkmcalError, match="not OLD=NEW"):
        parse_column_mapping("=x")
    assert make_mapping(None, None, None) is None
    with pytest.raises(PkmcalError, match="--length-unit 'furlong'"):
        make_mapping(None, "furlong", None)
    m = make_mapping("u=x", "in", "rad")
    assert m.units == {"length": "in", "angle": "rad"} and "length unit in" in m.describe()


def test_read_table_renames_and_converts(tmp_path):
    p = poses_deg(5)
    ref, foreign = write_pose_pair(tmp_path, p)
    mapping = ImportMapping(rename=parse_column_mapping(MAP_POSE), length_unit="m", angle_unit="rad")
    t = read_table(foreign, POSE_NAMES, mapping=mapping)
    np.testing.assert_allclose(t.values, read_table(ref, POSE_NAMES).values, rtol=1e-14, atol=1e-12)
    assert t.units == {"length": "m", "angle": "rad"}  # the options replaced the (wrong) units line
    # without the unit options, the file's own units line applies (here mm, deg): values unscaled
    t2 = read_table(foreign, POSE_NAMES, mapping=ImportMapping(rename=parse_column_mapping(MAP_POSE)))
    np.testing.assert_allclose(t2["x"], p[:, 0] / 1000.0, rtol=1e-15)
    # inch
    write_foreign(tmp_path / "in.csv", pose_cols(p), FOREIGN_POSE, length_names="xyz", length_factor=25.4,
                  units_line=None)
    t3 = read_table(tmp_path / "in.csv", POSE_NAMES, mapping=ImportMapping(rename=parse_column_mapping(MAP_POSE),
                                                                            length_unit="in"))
    np.testing.assert_allclose(t3.values, p, rtol=1e-14, atol=1e-12)


def test_rename_errors_name_file_line_and_column(tmp_path):
    _, foreign = write_pose_pair(tmp_path, poses_deg(3))
    with pytest.raises(InputFileError) as exc:
        read_table(foreign, POSE_NAMES, mapping=ImportMapping(rename={"x (m)": "x"}))
    msg = str(exc.value)
    assert msg.startswith(f"{foreign}, line 2:") and "'x (m)'" in msg and "'X [m]'" in msg
    # a rename onto a column the file already has is a duplicate, named
    with pytest.raises(InputFileError, match="both name 'comment'"):
        read_table(foreign, POSE_NAMES, mapping=ImportMapping(rename={"roll": "comment"}))
    # bad cell: the error names the column as written in the file
    text = foreign.read_text().splitlines()
    text[3] = text[3].replace(text[3].split(",")[1], "abc", 1)
    foreign.write_text("\n".join(text) + "\n")
    with pytest.raises(InputFileError) as exc:
        read_table(foreign, POSE_NAMES, mapping=ImportMapping(rename=parse_column_mapping(MAP_POSE)))
    assert f"{foreign}, line 4, column 'Yaw': 'abc' is not a number" in str(exc.value)


# -- every command that reads a CSV ------------------------------------------------------------

def test_ik_and_fk(tmp_path):
    p = poses_deg(10)
    ref, foreign = write_pose_pair(tmp_path, p)
    ok(run("ik", "stewart-prototype", "--poses", ref, "-o", tmp_path / "a.csv"))
    ok(run("ik", "stewart-prototype", "--poses", foreign, "-o", tmp_path / "b.csv", *FOREIGN_OPTS))
    legs = tuple(f"lambda{i}" for i in range(1, 7))
    a, b = read_table(tmp_path / "a.csv", legs), read_table(tmp_path / "b.csv", legs)
    np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-9)
    # fk on readings in inches under the names 'Leg 1'..'Leg 6'
    write_foreign(tmp_path / "legs.csv", {n: a[n] for n in legs}, {n: f"Leg {n[-1]}" for n in legs},
                  length_names=legs, length_factor=25.4, units_line=None)
    mapping = ",".join(f"Leg {i}=lambda{i}" for i in range(1, 7))
    ok(run("fk", "stewart-prototype", tmp_path / "legs.csv", "-o", tmp_path / "fk.csv", "--columns", mapping,
           "--length-unit", "in"))
    back = read_table(tmp_path / "fk.csv", POSE_NAMES)
    np.testing.assert_allclose(back.values, p, rtol=0, atol=1e-7)
    # without the mapping the file is refused with the header it has
    user_error(run("fk", "stewart-prototype", tmp_path / "legs.csv"), "legs.csv, line 1: missing columns",
               "'Leg 6'")


def test_simulate_identify_verify(tmp_path):
    p = poses_deg(40, seed=3)
    ref, foreign = write_pose_pair(tmp_path, p)
    sim = ("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
           "--seed", "5")
    ok(run(*sim, "--poses", ref, "-o", tmp_path / "meas.csv"))
    ok(run(*sim, "--poses", foreign, "-o", tmp_path / "meas2.csv", *FOREIGN_OPTS))
    cols = tuple(f"lambda{i}" for i in range(1, 7)) + ("d1", "d2", "d3")
    a, b = read_table(tmp_path / "meas.csv", cols), read_table(tmp_path / "meas2.csv", cols)
    np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-8)

    # identify on the measurements as a CMM-style export: dials named 'Dial A'.., metres,
    # legs as 'Leg i', commanded pose dropped
    meas = {n: a[n] for n in cols}
    rename = {**{f"lambda{i}": f"Leg {i}" for i in range(1, 7)}, "d1": "Dial A", "d2": "Dial B", "d3": "Dial C"}
    write_foreign(tmp_path / "cmm.csv", meas, rename, length_names=cols, length_factor=1000.0)
    mapping = ",".join(f"{v}={k}" for k, v in rename.items())
    ident = ("identify", "stewart-prototype", "--setup", "indicators-prototype")
    ok(run(*ident, tmp_path / "meas.csv", "-o", tmp_path / "cal.yaml"))
    ok(run(*ident, tmp_path / "cmm.csv", "-o", tmp_path / "cal2.yaml", "--columns", mapping, "--length-unit", "m"))
    c1, c2 = load_machine(tmp_path / "cal.yaml"), load_machine(tmp_path / "cal2.yaml")
    # Same data up to unit round-off: the two fits may stop at slightly different points
    # along the weakly determined direction (3 indicators), so compare against the
    # parameters' own uncertainty, not an absolute tolerance.
    std = np.sqrt(np.diag(c1.covariance))
    assert np.all(np.abs(c2.params - c1.params) <= 1e-2 * std + 1e-9)
    err = user_error(run(*ident, tmp_path / "cmm.csv", "-o", tmp_path / "cal3.yaml"), "cmm.csv, line 2: missing column")
    assert "'Dial A'" in err and not (tmp_path / "cal3.yaml").exists()

    # verify on held-out poses from the other tool
    held = poses_deg(15, seed=9)
    ref_h, foreign_h = tmp_path / "h.csv", tmp_path / "hf.csv"
    write_pkmcal(ref_h, pose_cols(held))
    write_foreign(foreign_h, pose_cols(held), FOREIGN_POSE, length_names="xyz", angle_names="abc")
    ver = ("verify", tmp_path / "cal.yaml", "--real", "stewart-prototype-real", "--nominal", "stewart-prototype",
           "--json")
    j1 = json.loads(ok(run(*ver, "--poses", ref_h)).stdout)
    j2 = json.loads(ok(run(*ver, "--poses", foreign_h, *FOREIGN_OPTS)).stdout)
    for part in ("before", "after"):
        for k, v in j1[part].items():
            if isinstance(v, float):
                assert j2[part][k] == pytest.approx(v, rel=1e-9, abs=1e-12), (part, k)


def test_identifiability_observability_plan(tmp_path):
    p = poses_deg(30, seed=4)
    ref, foreign = write_pose_pair(tmp_path, p)
    base = ("identifiability", "stewart-prototype", "--setup", "indicators-prototype", "--json")
    r1 = json.loads(ok(run(*base, "--poses", ref)).stdout)
    r2 = json.loads(ok(run(*base, "--poses", foreign, *FOREIGN_OPTS)).stdout)
    assert r1["rank"] == r2["rank"] == 39 and r1["n_params"] == 42
    s1, s2 = np.array(r1["singular_values"]), np.array(r2["singular_values"])
    np.testing.assert_allclose(s2[:39], s1[:39], rtol=1e-7)
    assert s1[39:].max() < 1e-12 * s1[0] and s2[39:].max() < 1e-12 * s2[0]  # the 3 null directions

    obs = ("observability", "stewart-prototype")
    o1 = json.loads(ok(run(*obs, ref, "--setup", "indicators-prototype", "--json")).stdout)
    o2 = json.loads(ok(run(*obs, foreign, "--setup", "indicators-prototype", "--json", *FOREIGN_OPTS)).stdout)
    for k in ("O1", "O2", "O3", "O4", "O5"):
        assert o2[k] == pytest.approx(o1[k], rel=1e-6), k

    plan = ("plan", "stewart-prototype", "--setup", "indicators-prototype", "--n-poses", "15", "--seed", "1")
    ok(run(*plan, "--candidates", ref, "-o", tmp_path / "p1.csv"))
    ok(run(*plan, "--candidates", foreign, "-o", tmp_path / "p2.csv", *FOREIGN_OPTS))
    np.testing.assert_allclose(read_table(tmp_path / "p2.csv", POSE_NAMES).values,
                               read_table(tmp_path / "p1.csv", POSE_NAMES).values, rtol=0, atol=1e-9)


def test_bad_options_are_user_errors(tmp_path):
    ref, foreign = write_pose_pair(tmp_path, poses_deg(3))
    user_error(run("ik", "stewart-prototype", "--poses", foreign, "--columns", "X [m]"), "--columns", "not OLD=NEW")
    res = run("ik", "stewart-prototype", "--poses", foreign, "--length-unit", "furlong")
    assert res.exit_code == 2 and "Traceback" not in res.output  # click's own usage error
    user_error(run("ik", "stewart-prototype", "--poses", ref, "--columns", "nope=x"), "poses.csv, line 1:", "'nope'")
