"""Measurement CSV files: round trips, leg lengths, units, deterministic bytes, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from pkmcal.errors import InputFileError
from pkmcal.io.measurements import Measurements, load_measurements, save_measurements
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype

MACHINE = stewart_prototype()
SETUPS = {name: load_setup(name) for name in ("indicators-prototype", "full-pose-paper1", "laser-tracker")}


def _meas(n, m, seed, commanded=True):
    rng = np.random.default_rng(seed)
    cmd = None
    if commanded:
        cmd = np.c_[rng.uniform(-20, 20, (n, 3)), rng.uniform(-0.2, 0.2, (n, 3))]
    return Measurements(actuators=rng.uniform(0, 50, (n, 6)), readings=rng.uniform(-0.5, 300, (n, m)), commanded=cmd)


@settings(max_examples=20, deadline=None)
@given(name=st.sampled_from(sorted(SETUPS)), n=st.integers(1, 30), seed=st.integers(0, 10**6), cmd=st.booleans())
def test_round_trip_and_deterministic_bytes(tmp_path_factory, name, n, seed, cmd):
    setup = SETUPS[name]
    meas = _meas(n, setup.sensor.n_readings, seed, cmd)
    d = tmp_path_factory.mktemp("m")
    save_measurements(d / "a.csv", meas, MACHINE, setup)
    save_measurements(d / "b.csv", meas, MACHINE, setup)
    assert (d / "a.csv").read_bytes() == (d / "b.csv").read_bytes()
    back = load_measurements(d / "a.csv", MACHINE, setup)
    np.testing.assert_array_equal(back.actuators, meas.actuators)            # lengths: exact
    ang = np.array(setup.sensor.reading_is_angle)
    np.testing.assert_array_equal(back.readings[:, ~ang], meas.readings[:, ~ang])
    # degrees in the file: rad → deg → rad is two products with rounded constants (180/π,
    # π/180), four roundings of u = ε/2 at most: relative error ≤ 2ε (+ O(ε²))
    rt = 2.5 * np.finfo(float).eps
    np.testing.assert_allclose(back.readings[:, ang], meas.readings[:, ang], rtol=rt, atol=0)
    if cmd:
        np.testing.assert_allclose(back.commanded, meas.commanded, rtol=rt, atol=0)
    else:
        assert back.commanded is None
    assert back.source == str(d / "a.csv") and len(back) == n and back.notes == ()
    assert list(back.lines) == list(range(2, 2 + n))  # header, then rows (no comment unless asked)


def test_full_pose_file_in_degrees_with_extra_columns(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("note,lambda1,lambda2,lambda3,lambda4,lambda5,lambda6,x,y,z,a,b,c\n"
                 "first,1,2,3,4,5,6,10,20,300,90,-45,180\n")
    m = load_measurements(p, MACHINE, SETUPS["full-pose-paper1"])
    np.testing.assert_array_equal(m.actuators, [[1, 2, 3, 4, 5, 6]])
    np.testing.assert_allclose(m.readings, [[10, 20, 300, np.pi / 2, -np.pi / 4, np.pi]])
    assert m.where(0) == f"{p}, line 2"


def test_leg_lengths_are_converted_with_the_machine_offsets(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("l1,l2,l3,l4,l5,l6,d1,d2,d3\n330,331,332,333,334,335.5,1,2,3\n")
    m = load_measurements(p, MACHINE, SETUPS["indicators-prototype"])
    np.testing.assert_allclose(m.actuators, [[25, 26, 27, 28, 29, 30.5]])   # L0 = 305 mm
    np.testing.assert_array_equal(m.readings, [[1, 2, 3]])
    assert "leg lengths; converted to actuator readings" in m.notes[0]


def test_units_line_is_honoured(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("# units: length=m, angle=rad\nlambda1,lambda2,lambda3,lambda4,lambda5,lambda6,px,py,pz\n"
                 "0.001,0.002,0.003,0.004,0.005,0.006,0.1,0.2,0.3\n")
    m = load_measurements(p, MACHINE, SETUPS["laser-tracker"])
    np.testing.assert_allclose(m.actuators, [[1, 2, 3, 4, 5, 6]])
    np.testing.assert_allclose(m.readings, [[100, 200, 300]])


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("lambda1,lambda2,lambda3,lambda4,lambda5,lambda6,d1,d2\n1,2,3,4,5,6,1,2\n",
         r"line 1: missing column d3.*the 'indicators' setup expects columns d1, d2, d3 \(mm\) and "
         r"lambda1..lambda6 \(actuator readings, mm\) or l1..l6 \(leg lengths, mm\)"),
        ("d1,d2,d3\n1,2,3\n", r"missing columns lambda1.*or l1..l6"),
        ("lambda1,lambda2,lambda3,lambda4,lambda5,lambda6,d1,d2,d3,cmd_x,cmd_y\n1,2,3,4,5,6,1,2,3,0,0\n",
         r"commanded-pose columns cmd_x, cmd_y but not cmd_z, cmd_a, cmd_b, cmd_c"),
        ("lambda1,lambda2,lambda3,lambda4,lambda5,lambda6,d1,d2,d3\n1,2,3,4,5,6,1,x,3\n",
         r"line 2, column 'd2': 'x' is not a number"),
        ("lambda1,lambda2,lambda3,lambda4,lambda5,lambda6,d1,d2,d3\n", r"no data rows"),
    ],
)
def test_errors_name_file_and_what_is_expected(tmp_path, text, pattern):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputFileError, match=pattern) as err:
        load_measurements(p, MACHINE, SETUPS["indicators-prototype"])
    assert str(err.value).startswith(str(p))


def test_missing_file(tmp_path):
    with pytest.raises(InputFileError, match="cannot read"):
        load_measurements(tmp_path / "nope.csv", MACHINE, SETUPS["laser-tracker"])


def test_shapes_are_checked():
    with pytest.raises(Exception, match="same N"):
        Measurements(actuators=np.zeros((3, 6)), readings=np.zeros((2, 3)))


@settings(max_examples=10, deadline=None)
@given(a=arrays(float, (3, 6), elements=st.floats(-1e6, 1e6, allow_nan=False)))
def test_lengths_round_trip_exactly(tmp_path_factory, a):
    setup = SETUPS["laser-tracker"]
    meas = Measurements(actuators=a, readings=a[:, :3])
    p = tmp_path_factory.mktemp("x") / "m.csv"
    save_measurements(p, meas, MACHINE, setup)
    back = load_measurements(p, MACHINE, setup)
    assert back.actuators.tobytes() == meas.actuators.tobytes()
    assert back.readings.tobytes() == meas.readings.tobytes()


def test_planar_rotary_encoders_are_degrees_in_files(tmp_path):
    from pkmcal.mechanisms.library import builtin_machine

    m = builtin_machine("planar-2dof-3act")
    setup = load_setup("planar-tracker", m)
    poses = np.array([[0.0, 205.0], [-30.0, 180.0], [40.0, 230.0]])
    q = m.ik(poses)
    meas = Measurements(actuators=q, readings=setup.sensor.predict(m.frame(poses)), commanded=poses)
    path = tmp_path / "m.csv"
    save_measurements(path, meas, m, setup)
    text = path.read_text()
    assert "q1,q2,q3,px,py,cmd_x,cmd_y" in text
    first = [float(v) for v in text.splitlines()[-3].split(",")]
    np.testing.assert_allclose(first[:3], np.rad2deg(q[0]), rtol=0, atol=1e-12)
    back = load_measurements(path, m, setup)
    np.testing.assert_allclose(back.actuators, q, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(back.commanded, poses)
    # linear encoders of planar-3dof-4act stay mm
    m4 = builtin_machine("planar-3dof-4act")
    s4 = load_setup("planar-tracker", m4)
    p4 = np.array([[0.0, 230.0, 0.1]])
    save_measurements(path, Measurements(m4.ik(p4), s4.sensor.predict(m4.frame(p4)), p4), m4, s4)
    assert float(path.read_text().splitlines()[-1].split(",")[0]) == m4.ik(p4)[0, 0]
    assert np.array_equal(load_measurements(path, m4, s4).actuators, m4.ik(p4))
